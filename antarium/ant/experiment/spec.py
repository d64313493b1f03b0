"""An experiment spec (TOML) and its expansion into runs.

    [experiment]
    protocols = ["ardin"]              # ardin: put back at 20 cm and counted; antcar: never put back
    seeds = [0, 1]                     # the mushroom bodies' random PN->KC wiring (perfect memory has none)
    releases = [{lateral_cm = 0, heading_deg = 0}, {lateral_cm = 5, heading_deg = 20}]
    face_size = 64                     # the renderer's cube-face side
    max_decisions = 0                  # 0: three times the route length in steps
    eye = {cols = 50, rows = 16}       # eye parameters over each model's own (optional)
    metrics = ["errors", "lateral_median_m"]   # the summary's metrics (default: all)

    [[worlds]]
    scene = "habitat"                  # a scene name, a mesh or a panorama file (relative to the spec)
    scale = 1.0                        # metres per file unit
    up = "z"                           # the file's up axis: z, or y
    eye_height_m = 0.01

    [[route_sets]]
    paths = "routes/*.csv"             # a folder or a glob of route files (CSV, trial logs)
    # or: curved = {seeds = [0, 1, 2], length_m = 10}

    [models.antcar]
    amplitude_deg = [10, 20, 30]       # a list is a grid axis; a number is fixed
    "eye.cols" = [25, 50]              # eye.* keys set the eye; learn_spacing_m the learning walk's spacing
    [models.perfect_memory]

Every combination of world x route x model x grid point x release x seed x protocol is one `Run`, named by a
hash of its contents (`run_id`), so a rerun of the same spec finds the runs already done.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import tomllib
from dataclasses import asdict, dataclass, field
from pathlib import Path

from antarium.ant.experiment.inputs import RouteInput, WorldSpec, eye_z, load_route, route_files, world_geometry
from antarium.ant.metrics import ARDIN_ERROR_DISTANCE_M
from antarium.ant.routes import curved_route

#: protocol -> put-back distance (m): Ardin et al. 2016 put the ant back at 20 cm and count an error; Antcar
#: (Gattaux et al. 2025) never puts it back
PROTOCOLS = {"ardin": ARDIN_ERROR_DISTANCE_M, "antcar": math.inf}
#: metrics of each run (columns of the results table; see docs/virtual_ant.md, "Experiments at scale")
METRICS = ("lateral_median_m", "lateral_mad_m", "angular_median_deg", "angular_mad_deg", "arrived", "errors",
           "decisions", "distance_m", "ms_per_decision_model", "ms_per_decision_loop", "memory_bytes",
           "learned_views")
SPECIAL_KEYS = ("learn_spacing_m",)


class SpecError(ValueError):
    """A spec that cannot be expanded: one line naming the key, what was wrong and what is allowed."""


@dataclass(frozen=True)
class Run:
    """One run: a model with its parameters learns a route in a world and is released on it."""

    world: WorldSpec
    route_set: str
    route: str                     # route name (file stem or curved:SEED)
    route_source: str              # path of the route file, or curved:SEED:LENGTH
    model: str
    params: tuple                  # sorted (key, value) pairs: model parameters, eye.* and learn_spacing_m
    lateral_cm: float
    heading_deg: float
    seed: int
    protocol: str
    face_size: int
    max_decisions: int
    eye_z_m: float
    route_heading_deg: float = 0.0   # the route file's release heading minus the route's own (deg, CCW)

    @property
    def run_id(self) -> str:
        text = json.dumps(asdict(self), sort_keys=True, default=str)
        return hashlib.sha1(text.encode()).hexdigest()[:16]

    @property
    def condition(self) -> str:
        """What the run's repetitions (routes, seeds) share: world, model, parameters, release, protocol."""
        p = ",".join(f"{k}={v}" for k, v in self.params)
        return (f"{self.world.name}/{self.model}[{p}]/release {self.lateral_cm:g} cm {self.heading_deg:g} deg/"
                f"{self.protocol}")


@dataclass
class Experiment:
    runs: list[Run]
    metrics: tuple[str, ...]
    routes: dict[tuple[str, str], RouteInput] = field(default_factory=dict)


def _list(value, key: str, kind) -> list:
    values = value if isinstance(value, list) else [value]
    for v in values:
        if not isinstance(v, kind) or isinstance(v, bool) and kind is not bool:
            raise SpecError(f"{key}: expected {kind.__name__ if isinstance(kind, type) else 'a value'}(s), "
                            f"got {v!r}")
    return values


def _grid(kind: str, table: dict) -> list[tuple]:
    from antarium.ant.eye import EyeParams
    from antarium.ant.models import MODELS

    params_cls = MODELS[kind][1]
    allowed = set(params_cls.__dataclass_fields__) | {f"eye.{k}" for k in EyeParams.__dataclass_fields__}
    allowed |= set(SPECIAL_KEYS)
    axes = []
    for key, value in table.items():
        if key not in allowed:
            raise SpecError(f"models.{kind}: unknown parameter {key!r}; allowed: {', '.join(sorted(allowed))}")
        values = value if isinstance(value, list) else [value]
        if not values:
            raise SpecError(f"models.{kind}.{key}: an empty list gives no runs")
        axes.append([(key, v) for v in values])
    return [tuple(sorted(combo)) for combo in itertools.product(*axes)] if axes else [()]


def _route_set(i: int, table: dict, base: Path) -> tuple[str, list[RouteInput]]:
    if not isinstance(table, dict):
        raise SpecError(f"route_sets[{i}] must be a table with paths = \"...\" or curved = {{...}}")
    name = table.get("name")
    if "paths" in table:
        files = route_files(table["paths"], base)
        return name or str(table["paths"]), [load_route(f) for f in files]
    if "curved" in table:
        c = table["curved"]
        seeds = _list(c.get("seeds", [0]), f"route_sets[{i}].curved.seeds", int)
        length = float(c.get("length_m", 10.0))
        if not length > 0:
            raise SpecError(f"route_sets[{i}].curved.length_m must be > 0 m, got {length}")
        return name or f"curved{length:g}m", [RouteInput(f"curved:{s}", f"curved:{s}:{length}",
                                                         curved_route(s, length=length)) for s in seeds]
    raise SpecError(f"route_sets[{i}]: give paths = \"folder or glob\" or curved = {{seeds = [...], length_m = ...}}")


def _world(i: int, table: dict, base: Path) -> WorldSpec:
    if not isinstance(table, dict) or "scene" not in table:
        raise SpecError(f"worlds[{i}] must be a table with scene = \"habitat\" or a mesh/panorama file")
    t = dict(table)
    scene = str(t.pop("scene"))
    if Path(scene).suffix and not Path(scene).is_absolute():
        scene = str((base / scene).resolve())
    kw = {k: t.pop(k) for k in ("name", "scale", "up", "eye_height_m") if k in t}
    return WorldSpec(scene, params=tuple(sorted(t.items())), **kw)


def load_spec(path: str | Path) -> Experiment:
    """Read a spec file and expand it into runs; checks every route against every world first."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"experiment spec {str(path)!r} not found")
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"{path}: not valid TOML ({exc})") from None
    return expand(data, path.parent)


def expand(data: dict, base: Path = Path(".")) -> Experiment:
    """Runs of a spec's tables (see the module docstring); paths relative to `base`."""
    from antarium.ant.models import MODELS

    unknown = set(data) - {"experiment", "worlds", "route_sets", "models"}
    if unknown:
        raise SpecError(f"unknown spec table(s) {', '.join(sorted(unknown))}; allowed: experiment, worlds, "
                        f"route_sets, models")
    exp = dict(data.get("experiment", {}))
    protocols = _list(exp.pop("protocols", ["ardin"]), "experiment.protocols", str)
    for p in protocols:
        if p not in PROTOCOLS:
            raise SpecError(f"experiment.protocols: unknown {p!r}; allowed: {', '.join(PROTOCOLS)}")
    seeds = _list(exp.pop("seeds", [0]), "experiment.seeds", int)
    releases = exp.pop("releases", [{"lateral_cm": 0.0, "heading_deg": 0.0}])
    releases = [(float(r.get("lateral_cm", 0.0)), float(r.get("heading_deg", 0.0))) for r in releases]
    face_size = int(exp.pop("face_size", 64))
    max_decisions = int(exp.pop("max_decisions", 0))
    eye = exp.pop("eye", {})
    metrics = tuple(exp.pop("metrics", METRICS))
    bad = [m for m in metrics if m not in METRICS]
    if bad:
        raise SpecError(f"experiment.metrics: unknown {bad}; allowed: {', '.join(METRICS)}")
    if exp:
        raise SpecError(f"experiment: unknown key(s) {', '.join(sorted(exp))}; allowed: protocols, seeds, releases, "
                        f"face_size, max_decisions, eye, metrics")
    worlds = [_world(i, w, base) for i, w in enumerate(data.get("worlds", [{"scene": "habitat"}]))]
    sets = [_route_set(i, t, base) for i, t in enumerate(data.get("route_sets", []))]
    if not sets:
        raise SpecError("the spec needs at least one [[route_sets]] (paths = \"routes/*.csv\" or curved = {...})")
    models = data.get("models", {})
    if not models:
        raise SpecError(f"the spec needs at least one [models.<kind>] table; kinds: {', '.join(MODELS)}")
    grids = {}
    for kind, table in models.items():
        if kind not in MODELS:
            raise SpecError(f"models: unknown model {kind!r}; allowed: {', '.join(MODELS)}")
        eye_table = {f"eye.{k}": v for k, v in eye.items()}
        grids[kind] = _grid(kind, {**eye_table, **(table or {})})
    runs, routes = [], {}
    for world in worlds:
        geometry = world_geometry(world)
        for set_name, inputs in sets:
            for ri in inputs:
                z = eye_z(world, ri.route, geometry)
                routes[(set_name, ri.name)] = ri
                extra = 0.0
                if ri.release_heading is not None:
                    extra = math.degrees(math.remainder(ri.release_heading - float(ri.route.at([0.0])[1][0]),
                                                        math.tau))
                for kind, grid in grids.items():
                    for params, (lat, hdg), seed, protocol in itertools.product(grid, releases, seeds, protocols):
                        runs.append(Run(world, set_name, ri.name, ri.source, kind, params, lat, hdg, seed,
                                        protocol, face_size, max_decisions, z, extra))
    ids = [r.run_id for r in runs]
    if len(set(ids)) != len(ids):
        raise SpecError("the spec names the same run twice (a repeated route, seed or parameter value)")
    return Experiment(runs, metrics, routes)
