"""`antarium demo`: the main job on the emulated dome (no hardware).

First the dome's geometry summary and layout pictures, then a virtual ant in the closed loop of the emulated rig:
Antcar learns a short route and follows it, walking through the emulated USB trackball (simulated clock, about
10 s); it prints the paths of the trial log, the path plot (learned and followed path over the world's top view),
the familiarity traces and the picture of what the dome showed. `--rig-seconds S` also runs the embedded default
rig (`antarium serve` with no config: the emulator as its own process, the scripted walker) in real time.
"""

from __future__ import annotations

import argparse

HELP = ("the main job, no hardware: the dome's layout, then a virtual ant learns a short route and follows it in "
        "the emulated rig's closed loop")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="demo-output", metavar="FOLDER",
                        help="folder for the outputs, made if missing; the pictures of an earlier run there are "
                             "overwritten, its trial logs in FOLDER/trials/ kept (a new one each run) "
                             "(default: %(default)s)")
    parser.add_argument("--rig-seconds", type=float, default=0.0, metavar="S",
                        help="also run the embedded default rig (served, real time, scripted walker) for S seconds, "
                             "0..3600 (default %(default)s: not run)")


def run(args: argparse.Namespace) -> int:
    from antarium.commands import check_output, layout
    from antarium.demos.virtual_ant import run_ant_demo

    if not 0 <= args.rig_seconds <= 3600:
        raise ValueError(f"--rig-seconds must be in [0, 3600], got {args.rig_seconds:g}")
    out = check_output(args.out, "--out", folder=True)  # a folder the system refuses (/proc/x) is said now
    out.mkdir(parents=True, exist_ok=True)
    code = layout.run(argparse.Namespace(out=args.out, no_pictures=False, export=None, regenerate=False,
                                         layout_out=None, margin_mm=None, min_pitch_mm=None))
    if code:
        return code
    print("virtual ant in the closed loop (emulated dome, default habitat, emulated USB trackball, simulated clock): "
          "learning a 1.5 m route, then following it ...", flush=True)
    for name, path in run_ant_demo(args.out).items():
        print(f"{name}: {path}")
    if args.rig_seconds:
        from antarium.demos.served_rig import run_demo_rig

        print(f"running the embedded default rig for {args.rig_seconds:g} s (emulator process, default habitat, "
              "scripted walker in closed loop; the scene turns 90 degrees half-way) ...", flush=True)
        for name, path in run_demo_rig(args.out, args.rig_seconds).items():
            print(f"{name}: {path}")
    return 0
