"""CPU time of processes, for benchmarks that report what a helper process costs (Linux /proc; 0 elsewhere)."""

from __future__ import annotations

import os

from antarium.core.realtime import descendants


def process_cpu_s(pid: int | None) -> float:
    """CPU seconds (user + system) used so far by process `pid` (0 for None, a process gone, or no /proc)."""
    try:
        text = open(f"/proc/{pid}/stat").read() if pid else ""
    except OSError:
        return 0.0
    if not text:
        return 0.0
    fields = text[text.rindex(")") + 2:].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def process_tree_cpu_s(root: int) -> float:
    """CPU seconds used so far by process `root` and every live descendant of it."""
    return sum(process_cpu_s(pid) for pid in (root, *descendants(root)))
