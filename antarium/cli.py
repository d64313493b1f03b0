"""The `antarium` command line: one sub-command per module in `antarium.commands`.

Each command module defines `HELP` (one line), `add_arguments(parser)` and `run(args) -> int`, and
imports its heavy dependencies inside `run`, so that `antarium --help` stays fast.

Bad input, a file that cannot be read or written, a port or address that cannot be used: `main` prints one line
`antarium COMMAND: error: ...` and returns 2 (`error_line` words it); `--debug` shows the traceback instead.
"""

from __future__ import annotations

import argparse
import re
import socket
import sys
from importlib import import_module
from typing import NoReturn

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

DEBUG_HELP = "on an error, show the full traceback instead of the one-line message (before or after COMMAND)"


class _Parser(argparse.ArgumentParser):
    """`antarium` (or `antarium ant`) alone lists its commands, with their one-line purposes, above the error."""

    def error(self, message: str) -> NoReturn:
        if self._subparsers is not None and "arguments are required" in message:
            self.print_help(sys.stderr)
        super().error(message)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="antarium", description="Stimulus server and tools for the Antarium LED dome.",
        epilog="Bad input is refused in one line `antarium COMMAND: error: ...` with exit status 2; "
               "--debug shows the traceback.")
    parser.add_argument("--version", action="version", version=f"antarium {__version__}")
    parser.add_argument("--debug", action="store_true", help=DEBUG_HELP)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name, module_name in COMMANDS.items():
        module = import_module(module_name)
        p = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        _finish(p)
        p.set_defaults(_run=module.run)
    return parser


def has_default(action: argparse.Action) -> bool:
    """The option's default is a value worth showing: not None, a flag's False, SUPPRESS or an empty list."""
    return not (action.default is None or action.default is False or action.default is argparse.SUPPRESS
                or action.default == [])


def _finish(parser: argparse.ArgumentParser) -> None:
    """Give `parser` and the actions below it (`antarium ant learn`, ...) `--debug`, each action its one-line
    help as the description its own --help shows, and each option with a default (`has_default`) whose help does
    not speak of it `(default X)`."""
    # SUPPRESS: a --debug before COMMAND is not reset by the sub-command's default
    parser.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help=DEBUG_HELP)
    for action in parser._actions:
        if (action.option_strings and action.help not in (None, argparse.SUPPRESS) and has_default(action)
                and "default" not in action.help.lower()):
            action.help += " (default %(default)s)"
        if isinstance(action, argparse._SubParsersAction):
            helps = {choice.dest: choice.help for choice in action._choices_actions}
            for name, sub in action.choices.items():
                sub.description = sub.description or helps.get(name)
                _finish(sub)


def _zenoh_error(exc: BaseException) -> bool:
    """A zenoh error (zenoh is imported only where the bus is used, never for this check)."""
    zenoh = sys.modules.get("zenoh")
    return zenoh is not None and isinstance(exc, getattr(zenoh, "ZError", ()))


def is_user_error(exc: BaseException) -> bool:
    """Errors `main` reports in one line: bad values (the project's own errors are ValueError or RuntimeError),
    files, folders, ports and addresses (OSError, OverflowError), the bus (zenoh)."""
    return isinstance(exc, ValueError | RuntimeError | OSError | OverflowError) or _zenoh_error(exc)


#: numpy scalars as they print in messages (`np.float64(-20.0)`): shown as plain numbers
_NUMPY_SCALAR = re.compile(r"\bnp\.(?:float|int|uint|bool)\w*\(([^()]*)\)")
#: where in zenoh's Rust sources an error was raised: of no use to the user
_RUST_LOCATION = re.compile(r"\s+at /\S+?\.rs:\d+\.?")


def error_line(exc: BaseException) -> str:
    """`exc` in one line for the user: what was wrong (and what is allowed, where the error says)."""
    if isinstance(exc, socket.gaierror):
        text = f"address not found ({exc.strerror or exc}); give an IP address or a host name this computer resolves"
    elif isinstance(exc, OSError) and exc.strerror:
        where = "" if exc.filename is None else repr(str(exc.filename))
        if exc.filename2 is not None:
            where += f" -> {str(exc.filename2)!r}"
        if where and isinstance(exc, IsADirectoryError):
            text = f"{where} is a folder; give a file"
        elif where and isinstance(exc, NotADirectoryError):
            text = f"{where}: a part of the path is a file, not a folder"
        else:
            text = f"{where}: {exc.strerror}" if where else exc.strerror
    elif isinstance(exc, OverflowError) and "port" in str(exc):
        text = f"{str(exc).rstrip('.')}; a port is an integer 0..65535"
    else:
        text = str(exc) or type(exc).__name__
    if _zenoh_error(exc):
        text = f"bus (zenoh): {_RUST_LOCATION.sub('', text)}"
    text = _NUMPY_SCALAR.sub(r"\1", text)
    return " ".join(text.split())  # one line


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args._run(args) or 0)
    except KeyboardInterrupt:  # a command that keeps something on Ctrl-C says what itself (serve, bench)
        print(f"antarium {args.command}: interrupted (Ctrl-C)", file=sys.stderr)
        return 130
    except Exception as exc:
        if args.debug or not is_user_error(exc):
            raise
        print(f"antarium {args.command}: error: {error_line(exc)}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
