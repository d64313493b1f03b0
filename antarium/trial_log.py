"""Trial logs: one self-describing HDF5 file per recording (h5py), written so that nothing is lost.

The frame loop only appends rows to in-memory buffers (cheap); every `flush_s` seconds (at most 1 s) they
go to a writer process, which opens the file, appends them in SWMR mode and closes it again. So after a
crash or SIGKILL the file holds everything up to the last batch and is almost always closed and clean
(any HDF5 >= 1.10 opens it, MATLAB included); a kill in the millisecond of a batch leaves it marked open,
which `open_log` (SWMR read) still opens. A write error (disk full) does not stop the stimulus: the log
keeps counting what it could not write and reports it in `status()`, and the server makes that loud.
Every dataset and its units are listed in `docs/logs.md`.
"""

from __future__ import annotations

import atexit
import datetime as _dt
import hashlib
import json
import threading
from pathlib import Path
from typing import Any

import numpy as np

from antarium.core.childproc import ChildProcess, connection_from_arg

#: 2: the frames table has `full_render`
FORMAT_VERSION = 2

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
    """A trial log that cannot be created (bad path, no permission); raised before anything starts."""


def file_sha256(path: str | Path) -> str:
    """Hex SHA-256 of a file's bytes (scene files are hashed into the log)."""
    h = hashlib.sha256()
    with Path(path).open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _json(value: Any) -> str:
    return json.dumps(value, sort_keys=True, default=str)


class TrialLog:
    """One recording. Append rows from any thread (cheap); a separate writer process owns the HDF5 file.

    path:     the .h5 file to create (its folder must exist and be writable; an existing file is refused)
    config:   the resolved rig config as TOML tables (`RigConfig.to_toml_dict()`; stored as JSON in the
              `config` attribute)
    name:     trial name; metadata: JSON-serialisable dict stored in the `metadata` attribute
    flush_s:  seconds between hand-overs to the writer, which appends and flushes to disk (at most 1 s)

    The writer is a process of its own so that HDF5 never holds the frame loop's GIL and a failing disk
    cannot take the stimulus down: a write error is reported in `status()["error"]`, the loop goes on.
    If this process dies (even SIGKILL) the writer sees its pipe close and ends; the file is closed between batches.
    """

    def __init__(self, path: str | Path, config: dict[str, Any], name: str = "", metadata: dict | None = None,
                 flush_s: float = 1.0, start_timeout_s: float = 30.0) -> None:
        from antarium import __version__

        if not 0 < flush_s <= 1.0:
            raise ValueError(f"flush_s must be in (0, 1] seconds, got {flush_s}")
        self.path = Path(path)
        if self.path.exists():
            raise LogError(f"trial log {str(self.path)!r} already exists; a recording never overwrites one")
        try:
            metadata_json = json.dumps(metadata or {}, sort_keys=True)
        except (TypeError, ValueError) as exc:
            raise LogError(f"trial metadata must be JSON-serialisable: {exc}") from None
        attrs = {"format": "antarium-trial-log", "format_version": FORMAT_VERSION, "software_version": __version__,
                 "created_utc": _dt.datetime.now(_dt.UTC).isoformat(), "trial_name": name,
                 "metadata": metadata_json, "config": _json(config)}
        self._proc = _take_writer()
        self._conn = self._proc.conn
        try:
            self._conn.send(("open", str(self.path), attrs))
            if not self._conn.poll(start_timeout_s):
                raise LogError(f"trial log writer for {str(self.path)!r} did not answer within {start_timeout_s} s")
            kind, detail = self._conn.recv()
        except (OSError, EOFError) as exc:
            self._proc.kill()
            raise LogError(f"trial log writer for {str(self.path)!r} failed to start: {exc}; "
                           f"{self._proc.output()}") from None
        except LogError:
            self._proc.kill()
            raise
        if kind != "ready":
            self._proc.stop(5)
            raise LogError(f"cannot create trial log {str(self.path)!r}: {detail}")
        self.flush_s = float(flush_s)
        self._tables = ("frames", "locomotion", "events", "commands", "scenes", "servosphere")
        self._pending: dict[str, list] = {table: [] for table in self._tables}
        self._lock = threading.Lock()
        self._send_lock = threading.Lock()
        self.rows_written = dict.fromkeys(self._tables, 0)
        self.rows_lost = 0
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
        self._append("events", (t, kind, _json(data)))

    def add_command(self, t: float, name: str, request: Any, reply: Any, ok: bool) -> None:
        self._append("commands", (t, name, _json(request), _json(reply), int(ok)))

    def add_scene(self, t: float, name: str, sha256: str) -> None:
        self._append("scenes", (t, name, sha256))

    def _append(self, table: str, row: tuple) -> None:
        with self._lock:
            if not self._closed:
                self._pending[table].append(row)

    # -- handing rows to the writer --------------------------------------------------------------------
    def _sender(self) -> None:
        while not self._stop.wait(self.flush_s):
            self.flush()

    def _collect_replies(self) -> None:
        while self._conn.poll():
            kind, detail = self._conn.recv()
            if kind == "written":
                for table, n in detail["rows_written"].items():
                    self.rows_written[table] = n
                self.rows_lost = detail["rows_lost"]
                self.error = detail["error"] or self.error

    def flush(self, wait: bool = False) -> None:
        """Hand every pending row to the writer (which appends and flushes it); with `wait`, until it is on disk."""
        with self._lock:
            pending, self._pending = self._pending, {table: [] for table in self._tables}
        with self._send_lock:
            if self._conn is None:
                return
            n = sum(len(rows) for rows in pending.values())
            try:
                self._collect_replies()
                if n or wait:
                    self._conn.send(("rows", {t: rows for t, rows in pending.items() if rows}))
                if wait:
                    if self._conn.poll(30.0):
                        self._collect_replies()
            except (OSError, EOFError, ValueError) as exc:
                code = self._proc.exitcode
                self.error = self.error or f"trial log writer for {str(self.path)!r} died (exit {code}): {exc}"
                self.rows_lost += n

    def status(self) -> dict[str, Any]:
        """Path, rows written and lost so far, and the error, if any. Never waits: while a batch is being handed
        over (a slow disk can hold that up), it answers with what the writer had reported before."""
        if self._send_lock.acquire(blocking=False):
            try:
                if self._conn is not None:
                    self._collect_replies()
            except (OSError, EOFError):
                self.error = self.error or f"trial log writer for {str(self.path)!r} died"
            finally:
                self._send_lock.release()
        return {"path": str(self.path), "rows_written": dict(self.rows_written), "rows_lost": self.rows_lost,
                "error": self.error}

    def close(self, timeout_s: float = 30.0) -> None:
        """Hand over what is pending, wait until it is written and end the writer. Safe twice."""
        if self._closed:
            return
        self._stop.set()
        if self._thread is not threading.current_thread():
            self._thread.join()
        self.flush()
        with self._lock:
            self._closed = True
        with self._send_lock:
            try:
                self._conn.send(("close", None))
                while self._conn.poll(timeout_s):
                    kind, detail = self._conn.recv()
                    if kind in ("written", "closed"):
                        self.rows_written.update(detail["rows_written"])
                        self.rows_lost = detail["rows_lost"]
                        self.error = detail["error"] or self.error
                    if kind == "closed":
                        break
            except (OSError, EOFError) as exc:
                self.error = self.error or f"trial log writer for {str(self.path)!r} died before closing: {exc}"
            self._conn.close()
            self._conn = None
        self._proc.wait(timeout_s)
        self._proc.kill()  # only if it has not ended; releases its output file

    def __enter__(self) -> TrialLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


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
        kind, path, attrs = conn.recv()
    except (EOFError, OSError):  # a spare that was never used: the server has ended
        return
    if kind == "open":
        _writer_main(conn, path, attrs)


def _open_for_append(path: str):
    """The log opened for one batch of appends, in SWMR-write mode (writes ordered so that a kill mid-batch
    leaves a file that SWMR readers can open); file locking off, so a reader that holds the file between two
    batches (h5py, MATLAB, HDFView) cannot block the recording."""
    import h5py

    f = h5py.File(path, "r+", libver=LIBVER, locking=False)
    f.swmr_mode = True
    return f


def _writer_main(conn, path: str, attrs: dict[str, Any]) -> None:
    """The writer process: create the file, then for each batch of rows it receives: open, append, close.

    The file is closed between batches (a batch takes about a millisecond), so a SIGKILL or crash almost
    always finds it closed: its superblock's status flags are clear and any HDF5 >= 1.10 opens it (MATLAB
    without `h5clear`). A kill during a batch leaves the SWMR flags set; `open_log` still opens it.
    """
    import os

    import h5py

    dtypes = {"frames": FRAME_DTYPE, "locomotion": SAMPLE_DTYPE, **_text_dtypes(), "servosphere": SERVOSPHERE_DTYPE}
    try:
        with h5py.File(path, "w-", libver=LIBVER, locking=False) as f:
            for key, value in attrs.items():
                f.attrs[key] = value
            for table, dtype in dtypes.items():
                f.create_dataset(table, shape=(0,), maxshape=(None,), dtype=dtype,
                                 chunks=(1024 if table in ("frames", "locomotion", "servosphere") else 64,))
    except (OSError, ValueError) as exc:
        conn.send(("error", str(exc)))
        return
    conn.send(("ready", None))
    written = dict.fromkeys(dtypes, 0)
    lost = 0
    error = None
    while True:
        try:
            kind, batch = conn.recv()
        except (EOFError, OSError):  # the server died: what is written stays, the file is closed
            break
        if kind == "close":
            break
        if error is None:
            try:
                arrays = {table: np.array(rows, dtype=dtypes[table]) for table, rows in batch.items()}
                f = _open_for_append(path)
                for table, data in arrays.items():
                    ds = f[table]
                    n = ds.shape[0]
                    ds.resize((n + len(data),))
                    ds[n:] = data
                f.close()  # flushes: only now is the batch in the file
                for table, rows in batch.items():
                    written[table] += len(rows)
                    rows.clear()
            except (OSError, RuntimeError, ValueError, TypeError) as exc:
                error = f"writing trial log {path!r} failed: {exc}"
        if error is not None:
            lost += sum(len(rows) for rows in batch.values())
        try:
            conn.send(("written", {"rows_written": written, "rows_lost": lost, "error": error}))
        except (OSError, EOFError):
            break
    if error is not None:  # HDF5 cannot close a file whose writes failed without risking a crash: keep what is
        # on disk (readable as after a crash), tell the parent, and leave without HDF5's shutdown
        _send_quietly(conn, ("closed", {"rows_written": written, "rows_lost": lost, "error": error}))
        os._exit(0)
    _send_quietly(conn, ("closed", {"rows_written": written, "rows_lost": lost, "error": error}))


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
    """`<folder>/<rig>_<UTC yyyymmdd-hhmmss>_<name>.h5` (name reduced to [A-Za-z0-9_-]; a suffix if taken)."""
    when = when or _dt.datetime.now(_dt.UTC)
    safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in name)[:64] or "trial"
    base = Path(folder) / f"{rig}_{when:%Y%m%d-%H%M%S}_{safe}"
    path, k = base.with_suffix(".h5"), 1
    while path.exists():
        path, k = Path(f"{base}-{k}.h5"), k + 1
    return path


def open_log(path: str | Path):
    """Open a trial log read-only, also one left open by a crashed or killed server (SWMR read)."""
    import h5py

    try:
        return h5py.File(path, "r")
    except OSError:
        return h5py.File(path, "r", libver="latest", swmr=True)


def read_table(path: str | Path, table: str) -> dict[str, np.ndarray]:
    """One table of a log as columns (text decoded to str): `pandas.DataFrame(read_table(path, "frames"))`."""
    with open_log(path) as f:
        if table not in f:
            raise ValueError(f"{str(path)!r} has no table {table!r}; tables: {', '.join(sorted(f))}")
        data = f[table][:]
    columns = {}
    for name in data.dtype.names:
        col = data[name]
        if col.dtype == object:
            col = np.array([v.decode() if isinstance(v, bytes) else v for v in col], dtype=object)
        columns[name] = col
    return columns


if __name__ == "__main__":
    import sys

    _writer_process_main(sys.argv[1])
