"""`antarium demo`: the main job on the embedded default (emulated dome, no hardware).

First the dome's geometry summary and layout pictures, then the embedded default rig (`antarium serve` with no
config: the emulator as its own process on loopback, the default habitat, the scripted walker in closed loop)
for a short fixed time, recording one trial; it prints the paths of the trial log, the path plot and the
picture of what the dome showed.
"""

from __future__ import annotations

import argparse

HELP = "run the embedded default rig for a short time and write its outputs (no hardware needed)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="demo-output", help="folder for the outputs (default: demo-output)")
    parser.add_argument("--seconds", type=float, default=8.0, help="how long the rig runs (default 8 s)")


def run(args: argparse.Namespace) -> int:
    from antarium.commands import layout
    from antarium.rig_demo import run_demo_rig

    if not 0 < args.seconds <= 3600:
        raise ValueError(f"--seconds must be in (0, 3600], got {args.seconds}")
    code = layout.run(argparse.Namespace(out=args.out, no_pictures=False, export=None, regenerate=False,
                                         layout_out=None, margin_mm=None, min_pitch_mm=None))
    if code:
        return code
    print(f"running the embedded default rig for {args.seconds:g} s (emulated dome, default habitat, "
          "scripted walker in closed loop; the scene turns 90 degrees half-way) ...", flush=True)
    for name, path in run_demo_rig(args.out, args.seconds).items():
        print(f"{name}: {path}")
    return 0
