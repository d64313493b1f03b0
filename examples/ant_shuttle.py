"""Antcar shuttling in silico (Gattaux et al. 2025, Fig. 7b): one outbound learning walk (left/right route MBONs,
nest views on the first and feeder views on the last 5 cm); released at the nest with motivation M = 1, the ant
walks to the feeder, and when the feeder MBON recognises the feeder (lambda_F < p = 0.2) M switches to -1 and it
walks backward, still facing the feeder, to the nest, where lambda_N < p switches M back to 1, and so on.

    .venv/bin/python examples/ant_shuttle.py --out ant-shuttle/          # 2 m route, two round trips
    .venv/bin/python examples/ant_shuttle.py --short --out ant-shuttle/  # 1.2 m route, seconds

Writes `shuttle.h5` (trial log), `shuttle_paths.png` and `shuttle_traces.png` into --out (`shuttle-1.h5`, ... when
a reused --out holds them) and prints where M switched.
"""

from __future__ import annotations

import argparse
import math
import sys

from antarium.ant.agent import follow_route, learning_walk
from antarium.ant.metrics import motivation_switches
from antarium.ant.models import make_model
from antarium.ant.route_following import FACE_SIZE, MODEL_EYES, MODEL_PARAMS, PLACE_LENGTH_M
from antarium.ant.routes import curved_route
from antarium.ant.world import virtual_rig
from antarium.client import ScriptArgumentError, check_script_arguments, finite_value, run_script
from antarium.plots.ant import plot_paths, plot_traces, scene_top_view
from antarium.trial_log import LogError, check_log_dir, free_log_path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="ant-shuttle", help="folder for the log and pictures (default %(default)s)")
    parser.add_argument("--length", type=float, default=2.0, help="route length (m, default %(default)g)")
    parser.add_argument("--seed", type=int, default=5, help="seed of the route (default %(default)s)")
    parser.add_argument("--trips", type=float, default=2.0,
                        help="round trips' worth of decisions to run (default %(default)g)")
    parser.add_argument("--threshold", type=float, default=0.2,
                        help="lambda below which a place is recognised (default %(default)g)")
    parser.add_argument("--short", action="store_true", help="a 1.2 m route, one round trip (for tests)")
    args = parser.parse_args(argv)
    check_script_arguments(args, numbers=("threshold",))
    finite_value("--length", args.length, 0.1, 100.0)
    finite_value("--trips", args.trips, 0.1, 100.0)
    try:  # shuttle.h5, or shuttle-1.h5, ... when taken (a log is never overwritten), its pictures named after it
        log = free_log_path(check_log_dir(args.out) / "shuttle")  # absolute
    except LogError as exc:
        raise ScriptArgumentError(f"--out: {exc}") from None
    paths_png, traces_png = (log.with_name(f"{log.stem}_{what}.png") for what in ("paths", "traces"))
    length, trips = (1.2, 1.0) if args.short else (args.length, args.trips)
    route = curved_route(args.seed, length=length)
    eye = MODEL_EYES["antcar"]
    model = make_model("antcar", eye.n_pn, **MODEL_PARAMS["antcar"], task="shuttle", threshold=args.threshold)
    decisions = int(trips * 2 * length / model.params.k_v) + 20
    rig = virtual_rig(model, eye_params=eye, renderer_kwargs={"face_size": FACE_SIZE}, log_path=log)
    with rig as ant:
        learning_walk(ant, route, 0.01, place_length=PLACE_LENGTH_M)
        result = follow_route(ant, route, decisions, end_on_arrival=False, put_back_distance=math.inf)
        top = scene_top_view(ant.loop.renderer.scene)
    track, s = result.track, result.summary
    plot_paths(paths_png, route, {"shuttling Antcar": track}, "shuttling: nest <-> feeder", top=top)
    plot_traces(traces_png, track,
                f"shuttling: M switches when lambda_F or lambda_N < {args.threshold}")
    switches = motivation_switches(route, track.arrays()[0], track.trace("motivation"))
    print(f"shuttling on {length:.1f} m: {s.decisions} decisions, lateral error {100 * s.lateral_median:.1f} ± "
          f"{100 * s.lateral_mad:.1f} cm, {len(switches)} switches"
          f"; log {log}, pictures {paths_png.name}, {traces_png.name} beside it")
    for i, m, to_nest, to_feeder in switches:
        where = f"{100 * to_feeder:.1f} cm from the feeder" if m == -1 else f"{100 * to_nest:.1f} cm from the nest"
        print(f"  decision {i}: M = {m:+d} ({'backward to the nest' if m == -1 else 'forward to the feeder'}), {where}")
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
