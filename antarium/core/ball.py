"""Motion of the ant standing on the top pole of the trackball.

A ball of radius R rotating by the small rotation vector r (rad, dome frame) moves its top-pole surface by
r x (R z). The ant walks relative to that surface, so in the ball's frame it moves by -(r x R z) and,
when it is held fixed in yaw, it turns by -r_z.
"""

from __future__ import annotations

BALL_RADIUS_M = 0.05  # the Antarium's 10 cm Styrofoam ball

#: how the ant is held on the ball -> what the ball's rotation moves (the one table of tethers)
TETHERS: dict[str, str] = {
    "free_yaw": "the ant turns on its pin: the ball gives translation only, the heading changes only by command",
    "fixed": "the ant is fixed in yaw: the ball gives translation and yaw, the scene rotates with the ant",
}


def check_tether(tether: object, what: str = "tether") -> str:
    """`tether` if it is one of `TETHERS`, else ValueError naming the allowed ones."""
    if tether not in TETHERS:
        raise ValueError(f"{what} must be one of {', '.join(map(repr, TETHERS))}, got {tether!r}")
    return tether


def pole_motion(rotation: tuple[float, float, float], radius: float = BALL_RADIUS_M) -> tuple[float, float, float]:
    """Ant displacement (dx, dy) in metres along the dome's x and y, and yaw (rad), for one increment."""
    rx, ry, rz = rotation
    return -radius * ry, radius * rx, -rz
