"""`antarium bench jitter`: how late this machine wakes the frame loop's thread, and how long it stops it.

No frame loop can be steadier than the machine under it. This benchmark runs the loop's skeleton, nothing else:
a thread with the loop's CPU and real-time priority (from the rig config, as `antarium serve` sets them) waits
for each frame slot on the loop's clock, then stays busy for `--work-ms` (the frame's work; default 2.5 ms,
the embedded default's median on a 2-core machine with software GL). It measures

- the wake-up lateness: how long after its slot the thread runs again (the kernel's timer, the CPU's way
  out of idle and, in a virtual machine, the hypervisor's scheduling of the virtual CPU);
- the stalls: gaps of more than STALL_S in the busy thread's reading of the clock, times when it did not run
  although it wanted to (interrupts, the kernel, a hypervisor running something else on that core);
- the slots a frame of that work would miss: wake-up lateness + work + stalls > one frame period. A frame
  loop on this machine cannot have fewer late frames than that, whatever it draws.

Compare it with `antarium bench loop` over the same time: late frames beyond the missed slots here are the
loop's own; those within them are the machine's. `StallProbes` does that comparison during the loop bench
itself (`antarium bench loop --machine-probe`): one small process per CPU, real-time above the loop, wakes every
two milliseconds and records when the machine woke it late; a late frame that overlaps such a stall on the loop's CPU
was the machine's (unknown where a probe is not real-time: our own load then delays it too).
"""

from __future__ import annotations

import argparse
import math
import multiprocessing
import os
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from antarium.bench import progress, write_json
from antarium.core.clock import Clock, MonotonicClock

#: a gap longer than this (s) between two clock readings of the busy thread counts as a stall
STALL_S = 100e-6
#: the summary counts wake-ups at least this late (s)
LATENESS_EDGES_S = (0.5e-3, 1e-3, 2e-3, 5e-3)


def measure(clock: Clock, period: float, work: float, slots: int,
            longest: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Wait for `slots` frame slots of `period` s on `clock`, each followed by `work` s of busy reading of the
    clock; in the calling thread.

    Returns (lateness, stalled): (slots,) float64 s, how late the thread ran after each slot's start; and
    (slots,) float64 s, the sum of its gaps longer than STALL_S while busy. `longest`, a (slots,) array when
    given, gets each slot's longest single such gap (s; 0 without one). Slots that have passed when the
    previous one's work ends are skipped (as the frame loop does) and not measured.
    """
    lateness = np.empty(slots)
    stalled = np.zeros(slots)
    if longest is None:
        longest = np.zeros(slots)
    longest[:] = 0.0
    t_slot = clock.now() + period
    for i in range(slots):
        clock.sleep_until(t_slot)
        last = start = clock.now()
        lateness[i] = start - t_slot
        end = start + work
        while last < end:
            now = clock.now()
            if now - last > STALL_S:
                stalled[i] += now - last
                longest[i] = max(longest[i], now - last)
            last = now
        t_slot += period
        if last > t_slot:  # slots passed meanwhile: skipped, as the frame loop skips them
            t_slot += math.ceil((last - t_slot) / period) * period
    return lateness, stalled


def summarise(lateness: np.ndarray, stalled: np.ndarray, period: float, work: float,
              longest: np.ndarray | None = None) -> dict[str, Any]:
    """Figures from `measure`'s arrays (times in ms in the result). `stall_max_ms` is the longest single gap
    (from `longest`; without it, unknown: the largest per-slot sum stands in and `stall_max_is_slot_sum` says so);
    `stalled_slot_max_ms` the most time stalled in one slot, all its gaps together."""
    missed = lateness + work + stalled > period
    p50, p99 = np.percentile(lateness, [50, 99])
    return {
        "slots": int(len(lateness)), "period_ms": 1e3 * period, "work_ms": 1e3 * work,
        "lateness": {"p50_ms": 1e3 * float(p50), "p99_ms": 1e3 * float(p99), "max_ms": 1e3 * float(lateness.max())},
        "lateness_at_least_ms": {f"{1e3 * edge:g}": int((lateness >= edge).sum()) for edge in LATENESS_EDGES_S},
        "slots_with_stalls": int((stalled > 0).sum()),
        "stall_max_ms": 1e3 * float((stalled if longest is None else longest).max()),
        "stall_max_is_slot_sum": longest is None, "stalled_slot_max_ms": 1e3 * float(stalled.max()),
        "missed_slots": int(missed.sum()),
    }


#: a stall probe wakes this often (s; a stall this long or longer always delays one of its wake-ups) and records
#: the wake-ups at least PROBE_THRESHOLD_S late
PROBE_PERIOD_S = 2e-3
PROBE_THRESHOLD_S = 0.5e-3


def _cpu_reader():
    """A function returning the CPU the calling thread runs on (glibc's sched_getcpu), or None where there is none."""
    try:
        import ctypes

        getcpu = ctypes.CDLL(None, use_errno=True).sched_getcpu
        getcpu.restype, getcpu.argtypes = ctypes.c_int, []
        return getcpu if getcpu() >= 0 else None
    except (OSError, AttributeError):
        return None


def _probe(cpu: int, priority: int, stop, conn) -> None:
    """Child process: wake every PROBE_PERIOD_S on `cpu` (SCHED_FIFO `priority` where allowed, else ordinary) until
    `stop` is set; send back (realtime, (n, 2) float64 [slot time, lateness] (s, time.monotonic) of the late
    wake-ups on `cpu`, {CPU: wake-ups that ran there}, times it was found moved off `cpu`).

    Something else may move it (the server's CPU placement moves every process of ours off the loop's CPU): it
    checks its CPUs at every wake-up and pins itself back to `cpu`; a wake-up that ran elsewhere is counted in
    the CPU map but never recorded as a stall of `cpu`."""
    from antarium.core.realtime import set_realtime

    os.sched_setaffinity(0, {cpu})
    realtime = False
    if priority:
        try:
            set_realtime(priority)
            realtime = True
        except OSError:
            pass
    getcpu = _cpu_reader()
    events = []
    ran_on: dict[int, int] = {}
    moved = 0
    t = time.monotonic()
    wakeups = 0
    while wakeups % 100 or not stop.is_set():  # asking `stop` costs system calls: every 0.1 s is enough
        wakeups += 1
        t += PROBE_PERIOD_S
        delay = t - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        late = time.monotonic() - t
        pinned = os.sched_getaffinity(0) == {cpu}
        where = getcpu() if getcpu is not None else (cpu if pinned else -1)  # -1: somewhere else, unknown
        ran_on[where] = ran_on.get(where, 0) + 1
        if not pinned:
            moved += 1
            os.sched_setaffinity(0, {cpu})
        if late >= PROBE_THRESHOLD_S:
            if where == cpu:
                events.append((t, late))
            t += (late // PROBE_PERIOD_S) * PROBE_PERIOD_S  # the wake-ups that passed meanwhile are skipped
    conn.send((realtime, np.array(events, dtype=np.float64).reshape(-1, 2), ran_on, moved))


class ProbeReport(tuple):
    """One probe's report, a (realtime, events) pair with, beside it, `ran_on` ({CPU: wake-ups that ran there};
    -1: elsewhere, CPU unknown) and `moved` (wake-ups at which it found itself moved off its CPU and pinned itself
    back). `events`: (n, 2) [slot time, lateness] s of its late wake-ups on its own CPU."""

    def __new__(cls, realtime: bool, events: np.ndarray, ran_on: dict[int, int] | None = None, moved: int = 0):
        self = super().__new__(cls, (realtime, events))
        self.ran_on, self.moved = dict(ran_on or {}), moved
        return self

    @property
    def realtime(self) -> bool:
        return self[0]

    @property
    def events(self) -> np.ndarray:
        return self[1]


class StallProbes:
    """One probe process on each of `cpus`, SCHED_FIFO `priority` (above the frame loop's, so that nothing of ours
    delays it; 0: ordinary), from construction until `stop()`. Each takes a few per cent of its CPU, and stays on
    its CPU when something moves it (see `_probe`)."""

    def __init__(self, cpus: list[int], priority: int) -> None:
        ctx = multiprocessing.get_context("spawn")
        self._stop = ctx.Event()
        self._procs = {}
        for c in cpus:
            receive, send = ctx.Pipe(duplex=False)
            proc = ctx.Process(target=_probe, args=(c, priority, self._stop, send), name=f"stall-probe-{c}",
                               daemon=True)
            proc.start()
            self._procs[c] = (proc, receive)

    @property
    def pids(self) -> dict[int, int]:
        """CPU -> the process id of its probe."""
        return {c: proc.pid for c, (proc, _) in self._procs.items()}

    def stop(self) -> dict[int, ProbeReport]:
        """Stop the probes; per CPU: its `ProbeReport` ((ran real-time, (n, 2) [slot time, lateness] s of its late
        wake-ups), with the CPUs it ran on). Raises RuntimeError naming the CPUs whose probe ended without a
        report (its stalls are unknown)."""
        self._stop.set()
        out, failed = {}, []
        for c, (proc, receive) in self._procs.items():
            try:
                if not receive.poll(10.0):
                    raise EOFError
                out[c] = ProbeReport(*receive.recv())
            except (EOFError, OSError):
                failed.append(c)
            proc.join(5.0)
        if failed:
            raise RuntimeError(f"the stall probe on CPU {', '.join(map(str, failed))} ended without a report")
        return out


def overlapping(t0: np.ndarray, t1: np.ndarray, stalls: np.ndarray) -> np.ndarray:
    """(n,) bool: which of the n intervals [t0, t1] (s) overlap a stall [slot time, slot time + lateness] of
    `stalls` (m, 2) s, one probe's (its stalls never overlap each other), in any order."""
    if not len(stalls):
        return np.zeros(len(t0), dtype=bool)
    ends = stalls[:, 0] + stalls[:, 1]
    order = np.argsort(ends)
    starts, ends = stalls[order, 0], ends[order]
    first = np.searchsorted(ends, t0)  # the first stall that ends at or after the interval starts
    hit = np.zeros(len(t0), dtype=bool)
    inside = first < len(ends)
    # one probe's stalls do not overlap, so ordering them by end orders their starts too
    hit[inside] = starts[first[inside]] <= t1[inside]
    return hit


def machine() -> dict[str, Any]:
    """What the kernel says about idle states and real-time throttling (Linux; empty where unknown)."""
    def read(path: str) -> str | None:
        try:
            return Path(path).read_text().strip()
        except OSError:
            return None

    return {"cpuidle_driver": read("/sys/devices/system/cpu/cpuidle/current_driver"),
            "cpuidle_governor": read("/sys/devices/system/cpu/cpuidle/current_governor_ro")
            or read("/sys/devices/system/cpu/cpuidle/current_governor"),
            "rt_runtime_us": read("/proc/sys/kernel/sched_rt_runtime_us"),
            "rt_period_us": read("/proc/sys/kernel/sched_rt_period_us")}


def _steal_s() -> float | None:
    """Seconds of steal time (the hypervisor ran something else) summed over all CPUs, from /proc/stat."""
    try:
        fields = Path("/proc/stat").read_text().split("\n", 1)[0].split()
        return int(fields[8]) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return None


def run(args: argparse.Namespace) -> int:
    from antarium.config import load_config
    from antarium.core import realtime

    loop_cfg = load_config(os.environ.get("ANTARIUM_RIG_CONFIG") or None).loop
    rate = loop_cfg.rate_hz
    period = 1.0 / rate
    seconds = 30.0 if args.seconds is None and args.frames is None else args.seconds
    # both given: whichever ends first, as `bench loop` (Server.run) does
    slots = min(n for n in (args.frames, None if seconds is None else int(seconds * rate)) if n is not None)
    if slots < 1:
        raise ValueError(f"--seconds must be at least one frame slot ({1e3 * period:.2f} ms at {rate:g} Hz), "
                         f"got {seconds:g}")
    work_ms = 2.5 if args.work_ms is None else args.work_ms
    work = work_ms / 1e3
    if not 0.0 <= work < period:
        raise ValueError(f"--work-ms must be in [0, {1e3 * period:.2f}) ms (one frame period at {rate:g} Hz), "
                         f"got {work_ms:g}")
    setup: dict[str, Any] = {"cpu": None, "realtime_priority": 0, "notes": []}
    out: dict[str, Any] = {}

    def skeleton() -> None:
        if loop_cfg.cpu != "off" and realtime.supported() and len(os.sched_getaffinity(0)) > 1:
            target = max(os.sched_getaffinity(0)) if loop_cfg.cpu == "auto" else loop_cfg.cpu
            try:
                os.sched_setaffinity(0, {target})  # this thread only; it ends with the benchmark
                setup["cpu"] = target
            except OSError as exc:
                setup["notes"].append(f"not on [loop] cpu {target} ({exc.strerror})")
        if loop_cfg.realtime_priority:
            try:
                realtime.set_realtime(loop_cfg.realtime_priority)
                setup["realtime_priority"] = loop_cfg.realtime_priority
            except (AttributeError, OSError) as exc:
                setup["notes"].append(f"not real-time ({type(exc).__name__}: {exc})")
        longest = np.zeros(slots)
        out["arrays"] = (*measure(MonotonicClock(), period, work, slots, longest), longest)

    progress("jitter", f"measuring {slots} frame slots ({slots / rate:.1f} s)")
    steal0 = _steal_s()
    thread = threading.Thread(target=skeleton, name="jitter-skeleton")
    thread.start()
    thread.join()
    steal1 = _steal_s()
    lateness, stalled, longest = out["arrays"]
    result = summarise(lateness, stalled, period, work, longest)
    result.update(rate_hz=rate, setup=setup, machine=machine(),
                  steal_s=None if steal0 is None or steal1 is None else steal1 - steal0)
    _print(result)
    if args.json_out:
        write_json(args.json_out, "jitter", result)
    return 0


def _print(r: dict[str, Any]) -> None:
    s, m, lat = r["setup"], r["machine"], r["lateness"]
    where = f"CPU {s['cpu']}" if s["cpu"] is not None else "any CPU"
    how = f"SCHED_FIFO {s['realtime_priority']}" if s["realtime_priority"] else "ordinary scheduling"
    print(f"jitter bench: {r['slots']} slots of {r['period_ms']:.2f} ms ({r['rate_hz']:g} Hz) on {where}, {how}, "
          f"{r['work_ms']:.2f} ms of work each" + "".join(f"; {n}" for n in s["notes"]))
    print(f"  machine         cpuidle {m['cpuidle_driver']}/{m['cpuidle_governor']}, real-time throttling "
          f"{m['rt_runtime_us']} of {m['rt_period_us']} us"
          + ("" if r["steal_s"] is None else f", steal {1e3 * r['steal_s']:.0f} ms during the run"))
    print(f"  wake-up late    p50 {lat['p50_ms']:.3f}  p99 {lat['p99_ms']:.3f}  max {lat['max_ms']:.2f} ms;  "
          + ", ".join(f">= {k} ms: {v}" for k, v in r["lateness_at_least_ms"].items()))
    longest = "the largest per-slot sum" if r.get("stall_max_is_slot_sum") else "the longest gap"
    print(f"  stalls          {r['slots_with_stalls']} slots with gaps > {1e3 * STALL_S:g} ms while busy, {longest} "
          f"{r['stall_max_ms']:.2f} ms; at most {r['stalled_slot_max_ms']:.2f} ms stalled in one slot")
    print(f"  missed slots    {r['missed_slots']}: a frame of {r['work_ms']:.2f} ms would have been late "
          f"that often on this machine, whatever the loop does")
