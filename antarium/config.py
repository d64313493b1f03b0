"""The rig configuration: TOML, one section per part, unknown sections kept verbatim.

The server owns `[rig]`, `[loop]`, `[locomotion]`, `[link]`, `[render]`, `[bus]` and `[log]`; their keys are
checked here (unknown key, wrong type or out-of-range value -> `ConfigError` naming what is allowed).
Every other section (`[trackball]`, `[ant]`, ...) is kept as it was written, for its owner to parse.
With no file the embedded default rig is used: emulator on loopback, default habitat, scripted walker
in closed loop. See `docs/rig.example.toml`.
"""

from __future__ import annotations

import copy
import math
import tomllib
from pathlib import Path
from typing import Any

#: section -> key -> default value. The type of the default is the type a value must have
#: (int is accepted where a float is expected).
DEFAULTS: dict[str, dict[str, Any]] = {
    "rig": {"name": "rig1"},
    "loop": {
        "rate_hz": 190.0,  # frames per second
        "closed_loop": True,
        "tether": "free_yaw",  # "free_yaw": ball gives translation only; "fixed": ball gives yaw too
        "gain_translation": 1.0,
        "gain_rotation": 1.0,
        "start_x": 0.0,  # virtual origin, metres
        "start_y": 0.0,
        "eye_height": 0.01,  # metres above the ground
        "start_heading_deg": 0.0,
        "ball_radius": 0.05,  # metres
        "stats_every": 19,  # publish frame statistics every N frames
        "pose_every": 1,  # publish the pose every N frames
        "realtime_priority": 10,  # 1..99: the frame loop SCHED_FIFO (a spawned emulator two below); 0: off
        "cpu": "auto",  # a CPU for the frame loop's thread alone, the rest of the rig on the others: a CPU number,
        # "auto" (the last one, when there are two or more) or "off"
    },
    "locomotion": {"source": "scripted"},  # other keys are passed to the source as keyword arguments
    "link": {
        "interface": "udp",  # "udp" (distributor or `antarium emulate`) or "virtual" (in-process)
        "host": "127.0.0.1",
        "port": 0,  # 0 with spawn_emulator: an OS-chosen free port
        "spawn_emulator": True,  # start `antarium emulate` as its own process on loopback
    },
    "render": {
        "scene": "habitat",  # a scene name, a file path, or a table {scene = name, ...parameters} (renderers)
        "face_size": 0,  # cube face side in texels; 0: the renderer's default (96 with a far layer, else 192)
        "far_layer": "auto",  # "off", "sync", "async" (meshes beyond near_radius_m from a recent eye position) or
        # "auto": off on the GPU path, async on the CPU path
        "path": "auto",  # per-LED sampling, conversion and packing on "gpu" or "cpu"; "auto": cpu on llvmpipe etc.
        "near_radius_m": 2.0,  # meshes within this distance are drawn every frame
        "far_layer_error_deg": 0.5,  # largest parallax error of the far layer before a frame is drawn in full
    },
    "bus": {
        "enabled": True,
        "mode": "peer",
        "listen": ["tcp/127.0.0.1:7447"],
        "connect": [],
        "multicast_scouting": False,
        "access_control": "",  # path of a JSON5 file holding a zenoh `access_control` object ("" = none)
    },
    "log": {
        "dir": "trials",
        "flush_s": 0.25,  # seconds between flushes to disk (smaller batches: shorter GIL holds by the log sender)
        "record": False,  # record from the start (otherwise only inside trials)
    },
}

#: the embedded default's walker, used when the config has no [locomotion] section: an ant-like scripted walk
#: (about 3 cm/s, in spurts, meandering), seeded so that every run is the same
DEFAULT_WALKER: dict[str, Any] = {"source": "scripted", "speed": 0.03, "meander": 0.6, "spurt_s": 0.8,
                                  "pause_fraction": 0.2, "seed": 1}

#: keys whose values are constrained beyond their type: key -> (allowed values or (lo, hi) range)
_CHOICES = {
    ("loop", "tether"): ("free_yaw", "fixed"),
    ("link", "interface"): ("udp", "virtual"),
    ("bus", "mode"): ("peer", "client", "router"),
    ("render", "far_layer"): ("off", "sync", "async", "auto"),
    ("render", "path"): ("auto", "gpu", "cpu"),
}
_RANGES = {
    ("loop", "rate_hz"): (1.0, 2000.0),
    ("loop", "gain_translation"): (-100.0, 100.0),
    ("loop", "gain_rotation"): (-100.0, 100.0),
    ("loop", "ball_radius"): (1e-3, 1.0),
    ("loop", "eye_height"): (0.0, 1000.0),
    ("loop", "stats_every"): (1, 100000),
    ("loop", "pose_every"): (1, 100000),
    ("loop", "realtime_priority"): (0, 99),
    ("link", "port"): (0, 65535),
    ("render", "face_size"): (0, 2048),
    ("render", "near_radius_m"): (0.01, 1000.0),
    ("render", "far_layer_error_deg"): (0.01, 5.0),
    ("log", "flush_s"): (0.01, 1.0),
}
#: sections whose extra keys are allowed (passed on to a back-end)
_OPEN_SECTIONS = {"locomotion"}


class ConfigError(ValueError):
    """A rig configuration that cannot be used; the message names the key and what is allowed."""


def check_value(section: str, key: str, value: Any) -> Any:
    """Validate one value of an owned section; returns it (ints widened to float where a float is expected)."""
    default = DEFAULTS[section][key]
    where = f"[{section}] {key}"
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ConfigError(f"{where} must be true or false, got {value!r}")
    elif isinstance(default, float):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ConfigError(f"{where} must be a finite number, got {value!r}")
        value = float(value)
    elif isinstance(default, int):
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where} must be an integer, got {value!r}")
    elif (section, key) == ("render", "scene"):
        if not isinstance(value, (str, dict)) or (isinstance(value, dict) and "scene" not in value):
            raise ConfigError(f"{where} must be a scene name, a file path or a table with 'scene', got {value!r}")
    elif (section, key) == ("loop", "cpu"):
        if not (value in ("auto", "off") or (isinstance(value, int) and not isinstance(value, bool) and value >= 0)):
            raise ConfigError(f"{where} must be a CPU number (>= 0), \"auto\" or \"off\", got {value!r}")
    elif isinstance(default, str):
        if not isinstance(value, str):
            raise ConfigError(f"{where} must be a string, got {value!r}")
    elif isinstance(default, list):
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise ConfigError(f"{where} must be a list of strings, got {value!r}")
    choices = _CHOICES.get((section, key))
    if choices is not None and value not in choices:
        raise ConfigError(f"{where} must be one of {', '.join(map(repr, choices))}, got {value!r}")
    bounds = _RANGES.get((section, key))
    if bounds is not None and not bounds[0] <= value <= bounds[1]:
        raise ConfigError(f"{where} must be in [{bounds[0]}, {bounds[1]}], got {value!r}")
    return value


def resolve(raw: dict[str, Any]) -> dict[str, Any]:
    """Defaults merged with `raw` (a parsed TOML document), owned sections checked, others kept verbatim."""
    if not isinstance(raw, dict):
        raise ConfigError(f"a rig config must be a table of sections, got {type(raw).__name__}")
    resolved = copy.deepcopy(DEFAULTS)
    if "locomotion" not in raw:
        resolved["locomotion"] = dict(DEFAULT_WALKER)
    for section, table in raw.items():
        if section not in DEFAULTS:
            resolved[section] = copy.deepcopy(table)
            continue
        if not isinstance(table, dict):
            raise ConfigError(f"[{section}] must be a table, got {table!r}")
        for key, value in table.items():
            if key in DEFAULTS[section]:
                resolved[section][key] = check_value(section, key, value)
            elif section in _OPEN_SECTIONS:
                resolved[section][key] = copy.deepcopy(value)
            else:
                raise ConfigError(
                    f"unknown key {key!r} in [{section}]; allowed: {', '.join(sorted(DEFAULTS[section]))}"
                )
    _one_ball_radius(raw, resolved)
    name = resolved["rig"]["name"]
    if not name or any(c in name for c in "/*?$# "):
        raise ConfigError(f"[rig] name must be a non-empty key chunk without '/', wildcards or spaces, got {name!r}")
    return resolved


def _one_ball_radius(raw: dict[str, Any], resolved: dict[str, Any]) -> None:
    """The ball has one radius: `[trackball] ball_radius` (the hardware's) is the loop's unless `[loop]` sets it;
    two different values are refused, since the ant's motion would be scaled by their ratio."""
    trackball = raw.get("trackball")
    if not isinstance(trackball, dict) or "ball_radius" not in trackball:
        return
    try:
        r = check_value("loop", "ball_radius", trackball["ball_radius"])
    except ConfigError as exc:
        raise ConfigError(str(exc).replace("[loop]", "[trackball]")) from None
    if "ball_radius" in raw.get("loop", {}) and not math.isclose(resolved["loop"]["ball_radius"], r):
        raise ConfigError(
            f"[loop] ball_radius {resolved['loop']['ball_radius']} m differs from [trackball] ball_radius {r} m; "
            "allowed: one value (set it in [trackball] only)"
        )
    resolved["loop"]["ball_radius"] = r


def load_config(path: str | Path | None = None) -> dict[str, Any]:
    """The resolved rig config from a TOML file, or the embedded default when `path` is None."""
    if path is None:
        return resolve({})
    path = Path(path)
    try:
        with path.open("rb") as f:
            raw = tomllib.load(f)
    except FileNotFoundError:
        raise ConfigError(f"rig config {str(path)!r} not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"rig config {str(path)!r} is not valid TOML: {exc}") from None
    return resolve(raw)
