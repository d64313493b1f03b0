"""`antarium demo`: the main job on the embedded default (emulated dome, no hardware)."""

from __future__ import annotations

import argparse

HELP = "run the embedded default rig for a short time and write its outputs (no hardware needed)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="demo-output", help="folder for the outputs (default: demo-output)")


def run(args: argparse.Namespace) -> int:
    from antarium.commands import layout

    return layout.run(argparse.Namespace(out=args.out, no_pictures=False, export=None, regenerate=False,
                                         layout_out=None, margin_mm=None, min_pitch_mm=None))
