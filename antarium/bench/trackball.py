"""`antarium bench trackball`: driver throughput and arrival-to-publication latency, unplug detection, FicTrac parsing.

The driver runs the real pyusb path against the emulated device and publishes every sample on the bus
(a zenoh client on loopback, a server session subscribed to it), as `antarium trackball` does.
Goals: >= 1,000 reports/s with p99 < 0.5 ms from a report's arrival (the USB read returned) to its
publication (the bus `put` returned); unplug seen within 100 ms; FicTrac >= 10,000 lines/s.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from antarium.bench import progress, write_json
from antarium.core.rates import DOME_RATE_HZ, FRAME_PERIOD_S

GOAL_REPORTS_HZ = 1000.0
GOAL_P99_S = 0.5e-3
GOAL_UNPLUG_S = 0.1
GOAL_FICTRAC_HZ = 10_000.0


def _driver(seconds: float, realtime: bool, publish) -> dict:
    from antarium.locomotion.trackball.driver import UsbTrackball
    from antarium.locomotion.trackball.emulator import EmulatedTrackball, walk

    backend = EmulatedTrackball(motion=walk(), realtime=realtime)
    src = UsbTrackball(backend=backend, on_sample=publish, max_queue=1000)
    with src:
        deadline = time.monotonic() + 5.0
        while not src.status()["connected"] and time.monotonic() < deadline:
            time.sleep(0.001)
        n0, t0 = src.status()["reports"], time.perf_counter()
        time.sleep(seconds)
        n1, t1 = src.status()["reports"], time.perf_counter()
    status = src.status()  # after stop: every report handled is counted
    lat = src.latencies()
    return {
        "reports_per_s": (n1 - n0) / (t1 - t0),
        "latency_p50_ms": float(np.percentile(lat, 50) * 1e3),
        "latency_p99_ms": float(np.percentile(lat, 99) * 1e3),
        "latency_max_ms": float(lat.max() * 1e3),
        "reports": status["reports"], "lost_reports": status["lost_reports"],
    }


def _unplug(repeats: int) -> dict:
    from antarium.locomotion.trackball.driver import UsbTrackball
    from antarium.locomotion.trackball.emulator import EmulatedTrackball

    backend = EmulatedTrackball(realtime=True)
    delays = []
    with UsbTrackball(backend=backend, retry_s=0.005) as src:
        for _ in range(repeats):
            while not (src.status()["connected"] and src.status()["reports"] > 0):
                time.sleep(0.0005)
            time.sleep(0.02)
            t0 = time.perf_counter()
            backend.unplug()
            while src.status()["connected"]:
                time.sleep(0.0002)
            delays.append(time.perf_counter() - t0)
            backend.replug()
    d = np.array(delays)
    return {"unplug_detect_median_ms": float(np.median(d) * 1e3), "unplug_detect_max_ms": float(d.max() * 1e3),
            "repeats": repeats}


def _fictrac(lines: int) -> dict:
    from antarium.locomotion.fictrac.protocol import FicTracFrame, format_line, parse_line, to_sample

    rng = np.random.default_rng(0)
    text = []
    for i in range(1000):
        values = [float(v) for v in rng.normal(size=25)]
        values[0] = values[22] = i
        text.append(format_line(FicTracFrame(*values)).encode())
    t0 = time.perf_counter()
    for k in range(lines):
        to_sample(parse_line(text[k % 1000]), 0.0)
    dt = time.perf_counter() - t0
    return {"lines_per_s": lines / dt, "lines": lines}


def run(args: argparse.Namespace) -> int:
    from antarium import bus
    from antarium.locomotion import wire

    seconds = args.seconds or 2.0
    progress("trackball", f"two driver runs of {seconds:g} s, 20 unplugs, {args.frames or 100_000:,} FicTrac lines")
    endpoint = bus.free_tcp_endpoint()
    with bus.open_session({"listen": [endpoint]}, "server") as server, \
            bus.open_session({"listen": [endpoint]}, "client") as client:
        received = [0]
        server.declare_subscriber(bus.locomotion_key("bench"), lambda s: received.__setitem__(0, received[0] + 1))
        pub = bus.locomotion_publisher(client, "bench")
        time.sleep(0.3)  # let the client connect

        def publish(sample):
            pub.put(wire.encode(sample))

        paced = _driver(seconds, True, publish)
        time.sleep(0.2)
        paced["received_on_bus"] = received[0]
        flat_out = _driver(seconds, False, publish)
        time.sleep(0.2)
        flat_out["received_on_bus"] = received[0] - paced["received_on_bus"]
    unplug = _unplug(20)
    fictrac = _fictrac(args.frames or 100_000)
    results = {"paced_1khz": paced, "flat_out": flat_out, "unplug": unplug, "fictrac": fictrac}

    print("trackball driver (emulated device through pyusb, samples published on the bus over loopback TCP)")
    for name, r in (("paced at 1 kHz", paced), ("as fast as possible", flat_out)):
        print(f"  {name:22} {r['reports_per_s']:9.0f} reports/s ({r['reports_per_s'] / GOAL_REPORTS_HZ:5.1f}x the "
              f"1,000/s goal, {r['reports_per_s'] / DOME_RATE_HZ:5.1f} per dome frame); arrival->publication "
              f"p50 {r['latency_p50_ms']:.3f} ms, p99 {r['latency_p99_ms']:.3f} ms "
              f"({GOAL_P99_S * 1e3 / max(r['latency_p99_ms'], 1e-9):.1f}x under the 0.5 ms goal, "
              f"{r['latency_p99_ms'] * 1e-3 / FRAME_PERIOD_S:.1%} of a 5.3 ms frame), "
              f"max {r['latency_max_ms']:.2f} ms; "
              f"{r['received_on_bus']} of {r['reports']} samples received by the subscriber")
    print(f"  unplug seen by status(): median {unplug['unplug_detect_median_ms']:.2f} ms, max "
          f"{unplug['unplug_detect_max_ms']:.2f} ms over {unplug['repeats']} unplugs (goal 100 ms: "
          f"{GOAL_UNPLUG_S * 1e3 / max(unplug['unplug_detect_max_ms'], 1e-9):.0f}x margin)")
    print(f"FicTrac parser: {fictrac['lines_per_s']:,.0f} lines/s ({fictrac['lines_per_s'] / GOAL_FICTRAC_HZ:.1f}x "
          f"the 10,000/s goal, {fictrac['lines_per_s'] / DOME_RATE_HZ:,.0f} lines per dome frame)")
    print("(shared machine: timings are noisy)")
    if args.json_out:
        write_json(args.json_out, "trackball", results)
    return 0
