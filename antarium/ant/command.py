"""What every model of the virtual ant decides: a `Command`."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True, slots=True)
class Command:
    """One decision: `forward` metres along the body axis (negative: backward), `turn` radians (CCW)."""

    forward: float
    turn: float
    trace: dict[str, float] = field(default_factory=dict)
