"""The frame loop on a simulated clock: pacing, closed/open loop, tether modes, gains, commands, health."""

import math

import numpy as np
import pytest

from antarium.core.clock import SimulatedClock
from antarium.core.pose import Pose
from antarium.locomotion import BallSample, LocomotionSource, open_source
from antarium.server.frame_loop import FrameLoop


class SlowRenderer:
    """A renderer whose work takes `cost` seconds of the simulated clock (the seam the loop times); work longer
    than a frame period is its slow path (`last_full_render`)."""

    def __init__(self, clock, cost):
        self.clock, self.cost, self.last_timings, self.last_full_render = clock, cost, {}, False

    def render(self, pose, out=None):
        self.clock.advance(self.cost)
        self.last_timings = {"render": self.cost, "sample": 0.0, "convert": 0.0}
        self.last_full_render = self.cost > 1 / 190
        return np.zeros((20350, 2), np.uint16) if out is None else out


class RecordingLink:
    def __init__(self):
        self.frames = 0

    def send_frame(self, frame):
        self.frames += 1

    def send_polarisers(self, angles):
        pass

    def telemetry(self):
        return {}


class SwitchableSource(LocomotionSource):
    """A constant forward walker whose `connected` flag the test flips (an unplugged trackball)."""

    def __init__(self, clock):
        self.clock, self.connected, self.seq = clock, True, 0

    def read(self):
        if not self.connected:
            return []
        self.seq += 1
        return [BallSample(self.clock.now(), self.seq, (0.0, -0.001, 0.0))]

    def status(self):
        return {"connected": self.connected}


def make_loop(clock, **kwargs):
    source = kwargs.pop("source", None) or open_source("scripted", speed=0.02, clock=clock)
    return FrameLoop(clock=clock, source=source, **kwargs)


def test_free_yaw_walker_moves_in_dome_frame_and_keeps_heading():
    clock = SimulatedClock()
    loop = make_loop(clock)
    loop.run(until=10.0)
    assert loop.frame == pytest.approx(1900, abs=1)
    assert loop.pose.x == pytest.approx(0.2, rel=0.01)
    assert loop.pose.y == pytest.approx(0.0, abs=1e-9)
    assert loop.pose.heading == 0.0
    assert loop.late_frames == 0 and loop.skipped_frames == 0


def test_fixed_tether_turns_the_heading_and_gains_scale_motion():
    clock = SimulatedClock()
    src = open_source("scripted", speed=0.02, turn_rate=0.1, tether="fixed", clock=clock)
    loop = make_loop(clock, source=src, tether="fixed", gain_rotation=2.0, gain_translation=0.5)
    loop.run(until=5.0)
    assert loop.pose.heading == pytest.approx(2.0 * 0.1 * 5.0, rel=0.01)
    assert math.hypot(loop.pose.x, loop.pose.y) == pytest.approx(0.5 * 0.02 * 5.0, rel=0.05)


def test_scene_rotation_turns_the_mapping_of_dome_to_world():
    clock = SimulatedClock()
    loop = make_loop(clock)
    loop.rotate_scene(math.pi / 2)  # scene turns CCW: walking along dome +x now goes along world -y
    loop.run(until=5.0)
    assert loop.pose.heading == pytest.approx(-math.pi / 2)
    assert loop.pose.y == pytest.approx(-0.1, rel=0.01) and abs(loop.pose.x) < 1e-9
    assert loop.scene_rotation == pytest.approx(math.pi / 2)


def test_open_loop_ignores_the_ball_and_set_pose_displaces():
    clock = SimulatedClock()
    loop = make_loop(clock, closed_loop=False)
    loop.run(until=2.0)
    assert loop.pose == Pose()
    loop.set_pose(Pose(3.0, 4.0, 0.01, 1.0))
    loop.set_closed_loop(True)
    loop.run(until=3.0)
    assert loop.pose.x > 3.0 and loop.pose.heading == 1.0
    loop.reset_origin()
    assert loop.pose == Pose() and loop.scene_rotation == 0.0


def test_bad_control_values_leave_state_unchanged():
    clock = SimulatedClock()
    loop = make_loop(clock)
    before = (loop.pose, loop.gain_translation, loop.gain_rotation, loop.tether, loop.closed_loop)
    for call, match in [
        (lambda: loop.set_gains(translation=float("nan")), "gain translation"),
        (lambda: loop.set_gains(rotation=1.0, translation=1e9), "gain translation"),
        (lambda: loop.set_tether("loose"), "tether"),
        (lambda: loop.set_closed_loop("yes"), "closed_loop"),
        (lambda: loop.rotate_scene(float("inf")), "finite angle"),
        (lambda: loop.set_pose((1, 2)), "Pose"),
    ]:
        with pytest.raises(ValueError, match=match):
            call()
    assert (loop.pose, loop.gain_translation, loop.gain_rotation, loop.tether, loop.closed_loop) == before


def test_late_frames_are_counted_and_skipped_not_queued():
    clock = SimulatedClock()
    period = 1 / 190
    renderer = SlowRenderer(clock, 0.2 * period)
    loop = make_loop(clock, renderer=renderer, link=RecordingLink())
    loop.run(frames=50)
    assert loop.late_frames == 0
    renderer.cost = 2.5 * period  # three slots' worth of work: late, and two slots skipped
    rec = loop.step()
    assert rec.late and rec.skipped == 2
    assert rec.full_render and rec.log_row()[-1] == 1  # the log says which path the late frame took
    renderer.cost = 0.2 * period
    nxt = loop.step()
    assert not nxt.full_render and nxt.log_row()[-1] == 0
    assert nxt.t_start == pytest.approx(rec.t_target + 3 * period)  # back on the grid, no backlog
    assert nxt.pacing_error == pytest.approx(0.0) and not nxt.late
    assert loop.late_frames == 1 and loop.skipped_frames == 2
    stats = loop.stats()
    assert stats["late_frames"] == 1 and stats["render"]["max"] == pytest.approx(2.5 * period)


def test_lost_locomotion_holds_the_pose_and_resumes():
    clock = SimulatedClock()
    events = []
    src = SwitchableSource(clock)
    loop = make_loop(clock, source=src, on_event=lambda t, kind, data: events.append(kind))
    loop.run(frames=20)
    x = loop.pose.x
    assert x > 0
    src.connected = False
    loop.run(frames=20)
    assert "locomotion_lost" in events and not loop.locomotion_connected
    held = loop.pose.x
    loop.run(frames=20)
    assert loop.pose.x == held
    src.connected = True
    loop.run(frames=20)
    assert "locomotion_back" in events and loop.pose.x > held


def test_a_replugged_source_moves_the_ant_from_its_first_sample():
    """Samples a source delivers right after it is back are integrated at once, not from the loop's next status
    check (up to LOCOMOTION_CHECK_EVERY frames later: 2.2 mm of a 1 kHz walk were lost)."""
    clock = SimulatedClock()
    src = SwitchableSource(clock)
    loop = make_loop(clock, source=src)
    src.connected = False
    loop.run(frames=23)  # the loop has seen it go; the next frame is not one of its status checks
    assert not loop.locomotion_connected and loop.frame % 10 != 0
    held = loop.pose.x
    src.connected = True
    loop.step()
    assert loop.locomotion_connected
    assert loop.pose.x == pytest.approx(held + 0.001 * loop.ball_radius)  # the first sample back, 1 mrad of roll


class SampleSource(SwitchableSource):
    """Delivers the rotations the test queues, one sample a frame."""

    def __init__(self, clock, rotations):
        super().__init__(clock)
        self.rotations = list(rotations)

    def read(self):
        self.seq += 1
        return [BallSample(self.clock.now(), self.seq, self.rotations.pop(0))] if self.rotations else []


def test_a_sample_that_is_not_a_finite_rotation_is_skipped_and_counted():
    clock = SimulatedClock()
    kinds = []
    bad = [(math.nan, 0.0, 0.0), (0.0, math.inf, 0.0), (-math.inf, 0.0, 0.0)]
    src = SampleSource(clock, [(0.0, -0.001, 0.0), *bad, (0.0, -0.001, 0.0)])
    loop = make_loop(clock, source=src, on_event=lambda t, kind, data: kinds.append(kind))
    loop.run(frames=8)
    assert loop.pose.x == pytest.approx(2 * 0.001 * loop.ball_radius) and loop.pose.y == 0.0
    assert math.isfinite(loop.pose.heading) and loop.faults["locomotion"] == 3
    assert "locomotion_error" in kinds and loop.frame == 8


def test_call_soon_runs_in_the_loop_and_returns_errors():
    clock = SimulatedClock()
    loop = make_loop(clock)
    ok = loop.call_soon(loop.set_gains, 2.0, None)
    bad = loop.call_soon(loop.set_tether, "loose")
    loop.step()
    assert ok.result(0) is None and loop.gain_translation == 2.0
    with pytest.raises(ValueError, match="tether"):
        bad.result(0)


def test_latency_measures_newest_sample_to_last_datagram():
    clock = SimulatedClock()
    renderer = SlowRenderer(clock, 0.001)
    loop = make_loop(clock, source=SwitchableSource(clock), renderer=renderer, link=RecordingLink())
    rec = loop.step()
    assert rec.latency == pytest.approx(0.001)
    assert rec.sample_seq == 1


class FailingSource(SwitchableSource):
    """A source whose driver raises while `failing` (a bug in a back-end)."""

    failing = False

    def read(self):
        if self.failing:
            raise RuntimeError("driver bug")
        return super().read()


def test_a_raising_source_or_renderer_never_stops_the_loop():
    clock = SimulatedClock()
    kinds = []
    src = FailingSource(clock)
    renderer = SlowRenderer(clock, 0.0)
    loop = make_loop(clock, source=src, renderer=renderer, link=RecordingLink(),
                     on_event=lambda t, kind, data: kinds.append(kind))
    loop.run(frames=10)
    src.failing = True
    loop.run(frames=40)
    assert not loop.locomotion_connected and loop.faults["locomotion"] == 40
    held = loop.pose
    src.failing = False
    loop.run(frames=20)
    assert loop.locomotion_connected and loop.pose.x > held.x
    assert kinds.count("locomotion_lost") == 1 and kinds.count("locomotion_back") == 1
    assert kinds.count("locomotion_error") == 1  # at most one a second
    renderer.render = lambda pose, out=None: 1 / 0
    sent = loop.link.frames
    loop.run(frames=5)
    assert loop.faults["render"] == 5 and loop.link.frames == sent + 5  # the previous frame is sent again
    assert "render_error" in kinds


def test_idle_work_runs_between_frames_only_with_time_to_spare_one_call_a_frame():
    clock = SimulatedClock()
    period = 1 / 190
    renderer = SlowRenderer(clock, 0.7 * period)  # 1.6 ms left before the next slot: no time to spare
    loop = make_loop(clock, renderer=renderer, link=RecordingLink())
    ran = []
    first = loop.when_idle(lambda: ran.append(("first", loop.frame)) or "done")
    second = loop.when_idle(lambda: ran.append(("second", loop.frame)))
    loop.run(frames=5)
    assert ran == [] and not first.done()
    renderer.cost = 0.2 * period  # 4.2 ms to spare: one call after each frame, in order, in the loop's thread
    loop.step()
    assert ran == [("first", 6)] and first.result(0) == "done"
    rec = loop.step()
    assert ran == [("first", 6), ("second", 7)] and second.done() and not rec.late
    failing = loop.when_idle(lambda: 1 / 0)  # an error goes to the caller, never into the loop
    loop.step()
    assert isinstance(failing.exception(0), ZeroDivisionError)


class FlakyPolariserLink:
    """The virtual link whose next POLARISER datagram fails to go out (a full send buffer), at the lowest seam."""

    @staticmethod
    def make(clock):
        from antarium.firmware_proto.virtual import VirtualLink

        class Link(VirtualLink):
            fail_next = False

            def _transmit(self, data):
                if self.fail_next and bytes(data)[2] == 0x02 and len(bytes(data)) == 994:  # a POLARISER datagram
                    self.fail_next = False
                    return False
                return super()._transmit(data)

        return Link(clock=clock)


class StillRenderer(SlowRenderer):
    def polariser_angles(self):
        return np.zeros((55, 9))


def test_a_polariser_update_that_failed_to_go_out_is_sent_again():
    clock = SimulatedClock()
    link = FlakyPolariserLink.make(clock)
    loop = make_loop(clock, renderer=StillRenderer(clock, 0.0), link=link)
    loop.run(frames=3)
    link.fail_next = True
    loop.set_polarisers(np.full((55, 9), math.pi / 4))  # held: nothing else would send them again
    loop.run(frames=400)  # 2.1 s: the actuators have turned there
    assert link.counters["datagrams_failed"] == 1
    assert set(np.ravel(link.telemetry(wait_s=0.01)["polariser_codes"])) == {16384}  # pi/4 on the dome


def test_polariser_angles_a_hair_below_zero_are_held_at_zero_and_frames_go_on():
    clock = SimulatedClock()
    link = FlakyPolariserLink.make(clock)
    loop = make_loop(clock, renderer=StillRenderer(clock, 0.0), link=link)
    loop.set_polarisers(np.full((55, 9), -1e-20))  # np.mod(-1e-20, pi) is pi itself, which no code encodes
    assert np.all(loop.polariser_override == 0.0)
    loop.run(frames=5)
    assert loop.frame == 5 and not loop.faults
