"""`antarium bench monitor`: the monitor page in headless chromium, and the frame loop with the monitor on and off.

Runs `antarium bench loop` three times on the same rig config (`$ANTARIUM_RIG_CONFIG` or the embedded default):
"off" (no LED stream, no monitor), "monitor" (`[monitor] enabled`: the LED stream every `leds_every` frames and the
monitor process, no page open) and "page" (the same with the page open in Debian's headless chromium, driven by
Selenium, for the whole run). Reports the
loop's figures for both (late frames, latency) and, from the page itself: first paint, first LED frame drawn,
updates drawn per second and frame -> screen latency (the LED frame's hand-over on the server, `t_wall`, to the
end of its drawing in the browser's animation frame; both clocks are this computer's).
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import tempfile
import threading
import time
import urllib.request
from typing import Any

import numpy as np

CHROMIUM, CHROMEDRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class PageWatcher(threading.Thread):
    """Opens `url` in headless chromium once it answers and reads the page's figures until `stop`."""

    def __init__(self, url: str) -> None:
        super().__init__(name="page-watcher", daemon=True)
        self.url = url
        self.stop_event = threading.Event()
        self.browser_ready = threading.Event()
        self.result: dict[str, Any] = {}

    def run(self) -> None:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service

        options = webdriver.ChromeOptions()
        options.binary_location = CHROMIUM
        for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--window-size=1500,1100"):
            options.add_argument(arg)
        driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
        self.browser_ready.set()
        while not self.stop_event.is_set():
            try:
                urllib.request.urlopen(self.url, timeout=1).close()
                break
            except OSError:
                time.sleep(0.2)
        try:
            driver.get(self.url)
            time.sleep(2.0)  # warm-up
            start = driver.execute_script("return window.antariumMonitor.drawn")
            t0 = time.monotonic()
            self.stop_event.wait()
            m = driver.execute_script(
                "const M = window.antariumMonitor; return {drawn: M.drawn, latencies: M.latencies, "
                "first_draw_ms: M.firstDrawMs, updates: M.updates, draw_ms: M.drawMs, "
                "paint: performance.getEntriesByName('first-contentful-paint').map(p => p.startTime)}")
            seconds = time.monotonic() - t0
            lat = np.asarray(m["latencies"]) * 1e3
            self.result = {"updates_per_s": (m["drawn"] - start) / seconds, "seconds": seconds,
                           "first_contentful_paint_ms": (m["paint"] or [None])[0],
                           "first_led_frame_drawn_ms": m["first_draw_ms"],
                           "frame_to_screen_ms": {"p50": float(np.percentile(lat, 50)),
                                                  "p99": float(np.percentile(lat, 99)), "max": float(lat.max()),
                                                  "n": int(lat.size)} if lat.size else None}
            draw = np.asarray(m["draw_ms"], dtype=float).reshape(-1, 2)
            if len(draw):  # the page's own drawing of one LED frame: the map (2D canvas), the 3D view (WebGL)
                self.result["draw_ms_p50"] = {"map": float(np.median(draw[:, 0])), "3d": float(np.median(draw[:, 1]))}
        finally:
            driver.quit()


def run(args: argparse.Namespace) -> int:
    import tomli_w

    from antarium.bench import loop as loop_bench
    from antarium.config import load_config

    base = load_config(os.environ.get("ANTARIUM_RIG_CONFIG") or None)
    results: dict[str, Any] = {}
    with tempfile.TemporaryDirectory(prefix="antarium-bench-monitor-") as tmp:
        for mode in ("off", "monitor", "page"):
            config = base.to_toml_dict()
            port = _free_port()
            config["monitor"].update(enabled=mode != "off", port=port)
            if mode == "off":
                config["monitor"]["leds_every_frames"] = 0
            path = os.path.join(tmp, f"monitor-{mode}.toml")
            with open(path, "w") as fh:
                fh.write(tomli_w.dumps(config))
            print(f"--- monitor {mode} ---", flush=True)
            watcher = PageWatcher(f"http://127.0.0.1:{port}/") if mode == "page" else None
            if watcher is not None:
                watcher.start()
                watcher.browser_ready.wait(60)  # the browser is started before the loop, not during it
            os.environ["ANTARIUM_RIG_CONFIG"] = path
            loop_json = os.path.join(tmp, f"loop-{mode}.json")
            loop_bench.run(argparse.Namespace(seconds=args.seconds, frames=args.frames, json_out=loop_json,
                                              machine_probe=False))
            if watcher is not None:
                watcher.stop_event.set()
                watcher.join(30)
            with open(loop_json) as fh:
                loop = json.load(fh)
            results[mode] = {"loop": loop, "page": watcher.result if watcher is not None else None}
    page = results["page"]["page"]
    print("--- the page ---")
    if page:
        f2s = page["frame_to_screen_ms"]
        print(f"  first contentful paint {page['first_contentful_paint_ms']:.0f} ms, first LED frame drawn "
              f"{page['first_led_frame_drawn_ms']:.0f} ms after navigation")
        print(f"  updates drawn   {page['updates_per_s']:.1f} /s over {page['seconds']:.1f} s")
        if f2s:
            print(f"  frame -> screen p50 {f2s['p50']:.1f}  p99 {f2s['p99']:.1f}  max {f2s['max']:.1f} ms "
                  f"({f2s['n']} frames)")
        if "draw_ms_p50" in page:
            d = page["draw_ms_p50"]
            print(f"  page's drawing of one frame, p50: map {d['map']:.1f} ms, 3D view {d['3d']:.1f} ms")
    for mode in ("off", "monitor", "page"):
        r = results[mode]["loop"]
        lat = r["latency"]
        print(f"  loop, {mode:7s}: {r['achieved_rate_hz']:.1f} Hz, {r['late_frames']} late of {r['frames']}, "
              f"latency p50 {lat['p50_ms']:.2f} p99 {lat['p99_ms']:.2f} ms")
    if args.json_out:
        with open(args.json_out, "w") as fh:
            json.dump(results, fh, indent=2)
    return 0
