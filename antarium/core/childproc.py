"""Child processes of the rig: `python -m MODULE ARGS` in a fresh interpreter.

A fresh interpreter is never a fork of a process that holds zenoh or GL threads, and never re-imports the user's
main script (multiprocessing's spawn would). With `connect=True` the two processes share a duplex message
connection: the child finds its end's file descriptor as its first argument (`connection_from_arg`). The child's
output goes to a temporary file, never to a pipe that could fill and block it; `output()` reads its end.

A child ends with its parent through that connection: its end reads end-of-file once the parent is gone (even
killed by SIGKILL), as the trial-log writer notices. A module that does not take the connection (`antarium emulate`)
gets it with `end_with_parent=True`: it then runs under this module's `__main__`, which watches the connection
in a thread and ends the child (SIGTERM, then exit after END_GRACE_S) when it closes.

    child = ChildProcess("antarium.trial_log", connect=True)
    child.conn.send(("open", path, attrs))
    ...
    child.stop()
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from collections.abc import Sequence

#: a child watching its parent (`end_with_parent`) that has not ended this long after SIGTERM exits at once (s)
END_GRACE_S = 5.0


class ChildProcess:
    """`python -m module *args` started at once. conn: the parent's end of the connection (None unless
    `connect`); proc: the `subprocess.Popen`. idle: run it under SCHED_IDLE (Linux), so that it has only CPU time
    nothing else wants from its first instruction on; it may leave that class itself (`os.sched_setscheduler`).
    end_with_parent: the child (a module that takes no connection) ends when this process ends or `close()`s it
    (module docstring); a `connect` child watches its connection itself."""

    def __init__(self, module: str, args: Sequence[str] = (), *, connect: bool = False, idle: bool = False,
                 end_with_parent: bool = False) -> None:
        from multiprocessing import Pipe

        if connect and end_with_parent:
            raise ValueError("end_with_parent is for a child without a connection (a connect child watches its own)")
        argv = [sys.executable, "-m", module]
        self.conn = child_end = None
        if connect or end_with_parent:
            self.conn, child_end = Pipe()
            fd = str(child_end.fileno())
            argv = [sys.executable, "-m", "antarium.core.childproc", fd, module] if end_with_parent else [*argv, fd]
        self._output = tempfile.TemporaryFile()
        try:
            self.proc = subprocess.Popen([*argv, *args], stdin=subprocess.DEVNULL, stdout=self._output,
                                         stderr=subprocess.STDOUT,
                                         pass_fds=() if child_end is None else (child_end.fileno(),))
        finally:
            if child_end is not None:
                child_end.close()
        if idle and hasattr(os, "SCHED_IDLE"):
            try:
                os.sched_setscheduler(self.proc.pid, os.SCHED_IDLE, os.sched_param(0))
            except OSError:  # refused, or already gone: it runs ordinary
                pass

    @property
    def pid(self) -> int:
        return self.proc.pid

    @property
    def exitcode(self) -> int | None:
        """None while it runs."""
        return self.proc.poll()

    @property
    def running(self) -> bool:
        return self.proc.poll() is None

    def output(self, max_bytes: int = 4000) -> str:
        """The end of what the child printed (for error messages); "" once closed."""
        if self._output.closed:
            return ""
        self._output.seek(0, 2)
        self._output.seek(max(0, self._output.tell() - max_bytes))
        return self._output.read().decode(errors="replace")

    def wait(self, timeout_s: float | None = None) -> bool:
        """True once the child has ended (within `timeout_s`)."""
        try:
            self.proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            return False
        return True

    def stop(self, timeout_s: float = 5.0) -> None:
        """Ask it to end (SIGTERM), kill it if it has not within `timeout_s`, release everything. Safe twice."""
        if self.proc.poll() is None:
            self.proc.terminate()
            if not self.wait(timeout_s):
                self.kill()
        self.close()

    def kill(self) -> None:
        """End it now (SIGKILL) and release everything."""
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        self.close()

    def close(self) -> None:
        """Release the connection and the output file (the child may go on running; one started `end_with_parent`
        then ends)."""
        if self.conn is not None:
            self.conn.close()
        self._output.close()


def connection_from_arg(arg: str):
    """In the child: its end of the connection, from the argument `ChildProcess(connect=True)` gave it."""
    from multiprocessing.connection import Connection

    return Connection(int(arg))


def _watch_parent(conn) -> None:
    """In the child (a thread): return when the parent's end of `conn` closes, then end this process."""
    import signal
    import time

    try:
        while True:
            conn.recv()
    except (EOFError, OSError):  # the parent is gone, or closed us
        pass
    os.kill(os.getpid(), signal.SIGTERM)  # its own way of ending (statistics, sockets closed)
    time.sleep(END_GRACE_S)
    os._exit(1)


def _run_watched(argv: Sequence[str]) -> None:
    """`python -m antarium.core.childproc FD MODULE ARGS`: `python -m MODULE ARGS` that ends with its parent."""
    import runpy
    import threading

    fd, module, *args = argv
    conn = connection_from_arg(fd)
    threading.Thread(target=_watch_parent, args=(conn,), name="parent-watch", daemon=True).start()
    sys.argv = [module, *args]
    runpy.run_module(module, run_name="__main__", alter_sys=True)


if __name__ == "__main__":
    _run_watched(sys.argv[1:])
