"""The demo run of the embedded default rig leaves a trial log, a path plot and a picture of the dome."""

import h5py

from antarium.rig_demo import run_demo_rig


def test_demo_rig_outputs(tmp_path):
    lines = []
    paths = run_demo_rig(tmp_path, seconds=2.0, echo=lines.append, render={"scene": "horizon", "face_size": 64})
    assert set(paths) == {"trial log", "path plot", "dome picture"}
    assert paths["path plot"].stat().st_size > 10_000 and paths["dome picture"].stat().st_size > 10_000
    with h5py.File(paths["trial log"], "r") as f:
        assert len(f["frames"]) >= 2 and f.attrs["trial_name"] == "demo"
    assert lines and lines[0].startswith("demo rig: ")
