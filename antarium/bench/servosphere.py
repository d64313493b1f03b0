"""`antarium bench servosphere`: the servosphere's speed and accuracy on one core.

- tracker: frames/s on 640x480 rendered frames (goal >= 700, the camera's rate);
- control loop: steps/s of the host's side of a step (tracker, PD, Eq. 4, encode/decode, fault checks), the
  simulated camera's rendering and the rig's physics timed apart (goal >= 500 Hz); and of the whole simulated step;
- sustained: the loop in its own process on the wall clock with the simulated rig, steps/s over 3 s;
- closed loop (simulated, ant at 5 cm/s turning): error from the apex median (goal <= 2 mm), p99 (<= 5 mm), and
  the path from the ball against the true one (<= 2 % of the distance walked).
"""

from __future__ import annotations

import argparse
import math
import os
import time

import numpy as np

from antarium.bench import write_json
from antarium.core.rates import DOME_RATE_HZ, FRAME_PERIOD_S

GOAL_TRACKER_HZ = 700.0
GOAL_LOOP_HZ = 500.0
GOAL_MEDIAN_MM, GOAL_P99_MM, GOAL_PATH = 2.0, 5.0, 0.02


def _one_core() -> str:
    import cv2

    cv2.setNumThreads(1)
    if hasattr(os, "sched_setaffinity"):
        cpu = sorted(os.sched_getaffinity(0))[-1]
        os.sched_setaffinity(0, {cpu})
        return f"CPU {cpu}"
    return "not pinned"


def _tracker(n: int) -> dict:
    from antarium.locomotion.servosphere.rig import SimulatedRig
    from antarium.locomotion.servosphere.tracker import Tracker

    rig = SimulatedRig()
    frames = []
    for k in range(64):
        rig.ant_xy[:] = (0.004 * math.cos(k / 10), 0.003 * math.sin(k / 7))
        rig.ant_heading = k * 0.2
        frames.append(rig.render())
    tracker = Tracker(rig.calibration)
    for f in frames[:8]:
        tracker.update(f)
    t0 = time.perf_counter()
    for k in range(n):
        tracker.update(frames[k % len(frames)], (30.0, 0.0))
    dt = time.perf_counter() - t0
    return {"frames": n, "frames_per_s": n / dt, "us_per_frame": dt / n * 1e6}


class SimulatedTime:
    """The time spent in the simulated rig (camera, physics, firmware emulator: not the host's work on a real rig),
    from the functions wrapped with `timed`. A wrapped function called from within another (the firmware emulator
    runs inside the camera's grab, which advances the rig) is counted once, in the outer call. `clock`: seconds
    (default: time.perf_counter, the clock the step's own time is taken with)."""

    def __init__(self, clock=None) -> None:
        self.clock = clock or (lambda: time.perf_counter())
        self.seconds, self._depth = 0.0, 0

    def timed(self, fn):
        def wrapped(*args, **kwargs):
            outer = self._depth == 0
            self._depth += 1
            t0 = self.clock() if outer else 0.0
            try:
                return fn(*args, **kwargs)
            finally:
                self._depth -= 1
                if outer:
                    self.seconds += self.clock() - t0
        return wrapped


def _loop(seconds: float) -> dict:
    from antarium.core.ball import pole_motion
    from antarium.core.clock import SimulatedClock
    from antarium.locomotion.servosphere.source import ServosphereSource

    clock = SimulatedClock()
    src = ServosphereSource(clock=clock, simulation={"speed": 0.05, "meander": 2.0, "seed": 7})
    rows: list[tuple] = []
    src.use_log(type("Rows", (), {"add_servosphere": staticmethod(rows.append)})())
    sim = SimulatedTime()
    camera = src.loop.camera
    camera.grab = sim.timed(camera.grab)  # the simulated camera, and the rig's physics it advances
    src.rig.port.deliver = sim.timed(src.rig.port.deliver)  # the firmware emulator (within the grab when it runs there)
    path = np.zeros(2)
    radius = src.loop.geometry.sphere_radius
    for _ in range(int(seconds * DOME_RATE_HZ)):
        clock.advance(1.0 / DOME_RATE_HZ)
        for s in src.read():
            path += pole_motion(s.rotation, radius)[:2]
    n = len(rows)
    host_s = src.step_s - sim.seconds
    err = np.hypot([r[2] for r in rows[70:]], [r[3] for r in rows[70:]])
    err = err[np.isfinite(err)]  # frames with the ant tracked, after the first 70 (the loop settling)
    rig = src.rig
    return {"steps": n, "simulated_s": seconds, "whole_step_hz": n / src.step_s, "host_step_hz": n / host_s,
            "host_us_per_step": host_s / n * 1e6, "error_median_mm": float(np.median(err)) if err.size else math.nan,
            "error_p99_mm": float(np.percentile(err, 99)) if err.size else math.nan, "walked_m": rig.walked,
            "path_error_fraction": float(np.hypot(*(path - rig.true_path)) / rig.walked),
            "faulty_frames": int(sum(1 for r in rows if r[-1]))}


def _realtime(seconds: float) -> dict:
    """The loop as `antarium serve` runs it on the wall clock: in a process of its own (same CPU as this one),
    paced by the simulated camera at 700 frames/s; a step that overruns lowers the rate sustained."""
    from antarium.locomotion.servosphere.process import ServosphereProcess

    src = ServosphereProcess(simulation={"speed": 0.05, "meander": 2.0, "seed": 7})
    src.start()
    time.sleep(0.3)
    f0, t0 = src.status()["frames"], time.perf_counter()
    time.sleep(seconds)
    f1, t1 = src.status()["frames"], time.perf_counter()
    src.stop()
    return {"frames_per_s": (f1 - f0) / (t1 - t0)}


def run(args: argparse.Namespace) -> int:
    where = _one_core()
    n = args.frames or 5000
    seconds = args.seconds or 20.0
    tr = _tracker(n)
    lp = _loop(seconds)
    rt = _realtime(3.0)
    print(f"servosphere bench on one core ({where})")
    print(f"  tracker: {tr['frames_per_s']:,.0f} frames/s on 640x480 ({tr['us_per_frame']:.0f} us/frame) = "
          f"{tr['frames_per_s'] / GOAL_TRACKER_HZ:.2f}x the camera's 700 frames/s goal "
          f"({tr['frames_per_s'] / DOME_RATE_HZ:.1f}x the dome's {DOME_RATE_HZ:.0f} frames/s)")
    print(f"  control loop, host side: {lp['host_step_hz']:,.0f} steps/s ({lp['host_us_per_step']:.0f} us/step) = "
          f"{lp['host_step_hz'] / GOAL_LOOP_HZ:.2f}x the 500 Hz goal; "
          f"{lp['host_us_per_step'] * 1e-6 / FRAME_PERIOD_S * 100:.0f} % of a dome frame period per step")
    print(f"  sustained on the wall clock (own process, simulated rig included): {rt['frames_per_s']:,.0f} steps/s "
          f"= {rt['frames_per_s'] / GOAL_LOOP_HZ:.2f}x the 500 Hz goal")
    print(f"  whole simulated step (camera rendering, physics, firmware included): {lp['whole_step_hz']:,.0f} steps/s")
    print(f"  closed loop, {seconds:g} s simulated, ant at 5 cm/s turning: error from the apex median "
          f"{lp['error_median_mm']:.2f} mm (goal <= {GOAL_MEDIAN_MM}), p99 {lp['error_p99_mm']:.2f} mm "
          f"(goal <= {GOAL_P99_MM}); path from the ball within {lp['path_error_fraction'] * 100:.2f} % of "
          f"{lp['walked_m'] * 100:.0f} cm walked (goal <= {GOAL_PATH * 100:.0f} %); "
          f"faulty frames {lp['faulty_frames']}")
    ok = (tr["frames_per_s"] >= GOAL_TRACKER_HZ and lp["host_step_hz"] >= GOAL_LOOP_HZ
          and rt["frames_per_s"] >= GOAL_LOOP_HZ
          and lp["error_median_mm"] <= GOAL_MEDIAN_MM and lp["error_p99_mm"] <= GOAL_P99_MM
          and lp["path_error_fraction"] <= GOAL_PATH)
    print(f"  goals {'met' if ok else 'NOT met'}")
    if args.json_out:
        write_json(args.json_out, "servosphere", {"where": where, "tracker": tr, "loop": lp, "realtime": rt,
                                                  "goals_met": ok})
    return 0 if ok else 1
