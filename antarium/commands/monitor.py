"""`antarium monitor`: the browser monitor of a running rig (see antarium.monitor)."""

from __future__ import annotations

import argparse

HELP = "serve a web page showing the dome as lit, the ant's path and the loop's health (live)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--rig", default=None, help="rig name (default: the config's [rig] name)")
    parser.add_argument("--config", default=None, help="rig config (TOML): [bus] says where the server is, "
                        "[monitor] where the page is served and who may open it")
    parser.add_argument("--host", default=None, help="address to serve the page on (default: [monitor] host)")
    parser.add_argument("--port", type=int, default=None,
                        help="TCP port, 0..65535 (default: [monitor] port; 0: any free)")


def run(args: argparse.Namespace) -> int:
    from antarium import bus
    from antarium.commands import require_port
    from antarium.config import MonitorSection, load_config
    from antarium.monitor.app import serve

    require_port(args, "port")  # named as given, not as the config's [monitor] port
    config = load_config(args.config)
    overrides = {k: v for k, v in (("host", args.host), ("port", args.port)) if v is not None}
    settings = MonitorSection.read({**config.monitor.model_dump(), **overrides})
    rig = bus.check_rig_name(args.rig or config.rig.name)
    session = bus.open_session(config.bus, role="client")
    try:
        serve(session, rig, settings, echo=lambda line: print(line, flush=True))
    finally:
        session.close()
    return 0
