"""CPU placement and scheduling (Linux): the frame loop's thread alone on one CPU and real-time, the rest of
the rig on the other CPUs.

On a small machine the frame loop shares its cores with the emulator, the far-layer builder, the bus and the
log writer. Giving the loop's thread a CPU of its own (`[loop] cpu`) keeps their bursts out of its frames:
`Isolation.apply` moves every other thread of this process and every process it started (and theirs) to the
remaining CPUs. Threads and processes started later inherit the mask of the thread that starts them, so
the server applies it again once a second. Work that may only have the loop's idle time (a scene being
prepared, and the processes it starts) is placed beside the loop on its CPU: a real-time loop always comes
first there, and the rest of the rig keeps the other CPUs to itself.

`set_realtime` makes the calling thread SCHED_FIFO with SCHED_RESET_ON_FORK: the threads and processes it
starts begin ordinary, so that none of them can hold off a real-time thread of the same priority, and a
process that embeds the server keeps its own threads as they are. Only what must be real-time is made so by
name: the renderer's sampling helper takes its starter's scheduling, and a spawned emulator runs two
priorities below the loop.
"""

from __future__ import annotations

import functools
import os
import threading
from collections.abc import Collection
from pathlib import Path


def supported() -> bool:
    return hasattr(os, "sched_setaffinity") and Path("/proc/self/task").is_dir()


def set_realtime(priority: int, pid: int = 0) -> None:
    """SCHED_FIFO at `priority` (1..99) for thread or process `pid` (0: the calling thread); the threads and
    processes it starts afterwards begin with ordinary scheduling. Raises OSError (PermissionError without
    CAP_SYS_NICE or an rtprio limit) or AttributeError (not Linux)."""
    os.sched_setscheduler(pid, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK, os.sched_param(priority))


def set_ordinary(pid: int = 0) -> None:
    """Back to ordinary scheduling (SCHED_OTHER) for thread or process `pid` (0: the calling thread)."""
    os.sched_setscheduler(pid, os.SCHED_OTHER, os.sched_param(0))


def _tids(pid: int | str) -> list[str]:
    """Thread ids of process `pid` ("self": this one), as /proc names them; none once it has ended."""
    try:
        return os.listdir(f"/proc/{pid}/task")
    except OSError:
        return []


def _read(path: str) -> bytes:
    """A small /proc file's contents (os calls: a frame loop's idle time reads a hundred of these); b"" if it is
    gone."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return b""
    try:
        return os.read(fd, 1 << 16)
    except OSError:
        return b""
    finally:
        os.close(fd)


@functools.cache
def _children_files() -> bool:
    """Whether the kernel lists a thread's children in /proc/PID/task/TID/children (CONFIG_PROC_CHILDREN)."""
    return os.path.exists(f"/proc/self/task/{threading.get_native_id()}/children")


def _thread_children(pid: int | str, tids) -> list[int]:
    """Process ids of the children that threads `tids` of process `pid` started (needs `_children_files`)."""
    kids: list[int] = []
    for tid in tids:
        kids += map(int, _read(f"/proc/{pid}/task/{tid}/children").split())
    return kids


def _children(pid: int) -> list[int]:
    """Process ids of the children of `pid` (/proc/PID/task/*/children; a full scan of /proc where the kernel
    lacks that file)."""
    if _children_files():
        return _thread_children(pid, _tids(pid))
    kids = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat.read_text()
        except OSError:  # the process ended meanwhile
            continue
        if int(text[text.rindex(")") + 2:].split()[1]) == pid:
            kids.append(int(stat.parent.name))
    return kids


def descendants(pid: int | None = None) -> list[int]:
    """Process ids of every descendant of `pid` (None: this process)."""
    found, frontier = [], [os.getpid() if pid is None else pid]
    while frontier:
        kids = _children(frontier.pop())
        found += kids
        frontier += kids
    return found


def _place(target: int, cpus: set) -> None:
    """Move thread or process `target` to `cpus` unless it is there already (a move migrates it)."""
    try:
        if os.sched_getaffinity(target) != cpus:
            os.sched_setaffinity(target, cpus)
    except OSError:  # it ended meanwhile
        pass


class Isolation:
    """The frame loop's thread on `cpu`, everything else of ours on the other CPUs this process may use now.

    cpu: a CPU number, or "auto": the highest usable one. Raises ValueError if `cpu` is not one this process
    may use, or it is the only one.
    """

    def __init__(self, cpu: int | str):
        self.usable = usable = os.sched_getaffinity(0)
        if cpu == "auto":
            cpu = max(usable)
        if cpu not in usable:
            raise ValueError(f"[loop] cpu {cpu} is not one this process may use; allowed: {sorted(usable)}")
        self.cpu, self.others = cpu, set(usable) - {cpu}
        self._state: tuple | None = None  # what the last full placement saw (see `apply`)
        if not self.others:
            raise ValueError(f"[loop] cpu {cpu} is the only CPU this process may use: nothing to keep off it")

    def apply(self, loop_thread_id: int, beside: Collection[int] = (),
              processes: Collection[int] | None = None) -> None:
        """Pin thread `loop_thread_id` (a native thread id of this process) and the threads `beside` it (work
        that may only have the loop's idle time) to the loop's CPU, every other thread of this process and every
        descendant process (only those in `processes` when given; the others stay where they are) to the others.

        Called once a second in the loop's idle time, it walks every thread of every process of ours (84 threads
        with pathlib: 2.4 ms on a 2-core VM, 7-15 ms on a 16-CPU GPU workstation, a late frame a second there;
        with os calls 0.8 ms on the VM) only when something may have landed on the loop's CPU: a thread of ours
        came or went, the loop's or a `beside` thread started or lost a child, or the arguments changed.
        Whatever a thread on the other CPUs starts inherits them. Otherwise it costs a directory listing and one
        /proc read per such thread (0.06 ms). Not followed: a process of ours that moves itself onto the loop's
        CPU (the kernel says nothing of it)."""
        state = (frozenset(_tids("self")), frozenset(beside), None if processes is None else frozenset(processes),
                 frozenset(_thread_children("self", (loop_thread_id, *beside))) if _children_files() else None)
        if state == self._state:
            return
        self._place(lambda tid: {self.cpu} if tid == loop_thread_id or tid in beside else self.others,
                    self.others, processes)
        self._state = state

    def release(self) -> None:
        """Every thread of this process and every descendant back on all the CPUs it could use before."""
        self._place(lambda tid: self.usable, self.usable)
        self._state = None

    @staticmethod
    def _place(thread_cpus, process_cpus: set, processes: Collection[int] | None = None) -> None:
        for tid in map(int, _tids("self")):
            _place(tid, thread_cpus(tid))
        for pid in descendants():
            if processes is not None and pid not in processes:
                continue
            for tid in _tids(pid):  # every thread of it (a GL driver's among them)
                _place(int(tid), process_cpus)
