"""Antcar homing in silico: one outbound learning walk with the oscillation turned back (phase 180 deg, "turn
back and look") and a nest place MBON; released at the feeder, the ant walks the route home in closed loop and
stops by itself when the nest MBON recognises the nest (lambda_N < p; Gattaux et al. 2025, Fig. 7).

The paper's p = 0.2 stops our ant too early: at ant scale the habitat's views are dominated by the far field,
so the nest's place memory generalises over a metre or more (lambda_N ~ 0.25 two metres away, 0.05 one metre
away). The example uses p = 0.03 (`--threshold`).

    .venv/bin/python examples/ant_homing.py --out ant-homing/

Writes `homing.h5` (trial log), `homing_paths.png`, `homing_traces.png` and prints the stopping distance.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from antarium.ant.agent import follow_route, learning_walk
from antarium.ant.experiments import FACE_SIZE
from antarium.ant.models import make_model
from antarium.ant.plots import plot_paths, plot_traces, scene_top_view
from antarium.ant.routes import curved_route
from antarium.ant.world import virtual_rig


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="ant-homing")
    parser.add_argument("--length", type=float, default=3.0, help="outbound route length (m)")
    parser.add_argument("--seed", type=int, default=5)
    parser.add_argument("--threshold", type=float, default=0.03, help="lambda_N below which the nest is recognised")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    outbound = curved_route(args.seed, length=args.length)
    model = make_model("antcar", 800, task="homing", phase_deg=180.0, threshold=args.threshold)
    with virtual_rig(model, renderer_kwargs={"face_size": FACE_SIZE}, log_path=out / "homing.h5") as ant:
        learning_walk(ant, outbound, 0.01)                     # outbound, learning views looking back
        home = outbound.reversed()                             # released at the feeder, the nest is its end
        result = follow_route(ant, home, int(3 * home.length / 0.02), end_on_arrival=False)
        top = scene_top_view(ant.loop.renderer.scene)
    s = result.summary
    plot_paths(out / "homing_paths.png", home, {"homing Antcar": result.track}, "homing: route home and stop",
               top=top)
    plot_traces(out / "homing_traces.png", result.track,
                f"homing: familiarities (lambda_nest < {args.threshold} stops it)")
    stopped = not math.isnan(s.stop_distance)
    print(f"homing over {home.length:.1f} m: lateral error {100 * s.lateral_median:.1f} ± {100 * s.lateral_mad:.1f} cm;"
          f" {'stopped ' + format(100 * s.stop_distance, '.1f') + ' cm from the nest' if stopped else 'did not stop'}"
          f" after {s.decisions} decisions; pictures in {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
