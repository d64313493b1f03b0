"""`antarium.Rig` raises `RigError`, and only `RigError`, for what the server refuses; messages show plain numbers
(issue 20, point 10). Pose-only rig on the bus; the start-up scene error with a real renderer."""

import numpy as np
import pytest

import antarium
from antarium import bus
from antarium.client import RigError
from antarium.config import resolve
from antarium.server import Server, ServerError


def _config(tmp_path, rig, **extra):
    return resolve({"rig": {"name": rig}, "bus": {"listen": [bus.free_tcp_endpoint()]},
                    "log": {"dir": str(tmp_path / "logs")}, **extra})


def _deep(n: int) -> list:
    """A list nested `n` deep."""
    value: list = []
    for _ in range(n):
        value = [value]
    return value


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    config = _config(tmp_path_factory.mktemp("client"), "terr")
    server = Server(config, renderer_factory=None, link=False).start_thread()
    with antarium.Rig("terr", config=config, timeout_s=10.0) as rig:
        yield rig
    server.stop()


@pytest.mark.parametrize("call, message", [
    (lambda rig: rig.polarisers("x"), "polarisers: parameter 'angles_deg' must be a (nested) list of numbers"),
    (lambda rig: rig.polarisers([[1.0, 2.0]]), "55 lists of 9 numbers"),
    (lambda rig: rig.gains(translation=np.float32(500.0)), "must be in [-100, 100], got 500.0"),
    (lambda rig: rig.set_pose(np.float64(1.0), np.int64(2), heading_deg=np.float64(1e5)), "got 100000.0"),
    (lambda rig: rig.wait(np.float64(-5.0)), "seconds in [0, 86400], got -5.0"),
    (lambda rig: rig.rotate_scene(object()), "rotate_scene: parameter 'deg' cannot be sent (object is not a number"),
    # nesting deeper than JSON's writer goes was a RecursionError; a set did not say which parameter it was
    (lambda rig: rig.set_pose(_deep(3000), 0), "set_pose: parameter 'x' cannot be sent (nested too deeply)"),
    (lambda rig: rig.call("trial_start", name="t", metadata={"a": _deep(5000)}),
     "trial_start: parameter 'metadata' cannot be sent (nested too deeply)"),
    (lambda rig: rig.set_pose(0, {1, 2}), "set_pose: parameter 'y' cannot be sent (set is not a number"),
    # a command name that is not a string was a TypeError (unhashable); a pose timeout that is not a duration a
    # TypeError, and NaN waited for ever
    (lambda rig: rig.call(["status"]), "unknown command ['status']; allowed: load_scene"),
    (lambda rig: rig.pose(timeout_s="x"), "pose: timeout_s must be a finite number of seconds >= 0, got 'x'"),
    (lambda rig: rig.pose(timeout_s=float("nan")), "pose: timeout_s must be a finite number of seconds >= 0, got nan"),
])
def test_every_refusal_is_a_rig_error_with_plain_numbers(rig, call, message):
    with pytest.raises(RigError) as info:
        call(rig)
    assert type(info.value) is RigError
    assert message in str(info.value) and "np." not in str(info.value)


def test_a_protocol_waits_on_the_clock_its_rig_was_given(tmp_path):
    """`Rig.wait` slept wall time whatever the script wanted: a protocol's schedule could not be tested without
    waiting it out. With `clock=`, wait and now run on that clock (no server needed for either)."""
    from antarium.core.clock import SimulatedClock

    config = _config(tmp_path, "tclock")
    rig = antarium.Rig("tclock", config=config, clock=SimulatedClock(start=100.0))
    rig.wait(3600)
    rig.wait(np.float64(0.5))
    assert rig.now() == 3700.5
    with pytest.raises(RigError, match=r"clock must have now\(\) and sleep_until\(t\).*got str"):
        antarium.Rig("tclock", config=config, clock="wall")
    wall = antarium.Rig("tclock", config=config)
    before = wall.now()
    wall.wait(0.01)
    assert wall.now() >= before + 0.01


def test_numpy_values_are_accepted(rig):
    state = rig.set_pose(np.float64(0.5), np.int64(1), heading_deg=np.float32(90.0))
    assert state["pose"]["x"] == 0.5 and state["pose"]["y"] == 1.0


def test_a_start_up_scene_error_does_not_name_a_scene_none(tmp_path):
    def small_renderer(render_cfg, clock=None):
        from antarium.renderers import Renderer

        return Renderer(face_size=64, clock=clock)

    config = _config(tmp_path, "tstart", render={"scene": str(tmp_path / "missing.glb")}, link={"interface": "virtual"})
    with pytest.raises(ServerError) as info:
        Server(config, renderer_factory=small_renderer, echo=lambda line: None).start_thread()
    assert "failed to load" in str(info.value) and "no scene was loaded before" in str(info.value)
    assert "None" not in str(info.value)
