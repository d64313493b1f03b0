"""A server's start and end when they are cut short: a start-up cancelled (`cancel_start`, `antarium serve` and a
signal), a start that times out, a trial the held-up loop does not take in time, commands logged from many threads,
and commands that come after the last frame of a timed run."""

import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import process_gone, wait_for

import antarium.server.server as server_module
from antarium import bus
from antarium.config import resolve
from antarium.core.clock import SimulatedClock
from antarium.locomotion.scripted import ScriptedSource
from antarium.server import Server, ServerError
from antarium.server.commands import CommandError
from antarium.server.frame_loop import FrameLoop, LoopClosed
from antarium.trial_log import read_table


def _config(tmp_path, rig, link=None):
    raw = {"rig": {"name": rig}, "bus": {"listen": [bus.free_tcp_endpoint()]},
           "log": {"dir": str(tmp_path / "logs"), "flush_s": 0.1},
           "locomotion": {"source": "scripted", "speed": 0.02},
           "link": link or {"interface": "virtual"}, "loop": {"rate_hz": 100.0}}
    return resolve(raw)


def _logs(tmp_path) -> list[Path]:
    return sorted((tmp_path / "logs").glob("*.h5"))


class GatedStart(ScriptedSource):
    """A device that takes long to open: `start()` returns once `gate` is set."""

    def __init__(self) -> None:
        super().__init__(rate_hz=100.0)
        self.entered, self.gate = threading.Event(), threading.Event()

    def start(self) -> None:
        self.entered.set()
        assert self.gate.wait(60.0)
        super().start()


def test_cancel_start_stops_a_start_up_before_its_first_frame(tmp_path):
    source = GatedStart()
    lines: list[str] = []
    server = Server(_config(tmp_path, "tlife2_cancel", {"interface": "udp", "spawn_emulator": True}), source=source,
                    renderer_factory=None, record="cancelled", echo=lines.append)
    ran: list = []
    thread = threading.Thread(target=lambda: ran.append(server.run()), daemon=True)
    thread.start()
    try:
        assert source.entered.wait(60.0)
        assert server.cancel_start() is True  # still starting
        source.gate.set()  # the device opens after all: the start-up goes on to where frames would begin
        thread.join(30.0)
        assert not thread.is_alive() and ran == [0]
        time.sleep(0.2)
        assert server.loop.frame == 0  # no loop left running behind
        assert not server.emulator.running
        assert _logs(tmp_path) == [] and server.trial_paths == []  # the trial opened for it ran no frame
        assert any("no frame ran: removed the empty trial log" in line for line in lines), lines
        assert server.cancel_start() is False  # stopped: nothing to cancel any more
    finally:
        source.gate.set()
        server.stop()


def test_cancel_start_leaves_a_running_server_alone(tmp_path):
    with Server(_config(tmp_path, "tlife2_running"), source=ScriptedSource(rate_hz=100.0), renderer_factory=None,
                echo=lambda line: None) as server:
        assert server.cancel_start() is False
        frames = server.loop.frame
        assert wait_for(lambda: server.loop.frame > frames + 10, 10.0)  # frames go on


def _children(pid: int) -> dict[int, str]:
    """The child processes of `pid`: pid -> command line."""
    out: dict[int, str] = {}
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            for child in map(int, (task / "children").read_text().split()):
                out[child] = Path(f"/proc/{child}/cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            pass
    return out


def test_a_signal_during_start_up_ends_it_and_its_children(tmp_path):
    """`antarium serve` interrupted while starting (its emulator already spawned): exit status 0, nothing left."""
    config = tmp_path / "rig.toml"
    config.write_text(f"""
[rig]
name = "tlife2_serve"
[bus]
listen = ["{bus.free_tcp_endpoint()}"]
[render]
scene = "horizon"
face_size = 64
[link]
interface = "udp"
host = "127.0.0.1"
port = 0
spawn_emulator = true
[log]
dir = "{tmp_path / 'logs'}"
""")
    proc = subprocess.Popen([sys.executable, "-m", "antarium", "serve", "--config", str(config), "--record", "early"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    seen: dict[int, str] = {}
    try:
        assert "antarium serve: rig 'tlife2_serve'" in proc.stdout.readline()  # printed before the start-up
        assert wait_for(lambda: any(" emulate " in cmd for cmd in seen.update(_children(proc.pid)) or seen.values()),
                        60.0)  # the emulator is up: the start-up goes on with the renderer, the bus, the trial
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    assert "SIGINT: stopping the start-up" in err and "Traceback" not in err, err
    assert "antarium serve: 0 frames" in out
    assert wait_for(lambda: all(process_gone(pid) for pid in seen), 10.0), seen
    assert _logs(tmp_path) == []


def test_a_start_that_times_out_leaves_no_trial_log(tmp_path):
    """start_thread(timeout_s) gives up while the source opens: the trial the start-up then opens ran no frame and is
    removed when the server stops, not left as an empty recording."""

    class SlowStart(ScriptedSource):
        def start(self):
            time.sleep(1.0)
            super().start()

    server = Server(_config(tmp_path, "tlife2_timeout"), source=SlowStart(rate_hz=100.0), renderer_factory=None,
                    record="ghost", echo=lambda line: None)
    try:
        with pytest.raises(ServerError, match="did not start within"):
            server.start_thread(timeout_s=0.2)
        assert server.loop.frame == 0
        assert _logs(tmp_path) == [] and server.trial_paths == []
    finally:
        server.stop()


@pytest.fixture
def quick_timeout(monkeypatch):
    """Commands give up on a held-up loop after 0.5 s (not 60)."""
    monkeypatch.setattr(server_module, "COMMAND_TIMEOUT_S", 0.5)


def test_a_trial_the_held_up_loop_does_not_take_is_not_started(tmp_path, quick_timeout):
    with Server(_config(tmp_path, "tlife2_attach"), source=ScriptedSource(rate_hz=100.0), renderer_factory=None,
                echo=lambda line: None) as server:
        hold = threading.Event()
        server.loop.call_soon(hold.wait, 30.0)  # the loop held up (a slow scene swap)
        with pytest.raises(RuntimeError, match=r"trial_start: the frame loop did not take it within 0\.5 s .*"
                                               "no trial was started"):
            server.command("trial_start", {"name": "late"})
        assert server.status()["trial"] is None and server.trial_paths == [] and _logs(tmp_path) == []
        hold.set()
        frames = server.loop.frame
        assert wait_for(lambda: server.loop.frame > frames + 5, 10.0)
        assert server.status()["trial"] is None and server.loop.log is None  # the refused attach never ran
        path = Path(server.command("trial_start", {"name": "on_time"})["path"])
        assert server.status()["trial"] == "on_time" and server.trial_paths == [path]

        hold_again = threading.Event()
        server.loop.call_soon(hold_again.wait, 30.0)
        with pytest.raises(RuntimeError, match="trial_stop: the frame loop did not take it.*trial 'on_time' goes on"):
            server.command("trial_stop")
        hold_again.set()
        assert server.status()["trial"] == "on_time" and server.loop.log is server.trial_log
        server.command("trial_stop")
    assert len(read_table(path, "frames")["frame"]) > 0


def test_the_commands_table_never_steps_back_in_time(tmp_path):
    """Commands from several threads at once (refused ones are logged in the caller's thread, the others in the
    loop's): the rows' t is non-decreasing."""
    server = Server(_config(tmp_path, "tlife2_order"), source=ScriptedSource(rate_hz=100.0), renderer_factory=None,
                    record="hammer", echo=lambda line: None).start_thread()
    junk = {f"k{i}": list(range(50)) for i in range(40)}  # a sizeable refused request: logging it takes a while
    sent = []

    def hammer() -> None:
        for i in range(150):
            try:
                if i % 3 == 0:
                    server.command("rotate_scene", {"deg": 1.0})
                else:
                    server.command("gains", {"translation": 1.0, "junk": junk})
            except CommandError:
                pass
            sent.append(i)

    threads = [threading.Thread(target=hammer) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120.0)
    server.stop()
    commands = read_table(server.trial_paths[0], "commands")
    t = np.asarray(commands["t"])
    assert len(sent) == 600 and len(t) == 600 + 2  # and trial_start, trial_stop
    assert np.all(np.diff(t) >= 0), f"{int((np.diff(t) < 0).sum())} rows step back in time"


class SilentLink:
    """A distributor that never answers: a run shorter than LINK_STARTUP_S reports its link_outage as the loop ends,
    after its last frame and the last commands it ran."""

    counters = {"datagrams_failed": 0}
    last_timings: dict = {}

    def telemetry(self):
        return {}

    def send_frame(self, frame):
        return 0

    def close(self):
        pass


def test_commands_after_the_last_frame_of_a_timed_run_are_refused_at_once(tmp_path, monkeypatch):
    monkeypatch.setattr(server_module, "COMMAND_TIMEOUT_S", 5.0)
    replies: dict[str, tuple[float, str]] = {}
    asked: list[threading.Thread] = []
    window: list[float] = []

    def ask(name, params):
        t0 = time.monotonic()
        try:
            server.command(name, params)
            outcome = "ran"
        except Exception as exc:  # noqa: BLE001 - what the caller would have got, whatever it is
            outcome = f"{type(exc).__name__}: {exc}"
        replies[name] = (time.monotonic() - t0, outcome)

    def echo(line: str) -> None:
        if "link_outage" in line and not asked:  # the loop's thread, its frames and last commands done
            window.append(time.monotonic())
            for name, params in (("trial_start", {"name": "late"}), ("rotate_scene", {"deg": 5.0})):
                asked.append(threading.Thread(target=ask, args=(name, params), daemon=True))
                asked[-1].start()
            for t in asked:
                t.join(0.3)  # queued for a frame that never comes

    server = Server(_config(tmp_path, "tlife2_late"), source=ScriptedSource(rate_hz=100.0), renderer_factory=None,
                    link=SilentLink(), echo=echo)
    frames = server.run(seconds=0.3)
    t_shutdown = time.monotonic()
    for t in asked:
        t.join(10.0)
    assert frames > 0 and len(asked) == 2
    for name in ("trial_start", "rotate_scene"):
        waited, outcome = replies[name]
        assert "the server is stopping" in outcome and waited < 2.0, (name, replies)
    assert t_shutdown - window[0] < 2.5  # the shutdown waited for none of them (before: COMMAND_TIMEOUT_S)
    assert server.trial_name is None and server.trial_paths == [] and _logs(tmp_path) == []


def test_a_loop_that_refuses_calls_fails_them_at_once():
    loop = FrameLoop(clock=SimulatedClock(), source=None, rate_hz=100.0)
    queued = loop.call_soon(lambda: "ran")
    idle = loop.when_idle(lambda: "ran")
    loop.refuse_calls("the server is stopping")
    later = loop.call_soon(lambda: "ran")
    for future in (queued, idle, later):
        with pytest.raises(LoopClosed, match="the server is stopping"):
            future.result(0)
