"""`antarium bench TARGET`: benchmarks reported as ratios to the dome's needs (190 frames/s, 5.3 ms)."""

from __future__ import annotations

import argparse
import math
from importlib import import_module

from antarium.bench import OPTIONS, TARGETS
from antarium.commands import check_output, require_seconds

HELP = "run a benchmark and report it against the dome's 190 frames/s (5.3 ms frame period)"

#: each option's usual meaning; `OPTIONS` (antarium.bench) says which targets take it and what it means in each
USUAL = {
    "--frames": "number of frames, at least 1",
    "--seconds": "duration in seconds",
    "--work-ms": "busy time standing for one frame's work (ms; default 2.5)",
    "--machine-probe": "also run a stall probe on every CPU and tell the machine's late frames (stalls on the loop's "
                       "CPU) from ours",
    "--path": "per-LED sampling on the GL device or the CPU (repeat to compare both in one run; default: chosen from "
              "the GL renderer)",
    "--load-every": "load the rig's scene again every S seconds (a scripted load_scene)",
    "--displace-every": "a virtual displacement (set_pose, 0.5 m away and back) every S seconds",
    "--edit-every": "move the scene's first object 0.2 m and back (scene_edit) every S seconds",
    "--sky-every": "move the sun 60 degrees and back (sky) every S seconds",
    "--browser-idle": "run the headless browser SCHED_IDLE, so that it gets only the CPU time the loop leaves, as if "
                      "it ran on the experimenter's computer",
}


def _help(option: str) -> str:
    """`option`'s help: its usual meaning, the targets that take it, and what it means where that differs."""
    takers = [t for t in sorted(OPTIONS) if option in OPTIONS[t]]
    own = "; ".join(f"{t}: {OPTIONS[t][option]}" for t in takers if OPTIONS[t][option])
    text = f"{USUAL[option]} (only {', '.join(takers)})" + (f". Per target: {own}" if own else "")
    return text.replace("%", "%%")


def takes(target: str) -> list[str]:
    """The options `target` takes, --json included."""
    return [*OPTIONS[target], "--json"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("target", choices=sorted(TARGETS),
                        help="what to measure; each takes only its own options: "
                             + "; ".join(f"{t}: {' '.join(takes(t))}" for t in sorted(TARGETS)))
    parser.add_argument("--frames", type=int, default=None, help=_help("--frames"))
    parser.add_argument("--seconds", type=float, default=None, help=_help("--seconds"))
    parser.add_argument("--work-ms", type=float, default=None, help=_help("--work-ms"))
    parser.add_argument("--machine-probe", action="store_true", help=_help("--machine-probe"))
    parser.add_argument("--path", action="append", choices=("gpu", "cpu"), default=None, help=_help("--path"))
    for option in ("--load-every", "--displace-every", "--edit-every", "--sky-every"):
        parser.add_argument(option, type=float, default=None, metavar="S", help=_help(option))
    parser.add_argument("--browser-idle", action="store_true", help=_help("--browser-idle"))
    parser.add_argument("--json", dest="json_out", default=None,
                        help="also write the results to this JSON file, in an existing folder; an existing file is "
                             "overwritten (loop with several --path: one file per path, NAME-gpu.json and "
                             "NAME-cpu.json)")


def refuse_others(args: argparse.Namespace) -> None:
    """ValueError, in one line naming the target and its options, when an option it does not take was given."""
    given = [o for o in USUAL if getattr(args, o[2:].replace("-", "_"), None) not in (None, False, [])]
    others = [o for o in given if o not in OPTIONS[args.target]]
    if others:
        raise ValueError(f"bench {args.target} takes only {', '.join(takes(args.target))}; not "
                         f"{', '.join(others)}")


def run(args: argparse.Namespace) -> int:
    refuse_others(args)
    require_seconds(args, "seconds")
    if args.frames is not None and args.frames < 1:
        raise ValueError(f"--frames must be at least 1, got {args.frames}")
    if args.work_ms is not None and not (math.isfinite(args.work_ms) and args.work_ms >= 0):
        raise ValueError(f"--work-ms must be a number of milliseconds >= 0, got {args.work_ms:g}")
    if args.json_out is not None:  # before the benchmark, which a bad name would throw away
        check_output(args.json_out, "--json", make_folders=False)
    module_name, func = TARGETS[args.target].split(":")
    return int(getattr(import_module(module_name), func)(args) or 0)
