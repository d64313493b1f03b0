"""The eye pose in the virtual world: position in metres, heading in radians (SI inside)."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class Pose:
    """Eye position (x, y, z) in metres in the world frame (+z up) and heading in radians.

    Heading is the azimuth of the ant's forward direction, 0 along +x, counter-clockwise seen from
    above, kept in [-pi, pi] (a heading given outside is wrapped: 450 deg is 90 deg). Non-finite values are
    rejected with a ValueError naming the field.
    """

    x: float = 0.0
    y: float = 0.0
    z: float = 0.01
    heading: float = 0.0

    def __post_init__(self) -> None:
        for name in ("x", "y", "z", "heading"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"pose {name} must be a finite number (metres or radians), got {value!r}")
        if not -math.pi <= self.heading <= math.pi:
            object.__setattr__(self, "heading", math.remainder(self.heading, math.tau))

    @classmethod
    def from_deg(cls, x: float, y: float, z: float = 0.01, heading_deg: float = 0.0) -> Pose:
        return cls(float(x), float(y), float(z), math.radians(heading_deg))

    @property
    def heading_deg(self) -> float:
        return math.degrees(self.heading)

    def moved(self, dx: float = 0.0, dy: float = 0.0, dz: float = 0.0, dheading: float = 0.0) -> Pose:
        """A new pose displaced in the world frame (metres) and turned (radians, wrapped to (-pi, pi])."""
        h = math.remainder(self.heading + dheading, math.tau)
        return Pose(self.x + dx, self.y + dy, self.z + dz, h)
