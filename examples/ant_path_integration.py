"""Path integration by the central complex in the emulated dome (Stone et al. 2017's foraging task), with the
compass read from the dome's polarised UV pixels, then the cluttered arena (outbound with optic-flow avoidance,
home by CX while the eight MBONs learn, then by CXMB with the vector memory restored).

    .venv/bin/python examples/ant_path_integration.py --out ant-pi/           # 3 routes of 1,500 steps, minutes
    .venv/bin/python examples/ant_path_integration.py --short --out ant-pi/   # 300-step routes, about a minute

Writes pi_homing_sky*.png/.json and arena_sky*.png/.json into --out and prints the summaries.
"""

from __future__ import annotations

import argparse
import json
import sys

from antarium.ant.homing import cluttered_arena, pi_homing
from antarium.client import run_script


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", required=True, help="folder for the pictures and summaries")
    parser.add_argument("--short", action="store_true", help="300-step routes in a smaller arena")
    args = parser.parse_args(argv)
    steps = 300 if args.short else 1500
    print(json.dumps(pi_homing(args.out, seeds=range(3), n_outbound=steps, echo=print), indent=2))
    arena = {"n": 30, "arena_radius": 1.5} if args.short else None
    print(json.dumps(cluttered_arena(args.out, seeds=[0], n_outbound=steps, echo=print, arena=arena), indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
