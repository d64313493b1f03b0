"""`antarium emulate`: run the distributor board and its 55 panels as a UDP server (see docs/protocol.md)."""

from __future__ import annotations

import argparse
import errno

from antarium.commands import require_port, require_seconds

HELP = "run the dome emulator (distributor + 55 panels) on UDP, as the real board would"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from antarium.firmware_proto import DEFAULT_HOST, DEFAULT_PORT

    parser.add_argument("--host", default=DEFAULT_HOST, help=f"address to listen on (default {DEFAULT_HOST})")
    parser.add_argument("--port", type=int, default=DEFAULT_PORT,
                        help=f"UDP port, 0..65535, 0: a free one (default {DEFAULT_PORT})")
    parser.add_argument("--line", choices=("fast", "bits"), default="fast",
                        help="panel links: fast (default), or bits: bit-exact Manchester framing (slower)")
    parser.add_argument("--seconds", type=float, default=None, help="stop after this many seconds (default: never)")
    parser.add_argument("--fault", action="append", default=[], metavar="PANEL:LED:KIND",
                        help="inject an LED fault, KIND open or short (repeatable)")


def _parse_fault(spec: str) -> tuple[int, int, str]:
    parts = spec.split(":")
    if len(parts) != 3 or not parts[0].isdigit() or not parts[1].isdigit():
        raise ValueError("expected PANEL:LED:KIND, e.g. 3:120:open")
    return int(parts[0]), int(parts[1]), parts[2]


def run(args: argparse.Namespace) -> int:
    require_seconds(args, "seconds")
    require_port(args, "port")
    from antarium.firmware_proto.emulator import Emulator
    from antarium.firmware_proto.server import format_stats, serve

    emulator = Emulator(line=args.line)
    for spec in args.fault:
        try:
            emulator.inject_fault(*_parse_fault(spec))
        except ValueError as exc:
            raise ValueError(f"--fault {spec!r}: {exc}") from None

    def ready(address):
        print(f"antarium emulate: listening on udp://{address[0]}:{address[1]} (line: {args.line})", flush=True)

    try:
        stats = serve(emulator, args.host, args.port, args.seconds, ready, handle_signals=True)
    except RuntimeError as exc:  # the port could not be bound
        if isinstance(exc.__cause__, OSError) and exc.__cause__.errno == errno.EADDRINUSE:
            raise RuntimeError(f"{exc} (something else listens there: give another --port, 0 for a free one)") from None
        raise
    print("antarium emulate: statistics\n" + format_stats(stats), flush=True)
    return 0
