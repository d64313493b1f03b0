"""What every model of the virtual ant decides: a `Command`."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True, slots=True)
class Command:
    """One decision: `forward` metres along the body axis (negative: backward), `turn` radians (CCW)."""

    forward: float
    turn: float
    trace: dict[str, float] = field(default_factory=dict)


def clip_turn(turn: float, limit: float) -> float:
    """`turn` (rad) clipped to +-`limit`, as float(np.clip(turn, -limit, limit)) (NaN kept) without numpy's per-call
    cost (a decision clips two or three turns)."""
    turn = float(turn)
    return -limit if turn < -limit else limit if turn > limit else turn
