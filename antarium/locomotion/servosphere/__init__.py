"""The servosphere: a free ant kept on a ball's apex by camera tracking, PD control and three omniwheel rotors
(Goulard et al. 2021); the ball's rotation is the ant's walk. See docs/servosphere.md.

Camera and motor link each sit behind one interface with a registry of back-ends imported lazily (python-can
style); `simulated` back-ends come from `rig.SimulatedRig`.

    rig = SimulatedRig(clock)
    link = open_motor_link("simulated", rig=rig)       # or open_motor_link("serial", url="/dev/ttyACM0")
    camera = open_camera("simulated", rig=rig)         # or open_camera("opencv", index=0)
"""

from __future__ import annotations

import math
from importlib import import_module
from typing import Any

import numpy as np

from antarium.core.numbers import as_real

#: back-end name -> "module:factory"
MOTOR_LINKS: dict[str, str] = {
    "simulated": "antarium.locomotion.servosphere.rig:open_simulated_link",
    "serial": "antarium.locomotion.servosphere.link:open_serial_link",
}
CAMERAS: dict[str, str] = {
    "simulated": "antarium.locomotion.servosphere.rig:open_simulated_camera",
    "opencv": "antarium.locomotion.servosphere.camera:OpenCVCamera",
}


def _open(registry: dict[str, str], kind: str, name: str, kwargs: dict[str, Any]):
    target = registry.get(name) if isinstance(name, str) else None
    if target is None:
        raise ValueError(f"unknown servosphere {kind} {name!r}; allowed: {', '.join(sorted(registry))}")
    module_name, attr = target.split(":")
    return getattr(import_module(module_name), attr)(**kwargs)


def open_motor_link(name: str, **kwargs: Any):
    """A `link.MotorLink` from back-end `name`."""
    return _open(MOTOR_LINKS, "motor link", name, kwargs)


def open_camera(name: str, **kwargs: Any):
    """A camera (`grab() -> (t, uint8 (H, W) frame, or None when the camera gave none)`, `frame_rate`, `close()`)
    from back-end `name`."""
    return _open(CAMERAS, "camera", name, kwargs)


def finite_numbers(values: Any, n: int) -> bool:
    """True when `values` is a sequence (tuple, list, 1-D array) of `n` finite real numbers (no bools)."""
    if isinstance(values, np.ndarray):
        values = values.tolist() if values.ndim == 1 else None
    return isinstance(values, (tuple, list)) and len(values) == n and all(math.isfinite(as_real(v)) for v in values)
