"""`antarium bench protocol`: frame encode rate, emulator decode rate (one core), and a loopback run.

Goals (issue 3): encode >= 5,000 frames/s; emulator decode >= 380 frames/s (twice the dome's 190) on one core;
zero loss on loopback while sending at 190 frames/s to `antarium emulate` in its own process. Figures are also
given as ratios to the dome's rate. Frames are seeded random LED frames.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from antarium.bench import write_json

GOAL_ENCODE_FPS = 5000.0
GOAL_DECODE_FPS = 380.0
START_TIMEOUT_S = 30.0  # the loopback run waits this long for `antarium emulate` to answer


def _frames(n: int, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        lum = rng.integers(0, 65536, 20350)
        share = (rng.random(20350) * lum).astype(np.int64)
        out.append(np.stack([share, lum - share], axis=1).astype(np.uint16))
    return out


def _rate(step, n: int, seconds: float) -> float:
    """Calls per second of step(i % n) for i = 1, 2, ... over at least `seconds` (step(0) is the warm-up)."""
    step(0)
    i, t0 = 1, time.perf_counter()
    while True:
        step(i % n)
        i += 1
        dt = time.perf_counter() - t0
        if dt >= seconds and i > n:
            return (i - 1) / dt


def measure_encode(frames, seconds: float) -> float:
    from antarium.firmware_proto.video import encode_frame

    out = np.empty((55, 1112), np.uint8)
    return _rate(lambda i: encode_frame(frames[i], i % 128, out=out), len(frames), seconds)


def measure_decode(frames, seconds: float, line: str) -> float:
    """Frames per second the emulator takes in: 55 VIDEO datagrams + LATCH each, fed as bytes."""
    from antarium.firmware_proto.control import encode_latch
    from antarium.firmware_proto.emulator import Emulator
    from antarium.firmware_proto.video import encode_frame

    streams = []  # one per sequence number, so that the stream can be cycled without going back in sequence
    for k in range(128):
        rows = [r.tobytes() for r in encode_frame(frames[k % len(frames)], k)]
        streams.append(rows + [encode_latch(k)])
    emu = Emulator(line=line)

    def step(i):
        for d in streams[i]:
            emu.handle_datagram(d)

    rate = _rate(step, len(streams), seconds)
    if emu.counters["frames_dropped"] or emu.counters["internal_errors"]:
        raise RuntimeError(f"emulator lost frames during the decode benchmark: {emu.stats()}")
    return rate


def achieved_rate(starts: list[float]) -> float:
    """Frames per second from the times (s) the frames began to be sent: n frames span n - 1 periods between the
    first one's start and the last one's (NaN for fewer than two)."""
    span = starts[-1] - starts[0] if len(starts) > 1 else 0.0
    return (len(starts) - 1) / span if span > 0 else float("nan")


def measure_loopback(frames, n_frames: int, rate_hz: float) -> dict:
    """Send `n_frames` at `rate_hz` to `antarium emulate` in a child process; count what it latched."""
    from antarium.core.clock import MonotonicClock
    from antarium.firmware_proto.link import open_link
    from antarium.server.emulator_process import EmulatorProcess

    emulator = EmulatorProcess(extra_args=["--seconds", str(n_frames / rate_hz + 30)])
    emulator.start()   # ends with this process even if it is killed
    try:
        clock = MonotonicClock()
        send_s, starts = [], []
        with open_link("udp", port=emulator.port) as link:
            deadline = clock.now() + START_TIMEOUT_S
            while link.hello(wait_s=0.2) is None:
                if not emulator.running or clock.now() > deadline:
                    raise RuntimeError(f"antarium emulate did not answer within {START_TIMEOUT_S:.0f} s: "
                                       f"{emulator.output()[-500:]!r}")
            t0 = clock.now()
            late = 0
            for k in range(n_frames):
                due = t0 + k / rate_hz
                if clock.now() > due + 1 / rate_hz:
                    late += 1
                clock.sleep_until(due)
                starts.append(clock.now())
                a = time.perf_counter()
                link.send_frame(frames[k % len(frames)])
                send_s.append(time.perf_counter() - a)
            t = link.telemetry(wait_s=3.0)
    finally:
        emulator.stop(timeout_s=10.0)
    c = t.get("counters", {})
    latched = c.get("frames_latched", 0)
    return {
        "frames_sent": n_frames,
        "achieved_rate_hz": achieved_rate(starts),
        "frames_latched": latched,
        "frames_lost": n_frames - latched,
        "frames_dropped_partial": c.get("frames_dropped", 0),
        "datagrams_received": c.get("datagrams_received", 0),
        "late_sends": late,
        "send_frame_ms_mean": 1000 * float(np.mean(send_s)),
        "send_frame_ms_max": 1000 * float(np.max(send_s)),
        "link": t["link"],
    }


def run(args: argparse.Namespace) -> int:
    from antarium.core.rates import DOME_RATE_HZ, FRAME_PERIOD_S

    seconds = args.seconds or 2.0
    n_loop = args.frames or 950
    if n_loop < 2:  # before any work: the loopback rate is measured between the first frame and the last
        raise ValueError(f"--frames must be at least 2 for bench protocol (the loopback rate spans two frames or "
                         f"more), got {n_loop}")
    frames = _frames(16)
    affinity = os.sched_getaffinity(0) if hasattr(os, "sched_setaffinity") else None
    if affinity is not None:
        os.sched_setaffinity(0, {min(affinity)})
    try:
        enc = measure_encode(frames, seconds)
        dec = measure_decode(frames, seconds, "fast")
        dec_bits = measure_decode(frames, seconds / 2, "bits")
    finally:
        if affinity is not None:
            os.sched_setaffinity(0, affinity)
    loop = measure_loopback(frames, n_loop, DOME_RATE_HZ)
    result = {
        "one_core": affinity is not None,
        "encode_frames_per_s": enc,
        "decode_frames_per_s": dec,
        "decode_bit_exact_frames_per_s": dec_bits,
        "loopback": loop,
    }
    period_ms = FRAME_PERIOD_S * 1000
    print("antarium bench protocol (timings on a shared machine are noisy)")
    print(f"  encode            {enc:9.0f} frames/s  = {enc / DOME_RATE_HZ:6.1f} x 190/s   "
          f"(goal {GOAL_ENCODE_FPS:.0f}: {'met' if enc >= GOAL_ENCODE_FPS else 'NOT met'})")
    print(f"  emulator decode   {dec:9.0f} frames/s  = {dec / DOME_RATE_HZ:6.1f} x 190/s   "
          f"(goal {GOAL_DECODE_FPS:.0f} on one core: {'met' if dec >= GOAL_DECODE_FPS else 'NOT met'})")
    print(f"  decode bit-exact  {dec_bits:9.0f} frames/s  = {dec_bits / DOME_RATE_HZ:6.1f} x 190/s   "
          "(Manchester + CRC on every panel link)")
    print(f"  loopback          {loop['frames_sent']} frames at {loop['achieved_rate_hz']:.1f}/s: "
          f"{loop['frames_latched']} latched whole, {loop['frames_lost']} lost "
          f"({'zero loss' if loop['frames_lost'] == 0 else 'LOSS'}); send_frame "
          f"{loop['send_frame_ms_mean']:.2f} ms mean, {loop['send_frame_ms_max']:.2f} ms max "
          f"of the {period_ms:.2f} ms period")
    if args.json_out:
        write_json(args.json_out, "protocol", result)
    return 0
