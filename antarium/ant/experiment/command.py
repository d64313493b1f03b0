"""`antarium ant experiment SPEC.toml --out results/`: expand a spec into runs, run them (Dask or serially),
and write the results table, the summary and the pictures."""

from __future__ import annotations

import argparse
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
    p.add_argument("--world", default=None, help="run in this world instead of the spec's: a scene name, mesh or "
                                                 "panorama file")
    p.add_argument("--world-scale", type=float, default=1.0, help="metres per unit of --world's file (default 1)")
    p.add_argument("--up", choices=("z", "y"), default="z", help="--world's up axis (GLB/GLTF: y by the standard)")
    p.add_argument("--eye-height-m", type=float, default=0.01, help="eye height above the ground (m, default 0.01)")


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
    if args.world is not None:
        world = str(Path(args.world).resolve()) if Path(args.world).suffix else args.world
        data["worlds"] = [{"scene": world, "scale": args.world_scale, "up": args.up,
                           "eye_height_m": args.eye_height_m}]
    exp = expand(data, spec.parent)
    out = Path(args.out)
    print(f"{len(exp.runs)} runs -> {out}")
    progress = run_experiment(exp.runs, out, scheduler=args.scheduler, workers=args.workers, serial=args.serial)
    print(f"runs: {progress.done} done now, {progress.skipped} done before, {progress.failed} failed")
    print(report(out, exp.routes, exp.metrics))
    return 1 if progress.failed else 0
