"""The `antarium` command line: one sub-command per module in `antarium.commands`.

Each command module defines `HELP` (one line), `add_arguments(parser)` and `run(args) -> int`, and
imports its heavy dependencies inside `run`, so that `antarium --help` stays fast.
"""

from __future__ import annotations

import argparse
import sys
from importlib import import_module

from antarium import __version__

#: sub-command name -> module implementing it
COMMANDS: dict[str, str] = {
    "serve": "antarium.commands.serve",
    "layout": "antarium.commands.layout",
    "demo": "antarium.commands.demo",
    "bench": "antarium.commands.bench",
    "render": "antarium.commands.render",
    "scene": "antarium.commands.scene",
    "emulate": "antarium.commands.emulate",
    "trackball": "antarium.commands.trackball",
    "ant": "antarium.commands.ant",
    "servosphere": "antarium.commands.servosphere",
    "monitor": "antarium.commands.monitor",
    "check": "antarium.commands.check",
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="antarium", description="Stimulus server and tools for the Antarium LED dome."
    )
    parser.add_argument("--version", action="version", version=f"antarium {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name, module_name in COMMANDS.items():
        module = import_module(module_name)
        p = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args._run(args) or 0)
    except (ValueError, FileNotFoundError, RuntimeError) as exc:
        print(f"antarium {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
