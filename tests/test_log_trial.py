"""Trial logs: self-describing tables, nothing lost on SIGKILL, clear errors, a bad value costs only itself, disk full
keeps going."""

import datetime
import json
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from multiprocessing import Pipe

import h5py
import numpy as np
import pytest
from conftest import wait_for

from antarium.core.childproc import ChildProcess
from antarium.core.clock import SimulatedClock
from antarium.locomotion import open_source
from antarium.server.frame_loop import FrameLoop
from antarium.trial_log import (
    FRAME_DTYPE,
    SERVOSPHERE_DTYPE,
    LogError,
    TrialLog,
    _writer_main,
    check_log_dir,
    log_path,
    open_log,
    read_table,
)

SERVO_ROW = np.zeros((), SERVOSPHERE_DTYPE).item()


def frame_row(frame: int) -> tuple:
    """A `FRAME_DTYPE` row: frame number `frame`, zeros elsewhere."""
    return (frame, *np.zeros((), FRAME_DTYPE).item()[1:])


def quiet_log(path, name: str) -> TrialLog:
    """A TrialLog whose rows reach the writer only when the test flushes (its sender thread ended)."""
    log = TrialLog(path, {}, name)
    log._stop.set()
    log._thread.join()
    return log


def test_loop_log_holds_frames_samples_events_commands_config(tmp_path):
    clock = SimulatedClock()
    config = {"rig": {"name": "r"}, "trackball": {"cpi": 1200}}
    with TrialLog(tmp_path / "a.h5", config, "trial one", {"ant": 7, "colony": "M. croslandi"}) as log:
        loop = FrameLoop(clock=clock, source=open_source("scripted", clock=clock), log=log)
        loop.run(until=1.0)
        loop.rotate_scene(np.pi / 2)
        log.add_command(clock.now(), "rotate_scene", {"deg": 90}, {"ok": True}, True)
        log.add_scene(clock.now(), "habitat.glb", "ab" * 32)
    with h5py.File(tmp_path / "a.h5", "r") as f:
        assert f.attrs["format"] == "antarium-trial-log"
        assert json.loads(f.attrs["config"])["trackball"] == {"cpi": 1200}
        assert json.loads(f.attrs["metadata"]) == {"ant": 7, "colony": "M. croslandi"}
        assert f.attrs["trial_name"] == "trial one"
        frames = f["frames"][:]
        assert len(frames) == 190 and frames.dtype == FRAME_DTYPE
        assert np.all(np.diff(frames["frame"]) == 1)
        assert len(f["locomotion"]) == int(frames["t_start"][-1] * 1000 + 1e-6)
        assert frames["x"][-1] == pytest.approx(0.02 * 189 / 190, rel=0.01)
        kinds = [k.decode() for k in f["events"]["kind"]]
        assert "scene_rotated" in kinds
        assert f["commands"][0]["name"] == b"rotate_scene"
        assert f["scenes"][0]["sha256"] == b"ab" * 32
    events = read_table(tmp_path / "a.h5", "events")
    assert "scene_rotated" in list(events["kind"])


def test_unwritable_or_existing_path_fails_at_start(tmp_path):
    (tmp_path / "x.h5").write_bytes(b"")
    with pytest.raises(LogError, match="already exists"):
        TrialLog(tmp_path / "x.h5", {})
    with pytest.raises(LogError, match="cannot create trial log"):
        TrialLog(tmp_path / "missing" / "x.h5", {})
    with pytest.raises(LogError, match="JSON-serialisable"):
        TrialLog(tmp_path / "y.h5", {}, "t", {"f": object()})
    (tmp_path / "file").write_bytes(b"")
    with pytest.raises(LogError, match="not writable"):
        check_log_dir(tmp_path / "file" / "logs")


def test_log_path_is_unique(tmp_path):
    a = log_path(tmp_path, "rig1", "homing/run 1")
    assert a.name.startswith("rig1_") and a.name.endswith("_homing_run_1.h5")
    a.write_bytes(b"")
    assert log_path(tmp_path, "rig1", "homing/run 1", when=None) != a


def test_a_rig_name_with_a_dot_keeps_its_trial_in_the_file_name(tmp_path):
    """docs/logs.md: <rig>_<UTC time>_<trial>.h5, for any rig name the config accepts ("lab.1" was cut to lab.h5)."""
    when = datetime.datetime(2026, 11, 27, 8, 0, 0, tzinfo=datetime.UTC)
    assert log_path(tmp_path, "lab.1", "familiar", when=when).name == "lab.1_20261127-080000_familiar.h5"


def test_log_path_keeps_only_ascii_letters_digits_dash_and_underscore(tmp_path):
    assert log_path(tmp_path, "rig1", "fourmi_é-ß 1").name.endswith("_fourmi__-__1.h5")


@pytest.mark.parametrize("name", ["a\x00b", "\udc80x", None])
def test_a_bad_trial_name_fails_before_a_file_is_made(tmp_path, name):
    with pytest.raises(LogError, match=re.escape(f"trial name {name!r} ") + ".*allowed: a str without NUL"):
        TrialLog(tmp_path / "n.h5", {}, name)
    assert not (tmp_path / "n.h5").exists()


def test_a_writer_that_cannot_make_its_file_removes_it(tmp_path):
    ours, writers = Pipe()
    _writer_main(writers, str(tmp_path / "w.h5"), {"note": "a\x00b"})  # an attribute HDF5 refuses
    kind, detail = ours.recv()
    assert kind == "error" and "NUL" in detail
    assert not (tmp_path / "w.h5").exists()


def test_a_writer_that_dies_at_start_is_named_with_its_output(tmp_path, monkeypatch):
    monkeypatch.setattr("antarium.trial_log._take_writer", lambda: ChildProcess("antarium.no_writer", connect=True))
    with pytest.raises(LogError, match="failed to start: .*No module named antarium.no_writer"):
        TrialLog(tmp_path / "d.h5", {}, "dies")


@pytest.mark.parametrize(("metadata", "message"), [
    ([], "trial metadata [] is of type list, not an object"),
    (0, "trial metadata 0 is of type int, not an object"),
    ({"ant": 1, 7: "x"}, "trial metadata key 7 is of type int, not str"),
    ({"ant": 1, "w_mg": float("nan")}, "trial metadata 'w_mg' must be JSON-serialisable: nan"),
])
def test_metadata_must_be_a_json_object_with_str_keys(tmp_path, metadata, message):
    with pytest.raises(LogError, match=re.escape(message) + ".*allowed: a dict with str keys and JSON values"):
        TrialLog(tmp_path / "m.h5", {}, "m", metadata)
    assert not (tmp_path / "m.h5").exists()


def test_events_and_commands_hold_strict_json(tmp_path):
    with TrialLog(tmp_path / "j.h5", {}, "json") as log:
        log.add_event(0.0, "weighed", {"w_mg": float("nan"), "dose": [float("inf"), 1.5]})
        log.add_command(0.0, "note", {"x": -float("inf")}, {"result": None}, True)
    strict = {"parse_constant": lambda c: pytest.fail(f"not JSON: {c}")}
    assert json.loads(read_table(tmp_path / "j.h5", "events")["data"][0], **strict) == {"dose": [None, 1.5],
                                                                                         "w_mg": None}
    assert json.loads(read_table(tmp_path / "j.h5", "commands")["request"][0], **strict) == {"x": None}


@pytest.mark.parametrize(("table", "bad", "named"), [
    ("servosphere", SERVO_ROW[:-1] + (-1,), "Python integer -1 out of bounds for uint32"),
    ("scenes", (1.0, "a\x00b", ""), "scenes.name 'a\\x00b' holds a NUL character"),
    ("scenes", (1.0, "scene_\udce9.json", ""), "scenes.name 'scene_\\udce9.json' holds '\\udce9'"),
], ids=["out-of-range", "nul", "surrogate"])
def test_a_bad_row_is_left_out_counted_and_named_and_the_rest_written(tmp_path, table, bad, named):
    path = tmp_path / "b.h5"
    with TrialLog(path, {}, "bad row") as log:
        for frame in range(100):
            log.add_frame(frame_row(frame))
        log.add_servosphere(SERVO_ROW)
        log._append(table, bad)  # as the writer gets it: past add_*'s checks, where there are any
        log.add_scene(1.0, "habitat", "")
        log.flush(wait=True)
        for frame in range(100, 200):
            log.add_frame(frame_row(frame))
    status = log.status()
    assert status["rows_lost"] == 1 and f"row(s) of table {table!r} not written" in status["error"]
    assert named in status["error"]
    assert {t: status["rows_written"][t] for t in ("frames", "servosphere", "scenes")} == \
        {"frames": 200, "servosphere": 1, "scenes": 1}
    with h5py.File(path, "r") as f:  # a plain reader: the file was closed
        assert list(f["frames"]["frame"]) == list(range(200))
        assert len(f["servosphere"]) == 1 and list(f["scenes"]["name"]) == [b"habitat"]


@pytest.mark.parametrize("add", [
    lambda log, text: log.add_scene(1.0, text, ""),
    lambda log, text: log.add_scene(1.0, "habitat", text),
    lambda log, text: log.add_event(1.0, text, {}),
    lambda log, text: log.add_command(1.0, text, {}, {}, True),
], ids=["scene name", "scene sha256", "event kind", "command name"])
@pytest.mark.parametrize(("text", "problem"), [
    ("a\x00b", "holds a NUL character"),
    ("scene_\udce9.json", "holds '\\udce9', which UTF-8 cannot encode"),
    (b"habitat", "is of type bytes, not str"),
], ids=["nul", "surrogate", "bytes"])
def test_bad_text_is_refused_at_the_call_and_loses_nothing(tmp_path, add, text, problem):
    with TrialLog(tmp_path / "t.h5", {}, "text") as log:
        with pytest.raises(ValueError, match=re.escape(f"{text!r} {problem}") + ".*allowed: a str without NUL"):
            add(log, text)
        log.add_scene(1.0, "habitat", "")
    assert log.status()["rows_lost"] == 0 and log.status()["error"] is None
    assert list(read_table(tmp_path / "t.h5", "scenes")["name"]) == ["habitat"]


def test_rows_added_while_closing_are_counted_lost(tmp_path):
    log = quiet_log(tmp_path / "c.h5", "closing")
    hand_over = log.flush

    def flush_as_a_row_arrives(wait: bool = False) -> None:
        hand_over(wait)
        log.add_frame(frame_row(1))  # another thread's row, right after close()'s last hand-over

    log.flush = flush_as_a_row_arrives
    log.add_frame(frame_row(0))
    log.close()
    log.add_event(2.0, "late")
    assert log.status()["rows_lost"] == 2 and log.status()["rows_written"]["frames"] == 1
    assert list(read_table(tmp_path / "c.h5", "frames")["frame"]) == [0]


def test_a_close_that_times_out_is_an_error_and_counts_the_rows(tmp_path):
    path = tmp_path / "s.h5"
    log = quiet_log(path, "stuck")
    for frame in range(3):
        log.add_frame(frame_row(frame))
    log.flush(wait=True)
    log.add_frame(frame_row(3))
    log.add_frame(frame_row(4))
    os.kill(log._proc.pid, signal.SIGSTOP)  # a writer that does not answer (a hung disk)
    log.close(timeout_s=0.5)
    status = log.status()
    assert status["rows_written"]["frames"] == 3 and status["rows_lost"] == 2
    assert status["error"] == (f"trial log writer for {str(path)!r} did not finish within 0.5 s and was killed; "
                               "2 rows not confirmed written, counted lost")


def test_a_writer_hung_behind_its_full_pipe_is_killed_at_the_deadline_of_close(tmp_path):
    """A hung writer (a stalled network disk) let a hand-over block in send() holding the send lock: close() joined
    the sender thread without a bound and trial_stop and the shutdown hung for ever."""
    import threading

    path = tmp_path / "h.h5"
    log = TrialLog(path, {}, "hung", flush_s=0.05)
    log.add_frame(frame_row(0))
    log.flush(wait=True)
    os.kill(log._proc.pid, signal.SIGSTOP)
    try:
        for frame in range(1, 200_001):  # megabytes: the sender's next hand-over blocks on the full pipe
            log.add_frame(frame_row(frame))
        assert wait_for(lambda: log.status()["unconfirmed_s"] > 0.3, 10.0)  # handed over (blocked), never confirmed
        closing = threading.Thread(target=log.close, kwargs={"timeout_s": 1.0}, daemon=True)
        t0 = time.monotonic()
        closing.start()
        closing.join(15.0)
        took = time.monotonic() - t0
        assert not closing.is_alive() and took < 6.0, took
    finally:
        if log._proc.exitcode is None:  # the code before the fix: let its close() end
            os.kill(log._proc.pid, signal.SIGCONT)
    status = log.status()
    assert log._proc.exitcode is not None and status["unconfirmed_s"] == 0.0
    assert status["rows_written"]["frames"] == 1 and status["rows_lost"] == 200_000
    assert status["error"] == (f"trial log writer for {str(path)!r} did not finish within 1 s and was killed; "
                               "200000 rows not confirmed written, counted lost")
    assert list(read_table(path, "frames")["frame"]) == [0]  # what was confirmed is in the file


def test_the_writer_fsyncs_the_file_and_folder_before_it_reports_them(tmp_path, monkeypatch):
    """Without fsync a power cut or OS crash could lose batches already reported written (and the file's entry)."""
    import threading

    synced = []
    real_fsync = os.fsync

    def recording_fsync(fd: int) -> None:
        synced.append(os.readlink(f"/proc/self/fd/{fd}"))
        real_fsync(fd)

    monkeypatch.setattr(os, "fsync", recording_fsync)
    path = tmp_path / "f.h5"
    ours, writers = Pipe()
    writer = threading.Thread(target=_writer_main, args=(writers, str(path), {"format": "antarium-trial-log"}))
    writer.start()
    assert ours.recv() == ("ready", None)
    assert synced == [str(path), str(tmp_path)]  # the new file, then its directory entry
    for batch in (1, 2):
        ours.send(("rows", batch, {"frames": [frame_row(batch)]}))
        kind, report = ours.recv()
        assert kind == "written" and report["batch"] == batch
        assert synced[2:] == [str(path)] * batch  # each batch is on the disk before it is reported written
    ours.send(("close", 3, {}))
    assert ours.recv()[0] == "closed"
    writer.join(10.0)


_DISK_FULL = textwrap.dedent("""
    import resource, signal, sys
    import numpy as np
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (300_000, 300_000))  # inherited by the writer: the 'disk' fills
    from antarium.trial_log import TrialLog, FRAME_DTYPE
    row = np.zeros((), FRAME_DTYPE).item()
    log = TrialLog(sys.argv[1], {}, "full", flush_s=0.05)
    for i in range(200):
        for k in range(100):
            log.add_frame((i * 100 + k, *row[1:]))
        log.flush(wait=True)
        if log.status()["error"]:
            break
    log.close()
    print(log.error)
""")


def test_a_disk_full_error_says_how_plain_readers_open_the_file(tmp_path):
    """After a failed write the file stays marked open for writing: MATLAB and plain h5py refuse it; the error said
    nothing of it."""
    path = tmp_path / "full.h5"
    out = subprocess.run([sys.executable, "-c", _DISK_FULL, str(path)], capture_output=True, text=True, timeout=90)
    assert out.returncode == 0, out.stderr
    error = out.stdout.strip()  # HDF5's error text spans lines
    assert error.startswith(f"writing trial log {str(path)!r} failed: ")
    assert error.endswith("what was written before stays, but the file stays marked open for writing: open_log() "
                          f"reads it, plain HDF5 readers (MATLAB) only after `h5clear -s {path}` (package hdf5-tools)")
    assert path.read_bytes()[11] == 0x05  # superblock v3 status flags: write + SWMR write, as the error says
    with pytest.raises(OSError, match="already open for write"):
        h5py.File(path, "r")
    with open_log(path) as f:
        frames = f["frames"][:]
    assert len(frames) > 0 and np.all(frames["frame"] == np.arange(len(frames)))


def test_created_monotonic_anchors_the_tables_clock_to_created_utc(tmp_path):
    """The tables' times are on the loop's clock; nothing tied them to wall time."""
    before = datetime.datetime.now(datetime.UTC)
    with TrialLog(tmp_path / "a.h5", {}, "anchor", clock=lambda: 1234.5):
        pass
    with open_log(tmp_path / "a.h5") as f:
        assert f.attrs["format_version"] == 3
        assert f.attrs["created_monotonic"] == 1234.5
        created = datetime.datetime.fromisoformat(f.attrs["created_utc"])
    assert before <= created <= datetime.datetime.now(datetime.UTC)


def test_a_rig_name_too_long_for_the_file_name_is_a_log_error_naming_the_path(tmp_path):
    """A 240-byte rig name made trial_start fail with a raw OSError (ENAMETOOLONG)."""
    from antarium.trial_log import RIG_NAME_MAX_BYTES

    with pytest.raises(LogError, match=re.escape(f"trial log '{tmp_path}/{'r' * 240}_") + r"\d{8}-\d{6}_ant7.h5': "
                       r"its file name is 264 bytes long; allowed: at most 255 bytes \(a \[rig\] name of at most "
                       r"166 bytes\)"):
        log_path(tmp_path, "r" * 240, "ant7")
    longest = log_path(tmp_path, "r" * RIG_NAME_MAX_BYTES, "t" * 100).name  # the trial name cut to 64 characters
    assert len(longest.encode()) == 255 - len("-9999")
    with pytest.raises(LogError, match=r"trial log path '.*' cannot be used: File name too long"):
        TrialLog(tmp_path / ("d" * 300) / "x.h5", {})


@pytest.mark.parametrize(("data", "stored"), [
    ({1: 2, "translation": 1.0}, {"1": 2, "translation": 1.0}),  # keys of mixed types: sort_keys raised TypeError
    ({("a", 1): float("nan")}, {"('a', 1)": None}),
])
def test_json_rows_take_keys_that_are_not_str(tmp_path, data, stored):
    with TrialLog(tmp_path / "k.h5", {}, "keys") as log:
        log.add_event(0.0, "edit", data)
        log.add_command(0.0, "gains", data, {"error": "x"}, False)
    events, commands = read_table(tmp_path / "k.h5", "events"), read_table(tmp_path / "k.h5", "commands")
    assert json.loads(events["data"][0]) == stored and json.loads(commands["request"][0]) == stored


class _ResumeOnSend:
    """A connection that resumes the stopped process `pid` (SIGCONT) as it sends a message."""

    def __init__(self, conn, pid: int) -> None:
        self._conn, self._pid = conn, pid

    def send(self, message) -> None:
        os.kill(self._pid, signal.SIGCONT)
        self._conn.send(message)

    def __getattr__(self, name: str):
        return getattr(self._conn, name)


def test_flush_wait_returns_once_its_own_rows_are_on_disk(tmp_path):
    path = tmp_path / "w.h5"
    log = quiet_log(path, "wait")
    log.add_event(0.0, "first")
    os.kill(log._proc.pid, signal.SIGSTOP)
    log.flush()  # batch 1, not reported on before the next flush has handed its own batch over
    log.add_event(1.0, "marker")
    for frame in range(50_000):
        log.add_frame(frame_row(frame))
    log._conn = _ResumeOnSend(log._conn, log._proc.pid)
    log.flush(wait=True)
    assert log.rows_written["frames"] == 50_000 and log.rows_written["events"] == 2
    with open_log(path) as f:
        assert len(f["frames"]) == 50_000 and len(f["events"]) == 2
    log.close()


_WRITER = textwrap.dedent("""
    import sys, threading, time
    from antarium.core.clock import MonotonicClock
    from antarium.server.frame_loop import FrameLoop
    from antarium.locomotion import open_source
    from antarium.trial_log import TrialLog
    clock = MonotonicClock()
    log = TrialLog(sys.argv[1], {"rig": {"name": "k"}}, "killed", flush_s=0.05)
    loop = FrameLoop(clock=clock, source=open_source("scripted", clock=clock), log=log)

    def tell():  # once the writer has reported 100 frames written (however slow a loaded machine makes it)
        while log.status()["rows_written"]["frames"] < 100:
            time.sleep(0.01)
        print("written", flush=True)

    threading.Thread(target=tell, daemon=True).start()
    loop.run(until=clock.now() + 60)
""")


def test_log_survives_sigkill(tmp_path):
    path = tmp_path / "k.h5"
    proc = subprocess.Popen([sys.executable, "-c", _WRITER, str(path)], stdout=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        assert proc.stdout.readline().strip() == "written"
        time.sleep(0.1)  # more batches on their way: the kill may fall in one
    finally:  # kill the server and its log writer at once, as a power cut or the OOM killer would
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(10)
    # superblock v3 status flags: 0 (killed between batches, the usual case: closed and clean) or write +
    # SWMR-write (killed during a batch's millisecond: consistent, open_log reads it; plain readers need h5clear -s)
    assert path.read_bytes()[11] in (0x00, 0x05)
    with open_log(path) as f:
        frames = f["frames"][:]
        assert len(frames) >= 100  # what the writer reported written before the kill
        assert np.all(np.diff(frames["frame"]) == 1) and frames["frame"][0] == 0
        assert len(f["locomotion"]) > 0 and json.loads(f.attrs["config"])["rig"]["name"] == "k"


_FILLER = textwrap.dedent("""
    import json, resource, signal, sys, time
    from antarium.config import resolve
    from antarium.server import Server
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (1_000_000, 1_000_000))  # the disk "fills" after 1 MB, some batches in
    # (2 kHz of samples: a batch stays far below 1 MB even when a loaded machine holds the sender for a second)
    config = resolve({"rig": {"name": "full"}, "bus": {"enabled": False}, "log": {"dir": sys.argv[1], "flush_s": 0.05},
                      "loop": {"rate_hz": 1000.0}, "locomotion": {"source": "scripted", "rate_hz": 2000.0}})
    alarms = []
    server = Server(config, renderer_factory=None, link=False, record="full", echo=alarms.append).start_thread()
    deadline = time.monotonic() + 30
    while not server.status()["alarms"] and time.monotonic() < deadline:
        time.sleep(0.05)
    frames = server.loop.frame
    deadline = time.monotonic() + 10  # the frames go on (as fast as a loaded machine lets them)
    while server.loop.frame <= frames + 100 and time.monotonic() < deadline:
        time.sleep(0.05)
    status = server.status()
    print(json.dumps({"alarms": status["alarms"], "lost": status["log"]["rows_lost"],
                      "written": status["log"]["rows_written"]["frames"],
                      "frames_go_on": server.loop.frame > frames + 100, "echo": alarms}), flush=True)
    server.stop()
""")


def test_disk_full_is_loud_while_the_stimulus_continues(tmp_path):
    out = subprocess.run([sys.executable, "-c", _FILLER, str(tmp_path)], capture_output=True, text=True, timeout=90)
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout.splitlines()[-1])
    assert any(a.startswith("TRIAL LOG NOT WRITTEN") for a in result["alarms"])
    assert result["lost"] > 0 and result["frames_go_on"]
    assert any("log_error" in line for line in result["echo"])  # printed for the operator
    (path,) = tmp_path.glob("*.h5")
    with open_log(path) as f:  # every batch written before the disk filled is still readable
        assert len(f["frames"]) >= result["written"] > 0


def test_status_never_waits_for_a_batch_being_handed_over(tmp_path):
    import threading

    with TrialLog(tmp_path / "s.h5", {}, "status") as log:
        log.add_event(0.0, "one", {})
        log.flush(wait=True)
        before = log.status()
        assert before["rows_written"]["events"] == 1
        answers = []
        with log._send_lock:  # a hand-over held up (the writer's pipe full behind a slow disk)
            asking = threading.Thread(target=lambda: answers.append(log.status()))  # e.g. the frame loop
            asking.start()
            asking.join(10.0)
        assert answers == [before]  # answered at once, with what the writer had reported


def test_a_log_being_written_reads_and_a_cut_or_foreign_file_is_refused_naming_it(tmp_path):
    """The SWMR fallback is for a file whose writer has it open (read while a trial runs); a log cut short (a
    partial copy) read back with zero-filled rows through it, and a foreign HDF5 file gave a TypeError."""
    import h5py

    path = tmp_path / "live.h5"
    log = TrialLog(path, {}, "live", {}, flush_s=0.05)
    try:
        for frame in range(2000):
            log.add_frame(frame_row(frame))
        log.flush(wait=True)
        assert np.array_equal(read_table(path, "frames")["frame"], np.arange(2000))  # open for write: SWMR read
    finally:
        log.close()
    cut = tmp_path / "cut.h5"
    cut.write_bytes(path.read_bytes()[:path.stat().st_size // 2])
    with pytest.raises(LogError, match=r"cut.h5' cannot be read as a trial log: truncated file"):
        read_table(cut, "frames")
    foreign = tmp_path / "foreign.h5"
    with h5py.File(foreign, "w") as f:
        f["frames"] = np.arange(5)
    with pytest.raises(LogError, match=r"foreign.h5' is an HDF5 file but not an antarium trial log"):
        read_table(foreign, "frames")
    text = tmp_path / "notes.h5"
    text.write_text("not hdf5")
    with pytest.raises(LogError, match=r"notes.h5' cannot be read as a trial log: file signature not found"):
        open_log(text)


def test_a_log_its_writer_holds_open_is_read_through_swmr(tmp_path):
    """HDF5 refuses a plain read of a file open for SWMR writing ('already open for write'): that case, and
    only that one, is read as SWMR."""
    path = tmp_path / "held.h5"
    holder = subprocess.Popen([sys.executable, "-c", textwrap.dedent("""
        import sys, time, h5py, numpy as np
        f = h5py.File(sys.argv[1], "w", libver="latest")
        f.attrs["format"] = "antarium-trial-log"
        f.create_dataset("frames", data=np.array([(7,), (8,), (9,)], [("frame", "<i8")]), maxshape=(None,))
        f.swmr_mode = True
        print("ready", flush=True)
        time.sleep(60)
    """), str(path)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "ready"
        with pytest.raises(OSError, match="already open for write"):
            import h5py

            h5py.File(path, "r")
        assert list(read_table(path, "frames")["frame"]) == [7, 8, 9]
    finally:
        holder.kill()
        holder.wait(10)


def kill_writer(log: TrialLog) -> int:
    """SIGKILL the log's writer (the OOM killer) and wait until it has ended; its pid."""
    pid = log._proc.pid
    os.kill(pid, signal.SIGKILL)
    log._proc.proc.wait(10)
    return pid


def add_frames(log: TrialLog, first: int, count: int) -> None:
    for frame in range(first, first + count):
        log.add_frame(frame_row(frame))


def test_a_writer_killed_between_batches_is_replaced_and_loses_nothing(tmp_path):
    """A writer killed mid-trial (the OOM killer) cost every later row ('rows_lost: 789') though its file was closed
    and intact: a new writer takes the file over."""
    path = tmp_path / "k.h5"
    log = quiet_log(path, "killed")
    add_frames(log, 0, 100)
    log.flush(wait=True)  # reported written: the writer waits for its next batch
    before_kill = time.monotonic()
    dead = kill_writer(log)
    add_frames(log, 100, 100)
    log.flush(wait=True)
    assert log.status()["rows_written"]["frames"] == 200 and log._proc.pid != dead  # a new writer wrote them
    add_frames(log, 200, 100)
    log.close()
    status = log.status()
    assert status["rows_lost"] == 0 and status["error"] is None and status["rows_written"]["frames"] == 300
    assert status["restarts"] == [f"trial log writer for {str(path)!r} died (exit -9): [Errno 32] Broken pipe; a new "
                                  "writer took the file over at 100 rows confirmed written and was handed the 0 "
                                  "unconfirmed batches (0 rows) again"]
    assert path.read_bytes()[11] == 0x00  # closed and clean: plain readers (MATLAB) open it
    with h5py.File(path, "r") as f:
        assert np.array_equal(f["frames"]["frame"], np.arange(300))
    events = read_table(path, "events")  # the file itself says that its writer was replaced, and when
    assert list(events["kind"]) == ["log_writer_restarted"]
    assert json.loads(events["data"][0]) == {"restart": 1, "of": 3, "detail": status["restarts"][0]}
    assert before_kill < events["t"][0] < time.monotonic()  # on the log's clock (time.monotonic here)


def test_unconfirmed_batches_of_a_killed_writer_are_handed_again_and_written_once(tmp_path):
    """Batches piled up behind a stopped writer, one of them written to the file but never confirmed, then the writer
    is killed: the new writer cuts the file back to the confirmed rows and gets every unconfirmed batch again."""
    path = tmp_path / "u.h5"
    log = quiet_log(path, "unconfirmed")
    add_frames(log, 0, 10)
    log.add_event(0.0, "first", {"n": 1})
    log.flush(wait=True)
    os.kill(log._proc.pid, signal.SIGSTOP)  # between batches: waiting for the next
    for first in (10, 20, 30):  # three batches handed over, none confirmed
        add_frames(log, first, 10)
        log.flush()
    with h5py.File(path, "r+", libver=("v110", "v110"), locking=False) as f:  # as the writer would have: batch 10..19
        frames = f["frames"]  # appended, closed, then killed before its report
        frames.resize((20,))
        frames[10:] = np.array([frame_row(frame) for frame in range(10, 20)], FRAME_DTYPE)
    assert log.status()["rows_written"]["frames"] == 10
    kill_writer(log)
    add_frames(log, 40, 10)
    log.flush(wait=True)
    log.close()
    status = log.status()
    assert status["rows_lost"] == 0 and status["error"] is None
    assert status["rows_written"] == {"frames": 50, "locomotion": 0, "events": 2, "commands": 0, "scenes": 0,
                                      "servosphere": 0}
    assert status["restarts"][0].endswith("a new writer took the file over at 11 rows confirmed written and was "
                                          "handed the 3 unconfirmed batches (30 rows) again")
    assert np.array_equal(read_table(path, "frames")["frame"], np.arange(50))  # each frame once, in order
    assert list(read_table(path, "events")["kind"]) == ["first", "log_writer_restarted"]


def test_a_writer_killed_more_often_than_the_restart_limit_ends_the_writing_counting_rows_lost(tmp_path):
    limit = 3  # restarts a trial gets (docs/logs.md)
    path = tmp_path / "r.h5"
    log = quiet_log(path, "again")
    for restart in range(limit + 1):
        add_frames(log, restart * 10, 10)
        log.flush(wait=True)
        assert log.status()["rows_written"]["frames"] == (restart + 1) * 10  # by a new writer after each death
        kill_writer(log)
    first = (limit + 1) * 10
    add_frames(log, first, 10)  # handed to no writer: the last death was one too many
    log.flush(wait=True)
    add_frames(log, first + 10, 5)
    log.close()
    status = log.status()
    assert len(status["restarts"]) == limit
    assert status["rows_written"]["frames"] == first and status["rows_lost"] == 15
    assert status["error"] == (f"trial log writer for {str(path)!r} died (exit -9): [Errno 32] Broken pipe; no new "
                               f"writer: {limit} restarts is the most a trial gets; its unconfirmed rows "
                               "and every later row counted lost")
    assert np.array_equal(read_table(path, "frames")["frame"], np.arange(first))
    restarts = [json.loads(data) for data in read_table(path, "events")["data"]]  # one event each, in order
    assert [(event["restart"], event["detail"]) for event in restarts] == list(enumerate(status["restarts"], 1))


def test_a_writer_that_died_within_a_batch_is_not_replaced_and_the_error_says_why(tmp_path):
    """A death within a batch leaves the file marked open for writing: no new writer may take it (as before)."""
    path = tmp_path / "b.h5"
    log = quiet_log(path, "in batch")
    add_frames(log, 0, 10)
    log.flush(wait=True)
    kill_writer(log)
    subprocess.run([sys.executable, "-c", textwrap.dedent("""
        import os, sys, h5py
        f = h5py.File(sys.argv[1], "r+", libver=("v110", "v110"), locking=False)
        f.swmr_mode = True  # as the writer does for each batch
        os._exit(0)  # killed before it closed the file
    """), str(path)], check=True, timeout=60)
    add_frames(log, 10, 10)
    log.flush(wait=True)
    log.close()
    status = log.status()
    assert status["error"].startswith(f"trial log writer for {str(path)!r} died (exit -9): [Errno 32] Broken pipe; "
                                      "a new writer could not take the file over: ")
    assert "already open for write" in status["error"]
    assert status["error"].endswith("the file stays as it is (open_log() reads it); its unconfirmed rows and every "
                                    "later row counted lost")
    assert status["restarts"] == [] and status["rows_written"]["frames"] == 10 and status["rows_lost"] == 10
    assert np.array_equal(read_table(path, "frames")["frame"], np.arange(10))


def test_a_server_whose_log_writer_is_killed_raises_an_alarm_and_keeps_every_frame(tmp_path):
    from antarium.config import resolve
    from antarium.server import Server

    config = resolve({"rig": {"name": "oom"}, "bus": {"enabled": False}, "log": {"dir": str(tmp_path), "flush_s": 1.0},
                      "loop": {"rate_hz": 200.0}, "locomotion": {"source": "scripted", "rate_hz": 400.0}})
    echoed = []
    server = Server(config, renderer_factory=None, link=False, echo=echoed.append).start_thread()
    try:
        assert wait_for(lambda: server.loop is not None and server.loop.frame > 5, 30.0)
        path = server.command("trial_start", {"name": "oom", "metadata": {}})["path"]
        log = server.trial_log
        confirmed = log.status()["rows_written"]["frames"]
        assert wait_for(lambda: log.status()["rows_written"]["frames"] > confirmed, 10.0)
        kill_writer(log)  # just after a report: a second before the next batch (flush_s 1 s)
        assert wait_for(lambda: any("RESTARTED" in a for a in server.status()["alarms"]), 10.0)
        alarms = server.status()["alarms"]
        assert [a for a in alarms if a.startswith("TRIAL LOG")] == [
            f"TRIAL LOG WRITER RESTARTED, 1 OF 3: {log.status()['restarts'][0]}"]
        assert wait_for(lambda: any(line.startswith("antarium serve: ALARM: TRIAL LOG WRITER RESTARTED, 1 OF 3: ")
                                    for line in echoed), 10.0)  # the status thread prints it for the operator
        frame = server.loop.frame
        assert wait_for(lambda: server.loop.frame > frame + 50, 20.0)  # the frames go on
        stopped = server.command("trial_stop")
    finally:
        server.stop()
    assert stopped["rows_lost"] == 0 and stopped["error"] is None and len(stopped["restarts"]) == 1
    frames = read_table(path, "frames")["frame"]
    assert len(frames) == stopped["rows_written"]["frames"] > 100
    assert np.array_equal(frames, np.arange(frames[0], frames[0] + len(frames)))  # each once, none missing


def test_a_writer_that_dies_holding_more_unconfirmed_rows_than_are_kept_is_not_replaced(tmp_path, monkeypatch):
    """Rows not confirmed are kept for a new writer up to RESEND_MAX_ROWS; beyond it the oldest are let go, and a
    writer that dies before confirming them is not replaced (the file would miss them): the rows count lost."""
    monkeypatch.setattr("antarium.trial_log.RESEND_MAX_ROWS", 15, raising=False)  # the code before had none
    path = tmp_path / "m.h5"
    log = quiet_log(path, "many")
    add_frames(log, 0, 10)
    log.flush(wait=True)
    os.kill(log._proc.pid, signal.SIGSTOP)  # a writer that stopped answering
    for first in (10, 20, 30):  # 30 rows not confirmed: the two oldest batches are no longer kept
        add_frames(log, first, 10)
        log.flush()
    kill_writer(log)
    add_frames(log, 40, 10)
    log.flush(wait=True)
    log.close()
    status = log.status()
    assert status["error"] == (f"trial log writer for {str(path)!r} died (exit -9): [Errno 32] Broken pipe; more than "
                               "15 rows were not confirmed and the oldest were no longer kept to hand over again; its "
                               "unconfirmed rows and every later row counted lost")
    assert status["restarts"] == [] and status["rows_written"]["frames"] == 10 and status["rows_lost"] == 40
    assert np.array_equal(read_table(path, "frames")["frame"], np.arange(10))
