"""CPU placement (Linux): the frame loop's thread alone on one CPU, the rest of the rig on the others.

On a small machine the frame loop shares its cores with the emulator, the far-layer builder, the bus and the
log writer. Giving the loop's thread a CPU of its own (`[loop] cpu`) keeps their bursts out of its frames:
`Isolation.apply` moves every other thread of this process and every process it started (and theirs) to the
remaining CPUs. Threads and processes started later inherit the mask of the thread that starts them, so
the server applies it again once a second.
"""

from __future__ import annotations

import os
from pathlib import Path


def supported() -> bool:
    return hasattr(os, "sched_setaffinity") and Path("/proc/self/task").is_dir()


def _descendants(pid: int) -> list[int]:
    """Process ids of every descendant of `pid` (from /proc/*/stat)."""
    parent_of: dict[int, int] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat.read_text()
        except OSError:  # the process ended meanwhile
            continue
        fields = text[text.rindex(")") + 2:].split()
        parent_of[int(stat.parent.name)] = int(fields[1])
    found, frontier = [], [pid]
    while frontier:
        p = frontier.pop()
        kids = [c for c, parent in parent_of.items() if parent == p]
        found += kids
        frontier += kids
    return found


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

    def apply(self, loop_thread_id: int) -> None:
        """Pin thread `loop_thread_id` (a native thread id of this process) to the loop's CPU, every other
        thread of this process and every descendant process to the others."""
        self._place(lambda tid: {self.cpu} if tid == loop_thread_id else self.others, self.others)

    def release(self) -> None:
        """Every thread of this process and every descendant back on all the CPUs it could use before."""
        self._place(lambda tid: self.usable, self.usable)

    @staticmethod
    def _place(thread_cpus, process_cpus: set) -> None:
        for task in Path("/proc/self/task").iterdir():
            try:
                os.sched_setaffinity(int(task.name), thread_cpus(int(task.name)))
            except OSError:  # the thread ended meanwhile
                pass
        for pid in _descendants(os.getpid()):
            try:
                os.sched_setaffinity(pid, process_cpus)
            except OSError:
                pass
