"""The experiment scripts in examples/, each run in its short mode against one embedded server."""

import importlib.util
import json
import re
from pathlib import Path

import numpy as np
import pytest

from antarium import bus
from antarium.trial_log import open_log, read_table

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def _load(name):
    spec = importlib.util.spec_from_file_location(f"example_{name}", EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def rig_config(tmp_path_factory):
    from antarium.config import load_config
    from antarium.server import Server

    folder = tmp_path_factory.mktemp("examples")
    toml = folder / "rig.toml"
    toml.write_text(f"""
[rig]
name = "texamples"
[bus]
listen = ["{bus.free_tcp_endpoint()}"]
[render]
face_size_px = 64
far_layer = "off"  # the scripts, not the far layer (test_server_scene_swap): a load replies at once
[link]
interface = "virtual"
[log]
dir = "{folder / 'logs'}"
flush_s = 0.2
""")
    server = Server(load_config(toml), echo=lambda line: None).start_thread()
    yield toml, folder
    server.stop()


def _args(rig_config, out):
    toml, _ = rig_config
    return ["--config", str(toml), "--rig", "texamples", "--short", "--out", str(out)]


def test_proof_of_concept(rig_config, tmp_path, capsys):
    assert _load("proof_of_concept").main(_args(rig_config, tmp_path)) == 0
    text = capsys.readouterr().out
    for condition in ("familiar", "nest", "unfamiliar", "unstructured"):  # each condition's own line
        assert re.search(rf"^{condition}: \d+ poses, 1 rotations, log /", text, re.MULTILINE), condition
    logs = sorted(tmp_path.glob("*poc-*.h5"))  # everything the run writes lies under its --out
    assert len(logs) == 4 and not list((rig_config[1] / "logs").glob("*poc-*.h5"))
    (picture,) = tmp_path.glob("*_proof_of_concept_paths.png")  # named after the run's first log
    assert picture.stat().st_size > 10_000 and logs[0].name.startswith(picture.name.split("_proof_of_concept")[0])
    assert f"log {logs[0]}" in text  # reported absolute
    for log in logs:  # one instant rotation by +-90 deg, in closed loop, free in yaw, in every condition's log
        frames = read_table(log, "frames")
        jumps = np.degrees(np.diff(frames["scene_rotation"]))
        assert np.isclose(np.abs(jumps[np.abs(jumps) > 1e-3]), 90.0).tolist() == [True], log.name
        assert frames["closed_loop"].all() and not frames["fixed_tether"].any()
        assert list(read_table(log, "events")["kind"]).count("scene_rotated") == 1
    with open_log(next(p for p in logs if p.name.endswith("poc-unstructured.h5"))) as f:
        assert json.loads(f.attrs["metadata"])["scene"] == {"scene": "horizon"}  # the spec as JSON, not its repr


def test_open_loop_panoramas(rig_config, tmp_path, capsys):
    assert _load("open_loop_panoramas").main(_args(rig_config, tmp_path)) == 0
    on = re.findall(r"^(\S+\.png) was on for ([\d.]+) s$", capsys.readouterr().out, re.MULTILINE)
    assert [name for name, _ in on] == ["one_landmark.png", "two_landmarks.png", "skyline.png"]
    assert all(float(seconds) >= 0.6 - 0.005 for _, seconds in on)  # --short: 0.6 s each, at least
    log = next(tmp_path.glob("*open-loop-panoramas.h5"))
    scenes = read_table(log, "scenes")
    # The trial opens on the first image (loaded before it starts), not on what the rig showed before.
    assert [Path(n).name for n in scenes["name"]] == ["one_landmark.png", "two_landmarks.png", "skyline.png"]
    assert all(len(h) == 64 for h in scenes["sha256"])
    frames = read_table(log, "frames")
    assert not frames["closed_loop"].any()


def test_virtual_displacement(rig_config, tmp_path, capsys):
    assert _load("virtual_displacement").main(_args(rig_config, tmp_path)) == 0
    assert "displaced to (4.00, -3.00) m" in capsys.readouterr().out
    log = next(tmp_path.glob("*virtual-displacement.h5"))
    frames = read_table(log, "frames")
    xy = np.stack([frames["x"], frames["y"]], axis=1)
    steps = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    (jump,) = np.flatnonzero(steps > 1.0) + 1  # one displacement; the rest is walking
    assert np.linalg.norm(xy[jump] - [4.0, -3.0]) < 0.05 and np.linalg.norm(xy[0]) < 0.05
    assert np.isclose(frames["heading"][jump], frames["heading"][jump - 1], atol=1e-3)  # the heading mapping kept
    assert frames["closed_loop"].all()
    (picture,) = tmp_path.glob("*_path.png")
    assert picture.name == f"{log.stem}_path.png" and picture.stat().st_size > 10_000


def test_the_displacement_plot_shows_the_trials_path_only(rig_config, tmp_path, capsys, monkeypatch):
    """The plot took every pose from before the trial started (the scene load and loop switch: its 'before
    displacement' phase was seconds longer than --before) and after it ended; now the poses of the trial alone."""
    module = _load("virtual_displacement")
    plotted = []
    real_plot = module.plot
    monkeypatch.setattr(module, "plot", lambda updates, png: plotted.extend(updates) or real_plot(updates, png))
    assert module.main(_args(rig_config, tmp_path)) == 0
    frames = read_table(next(tmp_path.glob("*virtual-displacement.h5")), "frames")
    shown = np.array([u.frame for u in plotted])
    assert len(shown) > 10 and frames["frame"].min() <= shown.min() and shown.max() <= frames["frame"].max()


def test_a_second_run_into_the_same_out_keeps_the_first_runs_plot(rig_config, tmp_path, capsys):
    """Each run's picture is named after its own trial log, so a reused --out holds both runs, log and plot."""
    for _ in range(2):
        assert _load("virtual_displacement").main(_args(rig_config, tmp_path)) == 0
    logs = sorted(tmp_path.glob("*virtual-displacement*.h5"))
    assert len(logs) == 2
    assert sorted(p.name for p in tmp_path.glob("*.png")) == [f"{log.stem}_path.png" for log in logs]


def test_the_rig_is_the_configs_without_rig(rig_config, tmp_path, capsys):
    """`--config rig.toml` alone talks to the rig that file names ([rig] name = "texamples"), not to rig1."""
    toml, _ = rig_config
    args = ["--config", str(toml), "--short", "--out", str(tmp_path)]
    assert _load("virtual_displacement").main(args) == 0
    assert "displaced to (4.00, -3.00) m" in capsys.readouterr().out


def test_ant_homing_draws_the_nest_where_the_nest_is(tmp_path, monkeypatch):
    """The paths picture labels the drawn route's start "nest" and its end "feeder": the route drawn is the
    learned outbound one (nest first), not the way home (released at the feeder, which would swap the labels)."""
    module = _load("ant_homing")
    drawn = {}
    real = module.plot_paths

    def keep(path, route, tracks, *args, **kwargs):
        drawn["route"], drawn["release"] = route, tracks["homing Antcar"].arrays()[0][0]
        return real(path, route, tracks, *args, **kwargs)

    monkeypatch.setattr(module, "plot_paths", keep)
    assert module.main(["--short", "--out", str(tmp_path)]) == 0
    route = drawn["route"]
    assert np.linalg.norm(route.end - drawn["release"]) < 0.05  # released at the feeder
    assert np.linalg.norm(route.start - drawn["release"]) > 1.0  # the nest, 1.2 m away along the route
    assert (tmp_path / "homing_paths.png").stat().st_size > 10_000
