"""Ball kinematics of a mouse-sensor trackball: sensor readings <-> ball rotation (pure numpy).

A sensor at the unit position p on a ball of radius R reads the surface displacement along two unit
surface axes s (tangent to the ball at p). For a small rotation vector r (rad, dome frame: +x forward,
+y left, +z up) the surface at R p moves by r x R p, so the reading along s is

    m = s . (r x R p) = r . (R p x s)

Each sensor axis is one row `R (p x s)` of the (K, 3) design matrix A; K readings (K >= 3, four for two
sensors) give r by least squares, and the residual m - A r (metres of surface displacement that no ball
rotation explains: slip, dirt, a lifted sensor) is the quality signal.

Sensor placement is given as azimuth and elevation of p (radians; azimuth 0 along +x, counter-clockwise
seen from above) and a roll of the sensor about p. With roll 0 the sensor's x axis points along
increasing azimuth ("east") and its y axis along increasing elevation ("north").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SensorPlacement:
    """One two-axis sensor on the ball: position angles and roll, radians."""

    azimuth: float
    elevation: float = 0.0
    roll: float = 0.0

    def position(self) -> np.ndarray:
        """Unit vector (3,) float64 from the ball centre to the sensor."""
        ca, sa = np.cos(self.azimuth), np.sin(self.azimuth)
        ce, se = np.cos(self.elevation), np.sin(self.elevation)
        return np.array([ce * ca, ce * sa, se])

    def axes(self) -> np.ndarray:
        """(2, 3) float64: unit surface directions of the sensor's x and y counts."""
        ca, sa = np.cos(self.azimuth), np.sin(self.azimuth)
        ce, se = np.cos(self.elevation), np.sin(self.elevation)
        east = np.array([-sa, ca, 0.0])
        north = np.array([-se * ca, -se * sa, ce])
        cr, sr = np.cos(self.roll), np.sin(self.roll)
        return np.stack([cr * east + sr * north, -sr * east + cr * north])


#: The default trackball: two sensors on the equator, at azimuth 0 (front) and 90 deg (left).
DEFAULT_SENSORS = (SensorPlacement(0.0), SensorPlacement(np.pi / 2))


def design_matrix(sensors: tuple[SensorPlacement, ...], radius: float) -> np.ndarray:
    """(2 * len(sensors), 3) float64: row k maps a rotation vector (rad) to reading k (metres).

    Rows are ordered sensor 0 x, sensor 0 y, sensor 1 x, ...
    """
    if radius <= 0 or not np.isfinite(radius):
        raise ValueError(f"ball radius must be a positive number of metres, got {radius!r}")
    rows = []
    for sensor in sensors:
        p = sensor.position()
        for s in sensor.axes():
            rows.append(radius * np.cross(p, s))
    return np.array(rows)


class BallSolver:
    """Least-squares ball rotation from sensor readings, for a fixed placement and radius.

    `slip_floor` (metres) keeps the relative slip finite when the ball is still: quality is
    1 - min(1, |residual| / (|readings| + slip_floor)).
    """

    def __init__(
        self,
        sensors: tuple[SensorPlacement, ...] = DEFAULT_SENSORS,
        radius: float = 0.05,
        slip_floor: float = 1e-4,
    ) -> None:
        self.sensors = tuple(sensors)
        self.radius = float(radius)
        self.slip_floor = float(slip_floor)
        self.matrix = design_matrix(self.sensors, self.radius)
        if np.linalg.matrix_rank(self.matrix) < 3:
            raise ValueError(
                "sensor placement cannot resolve all three rotation axes (design matrix rank < 3); "
                "place at least two sensors at different azimuths"
            )
        self._pinv = np.linalg.pinv(self.matrix)  # (3, K)
        self._pinv_rows = self._pinv.tolist()
        self._rows = self.matrix.tolist()

    def readings(self, rotation: np.ndarray) -> np.ndarray:
        """Forward model: rotation (..., 3) rad -> readings (..., K) metres."""
        return np.asarray(rotation, dtype=float) @ self.matrix.T

    def solve(self, readings: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Readings (..., K) metres -> (rotation (..., 3) rad, residual norm (...,) metres)."""
        m = np.asarray(readings, dtype=float)
        r = m @ self._pinv.T
        residual = np.linalg.norm(m - r @ self.matrix.T, axis=-1)
        return r, residual

    def quality(self, readings: np.ndarray, residual: np.ndarray) -> np.ndarray:
        """Quality 0..1 (...,) from readings (..., K) and residual norms (...,), both metres."""
        norm = np.linalg.norm(np.asarray(readings, dtype=float), axis=-1)
        return 1.0 - np.minimum(1.0, residual / (norm + self.slip_floor))

    def solve_one(self, m: list[float]) -> tuple[tuple[float, float, float], float]:
        """One sample in plain Python floats (the driver's hot path): readings (K,) -> (rotation, quality)."""
        rx, ry, rz = (sum(a * b for a, b in zip(row, m, strict=True)) for row in self._pinv_rows)
        res2 = 0.0
        norm2 = 0.0
        for row, v in zip(self._rows, m, strict=True):
            e = v - (row[0] * rx + row[1] * ry + row[2] * rz)
            res2 += e * e
            norm2 += v * v
        quality = 1.0 - min(1.0, res2**0.5 / (norm2**0.5 + self.slip_floor))
        return (rx, ry, rz), quality
