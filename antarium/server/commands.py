"""Commands to the rig: one table, each command's declared parameters beside the handler that runs it.

A command is a name and a JSON object of parameters. `parse_command(name, params)` returns the checked
parameters (defaults filled, degrees kept as given) or raises `CommandError` naming what was wrong and
what is allowed; nothing is changed before a command is fully valid. The server then looks the command up in
`COMMANDS` and runs its handler: in the frame loop's thread between two frames (`in_loop`), or in the caller's.
`docs/bus.md` lists the same table (a test keeps them equal).
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from antarium.core.ball import TETHERS
from antarium.core.numbers import as_real
from antarium.core.pose import Pose

if TYPE_CHECKING:
    from antarium.server.server import Server


class CommandError(ValueError):
    """A command that is unknown, or has a missing, unknown, mistyped or out-of-range parameter."""


@dataclass(frozen=True)
class Param:
    kind: str  # "number", "bool", "str", "object", "scene", "number_list", "xyz" (a list of 3 numbers)
    required: bool = False
    default: Any = None
    lo: float | None = None
    hi: float | None = None
    choices: tuple | None = None
    doc: str = ""
    nullable: bool = False  # null is a value of its own (e.g. "off")


@dataclass(frozen=True)
class Command:
    """params: name -> declaration; handler(server, checked params) -> result (None: the rig's state);
    in_loop: run in the frame loop's thread between two frames (anything that changes what the dome shows);
    prepare(server, checked params): the slow part of an in-loop command, run before it and beside the loop
    (`LoopPlacement.beside_loop`: never holding a frame); its result reaches the handler as parameter "prepared";
    reply_s: the least time (s) a client waits for the reply of a command whose work takes long (a scene load
    parses, builds and uploads a whole world: seconds, more on a busy machine); None: the client's own timeout.
    edits_scene: it changes the loaded scene until the next load (a trial's start state lists such changes)."""

    params: dict[str, Param]
    handler: Callable[[Server, dict[str, Any]], Any]
    in_loop: bool = True
    prepare: Callable[[Server, dict[str, Any]], Any] | None = None
    reply_s: float | None = None
    edits_scene: bool = False


_XY = 1e6  # metres: anything farther is a typo, not a world


# -- handlers: run with checked parameters; a handler that raises changes nothing --------------------------------
def _set_pose(server: Server, p: dict[str, Any]) -> None:
    cur = server.loop.pose
    z = cur.z if p["z"] is None else p["z"]
    heading = cur.heading if p["heading_deg"] is None else math.radians(p["heading_deg"])
    server.loop.set_pose(Pose(p["x"], p["y"], z, math.remainder(heading, math.tau)))


#: how long a displacement, an object edit or a sky change waits for the far layer at its target (with the edit, over
#: the new sky) before it is applied anyway (s)
PREFETCH_WAIT_S = 2.0


def _prefetched(server: Server, prefetch: Callable[[], None], ready: Callable[[], bool]) -> None:
    """`prefetch()` run in the loop's thread, then (in the caller's, beside the loop) a wait until `ready()` or for
    `PREFETCH_WAIT_S`. A loop held up longer leaves nothing to prepare: the command then waits in its queue."""
    import time

    try:
        server.loop.call_soon(prefetch).result(PREFETCH_WAIT_S)
    except TimeoutError:
        return
    deadline = time.monotonic() + PREFETCH_WAIT_S
    while not ready() and time.monotonic() < deadline:
        time.sleep(0.002)


def _prepare_pose(server: Server, p: dict[str, Any]) -> None:
    """Before a displacement: the far layer at its target is built while frames go on (caller's thread)."""
    renderer = server.renderer
    if renderer is None or not hasattr(renderer, "prefetch_pose"):
        return
    target = Pose(p["x"], p["y"], server.loop.pose.z if p["z"] is None else p["z"], 0.0)
    _prefetched(server, lambda: renderer.prefetch_pose(target), lambda: renderer.ready_for(target))


def _reset_origin(server: Server, p: dict[str, Any]) -> None:
    origin = None
    if p["x"] is not None:
        o = server.loop.origin
        heading = o.heading if p["heading_deg"] is None else math.radians(p["heading_deg"])
        origin = Pose(p["x"], p["y"], o.z if p["z"] is None else p["z"], math.remainder(heading, math.tau))
    server.loop.reset_origin(origin)


def _polarisers(server: Server, p: dict[str, Any]) -> None:
    import numpy as np

    if server.link is None:
        raise RuntimeError("polarisers: this rig has no dome link")
    server.require_renderer("polarisers")  # the updates go out with the rendered frames
    server.loop.set_polarisers(None if p["angles_deg"] is None else np.radians(p["angles_deg"]))


#: scene_edit operation -> (renderer method, {argument on the bus: (renderer argument, declaration)}); a `_deg`
#: argument reaches the renderer in radians
SCENE_EDITS: dict[str, tuple[str, dict[str, tuple[str, Param]]]] = {
    "move_object": ("move_object", {"name": ("name", Param("str", True)),
                                    "position": ("position", Param("xyz", False, None, lo=-_XY, hi=_XY, doc="m")),
                                    "yaw_deg": ("yaw", Param("number", False, None, lo=-3600, hi=3600))}),
    "remove_object": ("remove_object", {"name": ("name", Param("str", True))}),
    "scale_channel": ("scale_channel", {"channel": ("channel", Param("str", True)),
                                        "factor": ("factor", Param("number", True))}),
    "swap_green_blue": ("swap_green_blue", {"swap": ("swap", Param("bool", True))}),
    "set_lowpass": ("set_lowpass", {"cutoff_deg": ("cutoff_deg", Param("number", True, nullable=True,
                                                                       doc="null: off"))}),
    "set_contrast": ("set_contrast", {"contrast": ("contrast", Param("number", True))}),
    "set_brightness": ("set_brightness", {"brightness": ("brightness", Param("number", True))}),
}


def _edit_kwargs(op: str, args: dict[str, Any]) -> dict[str, Any]:
    """The renderer method's keyword arguments of a scene_edit, checked as command parameters are; CommandError
    naming what was wrong."""
    _, allowed = SCENE_EDITS[op]
    unknown = sorted(set(args) - set(allowed))
    if unknown:
        raise CommandError(f"scene_edit {op}: unknown argument(s) {unknown}; allowed: {sorted(allowed)}")
    checked = _checked(f"scene_edit {op}", {key: decl for key, (_, decl) in allowed.items()}, args)
    if op == "move_object" and checked["position"] is None and checked["yaw_deg"] is None:
        raise CommandError("scene_edit move_object: give 'position' [x, y, z] (m) and/or 'yaw_deg'")
    kwargs = {}
    for key, value in checked.items():
        if key in args:
            target = allowed[key][0]
            kwargs[target] = math.radians(value) if key.endswith("_deg") and target != key else value
    return kwargs


def _prepare_edit(server: Server, p: dict[str, Any]):
    """Before an object edit, while frames go on (caller's thread): the far layer with the edit is built, and a
    move's vertices and bounds are computed (`Renderer.prepare_move`; None when they cannot be: the loop's thread
    then computes them, and names what was wrong)."""
    renderer = server.renderer
    if renderer is None or not hasattr(renderer, "prefetch_edit"):
        return None
    kwargs = _edit_kwargs(p["op"], p["args"])
    try:
        _prefetched(server, lambda: renderer.prefetch_edit(server.loop.pose, p["op"], **kwargs),
                    lambda: renderer.edit_ready(server.loop.pose))
    except TypeError as exc:
        raise CommandError(f"scene_edit {p['op']}: {exc}") from None
    if p["op"] != "move_object" or not hasattr(renderer, "prepare_move"):
        return None
    try:
        return renderer.prepare_move(**kwargs)
    except (TypeError, ValueError, KeyError, AttributeError):  # an unknown object, or edited meanwhile
        return None


def _scene_edit(server: Server, p: dict[str, Any]) -> None:
    """One edit of the current scene (a renderer method); a failing edit changes nothing."""
    op, args = p["op"], p["args"]
    renderer = server.require_renderer("scene_edit")
    kwargs = _edit_kwargs(op, args)
    if p.get("prepared") is not None:
        kwargs["prepared"] = p["prepared"]
    try:
        getattr(renderer, SCENE_EDITS[op][0])(**kwargs)
    except (TypeError, ValueError) as exc:  # the renderer's own check of the value (its range): name the edit
        raise CommandError(f"scene_edit {op}: {_brief(str(exc))}") from None
    server.loop.renderer_changed()
    server.loop.event("scene_edit", op=op, args=args)


def _sky_layers(server: Server, p: dict[str, Any]) -> tuple[list, list]:
    """(the current scene's far-field layers, the same with its sky changed as asked); CommandError or RuntimeError
    naming what is wrong."""
    scene = server.require_renderer("sky").scene
    sky = getattr(scene, "sky", None)
    if sky is None:
        raise RuntimeError(f"sky: the current scene {server.scene_name!r} has no sky")
    changes = {k: math.radians(p[f"{k}_deg"]) for k in ("sun_azimuth", "sun_elevation") if p[f"{k}_deg"] is not None}
    changes.update({k: p[k] for k in ("dop_max", "sun_radiance") if p[k] is not None})
    if not changes:
        raise CommandError("sky: give at least one of sun_azimuth_deg, sun_elevation_deg, dop_max, sun_radiance")
    new_sky = dataclasses.replace(sky, **changes)
    return scene.far, [new_sky if layer is sky else layer for layer in scene.far]


@dataclasses.dataclass
class PreparedSky:
    """A sky change prepared off the frame loop: the far-field layers it changes (the scene's `far` list) and the
    renderer's `PreparedFar` of the new ones, its far layer prefetched; `release` withdraws that prefetch."""

    base: list
    far: Any
    server: Server

    def release(self) -> None:
        renderer = self.server.renderer
        self.server.loop.call_soon(renderer.withdraw_far, self.far)


def _prepare_sky(server: Server, p: dict[str, Any]) -> PreparedSky:
    """Before a sky change: the new far field's table is made, and the far layer over it built, while frames go on
    (caller's thread). Nothing else of the scene is made again: its objects and edits stay as they are."""
    renderer = server.require_renderer("sky")
    base, far = _sky_layers(server, p)
    ready = PreparedSky(base, renderer.prepare_far(far), server)
    _prefetched(server, lambda: renderer.prefetch_far(server.loop.pose, ready.far),
                lambda: renderer.edit_ready(server.loop.pose))
    return ready


def _sky(server: Server, p: dict[str, Any]) -> None:
    """Move the sun / change the sky's polarisation of the current scene: the prepared far field swapped in, or,
    when the scene or its far field changed meanwhile, the change made to the current one here (holding frames)."""
    renderer = server.require_renderer("sky")
    ready: PreparedSky | None = p.get("prepared")
    target = ready.far if ready is not None else None
    if ready is not None and (renderer.scene is not ready.far.scene or renderer.scene.far is not ready.base):
        renderer.withdraw_far(ready.far)
        target = None
    try:
        renderer.set_far(_sky_layers(server, p)[1] if target is None else target)
    except (OSError, ValueError, RuntimeError) as exc:
        if target is not None:
            renderer.withdraw_far(target)
        raise RuntimeError(f"sky: {exc}; the current sky stays") from None
    server.loop.renderer_changed()
    server.loop.event("sky", **{k: p[k] for k in p if p[k] is not None and k != "prepared"})


#: how long a client waits at least for a scene load's reply (s): the habitat loads in about 1.3 s on a quiet
#: 2-core machine and took over 10 s (the Rig's default timeout) at a load average of 8
SCENE_REPLY_S = 120.0

#: command name -> its parameters and handler (the one table: the bus, the Rig client and docs/bus.md follow it)
COMMANDS: dict[str, Command] = {
    "load_scene": Command(
        {"scene": Param("scene", True, doc="scene name, file path, or {scene: name, ...parameters}")},
        lambda server, p: server.load_scene(p["scene"], p["prepared"]),
        prepare=lambda server, p: server.prepare_scene(p["scene"]), reply_s=SCENE_REPLY_S),
    "set_pose": Command({
        "x": Param("number", True, lo=-_XY, hi=_XY, doc="m"),
        "y": Param("number", True, lo=-_XY, hi=_XY, doc="m"),
        "z": Param("number", False, None, lo=-_XY, hi=_XY, doc="m (eye height; default: keep)"),
        "heading_deg": Param("number", False, None, lo=-3600, hi=3600, doc="world azimuth of the dome's +x"),
    }, _set_pose, prepare=_prepare_pose),
    "reset_origin": Command({
        "x": Param("number", False, None, lo=-_XY, hi=_XY, doc="m; with y: a new origin"),
        "y": Param("number", False, None, lo=-_XY, hi=_XY, doc="m"),
        "z": Param("number", False, None, lo=-_XY, hi=_XY, doc="m"),
        "heading_deg": Param("number", False, None, lo=-3600, hi=3600),
    }, _reset_origin),
    "rotate_scene": Command(
        {"deg": Param("number", True, lo=-3600, hi=3600, doc="counter-clockwise seen from above")},
        lambda server, p: server.loop.rotate_scene(math.radians(p["deg"]))),
    "closed_loop": Command({"on": Param("bool", True)}, lambda server, p: server.loop.set_closed_loop(p["on"])),
    "tether": Command({"tether": Param("str", True, choices=tuple(TETHERS))},
                      lambda server, p: server.loop.set_tether(p["tether"])),
    "gains": Command({
        "translation": Param("number", False, None, lo=-100, hi=100),
        "rotation": Param("number", False, None, lo=-100, hi=100),
    }, lambda server, p: server.loop.set_gains(p["translation"], p["rotation"])),
    "scene_edit": Command({
        "op": Param("str", True, choices=tuple(SCENE_EDITS)),
        "args": Param("object", False, {}, doc="the operation's arguments (see docs/bus.md)"),
    }, _scene_edit, prepare=_prepare_edit, edits_scene=True),
    "trial_start": Command({
        "name": Param("str", True, doc="trial name (part of the log file name)"),
        "metadata": Param("object", False, {}, doc="JSON object stored with the trial"),
        "folder": Param("str", False, "", doc="absolute folder for this trial's log on the server's computer "
                                               "(default: [log] dir)"),
    }, lambda server, p: server.trial_start(p["name"], p["metadata"], p["folder"]), in_loop=False),
    "trial_stop": Command({
        "path": Param("str", False, None, doc="stop only the trial recording into this log (trial_start's reply: a "
                                               "script never stops another script's trial)"),
    }, lambda server, p: server.trial_stop(p["path"]), in_loop=False),
    "sky": Command({
        "sun_azimuth_deg": Param("number", False, None, lo=-360, hi=360),
        "sun_elevation_deg": Param("number", False, None, lo=-90, hi=90),
        "dop_max": Param("number", False, None, lo=0, hi=1, doc="maximum degree of polarisation"),
        "sun_radiance": Param("number", False, None, lo=0, hi=1000),
    }, _sky, prepare=_prepare_sky, edits_scene=True),
    "polarisers": Command(
        {"angles_deg": Param("number_list", False, None, doc="55 x 9 e-vector angles, degrees; null: follow the sky")},
        _polarisers),
    "status": Command({}, lambda server, p: server.status(), in_loop=False),
}


def _shown(value: Any) -> str:
    """`value` as a refusal shows it: its repr, cut to 60 characters."""
    return _brief(repr(value), 60)


def slow_command(name: str) -> bool:
    """A command whose work takes long (it prepares beside the loop, or a client waits `reply_s` for it): the bus
    answers such commands on a worker of their own (`Server._on_query`)."""
    command = COMMANDS.get(name)
    return command is not None and (command.prepare is not None or command.reply_s is not None)


def _brief(text: str, limit: int = 300) -> str:
    """`text` cut to `limit` characters (a refusal that echoes a long name from its input is not sent whole)."""
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _check(command: str, name: str, p: Param, value: Any) -> Any:
    where = f"{command}: parameter {name!r}"
    if value is None and p.nullable:
        return None
    if p.kind == "number":
        value = _range(where, p, as_real(value), value)
    elif p.kind == "xyz":
        xyz = [as_real(v) for v in value] if isinstance(value, list) and len(value) == 3 else None
        if xyz is None or not all(math.isfinite(v) for v in xyz):
            raise CommandError(f"{where} must be a list of 3 finite numbers [x, y, z], got {_shown(value)}")
        value = [_range(where, p, v, v) for v in xyz]
    elif p.kind == "bool":
        if not isinstance(value, bool):
            raise CommandError(f"{where} must be true or false, got {_shown(value)}")
    elif p.kind == "str":
        if not isinstance(value, str) or not value:
            raise CommandError(f"{where} must be a non-empty string, got {_shown(value)}")
        if p.choices is not None and value not in p.choices:
            raise CommandError(f"{where} must be one of {', '.join(map(repr, p.choices))}, got {_shown(value)}")
    elif p.kind == "object":
        if not isinstance(value, dict):
            raise CommandError(f"{where} must be a JSON object, got {_shown(value)}")
        try:
            json.dumps(value, allow_nan=False)
        except (TypeError, ValueError, OverflowError) as exc:
            raise CommandError(f"{where} must be plain JSON (no NaN or infinities): {exc}") from None
    elif p.kind == "scene":
        if not (isinstance(value, str) and value) and not (isinstance(value, dict) and "scene" in value):
            raise CommandError(f"{where} must be a scene name, a file path or an object with 'scene', got "
                               f"{_shown(value)}")
    elif p.kind == "number_list":
        if value is not None and not isinstance(value, list):
            raise CommandError(f"{where} must be a (nested) list of numbers, got {type(value).__name__}")
    return value


def _range(where: str, p: Param, number: float, given: Any) -> float:
    """`number` if finite and within the declaration's range, else CommandError showing what was `given`."""
    if not math.isfinite(number):
        raise CommandError(f"{where} must be a finite number, got {_shown(given)}")
    lo = -math.inf if p.lo is None else p.lo
    hi = math.inf if p.hi is None else p.hi
    if not lo <= number <= hi:
        raise CommandError(f"{where} must be in [{lo:g}, {hi:g}], got {number!r}")
    return number


def _checked(command: str, decl: dict[str, Param], params: dict[str, Any]) -> dict[str, Any]:
    """Every declared parameter, checked (defaults filled); CommandError naming a missing or wrong one."""
    out = {}
    for name, p in decl.items():
        if name not in params:
            if p.required:
                raise CommandError(f"{command}: missing parameter {name!r} ({p.kind}{', ' + p.doc if p.doc else ''})")
            out[name] = p.default
        else:
            out[name] = _check(command, name, p, params[name])
    return out


def parse_command(command: str, params: Any) -> dict[str, Any]:
    """Checked parameters of `command` (defaults filled); `CommandError` if anything is wrong."""
    entry = COMMANDS.get(command)
    if entry is None:
        raise CommandError(f"unknown command {command!r}; allowed: {', '.join(COMMANDS)}")
    decl = entry.params
    if params is None:
        params = {}
    if not isinstance(params, dict):
        raise CommandError(f"{command}: parameters must be a JSON object, got {type(params).__name__}")
    unknown = sorted(set(params) - set(decl))
    if unknown:
        raise CommandError(f"{command}: unknown parameter(s) {unknown}; allowed: {sorted(decl) or 'none'}")
    out = _checked(command, decl, params)
    if command == "reset_origin" and ((out["x"] is None) != (out["y"] is None) or (
            out["x"] is None and (out["z"] is not None or out["heading_deg"] is not None))):
        raise CommandError("reset_origin: give 'x' and 'y' (and optionally 'z', 'heading_deg') for a new origin, or "
                           "none of them")
    if command == "gains" and out["translation"] is None and out["rotation"] is None:
        raise CommandError("gains: give 'translation' and/or 'rotation'")
    if command == "polarisers" and out["angles_deg"] is not None:
        import numpy as np

        rows = out["angles_deg"]
        wanted = "55 lists of 9 numbers in [-3600, 3600] (degrees)"
        flat = next((i for i, row in enumerate(rows) if not isinstance(row, list)), None)
        if flat is not None:
            raise CommandError(f"polarisers: 'angles_deg' must be {wanted}; item {flat} is {_shown(rows[flat])}, "
                               f"not a list of 9")
        angles = [[as_real(v) for v in row] for row in rows]
        shape = (len(angles), *sorted({len(row) for row in angles}))
        if shape != (55, 9):
            raise CommandError(f"polarisers: 'angles_deg' must be {wanted}, got {len(angles)} lists of lengths "
                               f"{shape[1:]}")
        for i, row in enumerate(angles):
            for j, v in enumerate(row):
                if not abs(v) <= 3600:
                    raise CommandError(f"polarisers: 'angles_deg' must be {wanted}; panel {i}, polariser {j} is "
                                       f"{_shown(rows[i][j])}")
        out["angles_deg"] = np.array(angles, np.float64)
    return out
