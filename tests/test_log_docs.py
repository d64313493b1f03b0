"""docs/logs.md lists every column of every trial-log table, in that table's own paragraph, and the data of every
event that changes what the dome shows."""

import json
import math
import re
from pathlib import Path

import h5py

from antarium.core.clock import SimulatedClock
from antarium.core.pose import Pose
from antarium.locomotion import open_source
from antarium.server.frame_loop import FrameLoop
from antarium.trial_log import TrialLog, read_table

DOC = (Path(__file__).resolve().parent.parent / "docs" / "logs.md").read_text()
TABLES = DOC[DOC.index("## Tables"):DOC.index("## What the dome showed")]
SHOWN = DOC[DOC.index("## What the dome showed"):DOC.index("## Reading")]


def _section(table: str) -> str:
    """The paragraph (or column table) of `table` under '## Tables'."""
    match = re.search(rf"^`{table}` — (.*?)(?=^`\w+` — |\Z)", TABLES, re.S | re.M)
    assert match, f"docs/logs.md has no paragraph for table {table!r}"
    return match.group(1)


def test_every_table_and_column_of_a_log_is_documented_in_its_own_paragraph(tmp_path):
    """Checked against a file, not the dtypes: servosphere's omega_y, omega_z, rate2, ... were only 'omega_x/y/z'."""
    path = tmp_path / "doc.h5"
    TrialLog(path, {}, "doc").close()
    with h5py.File(path, "r") as f:
        attributes = DOC[DOC.index("## Attributes"):DOC.index("## Tables")]
        assert set(f.attrs) == set(re.findall(r"^\| `(\w+)`\s*\|", attributes, re.M))
        for table in f:
            text = _section(table)
            for name in f[table].dtype.names:
                assert f"`{name}`" in text, (table, name)


def test_every_event_that_changes_the_pose_or_loop_has_its_data_documented(tmp_path):
    path = tmp_path / "events.h5"
    clock = SimulatedClock()
    with TrialLog(path, {}, "events") as log:
        loop = FrameLoop(clock=clock, source=open_source("scripted", clock=clock), log=log)
        loop.run(until=0.1)
        loop.set_pose(Pose(0.1, 0.2, 0.01, math.pi / 2))
        loop.rotate_scene(math.pi / 4)
        loop.set_closed_loop(False)
        loop.set_tether("fixed")
        loop.set_gains(2.0)
        loop.reset_origin()
        loop.run(until=0.2)
    events = read_table(path, "events")
    assert len(events["kind"]) == 6
    for kind, data in zip(events["kind"], events["data"], strict=True):
        row = re.search(rf"^\| `{kind}`\s*\|(.*)$", SHOWN, re.M)
        assert row, f"event {kind!r} is not in the table of docs/logs.md"
        for key in json.loads(data):
            assert f"`{key}`" in row.group(1), (kind, key)
