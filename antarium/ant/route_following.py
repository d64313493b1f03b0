"""Experiments with the virtual ant, as the papers do them: learn a route, follow it, evaluate over many routes.

These functions back `antarium ant learn | run | evaluate | demo` and the examples; each run leaves an HDF5
trial log (the frame loop's own), a picture of the learned and followed paths and the familiarity traces.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from antarium.ant.agent import Track, follow_route, learning_walk
from antarium.ant.eye import EyeParams
from antarium.ant.metrics import ARDIN_ERROR_DISTANCE_M, json_text, median_mad, memory_pi_error
from antarium.ant.models import make_model
from antarium.ant.routes import Route, RouteError, curved_route
from antarium.ant.storage import mbon_bytes, save_model
from antarium.ant.world import EYE_HEIGHT_M, virtual_rig
from antarium.plots.ant import plot_paths, plot_traces, scene_top_view

#: metres between learned views: Antcar learns continuously (every frame of a 1 cm/frame walk), Ardin and
#: perfect memory at intervals
LEARN_SPACING_M = {"antcar": 0.01, "ardin": 0.04, "perfect_memory": 0.04}
#: the eye each model sees with. The MB models' are ours, not the papers': a gain control per elevation row after
#: the Sobel filter (`eye.row_gain_control`), and for Antcar photoreceptor compression (gamma 0.25), so that the
#: nearby grass and stones, not the far field alone, decide which KCs fire (docs/virtual_ant.md, "Models")
MODEL_EYES = {"antcar": EyeParams(gamma=0.25, row_gain=True), "ardin": EyeParams(row_gain=True),
              "perfect_memory": EyeParams()}
#: model parameters of the route-following experiments, unless given: Antcar's oscillation amplitude A = 20 deg
#: is ours (the paper's 45 deg is the model's default; docs/virtual_ant.md, "Models")
MODEL_PARAMS = {"antcar": {"amplitude_deg": 20.0}, "ardin": {}, "perfect_memory": {}}
#: Antcar learns its nest place views on the first and its feeder views on the last this many metres of the route
PLACE_LENGTH_M = 0.05
#: the ant has arrived within this distance of the route's end (m)
ARRIVE_RADIUS_M = 0.10
#: cube-face side the ant's rig renders with: 1.8 deg texels, finer than the eye's 4.4 deg acceptance and
#: several times faster on a software GL than the dome's default (192)
FACE_SIZE = 64
#: the demo's route: short, so that learning and following take seconds
DEMO_ROUTE_LENGTH_M = 1.5
DEMO_ROUTE_SEED = 1


def parse_route(spec: str, length: float = 10.0) -> Route:
    """A route from `curved:SEED` (seeded curved route of `length` m from the origin), a route file (`Route.load`:
    CSV/whitespace x_m, y_m[, heading_deg]) or an earlier trial log (.h5: the pose's x, y of every frame)."""
    if spec.startswith("curved:"):
        try:
            seed = int(spec.split(":", 1)[1])
        except ValueError:
            seed = -1
        if seed < 0:
            raise RouteError(f"route {spec!r}: use curved:SEED with an integer seed >= 0")
        return curved_route(seed, length=length)
    path = Path(spec)
    if not path.is_file():
        raise FileNotFoundError(f"route file {spec!r} not found (or use curved:SEED)")
    if path.suffix.lower() in (".h5", ".hdf5"):
        return route_from_log(path)
    return Route.load(path)


def route_from_log(path: str | Path, min_step: float = 0.005) -> Route:
    """The path walked in a trial log: pose positions (m) of its frames, thinned to steps >= `min_step`."""
    from antarium.trial_log import read_table

    frames = read_table(path, "frames")
    xy = np.stack([frames["x"], frames["y"]], axis=1).astype(np.float64)
    if len(xy) == 0:
        raise RouteError(f"{path}: the trial log holds no frames, so no path")
    keep = [0]
    for i in range(1, len(xy)):
        if np.hypot(*(xy[i] - xy[keep[-1]])) >= min_step:
            keep.append(i)
    return Route(xy[keep])


@dataclass
class TrialOutcome:
    """One closed-loop run: its summary figures, where its files are, and its timing."""

    model: str
    route: str
    summary: dict[str, Any]
    seconds_per_decision: float       # wall time per decision: frame (render, encode, emulate) + eye + model
    model_ms_per_decision: float      # the model's `decide` alone
    learned_views: int
    memory_bytes: dict[str, int]
    pi_error: float                   # Antcar's PI_error (eq. 11-12) over every 10th learned view; NaN otherwise
    log: str | None
    picture: str | None


def _timed_decide(model) -> list:
    """Wrap `model.decide` to accumulate the time it takes; returns a list [seconds, calls]."""
    acc = [0.0, 0]
    decide = model.decide

    def timed(view):
        t0 = time.perf_counter()
        cmd = decide(view)
        acc[0] += time.perf_counter() - t0
        acc[1] += 1
        return cmd

    model.decide = timed
    return acc


def _decision_limit(model, route: Route) -> int:
    step = getattr(model.params, "step", None) or model.params.k_v
    return int(math.ceil(3.0 * route.length / step)) + 10


def _follow(ant, route: Route, max_decisions: int, start_offset, progress, put_back: float = ARDIN_ERROR_DISTANCE_M):
    """follow_route with timing: (FollowResult, wall seconds per decision, model ms per decision)."""
    model = ant.model
    acc = _timed_decide(model)
    ant.loop.event("ant_release", start_offset=list(start_offset))
    t0 = time.perf_counter()
    try:
        result = follow_route(ant, route, max_decisions, ARRIVE_RADIUS_M, put_back_distance=put_back,
                              start_offset=start_offset, progress=progress)
    finally:
        del model.decide
    wall = time.perf_counter() - t0
    return result, wall / max(1, result.summary.decisions), 1e3 * acc[0] / max(1, acc[1])


def _outputs(out: Path | None, name: str, route: Route, kind: str, track: Track, top) -> str | None:
    if out is None:
        return None
    plot_traces(out / f"{name}_traces.png", track, title=f"{name}: model signals")
    return str(plot_paths(out / f"{name}_paths.png", route, {kind: track}, title=f"{name}: learned and followed",
                          top=top))


def train_and_follow(kind: str, route: Route, out_dir: str | Path | None, name: str, scene: Any = "habitat",
                     model_params: dict | None = None, tether: str = "free_yaw", learn_spacing: float | None = None,
                     max_decisions: int | None = None, start_offset: tuple[float, float] = (0.0, 0.0),
                     eye_params: EyeParams | None = None, progress=None, save: bool = True,
                     face_size: int = FACE_SIZE, put_back: float = ARDIN_ERROR_DISTANCE_M,
                     eye_height: float = EYE_HEIGHT_M, renderer: Any = None) -> tuple[TrialOutcome, Track]:
    """Learn `route` with a fresh `kind` model by a learning walk, then follow it in closed loop.

    eye_height: the eye's z in the world (m); renderer: one to reuse (see `virtual_rig`).
    Writes `<name>.h5` (trial log of the whole session), `<name>_paths.png`, `<name>_traces.png` and
    `<name>_model.npz` into `out_dir` (nothing when it is None).
    """
    eye_params = eye_params or MODEL_EYES[kind]
    model = make_model(kind, eye_params.n_pn, **{**MODEL_PARAMS[kind], **(model_params or {})})
    out = Path(out_dir) if out_dir is not None else None
    log_path = out / f"{name}.h5" if out is not None else None
    spacing = LEARN_SPACING_M[kind] if learn_spacing is None else learn_spacing
    with virtual_rig(model, scene=scene, eye_params=eye_params, tether=tether, log_path=log_path,
                     log_metadata={"route": route.points.tolist(), "model": kind},
                     renderer_kwargs={"face_size": face_size}, eye_height=eye_height, renderer=renderer) as ant:
        ant.loop.event("ant_learning_walk", spacing=spacing, route_length=route.length)
        kept: list = []
        learning_walk(ant, route, spacing, place_length=PLACE_LENGTH_M, progress=progress, keep=kept)
        result, wall, model_ms = _follow(ant, route, max_decisions or _decision_limit(model, route), start_offset,
                                         progress, put_back)
        top = scene_top_view(ant.loop.renderer.scene)
    picture = _outputs(out, name, route, kind, result.track, top)
    if out is not None and save:
        save_model(out / f"{name}_model.npz", model, eye_params, route.points,
                   scene=scene if isinstance(scene, str) else None)
    pi = memory_pi_error(model, kept) if hasattr(model, "lambda_diff") else math.nan
    outcome = TrialOutcome(kind, name, asdict(result.summary), wall, model_ms, model.learned_views,
                           mbon_bytes(model), pi, str(log_path) if log_path else None, picture)
    return outcome, result.track


def follow_saved(model, eye_params: EyeParams, route: Route, out_dir: str | Path, name: str = "run",
                 scene: Any = "habitat", tether: str = "free_yaw", max_decisions: int | None = None,
                 start_offset: tuple[float, float] = (0.0, 0.0), progress=None,
                 face_size: int = FACE_SIZE) -> tuple[TrialOutcome, Track]:
    """Release an already trained model on `route` in closed loop; writes `<name>.h5`, pictures, `<name>.json`."""
    out = Path(out_dir)
    log_path = out / f"{name}.h5"
    with virtual_rig(model, scene=scene, eye_params=eye_params, tether=tether, log_path=log_path,
                     log_metadata={"route": route.points.tolist(), "model": model.kind},
                     renderer_kwargs={"face_size": face_size}) as ant:
        result, wall, model_ms = _follow(ant, route, max_decisions or _decision_limit(model, route), start_offset,
                                         progress)
        top = scene_top_view(ant.loop.renderer.scene)
    picture = _outputs(out, name, route, model.kind, result.track, top)
    outcome = TrialOutcome(model.kind, name, asdict(result.summary), wall, model_ms, model.learned_views,
                           mbon_bytes(model), math.nan, str(log_path), picture)
    (out / f"{name}.json").write_text(json_text(asdict(outcome)))
    return outcome, result.track


def table(outcomes: list[TrialOutcome]) -> str:
    """A markdown table, one row per model: median +- MAD over routes of each route's median lateral / angular
    error, arrivals, Ardin errors per route (mean), time per decision, memory, median PI_error."""
    rows = ["| model | routes | lateral error median ± MAD (cm) | angular error median ± MAD (°) | "
            "arrived (without put-back) | "
            "errors per route (Ardin, > 20 cm) | ms per decision (model) | ms per decision (closed loop) | "
            "memory per route | PI_error |",
            "|---|---|---|---|---|---|---|---|---|---|"]
    for kind in dict.fromkeys(o.model for o in outcomes):
        mine = [o for o in outcomes if o.model == kind]
        lat = median_mad([o.summary["lateral_median"] for o in mine])
        ang = median_mad([o.summary["angular_median_deg"] for o in mine])
        arrived = sum(o.summary["arrived"] for o in mine)
        clean = sum(o.summary["arrived"] and o.summary["errors"] == 0 for o in mine)
        errors = np.mean([o.summary["errors"] for o in mine])
        mem = mine[0].memory_bytes
        mem_text = (f"{max(mem.get('left', 0), mem.get('familiarity', 0))} B per MBON" if "views" not in mem
                    else f"{int(np.mean([o.memory_bytes['views'] for o in mine]))} B of views")
        rows.append(
            f"| {kind} | {len(mine)} | {100 * lat[0]:.1f} ± {100 * lat[1]:.1f} | {ang[0]:.1f} ± {ang[1]:.1f} | "
            f"{arrived}/{len(mine)} ({clean}/{len(mine)}) | {errors:.1f} | "
            f"{np.mean([o.model_ms_per_decision for o in mine]):.2f} | "
            f"{1e3 * np.mean([o.seconds_per_decision for o in mine]):.1f} | {mem_text} | "
            f"{_pi_text([o.pi_error for o in mine])} |")
    return "\n".join(rows)


def _pi_text(values) -> str:
    v = np.asarray(values, np.float64)
    return "—" if not np.isfinite(v).any() else f"{100 * np.nanmedian(v):.1f} %"


def write_outcomes(out_dir: Path, outcomes: list[TrialOutcome], extra: dict | None = None) -> str:
    text = table(outcomes)
    (out_dir / "evaluation.md").write_text(text + "\n")
    payload = {"outcomes": [asdict(o) for o in outcomes], **(extra or {})}
    (out_dir / "evaluation.json").write_text(json_text(payload))
    return text


def evaluate(out_dir: str | Path, n_routes: int = 10, length: float = 10.0, kinds=("antcar", "ardin",
             "perfect_memory"), seed: int = 0, scene: Any = "habitat", progress_factory=None,
             put_back: float = ARDIN_ERROR_DISTANCE_M) -> str:
    """Each model learns and follows `n_routes` seeded curved routes of `length` m; returns the markdown table.
    `put_back`: Ardin's put-back distance (m; math.inf: never put back, Antcar's own protocol).

    Per route and model: a trial log, a picture of the paths, traces; `evaluation.md` / `.json` sum it up.
    """
    from antarium.renderers import build_scene

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    top = scene_top_view(build_scene(scene))
    outcomes: list[TrialOutcome] = []
    tracks: dict[int, dict[str, Track]] = {}
    for i in range(n_routes):
        route = curved_route(seed + i, length=length)
        route.save(out / f"route{i:02d}.csv")
        for kind in kinds:
            bar = progress_factory(f"route {i} {kind}") if progress_factory is not None else None
            outcome, track = train_and_follow(kind, route, out, f"route{i:02d}_{kind}", scene=scene,
                                              progress=bar.update if bar is not None else None, save=False,
                                              put_back=put_back)
            if bar is not None:
                bar.close()
            outcomes.append(outcome)
            tracks.setdefault(i, {})[kind] = track
            write_outcomes(out, outcomes, {"n_routes": n_routes, "length_m": length, "seed": seed,
                                           "put_back_m": put_back if math.isfinite(put_back) else None})
        plot_paths(out / f"route{i:02d}_all.png", route, tracks[i], title=f"route {i}: learned and followed", top=top)
    return write_outcomes(out, outcomes, {"n_routes": n_routes, "length_m": length, "seed": seed,
                                          "put_back_m": put_back if math.isfinite(put_back) else None})


#: the stem of every file `demo` writes (virtual_ant.h5, virtual_ant_paths.png, ...)
DEMO_NAME = "virtual_ant"


def demo(out_dir: str | Path, scene: Any = "habitat", progress=None) -> TrialOutcome:
    """One call for `make demo`: Antcar learns a short curved route, is released 3 cm off it and turned 15 deg,
    and follows it in closed loop. Writes `virtual_ant.h5` (trial log), `virtual_ant_paths.png` (learned and
    followed path), `virtual_ant_traces.png`, `virtual_ant_model.npz` and `virtual_ant.json` into `out_dir`."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    route = curved_route(DEMO_ROUTE_SEED, length=DEMO_ROUTE_LENGTH_M)
    outcome, _ = train_and_follow("antcar", route, out, DEMO_NAME, scene=scene,
                                  start_offset=(0.03, math.radians(15)), progress=progress)
    (out / f"{DEMO_NAME}.json").write_text(json_text(asdict(outcome)))
    return outcome
