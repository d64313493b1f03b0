"""A second look at today's core changes: the frame loop's catch-up before a command (053972e), the slow commands'
worker and trial_stop with the log's path (1428515). Each test here shows a defect found in them, fixed since."""

import dataclasses
import threading
import time

import h5py
import pytest
from test_proto_budget import SkyRenderer, loop_on_a_virtual_dome

import antarium
from antarium import bus
from antarium.client import RigError
from antarium.config import resolve
from antarium.core.clock import SimulatedClock
from antarium.core.pose import Pose
from antarium.firmware_proto.emulator import Emulator
from antarium.locomotion import BallSample, LocomotionSource
from antarium.server import Server, commands
from antarium.server.frame_loop import FrameLoop
from antarium.trial_log import TrialLog


class QueuedSource(LocomotionSource):
    """A driver's queue: the samples put in are read once."""

    def __init__(self):
        self.queue = []

    def put(self, t: float, seq: int) -> None:
        """A sample of 1 mm walked along the dome's +x (5 cm ball) that arrived at `t` (s)."""
        self.queue.append(BallSample(t, seq, (0.0, -0.02, 0.0)))

    def read(self):
        out, self.queue = self.queue, []
        return out


def pose_only_server(tmp_path, name: str, bus_on: bool = True) -> tuple:
    """A started pose-only server (scripted source standing still) logging under `tmp_path`; (config, server)."""
    section = {"listen": [bus.free_tcp_endpoint()]} if bus_on else {"enabled": False}
    config = resolve({"rig": {"name": name}, "bus": section, "log": {"dir": str(tmp_path / "logs")},
                      "locomotion": {"source": "scripted", "speed": 0.0}})
    return config, Server(config, renderer_factory=None, link=False, echo=lambda line: None).start_thread()


# a sample the loop cannot integrate (a driver's 2-component rotation) that arrived before a call_soon
# command makes _catch_up raise inside _run_pending after the command's future was set running: the loop ends as
# before, but the command is never answered (the server's caller waits COMMAND_TIMEOUT_S, 60 s, for a dead loop).
# Before 053972e the command ran first and was answered.
def test_a_command_is_answered_when_the_samples_before_it_end_the_loop():
    clock = SimulatedClock()
    source = QueuedSource()
    loop = FrameLoop(clock=clock, source=source)
    loop.step()
    clock.advance(0.002)
    source.queue.append(BallSample(clock.now(), 1, (0.0, 0.01)))  # a driver bug: two components, not three
    future = loop.call_soon(loop.set_pose, Pose(1.0, 0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="not enough values"):
        loop.run(frames=1)
    assert future.done()  # answered (with the pose set, or with the loop's error), never left running


# a trial started between frames (the server attaches its log with call_soon, Server._attach_log):
# _catch_up reads the samples that arrived before it while the loop has no log, so they are in no log, yet the
# trial's first frames row names one of them as its sample_seq (and its latency): a frames row whose sample the
# trial's locomotion table lacks. Before 053972e the frame read them with the log attached.
def test_a_trials_frames_name_only_samples_of_its_locomotion_table(tmp_path):
    clock = SimulatedClock()
    source = QueuedSource()
    loop = FrameLoop(clock=clock, source=source)
    loop.step()
    clock.advance(0.002)
    source.put(clock.now(), 1)  # arrived before the trial started
    log = TrialLog(tmp_path / "trial.h5", {}, "t")
    loop.call_soon(setattr, loop, "log", log)  # as Server._attach_log
    clock.advance(0.001)
    loop.step()
    clock.advance(0.004)
    source.put(clock.now(), 2)
    loop.step()
    log.close()
    with h5py.File(tmp_path / "trial.h5") as f:
        named = {int(seq) for seq in f["frames"]["sample_seq"] if seq >= 0}
        logged = {int(seq) for seq in f["locomotion"]["seq"]}
    assert named <= logged, f"frames name samples {sorted(named - logged)} the locomotion table lacks"


# trial_stop(path) while the server stops (its loop thread still in its last frame) skips the path
# check: script A, whose trial script B stopped before starting its own, is told its trial stopped, with B's reply.
def test_trial_stop_of_another_trial_during_the_shutdown_is_refused(tmp_path):
    _, server = pose_only_server(tmp_path, "advstop", bus_on=False)
    entered, release = threading.Event(), threading.Event()
    out = {}
    try:
        path_a = server.trial_start("a", {})["path"]
        server.trial_stop()  # script B stops A's trial and starts its own
        path_b = server.trial_start("b", {})["path"]
        server.loop.call_soon(lambda: (entered.set(), release.wait(30)))  # the loop's last frame takes a while
        assert entered.wait(10)
        stopper = threading.Thread(target=server.stop)
        stopper.start()
        while not server._stopping.is_set():
            time.sleep(0.001)

        def a_stops():
            try:
                out["reply"] = server.trial_stop(path_a)  # script A's `with rig.trial` block ends
            except RuntimeError as exc:
                out["error"] = str(exc)

        script_a = threading.Thread(target=a_stops)
        script_a.start()
        release.set()
        script_a.join(30)
        stopper.join(30)
    finally:
        release.set()
        server.stop()
    assert "reply" not in out, f"script A was told its trial stopped with {out['reply']['path']} (B's: {path_b})"
    assert "is not running" in out["error"]


# zenoh runs a queryable's callbacks one at a time and hands over a query that waited behind a running
# callback even after undeclare(): a slow command (set_pose) queued behind another script's fast command while the
# server stops reaches _on_query after _await_queries, which starts a new slow-commands worker that nobody ends
# (a thread left blocked forever per such shutdown).
def test_a_slow_query_handed_over_after_the_shutdown_leaves_no_worker(tmp_path, monkeypatch):
    held, release = threading.Event(), threading.Event()
    status = commands.COMMANDS["status"]

    def held_status(server, p):  # script A's status holds zenoh's callback thread while the server stops
        if not held.is_set():
            held.set()
            release.wait(30)
        return status.handler(server, p)

    monkeypatch.setitem(commands.COMMANDS, "status", dataclasses.replace(status, handler=held_status))
    config, server = pose_only_server(tmp_path, "advlate")
    before = {t.ident for t in threading.enumerate() if t.name == "slow-commands"}
    replies = {}

    def call(rig, name, **params):
        try:
            replies[name] = rig.call(name, **params)
        except RigError as exc:
            replies[name] = exc

    try:
        with antarium.Rig("advlate", config=config, timeout_s=20) as a, \
                antarium.Rig("advlate", config=config, timeout_s=20) as b:
            script_a = threading.Thread(target=call, args=(a, "status"))
            script_a.start()
            assert held.wait(10)
            script_b = threading.Thread(target=call, args=(b, "set_pose"), kwargs={"x": 0.2, "y": 0.0})
            script_b.start()
            time.sleep(1.0)  # B's query waits in zenoh behind A's callback
            stopper = threading.Thread(target=server.stop)
            stopper.start()
            deadline = time.monotonic() + 10
            while server._entities and time.monotonic() < deadline:  # the queryable is undeclared
                time.sleep(0.001)
            release.set()
            stopper.join(30)
            script_a.join(30)
            script_b.join(30)
    finally:
        release.set()
        server.stop()
    assert "set_pose" in replies  # (answered: the server is not running)
    left = [t for t in threading.enumerate() if t.name == "slow-commands" and t.ident not in before]
    assert not left, f"{len(left)} slow-commands worker(s) left running after stop()"


# FrameLoop starts counting the link's state_resent_bits from 0 (frame_loop.py, `self._resent_bits = 0`):
# a link that resent held state under an earlier loop (a Server given link=, run again in one process) puts all of
# that history into the new loop's first period: 358,228 bits (3.6 ms of wire) of backlog at 190 frames/s, drained
# over 49 frames, polariser updates deferred meanwhile, though nothing was resent in this run.
def test_a_link_resent_before_this_loop_adds_nothing_to_its_budget():
    clock = SimulatedClock()
    first = loop_on_a_virtual_dome(clock)
    link = first.link
    link.emulator = Emulator()  # the distributor rebooted during the first run: the held state is sent again
    for _ in range(200):
        first.step()
    assert link.counters["state_resent_bits"] > 0 and first.link_budget.backlog == 0.0
    second = FrameLoop(clock=clock, source=None, renderer=SkyRenderer(), link=link, rate_hz=190.0)
    resent = link.counters["state_resent_bits"]
    second.step()
    assert link.counters["state_resent_bits"] == resent  # nothing sent again in this run
    assert second.link_budget.backlog == 0.0
