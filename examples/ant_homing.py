"""Antcar homing in silico: one outbound learning walk with the oscillation turned back (phase 180 deg, "turn
back and look") and a nest place MBON; released at the feeder, the ant walks the route home in closed loop and
stops by itself when the nest MBON recognises the nest (lambda_N < p = 0.2, the paper's threshold; Gattaux et
al. 2025, Fig. 7).

The nest views are learned on the first 5 cm of the route (`route_following.PLACE_LENGTH_M`) with Antcar's eye of
this project (`route_following.MODEL_EYES`): gain control per elevation row, so that the grass and stones near the
nest, not the far field that looks the same metres away, make the nest familiar.

    .venv/bin/python examples/ant_homing.py --out ant-homing/          # 3 m route, about a minute
    .venv/bin/python examples/ant_homing.py --short --out ant-homing/  # 1.2 m route, seconds

Writes `homing.h5` (trial log), `homing_paths.png` and `homing_traces.png` into --out (`homing-1.h5`, ... when
a reused --out holds them) and prints the stopping distance.
"""

from __future__ import annotations

import argparse
import math
import sys

from antarium.ant.agent import follow_route, learning_walk
from antarium.ant.models import make_model
from antarium.ant.route_following import FACE_SIZE, MODEL_EYES, MODEL_PARAMS, PLACE_LENGTH_M
from antarium.ant.routes import curved_route
from antarium.ant.world import virtual_rig
from antarium.client import ScriptArgumentError, check_script_arguments, finite_value, run_script
from antarium.plots.ant import plot_paths, plot_traces, scene_top_view
from antarium.trial_log import LogError, check_log_dir, free_log_path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="ant-homing", help="folder for the log and pictures (default %(default)s)")
    parser.add_argument("--length", type=float, default=3.0, help="outbound route length (m, default %(default)g)")
    parser.add_argument("--seed", type=int, default=5, help="seed of the route (default %(default)s)")
    parser.add_argument("--threshold", type=float, default=0.2,
                        help="lambda_N below which the nest is recognised (default %(default)g)")
    parser.add_argument("--short", action="store_true", help="a 1.2 m route (for tests)")
    args = parser.parse_args(argv)
    check_script_arguments(args, numbers=("threshold",))
    finite_value("--length", args.length, 0.1, 100.0)
    try:  # homing.h5, or homing-1.h5, ... when taken (a log is never overwritten), its pictures named after it
        log = free_log_path(check_log_dir(args.out) / "homing")  # absolute
    except LogError as exc:
        raise ScriptArgumentError(f"--out: {exc}") from None
    paths_png, traces_png = (log.with_name(f"{log.stem}_{what}.png") for what in ("paths", "traces"))
    length = 1.2 if args.short else args.length
    outbound = curved_route(args.seed, length=length)
    eye = MODEL_EYES["antcar"]
    model = make_model("antcar", eye.n_pn, **MODEL_PARAMS["antcar"], task="homing", phase_deg=180.0,
                       threshold=args.threshold)
    rig = virtual_rig(model, eye_params=eye, renderer_kwargs={"face_size": FACE_SIZE}, log_path=log)
    with rig as ant:
        learning_walk(ant, outbound, 0.01, place_length=PLACE_LENGTH_M)  # outbound, learning views looking back
        home = outbound.reversed()                                        # released at the feeder; nest at its end
        result = follow_route(ant, home, int(3 * home.length / 0.02), end_on_arrival=False,
                              put_back_distance=math.inf)
        top = scene_top_view(ant.loop.renderer.scene)
    s = result.summary
    # The learned (outbound) route: its start is the nest and its end the feeder, as the picture labels them.
    plot_paths(paths_png, outbound, {"homing Antcar": result.track}, "homing: route home and stop",
               top=top)
    plot_traces(traces_png, result.track,
                f"homing: familiarities (lambda_nest < {args.threshold} stops it)")
    stopped = not math.isnan(s.stop_distance)
    print(f"homing over {home.length:.1f} m: lateral error {100 * s.lateral_median:.1f} ± {100 * s.lateral_mad:.1f} cm;"
          f" {'stopped ' + format(100 * s.stop_distance, '.1f') + ' cm from the nest' if stopped else 'did not stop'}"
          f" after {s.decisions} decisions"
          f"; log {log}, pictures {paths_png.name}, {traces_png.name} beside it")
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
