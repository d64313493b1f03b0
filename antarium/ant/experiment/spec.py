"""An experiment spec (TOML) and its expansion into runs.

    [experiment]
    protocols = ["ardin"]              # ardin: put back at 20 cm and counted; antcar: never put back
    seeds = [0, 1]                     # the mushroom bodies' random PN->KC wiring (a model without one runs once)
    releases = [{lateral_cm = 0, heading_deg = 0}, {lateral_cm = 5, heading_deg = 20}]
    face_size = 64                     # the renderer's cube-face side (an integer 55..2048; runs and rows
                                       # carry the side the renderer draws: 55 -> 56, `mip_face_size`)
    max_decisions = 0                  # 0: three times the route length in steps
    eye = {cols = 50, rows = 16}       # eye parameters over each model's own (optional)
    metrics = ["errors", "lateral_median_m"]   # the summary's metrics (default: all)

    [[worlds]]
    scene = "habitat"                  # a scene name, a mesh or a panorama file (relative to the spec)
    name = "habitat_seed7"             # the world's name in the results (default: the scene's file stem)
    seed = 7                           # other keys are the scene's own parameters
    scale = 1.0                        # metres per file unit
    up = "z"                           # the file's up axis: z, or y
    eye_height_m = 0.01

    [[route_sets]]
    paths = "routes/*.csv"             # a folder or a glob (** recurses) of route files (CSV, logs), from the spec
    # or: curved = {seeds = [0, 1, 2], length_m = 10}

    [models.antcar]
    amplitude_deg = [10, 20, 30]       # a list is a grid axis; a number is fixed
    "eye.cols" = [25, 50]              # eye.* keys set the eye; learn_spacing_m the learning walk's spacing
    [models.perfect_memory]

Every value is checked against its declaration (`_schema`: the spec's own keys here, the models' and the eye's
parameters from their dataclasses' field types) before anything is built: a wrong type, a value out of range,
an unknown key or an empty list is a SpecError naming the key, the value and what is allowed.

Every combination of world x route x model x grid point x release x seed x protocol is one `Run`, named by a
hash of its contents (`run_id`: the world and the SHA-1 of its file and the files that loads, `scene_digest`;
the route file's absolute path and the SHA-1 of its points, the parameters, face_size, max_decisions, the eye's
z, ...), so a rerun of the same spec finds the runs already done, and an edited route or world file is a new
run. A run's condition (what its repetitions over routes and seeds share) is its world, route set, model,
parameters, release and protocol.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import itertools
import json
import math
import tomllib
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path

from antarium.ant import ROUTE_MODELS
from antarium.ant.experiment.inputs import (
    UP_AXES,
    RouteInput,
    WorldSpec,
    eye_z,
    load_route,
    route_files,
    route_name,
    scene_digest,
    world_geometry,
)
from antarium.ant.metrics import ARDIN_ERROR_DISTANCE_M
from antarium.ant.routes import curved_route
from antarium.core.numbers import as_real

#: protocol -> put-back distance (m): Ardin et al. 2016 put the ant back at 20 cm and count an error; Antcar
#: (Gattaux et al. 2025) never puts it back
PROTOCOLS = {"ardin": ARDIN_ERROR_DISTANCE_M, "antcar": math.inf}
#: metrics of each run (columns of the results table; see docs/virtual_ant.md, "Experiments at scale")
METRICS = ("lateral_median_m", "lateral_mad_m", "angular_median_deg", "angular_mad_deg", "arrived", "errors",
           "decisions", "distance_m", "ms_per_decision_model", "ms_per_decision_loop", "memory_bytes",
           "learned_views")


class SpecError(ValueError):
    """A spec that cannot be expanded: one line naming the key, what was wrong and what is allowed."""


@dataclass(frozen=True)
class Run:
    """One run: a model with its parameters learns a route in a world and is released on it."""

    world: WorldSpec
    route_set: str
    route: str                     # route name (path relative to the set's folder, no suffix; or curved:SEED)
    route_source: str              # absolute path of the route file, or curved:SEED:LENGTH
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
    route_sha1: str = ""             # SHA-1 of the route's points (`inputs.route_digest`)

    @property
    def run_id(self) -> str:
        text = json.dumps(asdict(self), sort_keys=True, default=str)
        return hashlib.sha1(text.encode()).hexdigest()[:16]

    @property
    def condition(self) -> str:
        """What the run's repetitions (routes, seeds) share: world, route set, model, parameters, release,
        protocol."""
        p = ",".join(f"{k}={v}" for k, v in self.params)
        return (f"{self.world.name}/{self.route_set}/{self.model}[{p}]/release {self.lateral_cm:g} cm "
                f"{self.heading_deg:g} deg/{self.protocol}")

    def columns(self) -> dict:
        """What the run is, as columns of its results row: its id and condition, world, route set, route (name
        and source), model, `param.<key>`s, release, seed, protocol, face_size, max_decisions and eye_z_m (the
        eye's z in the world's own coordinates, m)."""
        return {"run_id": self.run_id, "condition": self.condition, "world": self.world.name,
                "route_set": self.route_set, "route": self.route, "route_source": self.route_source,
                "model": self.model, "lateral_cm": self.lateral_cm, "heading_deg": self.heading_deg,
                "seed": self.seed, "protocol": self.protocol, "face_size": self.face_size,
                "max_decisions": self.max_decisions, "eye_z_m": self.eye_z_m,
                **{f"param.{k}": v for k, v in self.params}}


@dataclass
class Experiment:
    runs: list[Run]
    metrics: tuple[str, ...]
    routes: dict[tuple[str, str], RouteInput] = field(default_factory=dict)


class Check:
    """A kind of spec value, declared once. Each kind below is a callable: `check(key, value)` returns the value
    normalised (numbers that are equal are equal: 10 and 10.0 of a float parameter are both 10.0) or raises
    SpecError naming the key, the value and what is allowed (`fail`, with the kind's `what`)."""

    what = "a value"

    def fail(self, key: str, value):
        shown = repr(value)
        raise SpecError(f"{key}: expected {self.what}, got {shown if len(shown) <= 60 else shown[:57] + '...'}")


@dataclass(frozen=True)
class Integer(Check):
    """An integer (not a float, not a boolean), >= `min` and <= `max` when given."""

    min: int | None = None
    max: int | None = None

    @property
    def what(self) -> str:
        bounds = [f">= {self.min}"] * (self.min is not None) + [f"<= {self.max}"] * (self.max is not None)
        return " and ".join(["an integer " + bounds[0], *bounds[1:]]) if bounds else "an integer"

    def __call__(self, key: str, value) -> int:
        if (not (isinstance(value, int) and not isinstance(value, bool)) or self.min is not None and value < self.min
                or self.max is not None and value > self.max):
            self.fail(key, value)
        return int(value)


@dataclass(frozen=True)
class Number(Check):
    """A finite number (an integer or a float, not a boolean), > `gt` when given; normalised to a float."""

    gt: float | None = None

    @property
    def what(self) -> str:
        return "a finite number" + (f" > {self.gt:g}" if self.gt is not None else "")

    def __call__(self, key: str, value) -> float:
        number = as_real(value)
        if not math.isfinite(number) or self.gt is not None and not number > self.gt:
            self.fail(key, value)
        return number


@dataclass(frozen=True)
class Boolean(Check):
    what = "true or false"

    def __call__(self, key: str, value) -> bool:
        if not isinstance(value, bool):
            self.fail(key, value)
        return value


@dataclass(frozen=True)
class String(Check):
    """A string, one of `choices` when given."""

    choices: tuple[str, ...] = ()

    @property
    def what(self) -> str:
        return f"one of {', '.join(self.choices)}" if self.choices else "a string"

    def __call__(self, key: str, value) -> str:
        if not isinstance(value, str) or self.choices and value not in self.choices:
            self.fail(key, value)
        return value


@dataclass(frozen=True)
class Scalar(Check):
    """A number, a string or a boolean (a parameter whose type the spec does not know: an integer stays one)."""

    what = "a finite number, a string or true/false"

    def __call__(self, key: str, value):
        if isinstance(value, bool | str | int) or isinstance(value, float) and math.isfinite(value):
            return value
        self.fail(key, value)


@dataclass(frozen=True)
class ListOf(Check):
    """A non-empty list (an empty one gives no runs) of `item`s, each given once."""

    item: Check

    @property
    def what(self) -> str:
        return f"a list, each item {self.item.what}"

    def __call__(self, key: str, value) -> list:
        if not isinstance(value, list):
            self.fail(key, value)
        if not value:
            raise SpecError(f"{key}: an empty list gives no runs; give at least one item ({self.item.what})")
        out = []
        for j, v in enumerate(value):
            v = self.item(f"{key}[{j}]", v)
            if v in out:
                i = out.index(v)
                raise SpecError(f"{key}[{j}]: {value[j]!r} repeats {key}[{i}] = {value[i]!r} (the same value); "
                                "give each once")
            out.append(v)
        return out


@dataclass(frozen=True)
class Axis(Check):
    """A grid axis: a list of `item`s (ListOf), or one item (a fixed value); always a list."""

    item: Check

    @property
    def what(self) -> str:
        return f"{self.item.what}, or a list of them (a grid axis)"

    def __call__(self, key: str, value) -> list:
        return ListOf(self.item)(key, value) if isinstance(value, list) else [self.item(key, value)]


@dataclass(frozen=True)
class Table(Check):
    """A table of the keys `fields` (each its Check; others refused, or checked by `extra` when given), with
    `defaults` for the keys not given and `required` keys."""

    fields: dict
    defaults: dict = field(default_factory=dict)
    required: tuple[str, ...] = ()
    extra: Check | None = None
    noun: str = "key"

    @property
    def what(self) -> str:
        return f"a table of {', '.join(self.fields)}"

    def __call__(self, key: str, value) -> dict:
        if not isinstance(value, dict):
            self.fail(key or "spec", value)
        out = dict(self.defaults)
        for k, v in value.items():
            sub = f"{key}.{k}" if key else k
            if k in self.fields:
                out[k] = self.fields[k](sub, v)
            elif self.extra is not None:
                out[k] = self.extra(sub, v)
            else:
                raise SpecError(f"{key or 'spec'}: unknown {self.noun} {k!r}; allowed: {', '.join(self.fields)}")
        for k in self.required:
            if k not in value:
                raise SpecError(f"{key}: {k} is required ({self.fields[k].what})")
        return out


#: a model parameter's or an eye parameter's declared field type -> its check
_FIELD_CHECKS = {"int": Integer(), "float": Number(), "bool": Boolean(), "str": String()}


def declared(params_cls, exclude: tuple[str, ...] = ()) -> dict[str, Check]:
    """Checks of a parameter dataclass's fields, from their declared types (a type the spec does not know takes
    any number, string or boolean; the model checks it when it is made)."""
    out = {}
    for f in fields(params_cls):
        if f.name not in exclude:
            t = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", "")
            out[f.name] = _FIELD_CHECKS.get(t, Scalar())
    return out


@functools.cache
def _schema() -> Table:
    """The spec's declaration: every key, its type, its range and its default."""
    from antarium.ant.eye import EyeParams
    from antarium.ant.models import MODELS
    from antarium.renderers.renderer import MAX_FACE_SIZE, smallest_face_size

    eye = {k: Axis(c) for k, c in declared(EyeParams).items()}
    special = {"learn_spacing_m": Axis(Number(gt=0.0))}
    models = {kind: Table({**{k: Axis(c) for k, c in declared(MODELS[kind][1], exclude=("seed",)).items()},
                           **{f"eye.{k}": c for k, c in eye.items()}, **special}, noun="parameter")
              for kind in ROUTE_MODELS}
    release = Table({"lateral_cm": Number(), "heading_deg": Number()},
                    defaults={"lateral_cm": 0.0, "heading_deg": 0.0})
    experiment = Table(
        {"protocols": ListOf(String(tuple(PROTOCOLS))), "seeds": ListOf(Integer(min=0)), "releases": ListOf(release),
         "face_size": Integer(min=smallest_face_size(), max=MAX_FACE_SIZE), "max_decisions": Integer(min=0),
         "eye": Table(eye, noun="eye parameter"),
         "metrics": ListOf(String(METRICS))},
        defaults={"protocols": ["ardin"], "seeds": [0], "releases": [{"lateral_cm": 0.0, "heading_deg": 0.0}],
                  "face_size": 64, "max_decisions": 0, "eye": {}, "metrics": list(METRICS)})
    world = Table({"scene": String(), "name": String(), "scale": Number(gt=0.0), "up": String(UP_AXES),
                   "eye_height_m": Number(gt=0.0)}, required=("scene",), extra=Scalar())
    curved = Table({"seeds": ListOf(Integer(min=0)), "length_m": Number(gt=0.0)},
                   defaults={"seeds": [0], "length_m": 10.0})
    route_set = Table({"name": String(), "paths": String(), "curved": curved})
    return Table({"experiment": experiment, "worlds": ListOf(world), "route_sets": ListOf(route_set),
                  "models": Table(models, noun="model")},
                 defaults={"experiment": experiment("experiment", {}), "worlds": [{"scene": "habitat"}]},
                 noun="table")


def model_args(kind: str, params: tuple, seed: int):
    """(eye parameters, model overrides, learning spacing) of a run of model `kind` with `params` (sorted (key,
    value) tuples): the model's own eye and parameters, then the eye.* keys, model parameters and `seed` (where the
    model has one). Raises ValueError for values out of range (the parameter classes check them)."""
    from antarium.ant.models import MODELS
    from antarium.ant.route_following import MODEL_EYES, MODEL_PARAMS

    params = dict(params)
    eye = {k[4:]: params.pop(k) for k in list(params) if k.startswith("eye.")}
    spacing = params.pop("learn_spacing_m", None)
    eye_params = dataclasses.replace(MODEL_EYES[kind], **eye)
    overrides = {**MODEL_PARAMS[kind], **params}
    params_cls = MODELS[kind][1]
    if "seed" in params_cls.__dataclass_fields__:
        overrides["seed"] = seed
    params_cls(**overrides)
    return eye_params, overrides, spacing


def _check_models(grids: dict[str, list[tuple]]) -> None:
    """SpecError naming the model table and its values for the first combination a model would refuse when made
    (out of range, e.g. kappa = 2 or eye.gamma = 0): refused when the spec is read, not run by run."""
    for kind, grid in grids.items():
        for params in grid:
            try:
                model_args(kind, params, 0)
            except ValueError as exc:
                values = ", ".join(f"{k} = {v!r}" for k, v in params) or "its defaults"
                raise SpecError(f"[models.{kind}] with {values}: {exc}") from None


def _eye_keys(data: dict) -> dict:
    """`data` with each model table's eye table (TOML reads an unquoted `eye.gamma = ...` as `eye = {gamma = ...}`)
    as its "eye.*" keys; SpecError for a key given both ways."""
    models = data.get("models")
    if not isinstance(models, dict):
        return data
    out = {}
    for kind, table in models.items():
        if isinstance(table, dict) and isinstance(table.get("eye"), dict):
            eye = {f"eye.{k}": v for k, v in table["eye"].items()}
            twice = sorted(set(eye) & set(table))
            if twice:
                raise SpecError(f"models.{kind}: {twice[0]} given twice (as \"{twice[0]}\" and in its eye table)")
            table = {**{k: v for k, v in table.items() if k != "eye"}, **eye}
        out[kind] = table
    return {**data, "models": out}


def _grid(axes: dict[str, list]) -> list[tuple]:
    """Every combination of the axes' values: sorted (key, value) tuples."""
    return [tuple(sorted(combo)) for combo in itertools.product(*([(k, v) for v in vs] for k, vs in axes.items()))]


def _route_set(i: int, table: dict, base: Path) -> tuple[str, list[RouteInput]]:
    key = f"route_sets[{i}]"
    if ("paths" in table) == ("curved" in table):
        raise SpecError(f"{key}: give one of paths = \"folder or glob\" or curved = {{seeds = [...], length_m = ...}}")
    name = table.get("name")
    if "paths" in table:
        folder, files = route_files(table["paths"], base)
        inputs, seen = [], {}
        for f in files:
            n = route_name(f, folder)
            if n in seen:
                raise SpecError(f"{key}.paths = {table['paths']!r}: {seen[n]} and {f} are both route {n!r}; "
                                "rename one, or put them in route sets of their own")
            seen[n] = f
            inputs.append(load_route(f, n))
        return name or table["paths"], inputs
    c = table["curved"]
    length = c["length_m"]
    return name or f"curved{length:g}m", [RouteInput(f"curved:{s}", f"curved:{s}:{length}",
                                                     curved_route(s, length=length)) for s in c["seeds"]]


def _world(table: dict, base: Path) -> WorldSpec:
    t = dict(table)
    scene = t.pop("scene")
    digest = ""
    if Path(scene).suffix:
        if not Path(scene).is_absolute():
            scene = str((base / scene).resolve())
        if Path(scene).is_file():
            digest = scene_digest(scene)
    kw = {k: t.pop(k) for k in ("name", "scale", "up", "eye_height_m") if k in t}
    return WorldSpec(scene, params=tuple(sorted(t.items())), digest=digest, **kw)


def _unique_names(key: str, names: list[str], what: list[str], table: str) -> None:
    """SpecError when two of `names` are the same (naming what they are)."""
    for j, n in enumerate(names):
        if n in names[:j]:
            i = names.index(n)
            raise SpecError(f"{key}[{i}] ({what[i]}) and {key}[{j}] ({what[j]}) are both named {n!r}: their runs "
                            f"would be one condition; give each [[{table}]] its own name = \"...\"")


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
    """Runs of a spec's tables (see the module docstring); paths relative to `base` (the spec's folder), made
    absolute. Raises SpecError for a spec that breaks its declaration (`_schema`)."""
    from antarium.ant.models import MODELS
    from antarium.renderers.renderer import mip_face_size

    base = Path(base).resolve()
    spec = _schema()("", _eye_keys(data))
    exp = spec["experiment"]
    if "route_sets" not in spec:
        raise SpecError("the spec needs at least one [[route_sets]] (paths = \"routes/*.csv\" or curved = {...})")
    if not spec.get("models"):
        raise SpecError(f"the spec needs at least one [models.<kind>] table; kinds: {', '.join(ROUTE_MODELS)}")
    worlds = [_world(w, base) for w in spec["worlds"]]
    _unique_names("worlds", [w.name for w in worlds],
                  [" ".join([w.scene, *(f"{k}={v}" for k, v in w.params)]) for w in worlds], "worlds")
    sets = [_route_set(i, t, base) for i, t in enumerate(spec["route_sets"])]
    _unique_names("route_sets", [name for name, _ in sets],
                  [f"paths = {t['paths']!r}" if "paths" in t else
                   f"curved = {{seeds = {t['curved']['seeds']}, length_m = {t['curved']['length_m']:g}}}"
                   for t in spec["route_sets"]], "route_sets")
    eye = {f"eye.{k}": v for k, v in exp["eye"].items()}
    grids, seeds = {}, {}
    for kind, axes in spec["models"].items():
        grids[kind] = _grid({**eye, **axes})
        # the seed is the model's random wiring: a model without one runs once per condition (seed 0)
        seeds[kind] = exp["seeds"] if "seed" in MODELS[kind][1].__dataclass_fields__ else [0]
    _check_models(grids)
    releases = [(r["lateral_cm"], r["heading_deg"]) for r in exp["releases"]]
    face_size = mip_face_size(exp["face_size"])  # the side the renderer draws (55 -> 56): one run, one record
    runs, routes = [], {}
    for world in worlds:
        geometry = world_geometry(world)
        for set_name, inputs in sets:
            for ri in inputs:
                z = eye_z(world, ri.route, geometry)
                routes[(set_name, ri.name)] = ri
                digest = ri.digest
                extra = 0.0
                if ri.release_heading is not None:
                    extra = math.degrees(math.remainder(ri.release_heading - float(ri.route.at([0.0])[1][0]),
                                                        math.tau))
                for kind, grid in grids.items():
                    for params, (lat, hdg), seed, protocol in itertools.product(grid, releases, seeds[kind],
                                                                                exp["protocols"]):
                        runs.append(Run(world, set_name, ri.name, ri.source, kind, params, lat, hdg, seed,
                                        protocol, face_size, exp["max_decisions"], z, extra, digest))
    ids = [r.run_id for r in runs]
    if len(set(ids)) != len(ids):
        raise SpecError("the spec names the same run twice (a repeated world, route set or route)")
    return Experiment(runs, tuple(exp["metrics"]), routes)
