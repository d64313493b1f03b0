"""The GPU's clocks and power while a benchmark runs, sampled with NVIDIA's `nvidia-smi` where it is installed.

An NVIDIA GPU that idles most of each frame period may never raise its clocks (an H200 stayed at its idle 345 MHz
through a whole `bench loop`, docs/rendering.md), and the frame's GPU work then takes several times as long; so a
GPU run's report says at which clocks it ran. Elsewhere (no `nvidia-smi`, another vendor) there is nothing to say.

    sampler = GpuClocks().start()
    ...                                   # the benchmark
    summary = sampler.stop()              # None, or {"0": {"sm_mhz": {...}, "power_w": ..., ...}, ...}
"""

from __future__ import annotations

import shutil
import statistics
import subprocess
import threading
from typing import Any

#: what is sampled, in `nvidia-smi --query-gpu` names
FIELDS = ("index", "clocks.sm", "clocks.max.sm", "power.draw", "utilization.gpu")
PERIOD_MS = 100


class GpuClocks:
    """`nvidia-smi` sampling every PERIOD_MS in a child process between `start()` and `stop()`; `exe`: the tool's
    path (default: `nvidia-smi` on PATH; None there: the sampler does nothing and `stop()` returns None). A thread
    reads its output as it comes: left in the pipe, it would block the tool once the pipe is full (64 kB, a few
    minutes on an 8-GPU machine) and the rest of the run would go unsampled."""

    def __init__(self, exe: str | None = None) -> None:
        self.exe = exe or shutil.which("nvidia-smi")
        self._proc: subprocess.Popen | None = None
        self._reader: threading.Thread | None = None
        self.lines: list[str] = []

    def start(self) -> GpuClocks:
        if self.exe is not None:
            try:
                self._proc = subprocess.Popen(
                    [self.exe, f"--query-gpu={','.join(FIELDS)}", "--format=csv,noheader,nounits",
                     "-lms", str(PERIOD_MS)], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
            except OSError:  # not executable after all: nothing to report
                self._proc = None
            else:
                self.lines = []
                self._reader = threading.Thread(target=self._drain, args=(self._proc.stdout,),
                                                name="nvidia-smi-reader", daemon=True)
                self._reader.start()
        return self

    def _drain(self, stream) -> None:
        for line in stream:
            self.lines.append(line)

    def stop(self) -> dict[str, dict[str, Any]] | None:
        """Per GPU index: SM clock median/min/max and the GPU's maximum (MHz), power and utilisation medians (W,
        %), and the number of samples; None when nothing was sampled."""
        if self._proc is None:
            return None
        self._proc.terminate()
        try:
            self._proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait()
        if self._reader is not None:
            self._reader.join(5)  # the rest of the pipe, up to its end
        self._proc.stdout.close()
        self._proc, self._reader = None, None
        return summarise(self.lines)


def _number(text: str) -> float | None:
    try:
        return float(text)
    except ValueError:  # "[N/A]", "[Not Supported]"
        return None


def summarise(lines: list[str]) -> dict[str, dict[str, Any]] | None:
    """The `stop()` summary from `nvidia-smi` CSV lines (FIELDS, no header, no units); lines that are not such a
    row are skipped."""
    rows: dict[str, list[tuple[float | None, ...]]] = {}
    for line in lines:
        parts = [p.strip() for p in line.split(",")]
        if len(parts) != len(FIELDS) or not parts[0].isdigit():
            continue
        rows.setdefault(parts[0], []).append(tuple(_number(p) for p in parts[1:]))
    if not rows:
        return None
    out = {}
    for index, samples in rows.items():
        sm, sm_max, power, util = ([s[k] for s in samples if s[k] is not None] for k in range(4))
        out[index] = {
            "samples": len(samples),
            "sm_mhz": {"median": statistics.median(sm), "min": min(sm), "max": max(sm)} if sm else None,
            "sm_max_mhz": max(sm_max) if sm_max else None,
            "power_w_median": statistics.median(power) if power else None,
            "utilization_pct_median": statistics.median(util) if util else None,
        }
    return out


def describe(summary: dict[str, dict[str, Any]] | None) -> list[str]:
    """One report line per GPU."""
    lines = []
    for index, g in (summary or {}).items():
        sm = g["sm_mhz"]
        clock = "SM clock not reported" if sm is None else (
            f"SM clock median {sm['median']:,.0f} MHz ({sm['min']:,.0f}-{sm['max']:,.0f}"
            + (f" of {g['sm_max_mhz']:,.0f}" if g["sm_max_mhz"] else "") + ")")
        power = "" if g["power_w_median"] is None else f", power {g['power_w_median']:.0f} W"
        util = "" if g["utilization_pct_median"] is None else f", utilisation {g['utilization_pct_median']:.0f} %"
        lines.append(f"GPU {index}: {clock}{power}{util} ({g['samples']} samples, nvidia-smi)")
    return lines
