"""Commands to the rig: declared parameters and their validation (pure Python, no bus).

A command is a name and a JSON object of parameters. `parse_command(name, params)` returns the checked
parameters (defaults filled, degrees kept as given) or raises `CommandError` naming what was wrong and
what is allowed; nothing is changed before a command is fully valid. `docs/bus.md` lists the same table.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any


class CommandError(ValueError):
    """A command that is unknown, or has a missing, unknown, mistyped or out-of-range parameter."""


@dataclass(frozen=True)
class Param:
    kind: str  # "number", "bool", "str", "object", "scene", "number_list"
    required: bool = False
    default: Any = None
    lo: float | None = None
    hi: float | None = None
    choices: tuple | None = None
    doc: str = ""


_XY = 1e6  # metres: anything farther is a typo, not a world
#: command name -> parameter name -> declaration
COMMANDS: dict[str, dict[str, Param]] = {
    "load_scene": {"scene": Param("scene", True, doc="scene name, file path, or {scene: name, ...parameters}")},
    "set_pose": {
        "x": Param("number", True, lo=-_XY, hi=_XY, doc="m"),
        "y": Param("number", True, lo=-_XY, hi=_XY, doc="m"),
        "z": Param("number", False, None, lo=-_XY, hi=_XY, doc="m (eye height; default: keep)"),
        "heading_deg": Param("number", False, None, lo=-3600, hi=3600, doc="world azimuth of the dome's +x"),
    },
    "reset_origin": {
        "x": Param("number", False, None, lo=-_XY, hi=_XY, doc="m; with y: a new origin"),
        "y": Param("number", False, None, lo=-_XY, hi=_XY, doc="m"),
        "z": Param("number", False, None, lo=-_XY, hi=_XY, doc="m"),
        "heading_deg": Param("number", False, None, lo=-3600, hi=3600),
    },
    "rotate_scene": {"deg": Param("number", True, lo=-3600, hi=3600, doc="counter-clockwise seen from above")},
    "closed_loop": {"on": Param("bool", True)},
    "tether": {"tether": Param("str", True, choices=("free_yaw", "fixed"))},
    "gains": {
        "translation": Param("number", False, None, lo=-100, hi=100),
        "rotation": Param("number", False, None, lo=-100, hi=100),
    },
    "scene_edit": {
        "op": Param("str", True, choices=("move_object", "remove_object", "scale_channel", "swap_green_blue",
                                          "set_lowpass", "set_contrast", "set_brightness")),
        "args": Param("object", False, {}, doc="the operation's arguments (see docs/bus.md)"),
    },
    "trial_start": {
        "name": Param("str", True, doc="trial name (part of the log file name)"),
        "metadata": Param("object", False, {}, doc="JSON object stored with the trial"),
    },
    "trial_stop": {},
    "sky": {
        "sun_azimuth_deg": Param("number", False, None, lo=-360, hi=360),
        "sun_elevation_deg": Param("number", False, None, lo=-90, hi=90),
        "dop_max": Param("number", False, None, lo=0, hi=1, doc="maximum degree of polarisation"),
        "sun_radiance": Param("number", False, None, lo=0, hi=1000),
    },
    "polarisers": {
        "angles_deg": Param("number_list", False, None, doc="55 x 9 e-vector angles, degrees; null: follow the sky"),
    },
    "status": {},
}


def _check(command: str, name: str, p: Param, value: Any) -> Any:
    where = f"{command}: parameter {name!r}"
    if p.kind == "number":
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise CommandError(f"{where} must be a finite number, got {value!r}")
        value = float(value)
        if (p.lo is not None and value < p.lo) or (p.hi is not None and value > p.hi):
            raise CommandError(f"{where} must be in [{p.lo}, {p.hi}], got {value!r}")
    elif p.kind == "bool":
        if not isinstance(value, bool):
            raise CommandError(f"{where} must be true or false, got {value!r}")
    elif p.kind == "str":
        if not isinstance(value, str) or not value:
            raise CommandError(f"{where} must be a non-empty string, got {value!r}")
        if p.choices is not None and value not in p.choices:
            raise CommandError(f"{where} must be one of {', '.join(map(repr, p.choices))}, got {value!r}")
    elif p.kind == "object":
        if not isinstance(value, dict):
            raise CommandError(f"{where} must be a JSON object, got {value!r}")
    elif p.kind == "scene":
        if not (isinstance(value, str) and value) and not (isinstance(value, dict) and "scene" in value):
            raise CommandError(f"{where} must be a scene name, a file path or an object with 'scene', got {value!r}")
    elif p.kind == "number_list":
        if value is not None and not isinstance(value, list):
            raise CommandError(f"{where} must be a (nested) list of numbers, got {type(value).__name__}")
    return value


def parse_command(command: str, params: Any) -> dict[str, Any]:
    """Checked parameters of `command` (defaults filled); `CommandError` if anything is wrong."""
    decl = COMMANDS.get(command)
    if decl is None:
        raise CommandError(f"unknown command {command!r}; allowed: {', '.join(COMMANDS)}")
    if params is None:
        params = {}
    if not isinstance(params, dict):
        raise CommandError(f"{command}: parameters must be a JSON object, got {type(params).__name__}")
    unknown = sorted(set(params) - set(decl))
    if unknown:
        raise CommandError(f"{command}: unknown parameter(s) {unknown}; allowed: {sorted(decl) or 'none'}")
    out = {}
    for name, p in decl.items():
        if name not in params:
            if p.required:
                raise CommandError(f"{command}: missing parameter {name!r} ({p.kind}{', ' + p.doc if p.doc else ''})")
            out[name] = p.default
        else:
            out[name] = _check(command, name, p, params[name])
    if command == "reset_origin" and (out["x"] is None) != (out["y"] is None):
        raise CommandError("reset_origin: give both 'x' and 'y' for a new origin, or neither")
    if command == "polarisers" and out["angles_deg"] is not None:
        import numpy as np

        try:
            angles = np.asarray(out["angles_deg"], dtype=np.float64)
        except (TypeError, ValueError):
            raise CommandError("polarisers: 'angles_deg' must be 55 lists of 9 numbers (degrees)") from None
        if angles.shape != (55, 9) or not np.all(np.isfinite(angles)):
            raise CommandError(f"polarisers: 'angles_deg' must be 55 x 9 finite numbers, got shape {angles.shape}")
        out["angles_deg"] = angles
    return out
