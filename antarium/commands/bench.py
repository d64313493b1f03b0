"""`antarium bench TARGET`: benchmarks reported as ratios to the dome's needs (190 frames/s, 5.3 ms)."""

from __future__ import annotations

import argparse
import math
import sys
from importlib import import_module

from antarium.bench import OPTIONS, TARGETS
from antarium.commands import check_output, require_seconds
from antarium.core.rates import DOME_RATE_HZ

#: the longest run a benchmark may be asked for (s), and the most frames: a day at the dome's rate
MAX_SECONDS = 86400.0
MAX_FRAMES = int(MAX_SECONDS * DOME_RATE_HZ)

HELP = "run a benchmark and report it against the dome's 190 frames/s (5.3 ms frame period)"

#: each option's usual meaning; `OPTIONS` (antarium.bench) says which targets take it and what it means in each
USUAL = {
    "--frames": f"number of frames, from 1 to {MAX_FRAMES:,} (a day at {DOME_RATE_HZ:g} frames/s)",
    "--seconds": f"duration in seconds, > 0 and at most {MAX_SECONDS:g} (a day)",
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
                        help="also write the results to this .json file, in an existing folder; an existing file is "
                             "overwritten (loop with several --path: one file per path, NAME-gpu.json and "
                             "NAME-cpu.json). Every bench puts the same \"run\" table "
                             "(bench, antarium version, host, platform, cpus, finished_utc) beside its own figures, "
                             "and a figure it could not measure (NaN) as null")


def refuse_others(args: argparse.Namespace) -> None:
    """ValueError, in one line naming the target and its options, when an option it does not take was given."""
    given = [o for o in USUAL if getattr(args, o[2:].replace("-", "_"), None) not in (None, False, [])]
    others = [o for o in given if o not in OPTIONS[args.target]]
    if others:
        raise ValueError(f"bench {args.target} takes only {', '.join(takes(args.target))}; not "
                         f"{', '.join(others)}")


def run(args: argparse.Namespace) -> int:
    refuse_others(args)
    require_seconds(args, "seconds", "load_every", "displace_every", "edit_every", "sky_every")
    if args.seconds is not None and args.seconds > MAX_SECONDS:
        raise ValueError(f"--seconds must be at most {MAX_SECONDS:g} seconds (a day), got {args.seconds:g}")
    if args.frames is not None and not 1 <= args.frames <= MAX_FRAMES:
        raise ValueError(f"--frames must be from 1 to {MAX_FRAMES:,} (a day at {DOME_RATE_HZ:g} frames/s), got "
                         f"{args.frames}")
    if args.work_ms is not None and not (math.isfinite(args.work_ms) and args.work_ms >= 0):
        raise ValueError(f"--work-ms must be a number of milliseconds >= 0, got {args.work_ms:g}")
    if args.json_out is not None:  # before the benchmark, which a bad name would throw away
        check_output(args.json_out, "--json", suffixes=(".json",), make_folders=False)
    module_name, func = TARGETS[args.target].split(":")
    try:
        return int(getattr(import_module(module_name), func)(args) or 0)
    except KeyboardInterrupt:
        print(f"antarium bench {args.target}: interrupted (Ctrl-C) before its end: what it measured is printed above "
              "(nothing, where no figures are), and no --json file was written unless said above", file=sys.stderr)
        return 130
