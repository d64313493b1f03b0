"""`antarium ant learn | run | evaluate | experiment | demo | serve | homing | arena | displace`: the virtual ant on
an emulated rig (no hardware needed)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from antarium.ant import ROUTE_MODELS

HELP = "virtual ant: learn a route, follow it in closed loop, evaluate models over seeded routes"


def _params(pairs: list[str] | None, kind: str) -> dict:
    """--param key=value pairs as overrides of model `kind`'s parameters, each value converted by its field's type
    (`models.parse_params`: bool from true/false/1/0, int integral, float finite, str as given)."""
    from antarium.ant.models import parse_params

    texts: dict[str, str] = {}
    for pair in pairs or ():
        key, sep, value = pair.partition("=")
        if not sep or not key:
            raise ValueError(f"--param wants key=value, got {pair!r}")
        texts[key.strip()] = value.strip()
    return parse_params(kind, texts)


def _positive(option: str, value: float | int, unit: str = "") -> float | int:
    """`value` of `option` when it is finite and > 0 (an int stays an int); else one ValueError naming it."""
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{option} must be > 0{' ' + unit if unit else ''} (leave it out for the default), "
                         f"got {value}")
    return value


def _finite(option: str, value: float, what: str) -> float:
    """`value` of `option` when it is a finite number; else one ValueError naming it and `what` it means."""
    if not math.isfinite(value):
        raise ValueError(f"{option} must be a finite number ({what}), got {value}")
    return value


def _common(p: argparse.ArgumentParser, scene_help: str = "default: habitat") -> None:
    p.add_argument("--scene", default=None, help=f"scene shown by the dome (name or file; {scene_help})")
    p.add_argument("--tether", choices=("free_yaw", "fixed"), default="free_yaw",
                   help="free_yaw: the ant turns inside the dome; fixed: the scene turns (default free_yaw)")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", metavar="ACTION")
    sub.required = True
    p = sub.add_parser("learn", help="walk the ant along a route while its model learns; save the model")
    p.add_argument("--model", choices=ROUTE_MODELS, default="antcar",
                   help="mushroom-body model to train (default antcar)")
    p.add_argument("--route", required=True, help="curved:SEED, a path file (x_m,y_m) or a trial log (.h5)")
    p.add_argument("--length", type=float, default=10.0, help="length of a curved:SEED route (m, default 10)")
    p.add_argument("--spacing", type=float, default=None, help="metres between learned views (model default)")
    p.add_argument("--param", action="append", metavar="KEY=VALUE", help="model parameter, e.g. task=homing")
    p.add_argument("--log", default=None, help="also write the learning walk's trial log here (.h5)")
    p.add_argument("--out", required=True, help="model file to write (.npz)")
    _common(p)
    p = sub.add_parser("run", help="release a trained ant on its route in closed loop; log, pictures, summary")
    p.add_argument("model_file", help="model file written by 'antarium ant learn'")
    p.add_argument("--route", default=None, help="route to judge against (default: the one it learned)")
    p.add_argument("--length", type=float, default=10.0, help="length of a curved:SEED route (m)")
    p.add_argument("--max-decisions", type=int, default=None,
                   help="stop after this many steering decisions (default: the route's own limit)")
    p.add_argument("--lateral-cm", type=float, default=0.0, help="release this far left of the route start (cm)")
    p.add_argument("--heading-deg", type=float, default=0.0, help="release turned this much CCW off the route")
    p.add_argument("--out", required=True, help="folder for run.h5, run_paths.png, run_traces.png, run.json")
    _common(p, "default: the one the model learned in, as its file says, else habitat")
    p = sub.add_parser("evaluate", help="each model learns and follows seeded curved routes; writes a table")
    p.add_argument("--routes", type=int, default=10, help="number of seeded curved routes per model (default 10)")
    p.add_argument("--length", type=float, default=10.0, help="route length (m, default 10)")
    p.add_argument("--models", default=",".join(ROUTE_MODELS), help=f"comma-separated, from {', '.join(ROUTE_MODELS)}")
    p.add_argument("--seed", type=int, default=0, help="seed of the first route")
    p.add_argument("--out", required=True, help="folder for logs, pictures, evaluation.md/.json")
    p.add_argument("--scene", default="habitat", help="scene shown by the dome (name or file; default: habitat)")
    p.add_argument("--put-back-cm", type=float, default=20.0,
                   help="Ardin's protocol: farther than this off the route counts an error and the ant is put "
                        "back (default 20; 0: never, Antcar's own protocol)")
    from antarium.ant.experiment import command as experiment

    experiment.add_arguments(sub.add_parser("experiment", help="expand an experiment spec (TOML) into runs and run "
                                                               "them on Dask, resumably; results table and summary"))
    p = sub.add_parser("demo", help="train on a short route, follow it; log and picture of both paths")
    p.add_argument("--out", default="ant-demo-output",
                   help="folder for the log, the paths picture and the traces (default: ant-demo-output)")
    p.add_argument("--scene", default="habitat", help="scene shown by the dome (name or file; default: habitat)")
    p = sub.add_parser("serve", help="put a trained ant on a served rig (`antarium serve --config`): it hosts the "
                                     "dome, walks through the emulated USB trackball and follows its route")
    p.add_argument("model_file", help="model file written by 'antarium ant learn' (holds its route)")
    p.add_argument("--config", required=True, help="the rig config `antarium serve` runs with (TOML)")
    p.add_argument("--out", required=True, help="folder for served.json and served_paths.png")
    p.add_argument("--lateral-cm", type=float, default=0.0, help="release this far left of the route start")
    p.add_argument("--heading-deg", type=float, default=0.0, help="release turned this much CCW off the route")
    p.add_argument("--max-decisions", type=int, default=None,
                   help="stop after this many steering decisions (default: the route's own limit)")
    p.add_argument("--timeout", type=float, default=30.0,
                   help="seconds to wait for the server and for each of its replies (default 30)")
    p = sub.add_parser("homing", help="Stone 2017's foraging task: random outbound routes, home by CX path "
                                      "integration; pictures and pi_homing_<compass>.json")
    _trips(p)
    p.add_argument("--tether", choices=("free_yaw", "fixed"), default="free_yaw",
                   help="free_yaw: the ant turns on its pin, the dome stands (default); fixed: the scene and its "
                        "polarised sky turn with the ant")
    p.add_argument("--cue-wait-frames", type=int, default=None,
                   help="frames the ant stands still waiting for a sky compass cue, e.g. while the polarisers turn "
                        "after a turn of the scene (default 60; 0: a trip ends at the first decision without one)")
    p = sub.add_parser("arena", help="the cluttered arena: outbound with optic-flow avoidance, home by CX, then "
                                     "by CXMB with the vector memory restored; collisions counted")
    _trips(p)
    p.add_argument("--model", choices=("cxmb", "one_ring"), default="cxmb",
                   help="homing model of the second trip: cxmb (PI + MBONs) or one_ring (+ optic flow)")
    p = sub.add_parser("displace", help="PI vs visual memory: a CXMB ant homes once (its MBONs learn), is put down "
                                        "beside the feeder with its memory restored, and homes for several k")
    p.add_argument("--seed", type=int, default=0, help="outbound route seed (default 0)")
    p.add_argument("--steps", type=int, default=600, help="outbound decisions of 1 cm (default 600)")
    p.add_argument("--lateral-cm", type=float, default=50.0, help="put down this far left of the feeder")
    p.add_argument("--compass", choices=("sky", "ideal"), default="sky",
                   help="sky: read from the dome's polarised UV pixels; ideal: the true heading (default sky)")
    p.add_argument("--scene", default="habitat", help="the world (default habitat)")
    p.add_argument("--out", required=True, help="folder for the pictures and the summary")


def _trips(p: argparse.ArgumentParser) -> None:
    p.add_argument("--seeds", type=int, default=20, help="outbound routes, seeds 0..N-1 (default 20)")
    p.add_argument("--steps", type=int, default=1500, help="outbound decisions of 1 cm (default 1500)")
    p.add_argument("--inbound", type=int, default=None, help="homeward decisions (default: as many as outbound)")
    p.add_argument("--compass", choices=("sky", "ideal", "both"), default="both",
                   help="sky: read from the dome's polarised UV pixels; ideal: the true heading (default both)")
    p.add_argument("--param", action="append", metavar="KEY=VALUE", help="model parameter, e.g. noise=0.05")
    p.add_argument("--out", required=True, help="folder for the pictures and the summary")


def _run_trips(args: argparse.Namespace) -> int:
    from antarium.ant.homing import check_compass, cluttered_arena, pi_homing
    from antarium.ant.metrics import json_text

    if args.seeds < 1 or args.steps < 2 or (args.inbound is not None and args.inbound < 1):
        raise ValueError("--seeds must be >= 1, --steps >= 2 and --inbound >= 1")
    compasses = ("sky", "ideal") if args.compass == "both" else (args.compass,)
    params = _params(args.param, "cx" if args.action == "homing" else args.model)
    for compass in compasses:  # refused before the first compass runs, not after it
        check_compass(params, compass)
    for compass in compasses:
        if args.action == "homing":
            wait = {} if args.cue_wait_frames is None else {"cue_wait_frames": args.cue_wait_frames}
            summary = pi_homing(args.out, range(args.seeds), args.steps, args.inbound, compass, params, echo=print,
                                tether=args.tether, **wait)
        else:
            summary = cluttered_arena(args.out, range(args.seeds), args.steps, args.inbound, compass, args.model,
                                      params, echo=print)
        print(json_text(summary))
    return 0


def _bar(desc: str, total=None):
    """A progress bar on a terminal; none where the output goes to a file or pipe (a log of every step else)."""
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="step", leave=False, disable=None)


def _outcome_line(outcome) -> str:
    """A closed-loop run's figures in one line (cm, degrees, ms)."""
    s = outcome.summary
    return (f"{outcome.model}: lateral error {100 * s['lateral_median']:.1f} ± {100 * s['lateral_mad']:.1f} cm, "
            f"angular {s['angular_median_deg']:.1f} ± {s['angular_mad_deg']:.1f} deg, arrived {s['arrived']}, "
            f"errors {s['errors']}, {s['decisions']} decisions, {1e3 * outcome.seconds_per_decision:.1f} ms each")


def run(args: argparse.Namespace) -> int:
    from antarium.ant import route_following

    if args.action == "learn":
        return _learn(args)
    if args.action == "run":
        return _run(args)
    if args.action == "experiment":
        from antarium.ant.experiment import command

        return command.run(args)
    if args.action in ("homing", "arena"):
        return _run_trips(args)
    if args.action == "displace":
        from antarium.ant.homing import displacement
        from antarium.ant.metrics import json_text

        if args.steps < 2 or args.seed < 0:
            raise ValueError(f"--steps must be >= 2 and --seed >= 0, got {args.steps} and {args.seed}")
        if not math.isfinite(args.lateral_cm):
            raise ValueError(f"--lateral-cm must be a finite number (cm left of the feeder; negative: right), "
                             f"got {args.lateral_cm}")
        print(json_text(displacement(args.out, args.seed, args.steps, None, args.lateral_cm / 100.0,
                                     compass=args.compass, scene=args.scene, echo=print)))
        return 0
    if args.action == "serve":
        from antarium.ant.served import run_served

        if args.max_decisions is not None:
            _positive("--max-decisions", args.max_decisions)
        _positive("--timeout", args.timeout, "s")
        _finite("--lateral-cm", args.lateral_cm, "cm left of the route start; negative: right")
        _finite("--heading-deg", args.heading_deg, "degrees CCW off the route")
        run_served(args.model_file, args.config, Path(args.out).resolve(),
                   (args.lateral_cm / 100.0, math.radians(args.heading_deg)), args.max_decisions,
                   timeout_s=args.timeout)
        return 0
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    if args.action == "evaluate":
        kinds = tuple(k.strip() for k in args.models.split(",") if k.strip())
        bad = [k for k in kinds if k not in ROUTE_MODELS]
        if bad or not kinds:
            raise ValueError(f"--models: unknown {bad or 'none given'}; allowed: {', '.join(ROUTE_MODELS)}")
        if args.routes < 1 or not (math.isfinite(args.length) and args.length > 0):
            raise ValueError(f"--routes must be >= 1 and --length a finite number > 0 m, got {args.routes} and "
                             f"{args.length}")
        if not (math.isfinite(args.put_back_cm) and args.put_back_cm >= 0):
            raise ValueError(f"--put-back-cm must be a finite number >= 0 (0: never put back), got {args.put_back_cm}")
        put_back = args.put_back_cm / 100.0 if args.put_back_cm > 0 else math.inf
        print(route_following.evaluate(out, args.routes, args.length, kinds, args.seed, args.scene, _bar, put_back))
        return 0
    bar = _bar("virtual ant demo")
    outcome = route_following.demo(out, scene=args.scene, progress=bar.update)
    bar.close()
    print(f"virtual ant demo: {_outcome_line(outcome)}\n  wrote into {out}: "
          f"{', '.join(sorted(p.name for p in out.glob(route_following.DEMO_NAME + '*')))}")
    return 0


def _learn(args: argparse.Namespace) -> int:
    from antarium.ant.agent import learning_walk
    from antarium.ant.models import make_model
    from antarium.ant.route_following import (
        FACE_SIZE,
        LEARN_SPACING_M,
        MODEL_EYES,
        MODEL_PARAMS,
        PLACE_LENGTH_M,
        parse_route,
    )
    from antarium.ant.storage import mbon_bytes, save_model
    from antarium.ant.world import virtual_rig

    route = parse_route(args.route, args.length)
    out = Path(args.out).resolve()
    if not out.parent.is_dir():
        raise FileNotFoundError(f"folder {str(out.parent)!r} for the model file does not exist")
    if out.is_dir():  # refused before the walk, not after it
        raise IsADirectoryError(f"--out {args.out!r} is a folder; give the model file to write (e.g. ant.npz)")
    scene = args.scene or "habitat"
    if Path(scene).is_file():  # a scene file is stored by its absolute path: `ant run` finds it from any folder
        scene = str(Path(scene).resolve())
    eye_params = MODEL_EYES[args.model]
    model = make_model(args.model, eye_params.n_pn, **{**MODEL_PARAMS[args.model], **_params(args.param, args.model)})
    spacing = LEARN_SPACING_M[args.model] if args.spacing is None else _positive("--spacing", args.spacing, "m")
    bar = _bar("learning walk", total=int(math.ceil(route.length / spacing)) + 1)
    with virtual_rig(model, scene=scene, eye_params=eye_params, tether=args.tether, log_path=args.log,
                     renderer_kwargs={"face_size": FACE_SIZE}) as ant:
        views = learning_walk(ant, route, spacing, place_length=PLACE_LENGTH_M, progress=bar.update)
    bar.close()
    save_model(out, model, eye_params, route.points, scene=scene)
    print(f"learned {views} views along {route.length:.2f} m; memory {mbon_bytes(model)} bytes; wrote {out}")
    return 0


def _run(args: argparse.Namespace) -> int:
    from antarium.ant.route_following import follow_saved, parse_route
    from antarium.ant.routes import Route
    from antarium.ant.storage import learned_scene, load_route_model

    if args.max_decisions is not None:
        _positive("--max-decisions", args.max_decisions)
    _finite("--lateral-cm", args.lateral_cm, "cm left of the route start; negative: right")
    _finite("--heading-deg", args.heading_deg, "degrees CCW off the route")
    model, eye_params, stored = load_route_model(args.model_file)
    if args.route is not None:
        route = parse_route(args.route, args.length)
    elif stored is not None:
        route = Route(stored)
    else:
        raise ValueError(f"{args.model_file} holds no route; give --route")
    scene = args.scene or learned_scene(args.model_file) or "habitat"
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    bar = _bar("closed loop")
    outcome, _ = follow_saved(model, eye_params, route, out, scene=scene, tether=args.tether,
                              max_decisions=args.max_decisions,
                              start_offset=(args.lateral_cm / 100.0, math.radians(args.heading_deg)),
                              progress=bar.update)
    bar.close()
    print(_outcome_line(outcome))
    print(f"  scene: {scene}\n  log: {outcome.log}\n  picture: {outcome.picture}")
    return 0
