"""`antarium bench experiment`: throughput of `antarium ant experiment` in runs per hour, in this process and on
a LocalCluster of 1 and 2 workers, and the cluster's overhead per run.

The same runs (seeded curved routes of --length m in the habitat, Ardin's MB model) are run three times into
fresh folders. Overhead per run: on one worker, results arrive one after another, so the time between two
arrivals minus the run's own time (measured in the worker) is what the cluster adds per run (scheduling,
transfer, writing the Parquet file); it is given as a fraction of the run's own time. The first run of each
worker (building the world, the footprint matrix) is counted in runs/hour but not in the overhead.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time

from antarium.bench import progress, write_json

GOAL_SCALING_2_WORKERS = 1.8
GOAL_OVERHEAD = 0.05


def _runs(n: int, length: float, model: str):
    from antarium.ant.experiment.spec import expand

    data = {"experiment": {"seeds": [0]}, "worlds": [{"scene": "habitat"}],
            "route_sets": [{"curved": {"seeds": list(range(n)), "length_m": length}}], "models": {model: {}}}
    return expand(data).runs


def _timed(runs, **kw) -> dict:
    from antarium.ant.experiment.runner import run_experiment

    arrivals: list[tuple[float, float]] = []
    with tempfile.TemporaryDirectory() as out:
        t0 = time.perf_counter()
        p = run_experiment(runs, out, progress_bar=False,
                           on_row=lambda row: arrivals.append((time.perf_counter(), row.get("run_s", float("nan")))),
                           **kw)
        wall = time.perf_counter() - t0
    if p.failed:
        raise RuntimeError(f"{p.failed} benchmark run(s) failed")
    gaps = [(t1 - t0_) - run_s for (t0_, _), (t1, run_s) in zip(arrivals[1:-1], arrivals[2:], strict=True)]
    run_s = [r for _, r in arrivals[1:]]
    return {"wall_s": wall, "runs_per_hour": 3600.0 * len(runs) / wall,
            "median_run_s": statistics.median(run_s) if run_s else float("nan"),
            "median_gap_minus_run_s": statistics.median(gaps) if gaps else float("nan")}


def measure(n: int = 6, length: float = 2.0, model: str = "ardin") -> dict:
    runs = _runs(n, length, model)
    out = {"runs": n, "route_length_m": length, "model": model,
           "serial": _timed(runs, serial=True),
           "workers_1": _timed(runs, workers=1),
           "workers_2": _timed(runs, workers=2)}
    w1, w2 = out["workers_1"], out["workers_2"]
    out["scaling_2_vs_1"] = w2["runs_per_hour"] / w1["runs_per_hour"]
    out["overhead_per_run"] = w1["median_gap_minus_run_s"] / w1["median_run_s"]
    return out


def run(args: argparse.Namespace) -> int:
    n = args.frames or 6
    if n < 3:  # the overhead is the gap between two arrivals after the first, on one worker
        raise ValueError(f"bench experiment: --frames (the number of runs) must be at least 3, got {n}: the "
                         "cluster's overhead is measured between the arrivals of the second and later runs")
    length = args.seconds or 2.0
    progress("experiment", f"{n} runs, three times over: in this process, on 1 worker, on 2 workers")
    r = measure(n, length)
    print(f"antarium ant experiment: {n} runs of Ardin's MB on {length:g} m curved routes in the habitat "
          f"(--frames runs, --seconds m)")
    for key in ("serial", "workers_1", "workers_2"):
        m = r[key]
        print(f"  {key:10s}: {m['runs_per_hour']:8.0f} runs/hour ({m['wall_s']:.1f} s in all, "
              f"median run {m['median_run_s']:.2f} s)")
    print(f"  2 workers vs 1: {r['scaling_2_vs_1']:.2f} x (goal >= {GOAL_SCALING_2_WORKERS})")
    print(f"  cluster overhead per run (1 worker): {100 * r['overhead_per_run']:.1f} % of a run "
          f"(goal < {100 * GOAL_OVERHEAD:.0f} %)")
    if args.json_out:
        write_json(args.json_out, "experiment", r)
    return 0
