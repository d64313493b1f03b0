"""`antarium bench TARGET`: benchmarks reported as ratios to the dome's needs (190 frames/s, 5.3 ms)."""

from __future__ import annotations

import argparse
from importlib import import_module

HELP = "run a benchmark and report it against the dome's 190 frames/s (5.3 ms frame period)"

#: benchmark name -> "module:function"; the function takes the parsed args and returns an exit code.
TARGETS: dict[str, str] = {
    "loop": "antarium.loop_bench:run",
    "ant": "antarium.ant.bench:run",
    "trackball": "antarium.trackball.bench:run",
    "protocol": "antarium.firmware_proto.bench:run",
    "render": "antarium.renderers.bench:run",
    "jitter": "antarium.jitter_bench:run",
    "experiment": "antarium.bench.experiment:run",  # runs/hour of `antarium ant experiment`: --frames runs,
                                                    # --seconds m routes
}

DOME_RATE_HZ = 190.0
FRAME_PERIOD_S = 1.0 / DOME_RATE_HZ


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("target", choices=sorted(TARGETS), help="what to measure")
    parser.add_argument("--frames", type=int, default=None, help="number of frames (target-specific default)")
    parser.add_argument("--seconds", type=float, default=None, help="duration (target-specific default)")
    parser.add_argument("--work-ms", type=float, default=2.5,
                        help="jitter: busy time standing for one frame's work (ms; default 2.5)")
    parser.add_argument("--machine-probe", action="store_true",
                        help="loop: also run a stall probe on every CPU and tell the machine's late frames from ours")
    parser.add_argument("--json", dest="json_out", default=None, help="also write the results to this JSON file")


def run(args: argparse.Namespace) -> int:
    module_name, func = TARGETS[args.target].split(":")
    return int(getattr(import_module(module_name), func)(args) or 0)
