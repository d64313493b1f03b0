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

import os
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


def _children(pid: int) -> list[int]:
    """Process ids of the children of `pid` (/proc/PID/task/*/children; a full scan of /proc where the kernel
    lacks that file)."""
    tasks = list(Path(f"/proc/{pid}/task").glob("*/children"))
    if tasks:
        kids = []
        for path in tasks:
            try:
                kids += [int(k) for k in path.read_text().split()]
            except OSError:  # the thread ended meanwhile
                pass
        return kids
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
        if not self.others:
            raise ValueError(f"[loop] cpu {cpu} is the only CPU this process may use: nothing to keep off it")

    def apply(self, loop_thread_id: int, beside: Collection[int] = (),
              processes: Collection[int] | None = None) -> None:
        """Pin thread `loop_thread_id` (a native thread id of this process) and the threads `beside` it (work
        that may only have the loop's idle time) to the loop's CPU, every other thread of this process and every
        descendant process (only those in `processes` when given; the others stay where they are) to the others."""
        self._place(lambda tid: {self.cpu} if tid == loop_thread_id or tid in beside else self.others,
                    self.others, processes)

    def release(self) -> None:
        """Every thread of this process and every descendant back on all the CPUs it could use before."""
        self._place(lambda tid: self.usable, self.usable)

    @staticmethod
    def _place(thread_cpus, process_cpus: set, processes: Collection[int] | None = None) -> None:
        for task in Path("/proc/self/task").iterdir():
            _place(int(task.name), thread_cpus(int(task.name)))
        for pid in descendants():
            if processes is not None and pid not in processes:
                continue
            for task in Path(f"/proc/{pid}/task").glob("*"):  # every thread of it (a GL driver's among them)
                _place(int(task.name), process_cpus)
