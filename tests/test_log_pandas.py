"""The pandas recipe of docs/logs.md, run as written on a real trial log: every table a DataFrame with the
documented columns, numbers in SI units, text as str."""

import json
import math
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from antarium.core.clock import SimulatedClock
from antarium.locomotion import open_source
from antarium.locomotion.scripted import BALL_RADIUS_M
from antarium.server.frame_loop import FrameLoop
from antarium.trial_log import FRAME_DTYPE, SAMPLE_DTYPE, TrialLog, _text_dtypes

DOC = (Path(__file__).resolve().parent.parent / "docs" / "logs.md").read_text()
DOC_PATH = "trials/rig1_20260101-120000_familiar.h5"


def _doc_recipe() -> str:
    reading = DOC[DOC.index("## Reading"):]
    match = re.search(r"```python\n(.*?)```", reading, re.S)
    assert match, "docs/logs.md: no python block under '## Reading'"
    assert f'"{DOC_PATH}"' in match.group(1)
    return match.group(1)


@pytest.fixture(scope="module")
def log_file(tmp_path_factory):
    """Two simulated seconds of a walker at 0.02 m/s along +x, the scene rotated by 90° at 1 s."""
    path = tmp_path_factory.mktemp("logs") / "rig1_pandas.h5"
    clock = SimulatedClock()
    with TrialLog(path, {"rig": {"name": "rig1"}}, "familiar", {"ant": 7, "colony": "M. croslandi"}) as log:
        loop = FrameLoop(clock=clock, source=open_source("scripted", clock=clock), log=log)
        loop.run(until=1.0)
        loop.rotate_scene(math.pi / 2)
        log.add_command(clock.now(), "rotate_scene", {"deg": 90}, {"ok": True, "result": {}}, True)
        log.add_command(clock.now(), "rotate_scene", {"deg": "a lot"}, {"error": "deg must be a number"}, False)
        loop.run(until=2.0)
        loop.event("note", text="after the last frame")
    return path


def test_the_documented_recipe_gives_dataframes_with_documented_columns_and_units(log_file):
    namespace = {}
    exec(_doc_recipe().replace(DOC_PATH, str(log_file)), namespace)  # noqa: S102 - the doc's own code
    frames, samples = namespace["frames"], namespace["samples"]
    events, commands = namespace["events"], namespace["commands"]
    text = _text_dtypes()
    for table, names in ((frames, FRAME_DTYPE.names), (samples, SAMPLE_DTYPE.names),
                         (events, (*text["events"].names, "frame")), (commands, text["commands"].names),
                         (namespace["scenes"], text["scenes"].names)):
        assert isinstance(table, pd.DataFrame)
        assert list(table.columns) == list(names)
    for name in FRAME_DTYPE.names:  # numeric columns keep their numeric types
        assert frames[name].dtype == FRAME_DTYPE[name], name

    assert len(frames) == 380 and (np.diff(frames["frame"]) == 1).all()
    assert frames["t_target"].iloc[-1] == pytest.approx(379 / 190)  # seconds
    walked = np.hypot(frames["x"].diff(), frames["y"].diff()).sum()  # metres: the 2 cm/s walker
    assert walked == pytest.approx(0.02 * 379 / 190, rel=0.01)
    assert frames["scene_rotation"].iloc[-1] == pytest.approx(math.pi / 2)  # radians, not degrees
    assert frames["scene_rotation"].iloc[0] == 0.0
    assert (frames["closed_loop"] == 1).all()

    assert len(samples) > 0 and (np.diff(samples["seq"]) == 1).all()
    assert (samples["t"].diff().dropna() >= 0).all() and samples["t"].iloc[-1] <= 2.0  # seconds
    rolled = float(np.hypot(samples["rx"], samples["ry"]).sum()) * BALL_RADIUS_M  # radians × ball radius
    assert rolled == pytest.approx(0.02 * samples["t"].iloc[-1], rel=0.01)  # = the 2 cm/s walk, in metres
    assert samples["rz"].abs().max() < 1e-12  # no turning

    kinds = list(events["kind"])
    assert "scene_rotated" in kinds and all(isinstance(k, str) for k in kinds)
    rotated = json.loads(events["data"][kinds.index("scene_rotated")])
    assert rotated["angle"] == pytest.approx(math.pi / 2)
    # the recipe's join: the first frame that showed the rotation, the frame before did not
    shown = int(events["frame"][kinds.index("scene_rotated")])
    assert frames["scene_rotation"][frames["frame"] == shown].item() == pytest.approx(math.pi / 2)
    assert frames["scene_rotation"][frames["frame"] == shown - 1].item() == 0.0
    assert math.isnan(events["frame"][kinds.index("note")])  # after the last frame: none showed it

    assert list(commands["name"]) == ["rotate_scene", "rotate_scene"]
    assert json.loads(commands["request"][0]) == {"deg": 90} and list(commands["ok"]) == [1, 0]
    assert "error" in json.loads(commands["reply"][1])
    assert namespace["config"] == {"rig": {"name": "rig1"}}
    assert namespace["metadata"] == {"ant": 7, "colony": "M. croslandi"}
