"""`antarium servosphere`: run the servosphere's control loop with a status line; `--simulate` runs the simulated
rig (ball, omniwheels, ant, camera, serial line) on a simulated clock, faster than real time unless --realtime.

    antarium servosphere --simulate --seconds 20 --plot servo.png
    antarium servosphere --config rig.toml           # [locomotion] source = "servosphere" with real back-ends
"""

from __future__ import annotations

import argparse
import math
import sys
import time

from antarium.commands import check_output, require_seconds
from antarium.core.numbers import check_number

HELP = "run the servosphere (free ant on a motion-compensating ball); --simulate for the simulated rig"


#: the simulated rig's option -> the command-line option that sets it (its range checks name the former)
SIMULATE_OPTIONS = {"speed": "--speed", "meander": "--meander", "pause_fraction": "--pauses", "slip": "--slip"}


#: the options only --simulate uses
SIMULATE_ONLY = ("--realtime", "--speed", "--meander", "--pauses", "--slip", "--seed")


class _Given(argparse.Action):
    """Store the value and note that the option was given (a default is not a choice the user made)."""

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, True if self.nargs == 0 else values)
        namespace.given = {*getattr(namespace, "given", ()), option_string}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--simulate", action="store_true", help="the simulated rig (no hardware)")
    parser.add_argument("--config", default=None, help="rig config TOML whose [locomotion] is the servosphere's")
    parser.add_argument("--seconds", type=float, default=10.0, help="how long to run (s; default 10)")
    parser.add_argument("--realtime", action=_Given, nargs=0, default=False, help="--simulate: pace on the wall clock")
    parser.add_argument("--speed", type=float, default=0.05, action=_Given,
                        help="--simulate: the ant's speed (m/s; default %(default)s)")
    parser.add_argument("--meander", type=float, default=2.0, action=_Given,
                        help="--simulate: s.d. of the ant's turn rate (rad/s, >= 0; default %(default)s)")
    parser.add_argument("--pauses", type=float, default=0.0, action=_Given,
                        help="--simulate: share of 0.5 s spurts the ant stands still (0..1; default %(default)s)")
    parser.add_argument("--slip", type=float, default=0.0, action=_Given,
                        help="--simulate: wheel slip fraction (0..0.5; default %(default)s)")
    parser.add_argument("--seed", type=int, default=0, action=_Given,
                        help="--simulate: random seed of the ant's walk (an integer >= 0; default %(default)s)")
    parser.add_argument("--plot", default=None, metavar="FILE.png",
                        help="write the error distribution and paths to this PNG (folders made; an existing file is "
                             "overwritten)")


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from antarium.core.ball import pole_motion
    from antarium.core.clock import MonotonicClock, SimulatedClock
    from antarium.locomotion import open_source

    require_seconds(args, "seconds")
    if args.simulate and args.config is not None:
        raise ValueError("--simulate and --config exclude each other; allowed: --simulate with --speed, --meander, "
                         "--pauses, --slip, --seed, --realtime; or --config (a simulated rig there takes "
                         "[locomotion] simulation = {speed, meander, pause_fraction, slip, seed})")
    given = sorted(o for o in getattr(args, "given", ()) if o in SIMULATE_ONLY)
    if given and not args.simulate:
        raise ValueError(f"{given[0]} is a --simulate option; allowed without --simulate: --config, --seconds, "
                         "--plot (with --config, a simulated rig takes [locomotion] simulation = {...})")
    if args.simulate:
        check_number("--seed", args.seed, 0, integer=True)
    if args.plot is not None:  # before the run, which a bad name would throw away
        check_output(args.plot, "--plot", suffixes=(".png",))
    simulated = args.simulate and not args.realtime
    clock = SimulatedClock() if simulated else MonotonicClock()
    if args.simulate:
        options = {"simulation": {"speed": args.speed, "meander": args.meander, "slip": args.slip, "seed": args.seed,
                                  "pause_fraction": args.pauses}}
    else:
        from antarium.config import load_config

        if args.config is None:
            raise ValueError("without --simulate a --config with [locomotion] source = \"servosphere\" is needed")
        config = load_config(args.config)
        locomotion = config.locomotion
        if locomotion.source != "servosphere":
            raise ValueError(f"{args.config}: [locomotion] source must be \"servosphere\"")
        # one ball, one tether: the loop's, as `antarium serve` passes them
        options = {"tether": config.loop.tether, "ball_radius": config.loop.ball_radius_m, **locomotion.options}
    try:
        # the loop here, in a thread of this process (its rig, its rows), whatever the config's `process` says
        src = open_source("servosphere", **{**options, "clock": clock, "process": False})
    except ValueError as exc:  # the simulated rig's own range checks: name the option that set the value
        option = next((o for key, o in SIMULATE_OPTIONS.items() if args.simulate and f" {key} " in f" {exc} "), None)
        raise ValueError(f"{option}: {exc}" if option else str(exc)) from None
    rows: list[tuple] = []
    src.use_log(type("Rows", (), {"add_servosphere": staticmethod(rows.append)})())
    radius = src.loop.geometry.sphere_radius
    ball_path = [np.zeros(2)]
    true_path = [np.zeros(2)]
    t_wall0 = time.perf_counter()
    t0 = clock.now()
    step = 1.0 / 190  # the dome's frame period: read() as the server's frame loop would
    src.start()
    try:
        k = 0
        while clock.now() - t0 < args.seconds:
            k += 1
            clock.sleep_until(t0 + k * step)
            for s in src.read():
                ball_path.append(ball_path[-1] + pole_motion(s.rotation, radius)[:2])
            if src.rig is not None:
                true_path.append(src.rig.true_path.copy())
            if k % 19 == 0 and rows:
                _status_line(rows, clock.now() - t0, time.perf_counter() - t_wall0)
    except KeyboardInterrupt:
        pass
    finally:
        src.stop()
    print(file=sys.stderr)
    err = np.array([(r[2], r[3]) for r in rows], dtype=float).reshape(-1, 2)
    dist = np.hypot(err[:, 0], err[:, 1])
    dist = dist[np.isfinite(dist)]
    rate = f"frames {len(rows)}, control loop {len(rows) / max(clock.now() - t0, 1e-9):.0f} Hz"
    if dist.size:
        print(f"{rate}; error from the apex: median {np.median(dist):.2f} mm, p99 {np.percentile(dist, 99):.2f} mm; "
              f"faults {src.status()['faults']}")
    else:
        print(f"{rate}; no ant tracked (no error statistics); faults {src.status()['faults']}")
    if src.rig is not None:
        walked = src.rig.walked
        gap = float(np.hypot(*(ball_path[-1] - src.rig.true_path)))
        print(f"walked {walked * 100:.1f} cm; path from the ball ends {gap * 1000:.1f} mm from the true one "
              f"({100 * gap / max(walked, 1e-9):.2f} % of the distance)")
    if args.plot and not dist.size:
        print(f"no plot written to {args.plot}: no ant tracked")
    elif args.plot:
        out = src.rig is not None
        from antarium.plots.servosphere import error_figure

        path = error_figure(err[:, 0], err[:, 1], np.array(true_path) if out else None,
                            np.array(ball_path) if out else None, args.plot,
                            title=f"Servosphere, {'simulated ' if args.simulate else ''}{args.seconds:g} s")
        print(f"wrote {path}")
    return 0


def _status_line(rows: list[tuple], t: float, wall: float) -> None:
    recent = rows[-700:]
    d = [math.hypot(r[2], r[3]) for r in recent if math.isfinite(r[2])]
    last = rows[-1]
    heading = math.degrees(last[5]) if math.isfinite(last[5]) else float("nan")
    faults = sum(1 for r in recent if r[-1])
    line = (f"t {t:7.2f} s  ({t / max(wall, 1e-9):5.1f}x real time)  frames {last[1]:7d}  "
            f"error {sorted(d)[len(d) // 2] if d else float('nan'):5.2f} mm  heading {heading:7.1f} deg  "
            f"faulty frames (last 1 s) {faults:4d}")
    print("\r" + line, end="", file=sys.stderr, flush=True)
