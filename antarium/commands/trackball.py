"""`antarium trackball`: run a locomotion input (USB trackball or FicTrac) and publish it, or calibrate the ball.

    antarium trackball --config rig.toml                 # USB trackball -> bus (locomotion + events)
    antarium trackball --emulate --seconds 10            # the emulated device, for demos
    antarium trackball --source fictrac --port 5000      # FicTrac's UDP stream -> bus
    antarium trackball calibrate --config rig.toml       # guided: whole turns about z, x, y; writes [trackball]

Samples go to `antarium/<rig>/locomotion` (44-byte `antarium.locomotion.wire` structs), device events
(locomotion_connected / locomotion_lost / locomotion_back, JSON) to `antarium/<rig>/events`, and the
source's status (JSON) once a second to `antarium/<rig>/trackball/status`.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from typing import TYPE_CHECKING, Any

from antarium.commands import require_seconds

if TYPE_CHECKING:
    from antarium.config import RigConfig

HELP = "run the USB trackball or FicTrac input and publish it on the bus; `calibrate` the ball's sensors"

#: the values of the options below left out (given as None, so that `refuse_others` sees what the user gave)
DEFAULTS: dict[str, Any] = {"replug_after": 0.5, "transport": "udp", "host": "127.0.0.1", "port": 5000,
                            "axes": "z,x,y", "turns": 3.0}

#: option -> (where it applies, in words for the message; whether it applies to `args`)
ONLY_WITH: dict[str, tuple[str, Any]] = {
    "--unplug-at": ("--emulate", lambda a: a.emulate),
    "--replug-after": ("--emulate", lambda a: a.emulate),
    "--transport": ("--source fictrac", lambda a: a.source == "fictrac"),
    "--host": ("--source fictrac", lambda a: a.source == "fictrac"),
    "--port": ("--source fictrac", lambda a: a.source == "fictrac"),
    "--path": ("--source fictrac-replay", lambda a: a.source == "fictrac-replay"),
    "--axes": ("calibrate", lambda a: a.action == "calibrate"),
    "--turns": ("calibrate", lambda a: a.action == "calibrate"),
    "--dry-run": ("calibrate", lambda a: a.action == "calibrate"),
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("action", nargs="?", default="run", choices=("run", "calibrate"),
                        help="run (default): publish samples; calibrate: guided calibration")
    parser.add_argument("--config", default=None, help="rig config TOML ([trackball], [bus], [rig] sections)")
    parser.add_argument("--source", default="usb", choices=("usb", "fictrac", "fictrac-replay"),
                        help="locomotion input (default usb)")
    parser.add_argument("--emulate", action="store_true", help="use the emulated USB trackball (no hardware)")
    parser.add_argument("--seconds", type=float, default=None, help="stop after this long (default: until Ctrl-C)")
    parser.add_argument("--no-bus", action="store_true", help="do not publish; print status only")
    parser.add_argument("--unplug-at", type=float, default=None,
                        help="emulated device: pull the cable after this many seconds (demo of unplug handling)")
    parser.add_argument("--replug-after", type=float, default=None,
                        help=f"emulated device: replug after (s; default {DEFAULTS['replug_after']:g})")
    parser.add_argument("--transport", default=None, choices=("udp", "tcp"),
                        help=f"FicTrac transport (FicTrac 2.1 sends UDP only; tcp fits 2.0; default "
                             f"{DEFAULTS['transport']})")
    parser.add_argument("--host", default=None,
                        help=f"FicTrac: UDP address to bind / TCP host to connect (default {DEFAULTS['host']})")
    parser.add_argument("--port", type=int, default=None,
                        help=f"FicTrac socket port, 0..65535 (default {DEFAULTS['port']})")
    parser.add_argument("--path", default=None, help="FicTrac .dat log for --source fictrac-replay")
    parser.add_argument("--axes", default=None, help=f"calibrate: rotation axes, in order (default {DEFAULTS['axes']})")
    parser.add_argument("--turns", type=float, default=None,
                        help=f"calibrate: whole turns per axis (default {DEFAULTS['turns']:g})")
    parser.add_argument("--dry-run", action="store_true", help="calibrate: print the result, do not write it")


def _rig(config_path: str | None) -> RigConfig:
    """The rig config at `config_path` (the embedded default for None); ConfigError when it is missing or bad."""
    from antarium.config import load_config

    return load_config(config_path)


def _open_source(args: argparse.Namespace, rig: RigConfig, on_sample=None, on_event=None):
    from antarium.locomotion import open_source

    if args.source == "usb":
        from antarium.locomotion.trackball import config as tbconfig

        trackball = tbconfig.load(args.config)
        if not math.isclose(trackball.ball_radius, rig.loop.ball_radius_m):
            print(f"warning: [trackball] ball_radius {trackball.ball_radius} m differs from [loop] ball_radius "
                  f"{rig.loop.ball_radius_m} m: the ant's motion will be scaled by their ratio", file=sys.stderr)
        backend = None
        if args.emulate:
            from antarium.locomotion.trackball.emulator import EmulatedTrackball, walk

            backend = EmulatedTrackball(motion=walk(radius=trackball.ball_radius), truth=trackball,
                                        replug_after_s=args.replug_after)
        return open_source("usb", trackball=trackball, backend=backend, on_sample=on_sample, on_event=on_event)
    if args.emulate:
        raise ValueError("--emulate applies to --source usb only")
    if args.source == "fictrac":
        return open_source("fictrac", transport=args.transport, host=args.host, port=args.port)
    if args.path is None:
        raise ValueError("--source fictrac-replay needs --path FILE.dat")
    return open_source("fictrac-replay", path=args.path)


class _Publisher:
    """Samples, events and status of one source on the bus (or nowhere with `session=None`)."""

    def __init__(self, session, rig: str) -> None:
        from antarium import bus

        self.session = session
        self.sample_pub = bus.locomotion_publisher(session, rig) if session else None
        self.events_key = bus.events_key(rig)
        self.status_key = bus.rig_key(rig, "trackball", "status")

    def sample(self, sample) -> None:
        if self.sample_pub is not None:
            from antarium.locomotion import wire

            self.sample_pub.put(wire.encode(sample))

    def event(self, event: dict[str, Any]) -> None:
        print(f"trackball event: {json.dumps(event)}", flush=True)
        if self.session is not None:
            self.session.put(self.events_key, json.dumps(event))

    def status(self, status: dict[str, Any]) -> None:
        if self.session is not None:
            self.session.put(self.status_key, json.dumps(status))


def _run(args: argparse.Namespace, rig: RigConfig) -> int:
    session = None
    if not args.no_bus and rig.bus.enabled:
        from antarium.bus import open_session

        session = open_session(rig.bus, role="client")
    publisher = _Publisher(session, rig.rig.name)
    try:
        source = _open_source(args, rig, on_sample=publisher.sample, on_event=publisher.event)
        pushes = args.source != "usb"  # the USB driver publishes from its reader thread
        t0 = time.monotonic()
        next_status = t0
        unplug_at = args.unplug_at
        warned = False
        with source:
            _check_replay(args, source.status())
            try:  # Ctrl-C is how a run without --seconds ends: it ends the loop, the final status is printed
                while args.seconds is None or time.monotonic() - t0 < args.seconds:
                    samples = source.read()
                    if pushes:
                        for sample in samples:
                            publisher.sample(sample)
                    now = time.monotonic()
                    if unplug_at is not None and now - t0 >= unplug_at and args.emulate:
                        source.backend.unplug()
                        unplug_at = None
                    if now >= next_status:
                        status = source.status()
                        publisher.status(status)
                        print("trackball status: " + json.dumps(status), flush=True)
                        next_status += 1.0
                        if not warned and now - t0 >= 1.0 and not _ever_read(status):
                            # once, while it keeps looking: what is missing, not only `"connected": false`
                            print(f"antarium trackball: {_nothing_read(args, source, status)}; still waiting",
                                  file=sys.stderr, flush=True)
                            warned = True
                    time.sleep(0.002)
            except KeyboardInterrupt:
                pass
            final = source.status()
        print("trackball final: " + json.dumps(final), flush=True)
    finally:
        if session is not None:
            session.close()
    if not _ever_read(final):
        raise RuntimeError(_nothing_read(args, source, final))
    return 0


def _ever_read(status: dict[str, Any]) -> bool:
    """Whether the source ever delivered anything: a USB report, a FicTrac frame."""
    return bool(status.get("reports") or status.get("connects") or status.get("frames"))


def _nothing_read(args: argparse.Namespace, source, status: dict[str, Any]) -> str:
    """One line naming what was missing when `source` delivered nothing."""
    error = f" (last error: {status['last_error']})" if status.get("last_error") else ""
    if args.source == "usb":
        return (f"no USB trackball {status.get('device', '?')} found{error}: {source.lost_hint()} "
                "(--emulate: no hardware)")
    if args.source == "fictrac":
        return f"no FicTrac frame arrived{error}: {source.lost_hint()}"
    return f"--path {args.path}: no FicTrac frame was replayed{error}"


def _check_replay(args: argparse.Namespace, status: dict[str, Any]) -> None:
    """A replayed file without a single FicTrac frame is refused at once (a wrong file, e.g. an image)."""
    if args.source == "fictrac-replay" and not status.get("frames"):
        lines = status.get("lines", 0)
        why = f"none of its {lines} line{'s' * (lines != 1)} is a FicTrac frame" if lines else "it is empty"
        first = f" ({status['last_error']})" if status.get("last_error") else ""
        raise ValueError(f"--path {args.path}: not a FicTrac .dat log: {why}{first}")


def _calibrate(args: argparse.Namespace) -> int:
    from antarium.locomotion.trackball import calibration
    from antarium.locomotion.trackball import config as tbconfig
    from antarium.locomotion.trackball.driver import UsbTrackball

    if args.config is None and not args.dry_run:
        raise ValueError("calibrate needs --config RIG.toml (the file its results are written to) or --dry-run")
    if args.emulate and args.config is not None and not args.dry_run:
        raise ValueError("calibrate --emulate measures the emulated device, not this rig's ball: add --dry-run "
                         "(nothing is written), or leave out --emulate to calibrate the real trackball into "
                         f"{args.config}")
    axes = [a.strip() for a in args.axes.split(",") if a.strip()]
    bad = [a for a in axes if a not in calibration.AXES]
    if bad or not axes:
        raise ValueError(f"--axes must list some of {', '.join(calibration.AXES)}, got {args.axes!r}")
    if not args.turns > 0:
        raise ValueError(f"--turns must be > 0, got {args.turns}")
    # an existing file (`run` refused a missing one); None: the defaults. A calibration made at another resolution
    # than resolution_cpi is what this measures anew (the refusal's advice), not refused
    config = tbconfig.load(args.config, recalibrating=True)
    backend = calibration.miscalibrated_emulator(config) if args.emulate else None
    driver = UsbTrackball(trackball=config, backend=backend)
    with driver:
        driver.wait_connected(5.0)
        turn = _turn_by_hand if backend is None else (
            lambda driver, axis, turns: calibration.turn_emulated(driver, backend, axis, turns))
        steps = [calibration.measure(driver, axis, args.turns, turn) for axis in axes]
    result = calibration.calibrate(config, steps)
    print(f"{'axis':6}{'old counts/mm':>15}{'new counts/mm':>15}{'sign':>6}{'spread':>9}")
    spread = result.spread()
    for i, (old, new) in enumerate(zip(config.sensors, result.config.sensors, strict=True)):
        for j, a in enumerate("xy"):
            name = f"{a}{i}"
            print(f"{name:6}{old.counts_per_mm[j]:15.3f}{new.counts_per_mm[j]:15.3f}{new.signs[j]:6d}"
                  f"{spread[name]:9.2%}")
    if args.dry_run:
        print("dry run: rig config not changed")
    else:
        backup = tbconfig.write_section(args.config, result.config)
        if backup is None:
            print(f"wrote [trackball] counts_per_mm and signs to {args.config}; every other line is unchanged")
        else:
            print(f"wrote [trackball] to {args.config}, rewriting the whole file (its comments are not kept); "
                  f"the previous file is {backup}")
    return 0


def _turn_by_hand(driver, axis: str, turns: float) -> list[int]:
    """One calibration step: the operator turns the ball `turns` times about `axis`; the raw counts."""
    driver.reset_raw_counts()
    print(f"Mark the ball. Turn it {turns:g} whole turns about the dome's {axis} axis "
          f"(right-hand rule, {'+z up' if axis == 'z' else '+x forward, +y left'}), "
          f"then press Enter.", flush=True)
    sys.stdin.readline()
    return driver.raw_counts()


def refuse_others(args: argparse.Namespace) -> None:
    """ValueError naming the first option given (not None, not False) that does nothing in the use `args` asks
    for (`ONLY_WITH`); then the options left out get their `DEFAULTS`."""
    for option, (where, applies) in ONLY_WITH.items():
        if getattr(args, option[2:].replace("-", "_")) not in (None, False) and not applies(args):
            raise ValueError(f"{option} applies only with {where}; leave it out here")
    for name, value in DEFAULTS.items():
        if getattr(args, name) is None:
            setattr(args, name, value)


def run(args: argparse.Namespace) -> int:
    refuse_others(args)
    require_seconds(args, "seconds", "unplug_at", "replug_after")
    rig = _rig(args.config)  # every action: a --config that is missing or unreadable is refused before anything runs
    if args.action == "calibrate":
        return _calibrate(args)
    return _run(args, rig)
