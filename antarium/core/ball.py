"""Motion of the ant standing on the top pole of the trackball.

A ball of radius R rotating by the small rotation vector r (rad, dome frame) moves its top-pole surface by
r x (R z). The ant walks relative to that surface, so in the ball's frame it moves by -(r x R z) and,
when it is held fixed in yaw, it turns by -r_z.
"""

from __future__ import annotations

BALL_RADIUS_M = 0.05  # the Antarium's 10 cm Styrofoam ball


def pole_motion(rotation: tuple[float, float, float], radius: float = BALL_RADIUS_M) -> tuple[float, float, float]:
    """Ant displacement (dx, dy) in metres along the dome's x and y, and yaw (rad), for one increment."""
    rx, ry, rz = rotation
    return -radius * ry, radius * rx, -rz
