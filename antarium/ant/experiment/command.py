"""`antarium ant experiment SPEC.toml --out results/`: expand a spec into runs, run them (Dask or serially),
and write the results table, the summary and the pictures."""

from __future__ import annotations

import argparse
import math
import tomllib
from pathlib import Path


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("spec", help="experiment spec (TOML): worlds, route sets, models, grids, releases, seeds, protocol")
    p.add_argument("--out", required=True, help="results folder: runs/<run_id>.parquet, results.parquet, summary, "
                                                "pictures; a rerun into it skips the runs already done")
    p.add_argument("--scheduler", default=None, help="a lab cluster's Dask scheduler, tcp://host:8786 (default: a "
                                                     "LocalCluster on this machine)")
    p.add_argument("--workers", type=int, default=None, help="LocalCluster worker processes (default: every core)")
    p.add_argument("--serial", action="store_true", help="run in this process, without Dask")
    p.add_argument("--run-timeout-s", type=float, default=None,
                   help="a run still running this many seconds after its worker started it is recorded as failed "
                        "(RunTimeout) and its worker restarted, so that a run that hangs cannot hold up the sweep "
                        "(default: no limit; not with --serial)")
    p.add_argument("--world", default=None, help="run in this world instead of the spec's: a scene name, mesh or "
                                                 "panorama file")
    p.add_argument("--world-scale", type=float, default=None, help="metres per unit of --world's file (default 1)")
    p.add_argument("--up", default=None, help="--world's up axis, z or y (default: y for GLB/GLTF, as their "
                                              "standard has it; z for the others)")
    p.add_argument("--eye-height-m", type=float, default=None, help="eye height above the ground under each "
                                                                    "route's start in --world (m, default 0.01)")


#: the flags that state --world, and the world keys they set
WORLD_FLAGS = {"--world-scale": "world_scale", "--up": "up", "--eye-height-m": "eye_height_m"}


def _world_table(args: argparse.Namespace) -> dict:
    """The [[worlds]] table of --world and its flags; ValueError naming the flag for a bad value, or for a flag
    given without --world (it would be ignored)."""
    from antarium.ant.experiment.inputs import UP_AXES

    given = [flag for flag, attr in WORLD_FLAGS.items() if getattr(args, attr) is not None]
    if args.world is None:
        raise ValueError(f"{', '.join(given)} without --world: --world-scale, --up and --eye-height-m state "
                         "--world's world; give --world too, or set scale, up, eye_height_m in the spec's [[worlds]]")
    scale = 1.0 if args.world_scale is None else args.world_scale
    eye = 0.01 if args.eye_height_m is None else args.eye_height_m
    for flag, value in (("--world-scale", scale), ("--eye-height-m", eye)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{flag} must be a finite number > 0, got {value!r}")
    path = Path(args.world)
    gltf = path.suffix.lower() in (".glb", ".gltf")
    up = args.up or ("y" if gltf else "z")
    if up not in UP_AXES:
        raise ValueError(f"--up must be one of {', '.join(UP_AXES)}, got {up!r}")
    if gltf and up != "y":
        raise ValueError(f"--up {up}: --world {args.world} is GLB/GLTF, +y up by its standard; give --up y or "
                         "leave --up out")
    world = str(path.resolve()) if path.suffix else args.world
    return {"scene": world, "scale": scale, "up": up, "eye_height_m": eye}


def run(args: argparse.Namespace) -> int:
    from antarium.ant.experiment.results import report
    from antarium.ant.experiment.runner import run_experiment
    from antarium.ant.experiment.spec import expand

    spec = Path(args.spec)
    if not spec.is_file():
        raise FileNotFoundError(f"experiment spec {str(spec)!r} not found")
    if args.workers is not None and args.workers < 1:
        raise ValueError(f"--workers must be >= 1, got {args.workers}")
    try:
        data = tomllib.loads(spec.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{spec}: not valid TOML ({exc})") from None
    if args.world is not None or any(getattr(args, attr) is not None for attr in WORLD_FLAGS.values()):
        data["worlds"] = [_world_table(args)]
    exp = expand(data, spec.parent)
    out = Path(args.out)
    print(f"{len(exp.runs)} runs -> {out}")
    progress = run_experiment(exp.runs, out, scheduler=args.scheduler, workers=args.workers, serial=args.serial,
                              run_timeout_s=args.run_timeout_s)
    print(f"runs: {progress.done} done now, {progress.skipped} done before, {progress.failed} failed")
    print(report(out, exp.routes, exp.metrics, [r.run_id for r in exp.runs]))
    return 1 if progress.failed else 0
