"""Calibration: counts per mm and mounting sign of every sensor axis, from whole turns about marked axes.

The operator marks the ball, turns it `turns` whole turns about a known dome axis (e.g. "z": about the
vertical) and the driver sums the raw counts of each sensor axis meanwhile. The geometry predicts each
axis's surface travel, `BallSolver.readings(axis * 2 pi turns)` (metres), so

    counts_per_mm = |counts| / |travel in mm|,   sign = sign(counts * travel).

An axis is calibrated by the steps where its predicted travel is at least `min_share` of the ball's
circumference per turn; with the default placement, "z" calibrates both sensors' x axes, "y" sensor 0's
y axis and "x" sensor 1's y axis. `measure` refuses a turn during which the driver lost motion.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from antarium.locomotion.trackball.config import TrackballConfig

AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
AXIS_NAMES = ("x0", "y0", "x1", "y1")


class CalibrationError(ValueError):
    """Calibration data that cannot give a result (an axis never turned, a dead sensor, ...)."""


@dataclass(frozen=True)
class Step:
    """One turn of the procedure: rotation axis name ("x", "y", "z"), whole turns, raw counts (x0, y0, x1, y1)."""

    axis: str
    turns: float
    counts: tuple[int, int, int, int]


@dataclass(frozen=True)
class Result:
    config: TrackballConfig  # the input config with new counts_per_mm and signs, calibration_cpi its resolution
    estimates: dict[str, list[float]]  # sensor axis -> counts per mm from each step that covered it

    def spread(self) -> dict[str, float]:
        """Relative spread (max - min) / mean of the estimates per axis (0 when one step covered it)."""
        return {k: (max(v) - min(v)) / float(np.mean(v)) for k, v in self.estimates.items()}


def predicted_travel(config: TrackballConfig, axis: str, turns: float) -> np.ndarray:
    """(4,) metres each sensor axis travels when the ball turns `turns` times about the dome `axis`."""
    if axis not in AXES:
        raise CalibrationError(f"calibration axis must be one of {', '.join(AXES)}, got {axis!r}")
    return config.solver().readings(np.array(AXES[axis]) * 2 * math.pi * turns)


#: driver counters that grow when motion never reached its raw counts: the device lost or found again, reports
#: lost on the way (a `seq` gap) or restarted, reports dropped as unreadable, a sensor past its tracking limit
LOSS_COUNTERS = ("unplugs", "connects", "lost_reports", "seq_resets", "short_reports", "bad_reports", "overflows")


def measure(driver, axis: str, turns: float, turn: Callable[[Any, str, float], list[int]]) -> Step:
    """One calibration step: `turn(driver, axis, turns)` has the ball turned (by hand, or `turn_emulated`) and
    returns the driver's raw counts (x0, y0, x1, y1). CalibrationError naming the `LOSS_COUNTERS` that grew
    meanwhile: counts lost there would give too few counts per mm."""
    before = {k: driver.counters[k] for k in LOSS_COUNTERS}
    counts = turn(driver, axis, turns)
    lost = [f"{k} +{driver.counters[k] - v}" for k, v in before.items() if driver.counters[k] != v]
    if lost:
        raise CalibrationError(f"the turn about {axis} lost motion: {', '.join(lost)} while its counts were summed "
                               "(they would give too few counts per mm): repeat the calibration")
    return Step(axis, turns, tuple(counts))


def calibrate(config: TrackballConfig, steps: list[Step], min_share: float = 0.5, min_counts: int = 100) -> Result:
    """New counts per mm and signs for every sensor axis (see the module docstring)."""
    estimates: dict[str, list[float]] = {name: [] for name in AXIS_NAMES}
    signs: dict[str, list[int]] = {name: [] for name in AXIS_NAMES}
    for step in steps:
        if not step.turns > 0:
            raise CalibrationError(f"turns must be > 0, got {step.turns!r} for axis {step.axis!r}")
        travel = predicted_travel(config, step.axis, step.turns)
        full = 2 * math.pi * config.ball_radius * step.turns
        for k, name in enumerate(AXIS_NAMES):
            if abs(travel[k]) < min_share * full:
                continue
            counts = step.counts[k]
            if abs(counts) < min_counts:
                raise CalibrationError(
                    f"sensor axis {name} counted only {counts} while the ball turned {step.turns} turns about "
                    f"{step.axis} (expected {abs(travel[k]) * 1e3:.0f} mm of travel): is the sensor working?"
                )
            estimates[name].append(abs(counts) / (abs(travel[k]) * 1e3))
            signs[name].append(1 if counts * travel[k] > 0 else -1)
    missing = [name for name, v in estimates.items() if not v]
    if missing:
        raise CalibrationError(
            f"sensor axes {missing} were not calibrated by the turns about {[s.axis for s in steps]}; "
            f"turn the ball also about the axes that move them (default placement: z, x and y)"
        )
    for name, s in signs.items():
        if len(set(s)) > 1:
            raise CalibrationError(f"sensor axis {name} changed sign between steps {s}: repeat the calibration")
    sensors = []
    for i, sensor in enumerate(config.sensors):
        cpmm = tuple(float(np.mean(estimates[f"{a}{i}"])) for a in "xy")
        sgn = tuple(signs[f"{a}{i}"][0] for a in "xy")
        sensors.append(replace(sensor, counts_per_mm=cpmm, signs=sgn, calibration_cpi=config.resolution_cpi))
    return Result(replace(config, sensors=tuple(sensors)), {k: v for k, v in estimates.items()})


#: how the emulated "lens" of `calibrate --emulate` differs from the config: factors on counts per mm
#: (x0, y0, x1, y1) and a flipped y1 sign, so that a demo or test has something to find
EMULATED_CPMM_FACTORS = (1.06, 0.94, 1.03, 0.91)
EMULATED_SIGN_FLIP = (1, 1, 1, -1)


def miscalibrated_emulator(config: TrackballConfig, realtime: bool = True):
    """An emulated trackball whose lens differs from `config` as above, turned on request (`turn_emulated`)."""
    from antarium.locomotion.trackball.emulator import EmulatedTrackball, Turns

    sensors = []
    for i, s in enumerate(config.sensors):
        f = EMULATED_CPMM_FACTORS[2 * i: 2 * i + 2]
        g = EMULATED_SIGN_FLIP[2 * i: 2 * i + 2]
        sensors.append(replace(s, counts_per_mm=(s.counts_per_mm[0] * f[0], s.counts_per_mm[1] * f[1]),
                               signs=(s.signs[0] * g[0], s.signs[1] * g[1])))
    return EmulatedTrackball(motion=Turns(), truth=replace(config, sensors=tuple(sensors)), realtime=realtime)


def turn_emulated(driver, backend, axis: str, turns: float, seconds_per_turn: float = 1.0) -> list[int]:
    """One calibration step on the emulated ball: `turns` whole turns about `axis`; the driver's raw counts."""
    import time

    driver.reset_raw_counts()
    period = 1.0 / driver.config.sample_rate_hz
    start = (math.floor(backend.device_time() / period) + 20) * period
    duration = round(turns * seconds_per_turn / period) * period
    end = backend.motion.schedule(start, AXES[axis], turns, duration)
    deadline = time.monotonic() + 10 * duration + 5.0
    while backend.device_time() < end + 20 * period:
        if time.monotonic() > deadline:
            raise RuntimeError("the emulated trackball stopped sending reports during calibration")
        time.sleep(0.005)
    return driver.raw_counts()
