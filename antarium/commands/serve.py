"""`antarium serve`: run the stimulus server (the embedded default rig when no config is given)."""

from __future__ import annotations

import argparse

from antarium.commands import require_seconds

HELP = "run the stimulus server: frame loop, closed loop, bus commands and trial logs"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", default=None, help="rig config (TOML); default: the embedded default rig "
                        "(emulator on loopback, default habitat, scripted walker in closed loop)")
    parser.add_argument("--seconds", type=float, default=None, help="stop after this many seconds (default: never)")
    parser.add_argument("--record", default=None, metavar="NAME",
                        help="record a trial named NAME from the start (stopped cleanly on exit)")
    parser.add_argument("--print-config", action="store_true",
                        help="check the config and print it resolved (TOML), then exit (ports in use not checked)")
    parser.add_argument("--status-every", type=float, default=10.0, metavar="S",
                        help="print a status line every S seconds (default 10; 0: never)")


def link_line(server) -> str:
    """Where the frames go: the UDP address in use (a spawned emulator's port is the OS's choice when [link] port
    is 0, else that port)."""
    from antarium.firmware_proto import DEFAULT_PORT

    address = getattr(server.link, "address", None)
    if server.link is None:
        return "antarium serve: no dome link"
    if address is None:
        return "antarium serve: dome link: virtual (emulator in this process)"
    spawned = ""
    if getattr(server, "emulator", None) is not None:
        port = (f"OS-chosen port ([link] port = 0); a distributor listens on {DEFAULT_PORT}"
                if server.config.link.port == 0 else "[link] port")
        spawned = f" (spawned emulator, {port})"
    return f"antarium serve: dome link: udp {address[0]}:{address[1]}{spawned}"


def _announce_link(server) -> None:
    if server.wait_ready(None):
        print(link_line(server), flush=True)


def _print_status(server, every_s: float, stopping) -> None:
    """One line every `every_s` seconds: frame rate, late frames, latency, alarms; none once `stopping` is set (a
    signal: the emulator and the link going down then are the shutdown, not alarms)."""
    if every_s <= 0 or not server.wait_ready(None):
        return
    while not stopping.wait(every_s):
        s = server.status()
        if stopping.is_set():
            return
        if "frames" not in s:
            continue
        lat = s["latency"]
        latency = "n/a" if lat is None else f"p50 {lat['p50'] * 1e3:.1f} p99 {lat['p99'] * 1e3:.1f} ms"
        rate = s["frame_rate_hz"] or 0.0
        print(f"antarium serve: {s['frames']} frames, {rate:.1f}/{s['target_rate_hz']:g} Hz, {s['late_frames']} late, "
              f"latency {latency}" + "".join(f"; ALARM: {a}" for a in s["alarms"]), flush=True)


def _check_arguments(args: argparse.Namespace) -> None:
    """ValueError naming a bad --record or --status-every (before anything starts)."""
    import math

    if args.record is not None and not args.record.strip():
        raise ValueError("--record needs a trial name (part of the log file's name, e.g. --record ant7), got "
                         f"{args.record!r}; leave --record out to record nothing")
    every = args.status_every
    if not (math.isfinite(every) and every >= 0):
        raise ValueError(f"--status-every must be a number of seconds >= 0 (0: no status lines), got {every:g}")


def run(args: argparse.Namespace) -> int:
    import signal
    import sys
    import threading

    from antarium.config import load_config
    from antarium.server import Server
    from antarium.server.config_check import check_config

    require_seconds(args, "seconds")  # before the config's checks, which look at this machine's ports
    _check_arguments(args)
    # --print-config checks what the file says, not this machine (a bus port held by a running server)
    config = check_config(load_config(args.config), ports=not args.print_config)
    if args.print_config:
        import tomli_w

        print(tomli_w.dumps(config.to_toml_dict()), end="")
        return 0
    server = Server(config, record=args.record)
    stopping = threading.Event()

    def stop(signum, frame):
        first = not stopping.is_set()
        stopping.set()
        if not first:
            return  # stopping already; a second Ctrl-C does not interrupt the shutdown
        interrupt = server.cancel_start()  # still starting: what it waits for (a device, the renderer) is interrupted
        print(f"antarium serve: {signal.Signals(signum).name}: "
              + ("stopping the start-up" if interrupt else "stopping after this frame"), file=sys.stderr, flush=True)
        if interrupt:
            raise KeyboardInterrupt
        server.stop()

    signal.signal(signal.SIGINT, stop)
    signal.signal(signal.SIGTERM, stop)
    bus = config.bus
    where = ", ".join(bus.listen) if bus.enabled else "bus disabled"
    try:
        print(f"antarium serve: rig {server.rig_name!r} at {config.loop.rate_hz:g} frames/s; bus: {where}; "
              f"trial logs in {server.log_dir}", flush=True)
        threading.Thread(target=_announce_link, args=(server,), daemon=True).start()
        threading.Thread(target=_print_status, args=(server, args.status_every, stopping), daemon=True).start()
        frames = server.run(seconds=args.seconds)
    except KeyboardInterrupt:  # the start-up interrupted (`cancel_start`): no frame ran
        server.close()  # what run() had not closed (it closes all it can itself)
        frames = 0
    finally:
        stopping.set()  # no status line (and no alarm) once the loop ended
    stats = server.final_stats or {"late_frames": 0, "skipped_frames": 0, "link_outages": 0}
    print(f"antarium serve: {frames} frames, {stats['late_frames']} late, {stats['skipped_frames']} skipped, "
          f"{stats['link_outages']} link outages", flush=True)
    for path in server.trial_paths:
        print(f"antarium serve: trial log {path}", flush=True)
    return 0
