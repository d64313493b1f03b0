"""`antarium bench TARGET`: benchmarks reported as ratios to the dome's needs (190 frames/s, 5.3 ms)."""

from __future__ import annotations

import argparse
import math
from importlib import import_module

from antarium.bench import TARGETS
from antarium.commands import check_output, require_seconds

HELP = "run a benchmark and report it against the dome's 190 frames/s (5.3 ms frame period)"

def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("target", choices=sorted(TARGETS), help="what to measure")
    parser.add_argument("--frames", type=int, default=None,
                        help="number of frames, at least 1 (default: the target's own)")
    parser.add_argument("--seconds", type=float, default=None, help="duration in seconds (default: the target's own)")
    parser.add_argument("--work-ms", type=float, default=2.5,
                        help="jitter: busy time standing for one frame's work (ms; default 2.5)")
    parser.add_argument("--machine-probe", action="store_true",
                        help="loop: also run a stall probe on every CPU and tell the machine's late frames from ours")
    parser.add_argument("--path", action="append", choices=("gpu", "cpu"), default=None,
                        help="render, loop: per-LED sampling on the GL device or the CPU (repeat to compare both in "
                             "one run; default: chosen from the GL renderer)")
    parser.add_argument("--load-every", type=float, default=None, metavar="S",
                        help="loop: load the rig's scene again every S seconds (a scripted load_scene)")
    parser.add_argument("--displace-every", type=float, default=None, metavar="S",
                        help="loop: a virtual displacement (set_pose, 0.5 m away and back) every S seconds")
    parser.add_argument("--edit-every", type=float, default=None, metavar="S",
                        help="loop: move the scene's first object 0.2 m and back (scene_edit) every S seconds")
    parser.add_argument("--sky-every", type=float, default=None, metavar="S",
                        help="loop: move the sun 60 degrees and back (sky) every S seconds")
    parser.add_argument("--browser-idle", action="store_true",
                        help="monitor: run the headless browser SCHED_IDLE, so that it gets only the CPU time the loop "
                             "leaves, as if it ran on the experimenter's computer")
    parser.add_argument("--json", dest="json_out", default=None,
                        help="also write the results to this JSON file, in an existing folder; an existing file is "
                             "overwritten (loop with several --path: one file per path, NAME-gpu.json and "
                             "NAME-cpu.json)")


def run(args: argparse.Namespace) -> int:
    require_seconds(args, "seconds")
    if args.frames is not None and args.frames < 1:
        raise ValueError(f"--frames must be at least 1, got {args.frames}")
    if not (math.isfinite(args.work_ms) and args.work_ms >= 0):
        raise ValueError(f"--work-ms must be a number of milliseconds >= 0, got {args.work_ms:g}")
    if args.json_out is not None:  # before the benchmark, which a bad name would throw away
        check_output(args.json_out, "--json", make_folders=False)
    module_name, func = TARGETS[args.target].split(":")
    return int(getattr(import_module(module_name), func)(args) or 0)
