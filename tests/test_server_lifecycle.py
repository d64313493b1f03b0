"""A server's life in a script (`start_thread`/`stop`) when something goes wrong: a start that times out, a frame
loop that dies, a shutdown step that fails, a renderer failing every frame, a flaky source, the emulator killed;
and what a stopped server leaves behind (nothing: its objects can be collected)."""

import gc
import json
import os
import signal
import sys
import weakref

import numpy as np
import pytest
from conftest import process_gone, wait_for

from antarium import bus
from antarium.config import resolve
from antarium.core.clock import SimulatedClock
from antarium.firmware_proto.link import IncompatibleDistributor
from antarium.locomotion.scripted import ScriptedSource
from antarium.server import Server, ServerError
from antarium.server.frame_loop import FrameLoop
from antarium.trial_log import read_table


def _config(tmp_path, rig, link=None, **extra):
    raw = {"rig": {"name": rig}, "bus": {"listen": [bus.free_tcp_endpoint()]},
           "log": {"dir": str(tmp_path / "logs"), "flush_s": 0.1},
           "locomotion": {"source": "scripted", "speed": 0.02},
           "link": link or {"interface": "virtual"}, "loop": {"rate_hz": 100.0}, **extra}
    return resolve(raw)


EMULATOR = {"interface": "udp", "spawn_emulator": True}


def _kill(pid: int | None) -> None:
    if pid is not None and not process_gone(pid):
        os.kill(pid, signal.SIGKILL)


class LedRenderer:
    """The lowest seam of a renderer: a dark LED frame every frame, or an exception while `failing`."""

    scene = None

    def __init__(self, failing: bool = False) -> None:
        self.failing = failing

    def set_scene(self, scene) -> None:
        pass

    def render(self, pose, out=None):
        if self.failing:
            raise RuntimeError("GL context lost")
        return np.zeros((20350, 2), np.uint16) if out is None else out


def test_a_start_that_times_out_leaves_no_server_behind(tmp_path):
    """start_thread() timing out stops what was starting: no frames, no trial, no emulator left running."""

    class SlowStart(ScriptedSource):  # a device that takes long to open: here, until the server is asked to stop
        def start(self):
            wait_for(server._stopping.is_set, 60.0, 0.01)
            super().start()

    config = _config(tmp_path, "tlife_timeout", EMULATOR)
    server = Server(config, source=SlowStart(rate_hz=100.0), renderer_factory=None, record="ghost",
                    echo=lambda line: None)
    try:
        with pytest.raises(ServerError, match="did not start within"):
            server.start_thread(timeout_s=0.2)
        assert not server._thread.is_alive()
        assert server.loop.frame == 0
        assert server.emulator is not None and not server.emulator.running
        assert server.trial_log is None
    finally:
        pid = server.emulator.pid if server.emulator is not None else None
        server.stop()
        _kill(pid)


class DyingLink:
    """A link whose telemetry() raises after a few polls (a network interface gone), or whose frames are refused
    (a distributor of another protocol version)."""

    counters = {"datagrams_failed": 0}
    last_timings = {}

    def __init__(self, how: str) -> None:
        self.how, self.polls = how, 0

    def telemetry(self):
        self.polls += 1
        if self.how == "telemetry" and self.polls > 10:
            raise OSError(19, "No such device")
        return {"age_s": 0.0, "link": {"datagrams_failed": 0}}

    def send_frame(self, frame):
        if self.how == "version" and self.polls > 10:
            raise IncompatibleDistributor("the distributor speaks protocol 9")
        return 0

    def close(self):
        pass


@pytest.mark.parametrize("how, error", [("telemetry", "OSError"), ("version", "IncompatibleDistributor")])
def test_a_frame_loop_that_dies_in_a_server_thread_is_reported(tmp_path, how, error):
    lines = []
    config = _config(tmp_path, f"tlife_dies_{how}")
    server = Server(config, link=DyingLink(how), renderer_factory=lambda cfg, clock=None: LedRenderer(),
                    record="dies", echo=lines.append).start_thread()
    try:
        assert wait_for(lambda: not server._thread.is_alive(), 30.0)
        assert any("server_failed" in line and error in line for line in lines), lines
        assert any(a.startswith(f"frame loop stopped: {error}") for a in server.status()["alarms"])
        with pytest.raises(ServerError, match=f"frame loop stopped: {error}"):
            server.stop()
    finally:
        try:
            server.stop()
        except ServerError:
            pass
    kinds = list(read_table(server.trial_paths[0], "events")["kind"])
    assert "server_failed" in kinds and kinds.index("server_failed") < kinds.index("trial_stopped")


def test_a_failing_shutdown_step_does_not_skip_the_others(tmp_path):
    """A source whose stop() raises (USB device gone): said on stderr; emulator stopped, placement undone."""

    class BadStop(ScriptedSource):
        def stop(self):
            raise OSError(5, "Input/output error (USB device gone)")

    lines = []
    switch_interval = sys.getswitchinterval()
    config = _config(tmp_path, "tlife_badstop", EMULATOR)
    server = Server(config, source=BadStop(rate_hz=100.0), renderer_factory=None, echo=lines.append)
    server.start_thread()
    pid = server.emulator.pid
    try:
        assert wait_for(lambda: server.loop.frame > 5, 20.0)
        server.stop()
        assert not server._thread.is_alive()
        assert wait_for(lambda: process_gone(pid), 10.0), "the emulator was left running"
        assert sys.getswitchinterval() == switch_interval
        assert any("stopping the locomotion source failed: OSError" in line for line in lines), lines
    finally:
        _kill(pid)


def test_a_renderer_failing_every_frame_is_an_alarm_while_it_fails(tmp_path):
    lines = []
    renderer = LedRenderer(failing=True)
    config = _config(tmp_path, "tlife_render", link=None)
    server = Server(config, link=False, renderer_factory=lambda cfg, clock=None: renderer, echo=lines.append)
    server.start_thread()
    try:
        assert wait_for(lambda: server.loop.faults.get("render", 0) > 10, 20.0)
        alarms = server.status()["alarms"]
        assert any(a.startswith("renderer failing") and "GL context lost" in a for a in alarms), alarms
        assert any("render_error" in line and "GL context lost" in line for line in lines), lines
        renderer.failing = False  # it recovers: the alarm goes
        assert wait_for(lambda: not any(a.startswith("renderer failing") for a in server.status()["alarms"]), 20.0)
    finally:
        server.stop()


def _run_and_stop(tmp_path) -> weakref.ref:
    """A server run a few frames and stopped; a weak reference to its frame loop."""
    config = _config(tmp_path, "tlife_gc")
    server = Server(config, renderer_factory=lambda cfg, clock=None: LedRenderer(), echo=lambda line: None)
    server.start_thread()
    try:
        assert wait_for(lambda: server.loop.frame > 5, 20.0)
        assert gc.get_freeze_count() > 0  # while it runs
    finally:
        server.stop()
    return weakref.ref(server.loop)


def test_a_stopped_server_can_be_collected(tmp_path):
    """gc.freeze() keeps the collector off the frame loop's objects while it runs, and is undone at the end."""
    loop = _run_and_stop(tmp_path)
    gc.collect()
    assert gc.get_freeze_count() == 0
    assert loop() is None


class Flaky(ScriptedSource):
    """read() raises on every third frame (a flaky driver)."""

    def __init__(self, **kw):
        super().__init__(**kw)
        self.reads = 0

    def read(self):
        self.reads += 1
        out = super().read()
        if self.reads % 3 == 0:
            raise OSError(5, "read failed")
        return out


def test_a_flaky_source_gives_one_locomotion_event_a_second_and_exact_frames():
    clock = SimulatedClock()
    events, records = [], []
    loop = FrameLoop(clock=clock, source=Flaky(rate_hz=200.0, clock=clock), rate_hz=100.0,
                     on_event=lambda t, kind, data: events.append((t, kind, data)), on_frame=records.append)
    loop.source.start()
    loop.run(until=5.0)
    told = [(t, kind, data) for t, kind, data in events if kind in ("locomotion_lost", "locomotion_back")]
    times = [t for t, _, _ in told]
    # at most one a second, but for the last: the state at the end of the run
    assert len(told) >= 2 and all(b - a >= 1.0 for a, b in zip(times[:-2], times[1:-1], strict=True))
    assert [kind for _, kind, _ in told] == ["locomotion_lost", "locomotion_back"] * (len(told) // 2) \
        + ["locomotion_lost"] * (len(told) % 2)  # alternating: never two of a kind in a row
    connected = [r.locomotion_connected for r in records]
    losses = sum(1 for a, b in zip([True, *connected[:-1]], connected, strict=True) if a and not b)
    assert losses > 100  # the frames keep every change
    assert told[-1][1] == ("locomotion_back" if loop.locomotion_connected else "locomotion_lost")
    assert loop.locomotion_losses == losses
    assert [d["losses"] for _, kind, d in told if kind == "locomotion_lost"][-1] > 100  # counted, not told


@pytest.mark.parametrize("status", [None, "connected", ["connected"]])
def test_a_source_status_that_is_no_dict_is_a_fault_not_the_end_of_the_loop(status):
    class OddStatus(ScriptedSource):
        def status(self):
            return status

    clock = SimulatedClock()
    loop = FrameLoop(clock=clock, source=OddStatus(rate_hz=200.0, clock=clock), rate_hz=100.0)
    loop.source.start()
    assert loop.run(frames=50) == 50
    assert loop.faults["locomotion"] >= 1 and not loop.locomotion_connected


def test_an_emulator_killed_and_restarted_is_printed_with_its_exit_status_and_recovery(tmp_path):
    lines = []
    config = _config(tmp_path, "tlife_emu", EMULATOR)
    server = Server(config, renderer_factory=None, echo=lines.append).start_thread()
    pids = [server.emulator.pid]
    try:
        loop = server.loop
        assert wait_for(lambda: loop.link_ok and loop.frame > 20, 20.0)
        os.kill(server.emulator.pid, signal.SIGKILL)
        assert wait_for(lambda: not server.emulator.running and not loop.link_ok, 10.0)
        alarms = server.status()["alarms"]
        assert any("emulator process is not running (exit status -9: killed by signal 9" in a for a in alarms), alarms
        assert wait_for(lambda: any("ALARM: the dome emulator process is not running" in line for line in lines), 10.0)
        server.emulator.start()
        pids.append(server.emulator.pid)
        assert wait_for(lambda: loop.link_ok, 20.0)
        assert wait_for(lambda: any("link_back" in line for line in lines), 10.0), lines
        assert wait_for(lambda: any("alarm cleared: the dome emulator process is not running" in line
                                    for line in lines), 10.0), lines
    finally:
        server.stop()
        for pid in pids:
            _kill(pid)


def test_a_trial_stop_while_the_server_stops_keeps_the_last_frame(tmp_path):
    """A client's trial_stop arriving while the server stops (Ctrl-C, stop()) detached the log from its own thread
    while the loop was still in its last frame: that frame and its samples were sent but never logged, uncounted."""
    import threading
    import time

    config = resolve({"rig": {"name": "tlast"}, "bus": {"enabled": False},
                      "log": {"dir": str(tmp_path), "flush_s": 0.05}, "loop": {"rate_hz": 100.0},
                      "locomotion": {"source": "scripted", "rate_hz": 1000.0}})
    server = Server(config, renderer_factory=None, link=False, echo=lambda *a: None).start_thread()
    path = server.trial_start("last", {})["path"]
    assert wait_for(lambda: server.loop.frame > 10, 10.0)
    read, in_frame = server.source.read, threading.Event()

    def slow_read():  # a frame that takes 50 ms: the stop and the trial_stop land inside it
        in_frame.set()
        time.sleep(0.05)
        return read()

    server.source.read = slow_read
    assert in_frame.wait(5.0)
    stopper = threading.Thread(target=server.stop)
    stopper.start()
    time.sleep(0.005)
    reply = server.trial_stop()
    stopper.join(30.0)
    frames = read_table(path, "frames")["frame"]
    assert reply["path"] == path and reply["rows_lost"] == 0 and reply["error"] is None
    assert frames[-1] == server.loop.frame - 1  # the last frame the loop ran is in the log


def _recording_server(tmp_path, rig: str, lines: list[str]) -> Server:
    config = resolve({"rig": {"name": rig}, "bus": {"enabled": False},
                      "log": {"dir": str(tmp_path), "flush_s": 0.05}, "loop": {"rate_hz": 200.0},
                      "locomotion": {"source": "scripted", "rate_hz": 500.0}})
    return Server(config, renderer_factory=None, link=False, echo=lines.append).start_thread()


WRITER_ALARM = "TRIAL LOG WRITER NOT ANSWERING"


def test_a_writer_that_stops_answering_is_an_alarm_until_it_answers_again(tmp_path):
    """A hung writer (a stalled disk: SIGSTOP here) raised no alarm: rows piled up unconfirmed, nobody knew."""
    lines: list[str] = []
    server = _recording_server(tmp_path, "wstall", lines)
    pid = None
    try:
        server.trial_start("stall", {})
        assert wait_for(lambda: server.status()["log"]["rows_written"]["frames"] > 0, 10.0)
        assert not any(a.startswith(WRITER_ALARM) for a in server.status()["alarms"])
        pid = server.trial_log._proc.pid
        os.kill(pid, signal.SIGSTOP)
        assert wait_for(lambda: any(a.startswith(WRITER_ALARM) for a in server.status()["alarms"]), 10.0)
        assert wait_for(lambda: any(f"ALARM: {WRITER_ALARM}" in line for line in lines), 5.0)  # on stderr
        frames = server.loop.frame
        os.kill(pid, signal.SIGCONT)
        pid = None
        assert wait_for(lambda: not any(a.startswith(WRITER_ALARM) for a in server.status()["alarms"]), 10.0)
        assert wait_for(lambda: f"antarium serve: alarm cleared: {WRITER_ALARM}" in lines, 5.0)
        assert server.loop.frame > frames  # the frames never waited for the writer
        reply = server.trial_stop()
        assert reply["rows_lost"] == 0 and reply["error"] is None
    finally:
        if pid is not None:
            os.kill(pid, signal.SIGCONT)
        server.stop()


def test_a_hung_writer_ends_trial_stop_and_the_shutdown_within_the_close_timeout(tmp_path, monkeypatch):
    """trial_stop and the shutdown waited for ever on a hung writer (close() joined the sender thread, blocked in
    send() on the full pipe, without a bound); docs/logs.md promises at most 30 s, here 1 s."""
    import threading
    import time

    monkeypatch.setattr("antarium.trial_log.CLOSE_TIMEOUT_S", 1.0, raising=False)
    lines: list[str] = []
    server = _recording_server(tmp_path, "whung", lines)
    pids, replies = [], []
    try:
        for trial in ("stopped", "shut down"):
            server.trial_start(trial, {"notes": "x" * 20000})
            assert wait_for(lambda: server.status()["log"]["rows_written"]["frames"] > 0, 10.0)
            pids.append(server.trial_log._proc.pid)
            os.kill(pids[-1], signal.SIGSTOP)
            assert wait_for(lambda: any(a.startswith(WRITER_ALARM) for a in server.status()["alarms"]), 10.0)
            if trial == "stopped":
                stopping = threading.Thread(target=lambda: replies.append(server.trial_stop()), daemon=True)
                stopping.start()
                stopping.join(20.0)
                assert replies, "trial_stop still waits on the hung writer"
                (reply,) = replies
                assert reply["error"].startswith(f"trial log writer for {reply['path']!r} did not finish within 1 s "
                                                 "and was killed; ")
                assert reply["rows_lost"] > 0 and server.trial_log is None
            else:
                t0 = time.monotonic()
                server.stop(timeout_s=20.0)
                assert not server._thread.is_alive(), "the shutdown still waits on the hung writer"
                assert time.monotonic() - t0 < 15.0
    finally:
        for pid in pids:
            if not process_gone(pid):
                os.kill(pid, signal.SIGCONT)
        server.stop(timeout_s=60.0)


def test_commands_arriving_while_trial_stop_closes_the_log_are_not_counted_lost(tmp_path):
    """A command logged while trial_stop closed the log (the server still held it) was counted in rows_lost with
    error None: a trial that lost nothing reported losses nobody could explain."""
    lines: list[str] = []
    server = _recording_server(tmp_path, "wclose", lines)
    try:
        path = server.trial_start("closing", {})["path"]
        assert wait_for(lambda: server.loop.frame > 10, 10.0)
        log, replies = server.trial_log, []
        hand_over = log.flush

        def flush_as_a_command_arrives(wait: bool = False) -> None:
            if log._closed and not replies:  # close() has begun: the log takes no more rows
                replies.append(server.command("gains", {"translation": 2.0}))
            hand_over(wait)

        log.flush = flush_as_a_command_arrives
        reply = server.command("trial_stop")
        assert replies and replies[0]["gains"]["translation"] == 2.0  # the command itself ran
        assert reply["rows_lost"] == 0 and reply["error"] is None
    finally:
        server.stop()
    commands = read_table(path, "commands")
    assert list(commands["name"]) == ["trial_start", "trial_stop"]


def test_the_trial_events_anchor_the_loop_clock_to_utc(tmp_path):
    """Nothing tied the tables' times (loop clock) to wall time: trial_started and trial_stopped carry a (UTC, loop
    clock) pair read together, the file its creation's pair."""
    import datetime
    import json

    from antarium.trial_log import open_log

    lines: list[str] = []
    server = _recording_server(tmp_path, "wanchor", lines)
    try:
        before = datetime.datetime.now(datetime.UTC)
        path = server.trial_start("anchor", {})["path"]
        assert wait_for(lambda: server.loop.frame > 10, 10.0)
        server.trial_stop()
        after = datetime.datetime.now(datetime.UTC)
    finally:
        server.stop()
    events, frames = read_table(path, "events"), read_table(path, "frames")
    anchors = {kind: json.loads(data) for kind, data in zip(events["kind"], events["data"], strict=True)
               if kind in ("trial_started", "trial_stopped")}
    started, stopped = anchors["trial_started"], anchors["trial_stopped"]
    assert before <= datetime.datetime.fromisoformat(started["utc"]) <= datetime.datetime.fromisoformat(
        stopped["utc"]) <= after
    assert started["monotonic"] <= frames["t_start"][0] and frames["t_start"][-1] <= stopped["monotonic"]
    wall = (datetime.datetime.fromisoformat(stopped["utc"]) - datetime.datetime.fromisoformat(started["utc"]))
    assert wall.total_seconds() == pytest.approx(stopped["monotonic"] - started["monotonic"], abs=0.05)
    with open_log(path) as f:
        assert f.attrs["created_monotonic"] <= started["monotonic"]
        assert datetime.datetime.fromisoformat(f.attrs["created_utc"]) <= datetime.datetime.fromisoformat(
            started["utc"])


def test_the_status_says_when_the_running_trial_started_and_its_metadata(tmp_path):
    """For a client that subscribed after trial_started (the monitor opened mid-trial): the instant of the event's
    `monotonic` and the metadata, in every status while the trial runs; None without a trial."""
    server = _recording_server(tmp_path, "tstarted", [])
    try:
        assert server.status()["trial_started"] is None
        path = server.trial_start("t1", {"ant": 7, "colony": "C3"})["path"]
        started = server.status()["trial_started"]
        server.trial_stop()
        assert server.status()["trial_started"] is None
    finally:
        server.stop()
    events = read_table(path, "events")
    data = json.loads(events["data"][list(events["kind"]).index("trial_started")])
    assert started == {"t": data["monotonic"], "metadata": {"ant": 7, "colony": "C3"}}


@pytest.mark.parametrize("every", [0, 5])
def test_the_status_says_how_often_the_led_stream_runs(every, tmp_path):
    """`led_stream_every_frames` (0: no LED frames on the bus), so that a monitor can say why its dome is dark."""
    from antarium.server.status import rig_status

    config = resolve({"rig": {"name": "tledstream"}, "monitor": {"leds_every_frames": every},
                      "log": {"dir": str(tmp_path)}})  # not ./trials in the working folder
    assert rig_status(Server(config, renderer_factory=None, link=False))["led_stream_every_frames"] == every
