"""Motion of the ant standing on the top pole of the trackball.

A ball of radius R rotating by the small rotation vector r (rad, dome frame) moves its top-pole surface by
r x (R z). The ant walks relative to that surface, so in the ball's frame it moves by -(r x R z) and,
when it is held fixed in yaw, it turns by -r_z.
"""

from __future__ import annotations

import math

BALL_RADIUS_M = 0.05  # the Antarium's 10 cm Styrofoam ball

#: how the ant is held on the ball -> what the ball's rotation moves (the one table of tethers)
TETHERS: dict[str, str] = {
    "free_yaw": "the ant turns on its pin: the ball gives translation only, the heading changes only by command",
    "fixed": "the ant is fixed in yaw: the ball gives translation and yaw, the scene rotates with the ant",
}


def check_tether(tether: object, what: str = "tether") -> str:
    """`tether` if it is one of `TETHERS`, else ValueError naming the allowed ones."""
    if not isinstance(tether, str) or tether not in TETHERS:
        raise ValueError(f"{what} must be one of {', '.join(map(repr, TETHERS))}, got {tether!r}")
    return tether


def pole_motion(rotation: tuple[float, float, float], radius: float = BALL_RADIUS_M) -> tuple[float, float, float]:
    """Ant displacement (dx, dy) in metres along the dome's x and y, and yaw (rad), for one increment."""
    rx, ry, rz = rotation
    return -radius * ry, radius * rx, -rz


def arc_step(heading: float, dx: float, dy: float, dyaw: float) -> tuple[float, float, float]:
    """World displacement (metres) and new heading (rad) of one step walked along its arc.

    (dx, dy) is the step in the ant's frame at the start of the step, dyaw the turn made during it. The ant
    walks a circular arc: the chord points along the heading halfway through the turn (as FicTrac's
    integrated columns 15-17 do) and is shorter than the path by sin(dyaw/2) / (dyaw/2).
    """
    mid, scale = heading + 0.5 * dyaw, chord_ratio(dyaw)
    c, s = math.cos(mid) * scale, math.sin(mid) * scale
    return c * dx - s * dy, s * dx + c * dy, heading + dyaw


def chord_ratio(dyaw: float) -> float:
    """Chord / arc length of an arc turning by `dyaw` rad: sin(dyaw/2) / (dyaw/2)."""
    half = 0.5 * dyaw
    return math.sin(half) / half if abs(half) > 1e-9 else 1.0 - half * half / 6.0
