"""Trial logs: one self-describing HDF5 file per recording (h5py), written so that nothing is lost.

The frame loop only appends rows to in-memory buffers (cheap); every `flush_s` seconds (at most 1 s) they
go to a writer process, which opens the file, appends them in SWMR mode and closes it again. So after a
crash or SIGKILL the file holds everything up to the last batch and is almost always closed and clean
(any HDF5 >= 1.10 opens it, MATLAB included); a kill in the millisecond of a batch leaves it marked open,
which `open_log` (SWMR read) still opens. The writer fsyncs the file after each batch, before it reports the
batch written, so a power cut keeps what was reported. A write error (disk full) does not stop the stimulus: the
log keeps counting what it could not write and reports it in `status()`, and the server makes that loud; so does
a writer that stops answering (a hung disk), which the end of the trial kills after at most `CLOSE_TIMEOUT_S`.
A writer that dies (the OOM killer, a crash in HDF5) is replaced, at most `MAX_WRITER_RESTARTS` times a trial: the
file is closed between batches, so a new writer opens it, cuts each table back to the rows the dead one confirmed
and is handed again every batch that was not confirmed (kept in memory until confirmed, at most `RESEND_MAX_ROWS`
rows); each restart is reported in `status()["restarts"]` and raises an alarm.
Every dataset and its units are listed in `docs/logs.md`.
"""

from __future__ import annotations

import atexit
import collections
import datetime as _dt
import hashlib
import json
import math
import os
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from antarium.core.childproc import ChildProcess, connection_from_arg
from antarium.core.log_names import NAME_MAX_BYTES, RIG_NAME_MAX_BYTES, TRIAL_NAME_MAX

#: 2: the frames table has `full_render`; 3: the root attribute `created_monotonic`
FORMAT_VERSION = 3

#: the longest the end of a trial (`TrialLog.close`) waits for the writer before killing it (s)
CLOSE_TIMEOUT_S = 30.0

#: writers that die during a trial are replaced this many times; the next death ends the writing as before (its rows
#: and every later row counted lost, `error` says why)
MAX_WRITER_RESTARTS = 3
#: the event each restart writes into the trial's `events` table (data: `restart` k, `of`, `detail`: the restart's line)
RESTART_EVENT = "log_writer_restarted"

#: rows handed over and not yet confirmed written that are kept for a new writer should the writer die; beyond this
#: (a writer that stopped answering for minutes) the oldest batches are no longer kept, and a writer that dies before
#: confirming them is not replaced (about 200 MB of frame rows: minutes of a 1 kHz loop and a 1 kHz ball)
RESEND_MAX_ROWS = 250_000

#: how long a writer whose connection broke is given to be seen ended before a new one may take its file (s)
WRITER_EXIT_WAIT_S = 5.0

#: HDF5 format bounds: 1.10 is the oldest format with SWMR and the newest that HDF5 1.10 libraries (MATLAB's,
#: Debian 12's tools) read; h5py's "latest" (HDF5 2.0 here) writes datatype messages that 1.10 cannot decode
LIBVER = ("v110", "v110")

#: per-frame table: times in seconds on the loop's clock, positions in metres, angles in radians
FRAME_DTYPE = np.dtype([
    ("frame", "<i8"), ("t_target", "<f8"), ("t_start", "<f8"), ("t_sent", "<f8"),
    ("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("heading", "<f8"), ("scene_rotation", "<f8"),
    ("closed_loop", "u1"), ("fixed_tether", "u1"), ("sample_seq", "<i8"), ("latency", "<f8"),
    ("render", "<f8"), ("sample", "<f8"), ("convert", "<f8"), ("encode", "<f8"), ("send", "<f8"),
    ("pacing_error", "<f8"), ("late", "u1"), ("skipped", "<i4"), ("locomotion_connected", "u1"), ("link_ok", "u1"),
    ("full_render", "u1"),
])
#: per-sample locomotion table: ball rotation increments in radians about the dome axes
SAMPLE_DTYPE = np.dtype([
    ("t", "<f8"), ("seq", "<i8"), ("rx", "<f8"), ("ry", "<f8"), ("rz", "<f8"), ("t_device", "<f8"), ("quality", "<f4"),
])

#: per-camera-frame servosphere table (source "servosphere"; empty otherwise): tracker error from the apex (mm),
#: body axis and resolved heading (rad), ball angular velocity asked for (rad/s), rotor rates sent (steps/s),
#: the firmware's newest step counts, and the fault bits (`antarium.locomotion.servosphere.source.FAULTS`)
SERVOSPHERE_DTYPE = np.dtype([
    ("t", "<f8"), ("frame", "<i8"), ("err_x_mm", "<f4"), ("err_y_mm", "<f4"), ("orientation", "<f4"),
    ("heading", "<f4"), ("omega_x", "<f4"), ("omega_y", "<f4"), ("omega_z", "<f4"), ("rate1", "<f4"),
    ("rate2", "<f4"), ("rate3", "<f4"), ("steps1", "<i8"), ("steps2", "<i8"), ("steps3", "<i8"), ("faults", "<u4"),
])


def _text_dtypes():
    import h5py

    s = h5py.string_dtype()
    events = np.dtype([("t", "<f8"), ("kind", s), ("data", s)])
    commands = np.dtype([("t", "<f8"), ("name", s), ("request", s), ("reply", s), ("ok", "u1")])
    scenes = np.dtype([("t", "<f8"), ("name", s), ("sha256", s)])
    return {"events": events, "commands": commands, "scenes": scenes}


class LogError(RuntimeError):
    """A trial log that cannot be created (bad path, no permission, a bad name or metadata); raised before anything
    starts."""


def file_sha256(path: str | Path) -> str:
    """Hex SHA-256 of a file's bytes (scene files are hashed into the log)."""
    h = hashlib.sha256()
    with Path(path).open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _json(value: Any) -> str:
    """`value` as strict JSON text (RFC 8259): NaN and ±Infinity as null, values JSON has no type for as their str(),
    dict keys that are not str as their str() (keys of mixed types cannot be sorted as they are)."""
    try:
        return json.dumps(value, sort_keys=True, default=str, allow_nan=False)
    except (ValueError, TypeError):  # a non-finite float or a key that is not str: only these rare cases pay the copy
        return json.dumps(_plain(value), sort_keys=True, default=str, allow_nan=False)


def _plain(value: Any) -> Any:
    """`value` with every non-finite float in it (in dicts, lists and tuples, at any depth) replaced by None and every
    dict key that is not a str by its str()."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {key if isinstance(key, str) else str(key): _plain(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(item) for item in value]
    return value


def _check_text(what: str, value: Any, error: type[Exception] = ValueError) -> None:
    """Raise `error` naming `what` and `value` unless it is text HDF5 stores: a str without NUL, encodable as UTF-8."""
    problem = None
    if not isinstance(value, str):
        problem = f"is of type {type(value).__name__}, not str"
    elif "\x00" in value:
        problem = "holds a NUL character"
    else:
        try:
            value.encode()
        except UnicodeEncodeError as exc:
            problem = f"holds {value[exc.start]!r}, which UTF-8 cannot encode (a lone surrogate)"
    if problem:
        raise error(f"{what} {value!r} {problem}; allowed: a str without NUL characters, encodable as UTF-8")


def _metadata_json(metadata: Any) -> str:
    """Trial metadata (None: none) as strict JSON text; `LogError` naming the key at fault unless it is a dict with
    str keys and JSON values (str, finite numbers, bools, None, lists, dicts)."""
    allowed = "allowed: a dict with str keys and JSON values (str, finite numbers, bools, None, lists, dicts)"
    metadata = {} if metadata is None else metadata
    if not isinstance(metadata, dict):
        raise LogError(f"trial metadata {metadata!r} is of type {type(metadata).__name__}, not an object; {allowed}")
    for key, value in metadata.items():
        if not isinstance(key, str):
            raise LogError(f"trial metadata key {key!r} is of type {type(key).__name__}, not str; {allowed}")
        try:
            json.dumps(value, sort_keys=True, allow_nan=False)
        except (TypeError, ValueError) as exc:
            raise LogError(f"trial metadata {key!r} must be JSON-serialisable: {value!r}: {exc}; {allowed}") from None
    return json.dumps(metadata, sort_keys=True, allow_nan=False)


class TrialLog:
    """One recording. Append rows from any thread (cheap); a separate writer process owns the HDF5 file.

    path:     the .h5 file to create (its folder must exist and be writable; an existing file is refused)
    config:   the resolved rig config as TOML tables (`RigConfig.to_toml_dict()`; stored as JSON in the
              `config` attribute)
    name:     trial name (a str without NUL, encodable as UTF-8); metadata: dict with str keys and JSON values
              (no NaN or Infinity) stored as JSON in the `metadata` attribute (None: {})
    flush_s:  seconds between hand-overs to the writer, which appends, closes and fsyncs the file (at most 1 s)
    clock:    the clock the tables' times are read on (s; the frame loop's `clock.now`); read with the wall time
              into the `created_monotonic` and `created_utc` attributes

    The writer is a process of its own so that HDF5 never holds the frame loop's GIL and a failing disk
    cannot take the stimulus down: a write error is reported in `status()["error"]`, the loop goes on.
    If this process dies (even SIGKILL) the writer sees its pipe close and ends; the file is closed between batches.
    If the writer dies (its connection breaks, in the sender thread: never in the frame loop), a new one takes the
    file over (`_restart`), at most `MAX_WRITER_RESTARTS` times; not after `close()`'s deadline killed it, nor after a
    write error (a full disk), which ends the writing for good.
    """

    def __init__(self, path: str | Path, config: dict[str, Any], name: str = "", metadata: dict | None = None,
                 flush_s: float = 1.0, start_timeout_s: float = 30.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        from antarium import __version__

        if not 0 < flush_s <= 1.0:
            raise ValueError(f"flush_s must be in (0, 1] seconds, got {flush_s}")
        _check_text("trial name", name, LogError)
        metadata_json = _metadata_json(metadata)
        self.path = Path(path)
        if _exists(self.path):
            raise LogError(f"trial log {str(self.path)!r} already exists; a recording never overwrites one")
        self._clock = clock
        created, created_utc = clock(), _dt.datetime.now(_dt.UTC)  # the anchor of the tables' times to UTC
        attrs = {"format": "antarium-trial-log", "format_version": FORMAT_VERSION, "software_version": __version__,
                 "created_utc": created_utc.isoformat(), "created_monotonic": float(created), "trial_name": name,
                 "metadata": metadata_json, "config": _json(config)}
        self._start_timeout_s = float(start_timeout_s)
        self._expired = False  # close()'s deadline has passed: no new writer
        self._proc = None
        kind, detail = self._start(("open", str(self.path), attrs))
        if kind != "ready":
            self._proc.stop(5)
            raise LogError(f"cannot create trial log {str(self.path)!r}: {detail}")
        self.flush_s = float(flush_s)
        self._tables = ("frames", "locomotion", "events", "commands", "scenes", "servosphere")
        self._pending: dict[str, list] = {table: [] for table in self._tables}
        self._lock = threading.Lock()
        self._send_lock = threading.Lock()
        self.rows_written = dict.fromkeys(self._tables, 0)
        self._lost_here = 0  # rows lost in this process: added after close(), or never handed over
        self._unsent = 0  # of these, rows whose hand-over failed (the writer dead or killed)
        self._writer_lost = 0  # as the writer last reported
        self._batch = 0  # number of the last batch (or close) handed to the writer
        self._confirmed = 0  # number of the last one it reported on
        self._rows_sent = 0
        #: [batch number, monotonic time its hand-over began, kind, its rows (None once no longer kept, see
        #: RESEND_MAX_ROWS)] of each batch the writer has not reported on yet
        self._handed: collections.deque[list] = collections.deque()
        self._kept = 0  # rows kept in `_handed` for a new writer
        self._write_failed = False  # the writer reported an HDF5 write error (disk full): no new writer
        self._gave_up = False  # a writer died and was not replaced: nothing more is handed over
        #: one line for each writer that died and was replaced (status()["restarts"])
        self.restarts: list[str] = []
        self._killed = False  # by close() at its deadline
        self.error: str | None = None
        self._closed = False
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._sender, name=f"trial-log {self.path.name}", daemon=True)
        self._thread.start()

    # -- appending (any thread; cheap) -----------------------------------------------------------------
    def add_frame(self, row: tuple) -> None:
        """One row in `FRAME_DTYPE` field order."""
        self._append("frames", row)

    def add_samples(self, samples) -> None:
        """`BallSample`s as they were consumed by the loop."""
        for s in samples:
            t_dev = s.t_device if s.t_device is not None else float("nan")
            self._append("locomotion", (s.t, s.seq, *s.rotation, t_dev, s.quality))

    def add_servosphere(self, row: tuple) -> None:
        """One row in `SERVOSPHERE_DTYPE` field order."""
        self._append("servosphere", row)

    def add_event(self, t: float, kind: str, data: Any = None) -> None:
        """`kind`: text (ValueError otherwise, see `_check_text`); `data` stored as strict JSON."""
        _check_text("event kind", kind)
        self._append("events", (t, kind, _json(data)))

    def add_command(self, t: float, name: str, request: Any, reply: Any, ok: bool) -> None:
        """`name`: text (ValueError otherwise); `request` and `reply` stored as strict JSON."""
        _check_text("command name", name)
        self._append("commands", (t, name, _json(request), _json(reply), int(ok)))

    def add_scene(self, t: float, name: str, sha256: str) -> None:
        """`name` and `sha256`: text (ValueError otherwise)."""
        _check_text("scene name", name)
        _check_text("scene sha256", sha256)
        self._append("scenes", (t, name, sha256))

    def _append(self, table: str, row: tuple) -> None:
        with self._lock:
            if self._closed:
                self._lost_here += 1
            else:
                self._pending[table].append(row)

    @property
    def rows_lost(self) -> int:
        """Rows not written: refused by the writer (bad values, a write error) or added after `close()`."""
        return self._lost_here + self._writer_lost

    # -- handing rows to the writer --------------------------------------------------------------------
    def _sender(self) -> None:
        while not self._stop.wait(self.flush_s):
            self.flush()

    def _collect_replies(self, batch: int = 0, timeout_s: float = 0.0) -> bool:
        """Take in the writer's reports, waiting up to `timeout_s` seconds for the one on batch number `batch`;
        True once that is in."""
        deadline = time.monotonic() + timeout_s
        while self._conn.poll(max(0.0, deadline - time.monotonic()) if self._confirmed < batch else 0.0):
            kind, report = self._conn.recv()
            self.rows_written.update(report["rows_written"])
            self._writer_lost = report["rows_lost"]
            self.error = report["error"] or self.error
            self._write_failed = self._write_failed or report["failed"]
            self._confirmed = report["batch"]
            while self._handed and self._handed[0][0] <= self._confirmed:
                rows = self._handed.popleft()[3]
                self._kept -= 0 if rows is None else _count(rows)
            if kind == "closed":  # its last word: the pipe's end follows
                break
        return self._confirmed >= batch

    def _hand_over(self, kind: str, rows: dict[str, list]) -> None:
        """Send the next batch (holding `_send_lock`); the time its hand-over began is kept until the writer reports
        on it, so that a writer that stops answering shows in `status()["unconfirmed_s"]` even while the hand-over
        itself is blocked (its pipe full)."""
        number = self._batch + 1
        self._handed.append([number, time.monotonic(), kind, rows])
        try:
            self._conn.send((kind, number, rows))
        except BaseException:
            self._handed.pop()
            raise
        self._batch = number
        self._kept += _count(rows)
        for entry in self._handed:  # beyond the bound, the oldest batches are no longer kept for a new writer
            if self._kept <= RESEND_MAX_ROWS:
                break
            if entry[3] is not None:
                self._kept -= _count(entry[3])
                entry[3] = None

    def _start(self, message: tuple) -> tuple[str, Any]:
        """Start a writer (the prepared spare) with `message` (("open", path, attrs) or ("resume", path, state))
        and return its answer (("ready", None) or ("error", reason)); LogError when it dies or does not answer
        within the start timeout. It is `_proc` from the start, so that close()'s deadline kills it."""
        self._proc = _take_writer()
        self._conn = self._proc.conn
        if self._expired:
            self._proc.kill()
        try:
            self._conn.send(message)
            if not self._conn.poll(self._start_timeout_s):
                raise LogError(f"trial log writer for {str(self.path)!r} did not answer within "
                               f"{self._start_timeout_s:g} s")
            return self._conn.recv()
        except (OSError, EOFError) as exc:
            output = self._proc.output()  # what it printed (a traceback), read before kill() releases it
            self._proc.kill()
            raise LogError(f"trial log writer for {str(self.path)!r} failed to start: {exc}; {output}") from None
        except LogError:
            self._proc.kill()
            raise

    def _restart(self, exc: BaseException) -> bool:
        """After the connection to the writer failed with `exc` (holding `_send_lock`): if the writer has ended,
        start a new one that opens the file, cuts each table back to the rows confirmed written and is handed again
        every batch not confirmed; True when it has them. False, with `error` saying why, when none may be started:
        close()'s deadline passed, the writer had reported a write error (disk full), rows not confirmed were no
        longer kept (RESEND_MAX_ROWS), MAX_WRITER_RESTARTS reached, the writer has not ended, or the new one cannot
        take the file (it was left marked open by a death within a batch)."""
        if self._gave_up:
            return False
        self._gave_up = True  # until a new writer has the rows
        if not self._proc.wait(WRITER_EXIT_WAIT_S):  # never two writers on one file
            self.error = self.error or (f"trial log writer for {str(self.path)!r} failed ({exc}) and has not "
                                        "ended: no new writer; its unconfirmed rows and every later row counted lost")
            return False
        try:  # its last reports, up to the end of the connection
            self._collect_replies()
        except (OSError, EOFError):
            pass
        output = self._proc.output().strip().splitlines()
        died = (f"trial log writer for {str(self.path)!r} died (exit {self._proc.exitcode}): {exc}"
                + (f"; it printed: {output[-1]}" if output else ""))
        self._proc.close()
        unsent = [entry for entry in self._handed if entry[2] == "rows"]
        rows = sum(_count(entry[3]) for entry in unsent if entry[3] is not None)
        if self._expired:
            why = "the end of the trial's deadline had passed (no new writer then)"
        elif self._write_failed:
            why = "it had failed to write (no new writer after a write error)"
        elif any(entry[3] is None for entry in unsent):
            why = (f"more than {RESEND_MAX_ROWS} rows were not confirmed and the oldest were no longer kept to hand "
                   "over again")
        elif len(self.restarts) >= MAX_WRITER_RESTARTS:
            why = f"no new writer: {MAX_WRITER_RESTARTS} restarts is the most a trial gets"
        else:
            why = None
        if why is None:
            state = {"rows_written": dict(self.rows_written), "rows_lost": self._writer_lost}
            try:
                kind, detail = self._start(("resume", str(self.path), state))
            except (LogError, OSError) as start_error:  # OSError: no process could be started
                kind, detail = "error", str(start_error)
            if kind != "ready":
                why = f"a new writer could not take the file over: {detail}"
        if why is not None:
            self.error = self.error or f"{died}; {why}; its unconfirmed rows and every later row counted lost"
            return False
        self._handed = collections.deque(unsent)  # a "close" not answered is handed over again by close()
        self._gave_up = False
        self.restarts.append(f"{died}; a new writer took the file over at {sum(self.rows_written.values())} rows "
                             f"confirmed written and was handed the {len(unsent)} unconfirmed batches ({rows} rows) "
                             "again")
        event = (self._clock(), RESTART_EVENT, _json({"restart": len(self.restarts), "of": MAX_WRITER_RESTARTS,
                                                      "detail": self.restarts[-1]}))
        self._batch += 1  # a batch of its own, after the rows handed again; kept like them until confirmed
        self._handed.append([self._batch, 0.0, "rows", {"events": [event]}])
        self._kept += 1
        self._rows_sent += 1
        try:
            for entry in self._handed:
                entry[1] = time.monotonic()
                self._conn.send(("rows", entry[0], entry[3]))
        except (OSError, EOFError) as resend_error:  # the new writer died too
            return self._restart(resend_error)
        return True

    def flush(self, wait: bool = False) -> None:
        """Hand every pending row to the writer (which appends them, closes and fsyncs the file); with `wait`, wait
        (up to 30 s) for its report on them: then they are on disk or counted in `rows_lost`."""
        with self._lock:
            pending, self._pending = self._pending, {table: [] for table in self._tables}
        rows = {table: table_rows for table, table_rows in pending.items() if table_rows}
        n = sum(len(table_rows) for table_rows in rows.values())
        with self._send_lock:
            while True:
                if self._conn is None or self._gave_up:  # closed meanwhile (rows taken just before), or no writer
                    self._lost_here += n  # rows it never got; those it got but never reported on count at close()
                    self._unsent += n
                    return
                try:
                    if n:
                        self._hand_over("rows", rows)
                        self._rows_sent, n = self._rows_sent + n, 0
                    self._collect_replies(self._batch if wait else 0, 30.0)
                    return
                except (OSError, EOFError, ValueError) as exc:
                    self._restart(exc)  # a new writer, or `_gave_up` and the error set

    def status(self) -> dict[str, Any]:
        """Path, rows written and lost so far, the error, if any, `unconfirmed_s`: seconds since the hand-over
        of the oldest batch the writer has not reported on began (0.0 when there is none; a writer that has stopped
        answering, a hung disk, makes it grow), and `restarts`: one line for each writer that died and was replaced.
        Never waits: while a batch is being handed over (a slow disk can hold that up), it answers with what the
        writer had reported before. A writer found dead here is replaced by the next hand-over (sender thread)."""
        if self._send_lock.acquire(blocking=False):
            try:
                if self._conn is not None and not self._gave_up:
                    self._collect_replies()
            except (OSError, EOFError):
                pass  # its reports up to its death are taken; the sender replaces it within flush_s
            finally:
                self._send_lock.release()
        try:
            unconfirmed_s = time.monotonic() - self._handed[0][1]
        except IndexError:  # none outstanding (or the last one confirmed just now, in another thread)
            unconfirmed_s = 0.0
        return {"path": str(self.path), "rows_written": dict(self.rows_written), "rows_lost": self.rows_lost,
                "error": self.error, "unconfirmed_s": unconfirmed_s, "restarts": list(self.restarts)}

    def close(self, timeout_s: float | None = None) -> None:
        """Hand over what is pending and end the writer, returning within `timeout_s` seconds (None:
        `CLOSE_TIMEOUT_S`) whatever the writer does. A writer that has not reported on every row and ended by then
        (a hung disk) is killed, which also ends a hand-over blocked on its full pipe; the rows it had not confirmed
        count in `rows_lost` and `error` says so. Rows added from now on count in `rows_lost` too. Safe twice."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        self._stop.set()
        timeout_s = CLOSE_TIMEOUT_S if timeout_s is None else timeout_s
        end = time.monotonic() + timeout_s
        earlier_error, unsent_before = self.error, self._unsent
        deadline = threading.Timer(timeout_s, self._kill_writer)
        deadline.daemon = True
        deadline.start()
        try:
            if self._thread is not threading.current_thread():
                self._thread.join()  # by the deadline at the latest: the kill fails a blocked hand-over
            self.flush()
            with self._send_lock:
                while not self._gave_up:
                    try:
                        self._hand_over("close", {})
                        if not self._collect_replies(self._batch, max(0.0, end - time.monotonic())):
                            self._kill_writer()
                        break
                    except (OSError, EOFError) as exc:
                        if not self._restart(exc):
                            self.error = self.error or (f"trial log writer for {str(self.path)!r} died before "
                                                        f"closing: {exc}")
                unconfirmed = self._rows_sent - sum(self.rows_written.values()) - self._writer_lost
                self._lost_here += unconfirmed  # 0 once the writer has reported on every row
                if self._killed:
                    lost = unconfirmed + self._unsent - unsent_before
                    self.error = (f"trial log writer for {str(self.path)!r} did not finish within {timeout_s:g} s "
                                  f"and was killed; {lost} rows not confirmed written, counted lost"
                                  + (f"; before that: {earlier_error}" if earlier_error else ""))
                self._handed.clear()
                self._kept = 0
                self._conn.close()
                self._conn = None
        finally:
            deadline.cancel()
        if not self._killed:
            self._proc.wait(max(0.0, end - time.monotonic()))
        self._proc.kill()  # only if it has not ended; releases its output file

    def _kill_writer(self) -> None:
        """SIGKILL the writer (`close`'s deadline): a hand-over blocked on its full pipe then fails at once. The
        connection stays open until `close` closes it, in its own thread. No new writer is started after it."""
        self._expired = True
        if self._proc.exitcode is None:
            self._killed = True
            try:
                self._proc.proc.kill()
            except ProcessLookupError:  # it ended just now
                pass

    def __enter__(self) -> TrialLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _count(rows: dict[str, list]) -> int:
    """Rows in a batch (table name -> rows)."""
    return sum(len(table_rows) for table_rows in rows.values())


_spare_lock = threading.Lock()
_spare: ChildProcess | None = None


def prepare_writer() -> None:
    """Start a writer process now, so that the next trial starts without waiting for Python to import h5py."""
    global _spare
    with _spare_lock:
        if _spare is None or _spare.exitcode is not None:
            _spare = _start_writer()


def _start_writer() -> ChildProcess:
    """`python -m antarium.trial_log FD`: the writer, importing numpy and h5py while it waits for its trial."""
    return ChildProcess("antarium.trial_log", connect=True)


@atexit.register
def _end_spare() -> None:
    """The unused spare ends with its parent (it reads the end of its connection and returns)."""
    with _spare_lock:
        if _spare is not None:
            _spare.close()
            _spare.wait(5.0)


def _take_writer() -> ChildProcess:
    """The prepared writer (or a new one); a new spare is started for the trial after."""
    global _spare
    with _spare_lock:
        writer = _spare if _spare is not None and _spare.exitcode is None else _start_writer()
        _spare = _start_writer()
    return writer


def _writer_process_main(conn_arg: str) -> None:
    """Entry of the writer process: wait for ("open", path, attrs), then write (see `_writer_main`)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the whole process group: the parent closes us
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    import h5py  # noqa: F401 - imported while waiting, so that opening is quick

    conn = connection_from_arg(conn_arg)
    try:
        kind, path, detail = conn.recv()
    except (EOFError, OSError):  # a spare that was never used: the server has ended
        return
    if kind == "open":
        _writer_main(conn, path, detail)
    elif kind == "resume":
        _writer_main(conn, path, None, resume=detail)


def _open_for_append(path: str):
    """The log opened for one batch of appends, in SWMR-write mode (writes ordered so that a kill mid-batch
    leaves a file that SWMR readers can open); file locking off, so a reader that holds the file between two
    batches (h5py, MATLAB, HDFView) cannot block the recording."""
    import h5py

    f = h5py.File(path, "r+", libver=LIBVER, locking=False)
    f.swmr_mode = True
    return f


#: what a row that does not fit its table raises: numpy for a wrong number or type of fields or a value out of its
#: column's range (OverflowError, an ArithmeticError), `_check_text` for text HDF5 cannot store
_BAD_ROW = (ValueError, TypeError, ArithmeticError)


def _table_array(table: str, rows: list, dtype: np.dtype) -> np.ndarray:
    """`rows` as an array of `dtype`, text fields checked (HDF5 would refuse bad text only while writing)."""
    data = np.array(rows, dtype=dtype)
    for field in dtype.names:
        if dtype[field].kind == "O":
            for value in data[field]:
                _check_text(f"{table}.{field}", value)
    return data


def _convert(table: str, rows: list, dtype: np.dtype) -> tuple[np.ndarray, list[str]]:
    """The rows that fit `dtype`, as an array, and each row that does not with the reason; the batch is converted
    at once, row by row only when that fails."""
    try:
        return _table_array(table, rows, dtype), []
    except _BAD_ROW:
        pass
    good, bad = [], []
    for row in rows:
        try:
            _table_array(table, [row], dtype)
            good.append(row)
        except _BAD_ROW as exc:
            bad.append(f"{row!r} ({exc})")
    return _table_array(table, good, dtype), bad


def _writer_main(conn, path: str, attrs: dict[str, Any] | None, resume: dict[str, Any] | None = None) -> None:
    """The writer process: create the file with root attributes `attrs` (or, with `resume`, take over the file of a
    writer that died: see `_resume`), then for each batch of rows it receives: open, append, close, fsync
    (batches already waiting behind it, when the disk is slower than the hand-overs, are written with it).

    The file is closed between batches (a batch takes about a millisecond), so a SIGKILL or crash almost
    always finds it closed: its superblock's status flags are clear and any HDF5 >= 1.10 opens it (MATLAB
    without `h5clear`). A kill during a batch leaves the SWMR flags set; `open_log` still opens it.
    The file is fsynced after each batch's close, before the batch is reported written, and it and its folder after
    the file is made, before "ready": what was reported written survives a power cut or an OS crash.
    Each table's rows are converted on their own: a row that does not fit its table is left out and counted lost,
    named in `error`, and everything else is written. Only an HDF5 error while writing stops the writing for good.
    """
    dtypes = {"frames": FRAME_DTYPE, "locomotion": SAMPLE_DTYPE, **_text_dtypes(), "servosphere": SERVOSPHERE_DTYPE}
    if resume is not None:
        _resume(conn, path, resume, dtypes)
        return
    _create(conn, path, attrs, dtypes)


def _create(conn, path: str, attrs: dict[str, Any], dtypes: dict[str, np.dtype]) -> None:
    """Make the file (fsynced with its folder entry), answer "ready" (or "error", reason) and write (`_write`)."""
    import h5py

    try:
        f = h5py.File(path, "w-", libver=LIBVER, locking=False)
    except FileExistsError as exc:  # another's file: it stays
        conn.send(("error", str(exc)))
        return
    except (OSError, ValueError) as exc:  # its folder missing or not writable, or a full disk (an empty file made)
        Path(path).unlink(missing_ok=True)
        conn.send(("error", str(exc)))
        return
    try:
        with f:
            for key, value in attrs.items():
                f.attrs[key] = value
            for table, dtype in dtypes.items():
                f.create_dataset(table, shape=(0,), maxshape=(None,), dtype=dtype,
                                 chunks=(1024 if table in ("frames", "locomotion", "servosphere") else 64,))
        _fsync(path)
        _fsync(str(Path(path).parent))  # its directory entry: the file itself survives a power cut
    except (OSError, ValueError, TypeError) as exc:  # no half-made log is left behind
        Path(path).unlink(missing_ok=True)
        conn.send(("error", str(exc)))
        return
    conn.send(("ready", None))
    _write(conn, path, dtypes, dict.fromkeys(dtypes, 0), 0)


def _resume(conn, path: str, state: dict[str, Any], dtypes: dict[str, np.dtype]) -> None:
    """Take over the file of a writer that died: open it (refused when that writer died within a batch and left it
    marked open), cut each table back to `state["rows_written"]` (the rows it confirmed; a batch it wrote but never
    confirmed is handed over again), close and fsync it, answer "ready" (or "error", reason) and write (`_write`),
    counting on from `state`'s rows written and lost."""
    import h5py

    written = dict(state["rows_written"])
    try:
        f = h5py.File(path, "r+", libver=LIBVER, locking=False)  # not SWMR: SWMR writing only appends
    except OSError as exc:
        conn.send(("error", f"{exc}; the file stays as it is (open_log() reads it)"))
        return
    short = [f"{table!r} holds {f[table].shape[0]} rows, {count} were confirmed written"
             for table, count in written.items() if f[table].shape[0] < count]
    if short:  # never expected (fsync before each report): the file is not what the writer reported
        f.close()
        conn.send(("error", "; ".join(short)))
        return
    try:
        for table, count in written.items():
            f[table].resize((count,))
        f.close()
        _fsync(path)
    except (OSError, RuntimeError, ValueError) as exc:  # `f` stays open until os._exit, as after a failed write
        conn.send(("error", f"cutting the tables back to the confirmed rows failed: {exc}"))
        os._exit(0)
    conn.send(("ready", None))
    _write(conn, path, dtypes, written, state["rows_lost"])


def _write(conn, path: str, dtypes: dict[str, np.dtype], written: dict[str, int], lost: int) -> None:
    """Write each batch received until a "close" or the connection's end (see `_writer_main`), counting on from
    `written` rows per table and `lost` rows; each report holds the totals."""
    number = 0
    error = None
    failed = ended = False
    while not ended:
        try:
            kind, number, batch = conn.recv()
        except (EOFError, OSError):  # the server died: what is written stays, the file is closed
            break
        if kind == "close":
            break
        ended, number = _take_waiting(conn, number, batch)
        if failed:
            lost += sum(len(rows) for rows in batch.values())
        else:
            arrays = {}
            for table, rows in batch.items():
                arrays[table], bad = _convert(table, rows, dtypes[table])
                if bad:
                    lost += len(bad)
                    error = (f"trial log {path!r}: {len(bad)} row(s) of table {table!r} not written, the first "
                             f"{bad[0]}; allowed: values of the table's column types (docs/logs.md)")
            f = None
            try:  # the rows fit their tables: only HDF5 can fail here (disk full)
                f = _open_for_append(path)
                for table, data in arrays.items():
                    ds = f[table]
                    n = ds.shape[0]
                    ds.resize((n + len(data),))
                    ds[n:] = data
                    ds.flush()  # a full disk fails here or at f.flush(), never in a dataset's or the file's close,
                    # where HDF5 only prints the error and can then crash (SIGSEGV) at the next call
                f.flush()
                f.close()  # only now is the batch in the file
                _fsync(path)  # and only now on the disk
                for table, data in arrays.items():
                    written[table] += len(data)
            except (OSError, RuntimeError, ValueError, TypeError) as exc:  # `f` stays open and referenced until
                # os._exit below: closing a file whose write failed (even by garbage collection) can crash HDF5
                failed = True
                error = f"writing trial log {path!r} failed: {exc}; " + (_unopened if f is None else _marked_open)(path)
                lost += sum(len(data) for data in arrays.values())
        try:
            conn.send(("written", {"batch": number, "rows_written": written, "rows_lost": lost, "error": error,
                                   "failed": failed}))
        except (OSError, EOFError):
            break
    _send_quietly(conn, ("closed", {"batch": number, "rows_written": written, "rows_lost": lost, "error": error,
                                    "failed": failed}))
    if failed:  # HDF5 cannot shut down after a failed write without risking a crash: what is on disk stays
        # (readable as after a crash), the parent has been told, leave without HDF5's shutdown
        os._exit(0)


def _marked_open(path: str) -> str:
    """What a write that failed (disk full) leaves: the error's end."""
    return ("what was written before stays, but the file stays marked open for writing: open_log() reads it, plain "
            f"HDF5 readers (MATLAB) only after `h5clear -s {path}` (package hdf5-tools)")


def _unopened(path: str) -> str:
    """What a file that could not be opened for a batch is: the error's end (no more rows are written to it)."""
    if not os.path.exists(path):
        return ("no file is at that path any more (it, or its folder, was removed or moved): the rows written "
                "before went with it")
    return "nothing was written to it: it stays as the batches before left it, closed and readable"


def _take_waiting(conn, number: int, batch: dict[str, list]) -> tuple[bool, int]:
    """Add the batches already waiting behind batch `number` (the disk, or fsync, slower than the hand-overs) to
    `batch`, in order, so that one open, append, close and fsync writes them all. Returns (ended: a "close" or the
    connection's end came, number: that of the last batch taken, or of the close)."""
    try:
        while conn.poll():
            kind, number, rows = conn.recv()
            if kind == "close":
                return True, number
            for table, table_rows in rows.items():
                batch.setdefault(table, []).extend(table_rows)
    except (EOFError, OSError):  # the server died: what it had handed over is written
        return True, number
    return False, number


def _fsync(path: str) -> None:
    """Make what was written to the file or folder `path` durable (fsync; a folder: its entries)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _send_quietly(conn, message) -> None:
    try:
        conn.send(message)
    except (OSError, EOFError):
        pass


def check_log_dir(folder: str | Path) -> Path:
    """The log folder as an absolute path, created if missing; raises `LogError` when it cannot be written."""
    folder = Path(folder).expanduser().resolve()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        probe = folder / ".antarium-write-test"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise LogError(f"trial log folder {str(folder)!r} is not writable: {exc}") from None
    return folder


def log_path(folder: str | Path, rig: str, name: str, when: _dt.datetime | None = None) -> Path:
    """`<folder>/<rig>_<UTC yyyymmdd-hhmmss>_<name>.h5` (name reduced to [A-Za-z0-9_-], at most TRIAL_NAME_MAX
    characters; a suffix `-<k>` if taken). LogError naming the path when it cannot be used (a file name over
    NAME_MAX_BYTES, a folder the system refuses)."""
    when = when or _dt.datetime.now(_dt.UTC)
    safe = "".join(c if c.isascii() and c.isalnum() or c in "-_" else "_" for c in name)[:TRIAL_NAME_MAX] or "trial"
    base = Path(folder) / f"{rig}_{when:%Y%m%d-%H%M%S}_{safe}"
    size = len(f"{base.name}.h5".encode())
    if size > NAME_MAX_BYTES:
        raise LogError(f"trial log {f'{base}.h5'!r}: its file name is {size} bytes long; allowed: at most "
                       f"{NAME_MAX_BYTES} bytes (a [rig] name of at most {RIG_NAME_MAX_BYTES} bytes)")
    return free_log_path(base)


def free_log_path(base: str | Path) -> Path:
    """`<base>.h5`, or `<base>-<k>.h5` with the smallest k >= 1 not taken: a log is never overwritten. LogError
    naming the path when the system cannot tell whether it is taken."""
    path, k = Path(f"{base}.h5"), 1  # appended: a name may hold a dot ("lab.1"), which with_suffix would cut
    while _exists(path):
        path, k = Path(f"{base}-{k}.h5"), k + 1
    return path


def _exists(path: Path) -> bool:
    """Whether `path` exists; LogError naming it when the system cannot tell (a name too long, a folder refused)."""
    try:
        return path.exists()
    except OSError as exc:
        raise LogError(f"trial log path {str(path)!r} cannot be used: {exc.strerror or exc}") from None


#: what HDF5 says of a file whose writer has not closed it (a running, crashed or killed server): read it as SWMR
_OPEN_FOR_WRITE = "already open for write"

#: a read that fails is tried again this many times (READ_RETRY_S apart) even when the file looks unchanged (its
#: writer may be in a batch, a few ms, whose size and time stamp have not shown yet), and as long as it changes (a
#: writer appending) up to READ_ATTEMPTS times; after that the error is raised
READ_RETRIES_UNCHANGED = 5
READ_ATTEMPTS = 200
READ_RETRY_S = 0.02


def open_log(path: str | Path):
    """Open a trial log read-only, also one left open by a running, crashed or killed server (SWMR read). A file
    that is not an antarium trial log, or is cut short (a partial copy), raises LogError naming it (an SWMR read
    skips HDF5's length check, so it is used only for a file whose writer has not closed it). A log being written
    is opened between two of its writer's batches (see `_retrying`)."""
    return _retrying(path, lambda: _open_log(path))


def _open_log(path: str | Path):
    import h5py

    try:
        f = h5py.File(path, "r")
    except FileNotFoundError:
        raise
    except OSError as exc:
        if _OPEN_FOR_WRITE not in str(exc):
            raise LogError(f"{str(path)!r} cannot be read as a trial log: {_hdf5_reason(exc)}") from None
        f = h5py.File(path, "r", libver="latest", swmr=True)
    if f.attrs.get("format") != "antarium-trial-log":
        f.close()
        raise LogError(f"{str(path)!r} is an HDF5 file but not an antarium trial log (no format attribute "
                       "'antarium-trial-log')")
    return f


def _file_state(path: str | Path) -> tuple[int, int, int]:
    """(size in bytes, mtime and ctime in ns): what changes when a writer appends a batch."""
    st = os.stat(path)
    return st.st_size, st.st_mtime_ns, st.st_ctime_ns


def _retrying(path: str | Path, read: Callable[[], Any]) -> Any:
    """`read()` (which opens and reads the log `path`), tried again when it fails with an HDF5 error while the file is
    being written: the writer takes no file lock and appends a batch in SWMR mode every `flush_s`, so a read that
    falls into a batch (a few ms) can see the file half-updated ("truncated file", "addr overflow", "not already
    open for SWMR writing"). A file that stays as it is fails for good: LogError naming it and HDF5's reason
    (FileNotFoundError as it is)."""
    state = _file_state(path)
    unchanged = 0
    for _attempt in range(READ_ATTEMPTS):
        try:
            return read()
        except FileNotFoundError:
            raise
        except (OSError, LogError) as exc:
            error = exc
        time.sleep(READ_RETRY_S)
        now = _file_state(path)
        unchanged = 0 if now != state else unchanged + 1
        state = now
        if unchanged >= READ_RETRIES_UNCHANGED:
            break
    if isinstance(error, LogError):
        raise error
    raise LogError(f"{str(path)!r} cannot be read as a trial log: {_hdf5_reason(error)}") from None


def _hdf5_reason(exc: OSError) -> str:
    """HDF5's error in a few words: "truncated file: eof = ...", "file signature not found", "No such file"."""
    text = str(exc)
    return text.split("(", 1)[1].rsplit(")", 1)[0] if "(" in text else text


def read_table(path: str | Path, table: str) -> dict[str, np.ndarray]:
    """One table of a log as columns (text decoded to str): `pandas.DataFrame(read_table(path, "frames"))`; the rows
    written so far of a log being recorded (read between two of its writer's batches, see `_retrying`), every row
    written before a crash or kill. ValueError naming the tables when there is no `table`."""
    data = _retrying(path, lambda: _read_dataset(path, table))
    if data.dtype.names is None:
        raise LogError(f"{str(path)!r}: table {table!r} is not a table of named columns (not written by antarium)")
    columns = {}
    for name in data.dtype.names:
        col = data[name]
        if col.dtype == object:
            col = np.array([v.decode() if isinstance(v, bytes) else v for v in col], dtype=object)
        columns[name] = col
    return columns


def _read_dataset(path: str | Path, table: str) -> np.ndarray:
    with _open_log(path) as f:
        if table not in f:
            raise ValueError(f"{str(path)!r} has no table {table!r}; tables: {', '.join(sorted(f))}")
        return f[table][:]


if __name__ == "__main__":
    import sys

    _writer_process_main(sys.argv[1])
