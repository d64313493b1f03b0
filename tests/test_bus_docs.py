"""docs/bus.md lists every command, parameter, scene-edit operation and stream struct size."""

from pathlib import Path

from antarium import bus
from antarium.locomotion import wire
from antarium.server.commands import COMMANDS, SCENE_EDITS

DOC = (Path(__file__).resolve().parent.parent / "docs" / "bus.md").read_text()


def test_every_command_and_parameter_is_documented():
    for command, entry in COMMANDS.items():
        assert f"`{command}`" in DOC, command
        for name in entry.params:
            assert f"`{name}`" in DOC, (command, name)
    for op, (_, args) in SCENE_EDITS.items():
        assert f"`{op}`" in DOC, op
        for name in args:
            assert f"`{name}`" in DOC, (op, name)


def test_struct_sizes_match_the_document():
    assert f"{bus.POSE_STRUCT.size}-byte pose" in DOC
    assert f"{bus.STATS_STRUCT.size}-byte frame-statistics" in DOC
    assert f"{wire.SIZE}-byte locomotion" in DOC
