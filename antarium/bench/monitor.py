"""`antarium bench monitor`: the monitor page in headless chromium, and the frame loop with the monitor on and off.

Runs `antarium bench loop` three times on the same rig config (`$ANTARIUM_RIG_CONFIG` or the embedded default):
"off" (no LED stream, no monitor), "monitor" (`[monitor] enabled`: the LED stream every `leds_every` frames and the
monitor process, no page open) and "page" (the same with the page open in Debian's headless chromium, driven by
Selenium, for the whole run). Reports the
loop's figures for both (late frames, latency) and, from the page itself over a window from 2 s after it opened to
the loop's last frame: first paint, first LED frame drawn, updates drawn per second, frame -> screen latency (every
LED frame drawn in that window) (the LED frame's hand-over on the server, `t_wall`, to the
end of its drawing in the browser's animation frame; both clocks are this computer's) and the browser's CPU time per
update drawn (all its processes). On a small machine the browser takes CPU from the loop, where in a lab it runs on
the experimenter's computer: `--browser-idle` runs it SCHED_IDLE, so that it gets only what the loop leaves.
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import sys
import tempfile
import threading
import time
import urllib.request
from typing import Any

import numpy as np

from antarium.bench import write_json
from antarium.bench.cpu import process_tree_cpu_s

CHROMIUM, CHROMEDRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def idle_browser(binary: str, folder: str) -> str:
    """A script in `folder` that runs `binary` SCHED_IDLE. Its processes inherit the class, and the browser cannot
    leave it by itself: chromium raises its own processes' nice values (to -8 when it may), which a nice value given
    from outside does not stop."""
    path = os.path.join(folder, "browser-idle")
    with open(path, "w") as fh:
        fh.write(f"#!{sys.executable}\nimport os, sys\n"
                 "os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))\n"
                 f"os.execv({binary!r}, [{binary!r}, *sys.argv[1:]])\n")
    os.chmod(path, 0o755)
    return path


def page_figures(m: dict[str, Any], seconds: float, cpu_s: float) -> dict[str, Any]:
    """The page's figures over a measuring window of `seconds` (s) in which the browser took `cpu_s` of CPU time:
    `m` is what the page reported at the window's end, `measured` the frame -> screen latencies (s) of the LED
    frames it drew in the window (the page keeps them from the window's start: `M.measured`), `drawn` the frames
    drawn in the window."""
    lat = np.asarray(m["measured"], dtype=float) * 1e3
    drawn = m["drawn"]
    out = {"updates_per_s": drawn / seconds, "seconds": seconds, "browser_cpu_per_s": cpu_s / seconds,
           "browser_cpu_ms_per_update": 1e3 * cpu_s / drawn if drawn else None,
           "first_contentful_paint_ms": (m["paint"] or [None])[0], "first_led_frame_drawn_ms": m["first_draw_ms"],
           "frame_to_screen_ms": {"p50": float(np.percentile(lat, 50)), "p99": float(np.percentile(lat, 99)),
                                  "max": float(lat.max()), "n": int(lat.size)} if lat.size else None}
    draw = np.asarray(m["draw_ms"], dtype=float).reshape(-1, 2)
    if len(draw):  # the page's own drawing of one LED frame: the map (2D canvas), the 3D view (WebGL)
        out["draw_ms_p50"] = {"map": float(np.median(draw[:, 0])), "3d": float(np.median(draw[:, 1]))}
    return out


def page_lines(page: dict[str, Any] | None) -> list[str]:
    """The report's lines for the page's figures (`page_figures`); what the page never measured (no paint, no LED
    frame drawn: e.g. the rig config's `[monitor] leds_every_frames = 0`) is said as such."""
    if not page:
        return ["  the page reported nothing (it did not open)"]

    def ms(v: float | None) -> str:
        return "none" if v is None else f"{v:.0f} ms"

    lines = [f"  first contentful paint {ms(page['first_contentful_paint_ms'])}, first LED frame drawn "
             f"{ms(page['first_led_frame_drawn_ms'])} after navigation",
             f"  updates drawn   {page['updates_per_s']:.1f} /s over {page['seconds']:.1f} s"]
    if page["browser_cpu_ms_per_update"]:
        lines.append(f"  browser CPU     {page['browser_cpu_ms_per_update']:.1f} ms per update drawn (all its "
                     f"processes, {page['browser_cpu_per_s']:.2f} of a core): with a core to itself, up to "
                     f"{1e3 / page['browser_cpu_ms_per_update']:.0f} updates/s")
    f2s = page["frame_to_screen_ms"]
    if f2s:
        lines.append(f"  frame -> screen p50 {f2s['p50']:.1f}  p99 {f2s['p99']:.1f}  max {f2s['max']:.1f} ms "
                     f"({f2s['n']} frames)")
    else:
        lines.append("  frame -> screen: no LED frame drawn (is the LED stream on? [monitor] leds_every_frames)")
    if "draw_ms_p50" in page:
        d = page["draw_ms_p50"]
        lines.append(f"  page's drawing of one frame, p50: map {d['map']:.1f} ms, 3D view {d['3d']:.1f} ms")
    return lines


class PageWatcher(threading.Thread):
    """Opens `url` in headless chromium once it answers and measures the page from a warm-up after it opened until
    `stop_event` (set when the loop's frames end: `bench loop`'s `on_frames_end`)."""

    def __init__(self, url: str, browser: str = CHROMIUM) -> None:
        super().__init__(name="page-watcher", daemon=True)
        self.url, self.browser = url, browser
        self.stop_event = threading.Event()
        self.browser_ready = threading.Event()
        self.result: dict[str, Any] = {}

    def run(self) -> None:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service

        options = webdriver.ChromeOptions()
        options.binary_location = self.browser
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
            # the window opens: the frames drawn from here on, each one's latency kept by the page
            start = driver.execute_script("const M = window.antariumMonitor; M.measured = []; return M.drawn")
            browser_pid = driver.service.process.pid
            t0, cpu0 = time.monotonic(), process_tree_cpu_s(browser_pid)
            self.stop_event.wait()  # the loop's frames ended: the window closes
            seconds = time.monotonic() - t0
            cpu = process_tree_cpu_s(browser_pid) - cpu0
            m = driver.execute_script(
                "const M = window.antariumMonitor; const measured = M.measured; M.measured = null; "
                "return {drawn: M.drawn, measured: measured, first_draw_ms: M.firstDrawMs, updates: M.updates, "
                "draw_ms: M.drawMs, "
                "paint: performance.getEntriesByName('first-contentful-paint').map(p => p.startTime)}")
            m["drawn"] -= start
            self.result = page_figures(m, seconds, cpu)
        finally:
            driver.quit()


def run(args: argparse.Namespace) -> int:
    import tomli_w

    from antarium.bench import loop as loop_bench
    from antarium.config import load_config

    base = load_config(os.environ.get("ANTARIUM_RIG_CONFIG") or None)
    results: dict[str, Any] = {}
    idle = getattr(args, "browser_idle", False)
    with tempfile.TemporaryDirectory(prefix="antarium-bench-monitor-") as tmp:
        browser = idle_browser(CHROMIUM, tmp) if idle else CHROMIUM
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
            watcher = PageWatcher(f"http://127.0.0.1:{port}/", browser) if mode == "page" else None
            if watcher is not None:
                watcher.start()
                watcher.browser_ready.wait(60)  # the browser is started before the loop, not during it
            os.environ["ANTARIUM_RIG_CONFIG"] = path
            loop_json = os.path.join(tmp, f"loop-{mode}.json")
            loop_bench.run(argparse.Namespace(
                seconds=args.seconds, frames=args.frames, json_out=loop_json, machine_probe=False,
                on_frames_end=watcher.stop_event.set if watcher is not None else None))
            if watcher is not None:
                watcher.stop_event.set()
                watcher.join(30)
            with open(loop_json) as fh:
                loop = json.load(fh)
            results[mode] = {"loop": loop, "page": watcher.result if watcher is not None else None}
    print(f"--- the page (browser {'SCHED_IDLE' if idle else 'at normal priority'}) ---")
    for line in page_lines(results["page"]["page"]):
        print(line)
    for mode in ("off", "monitor", "page"):
        r = results[mode]["loop"]
        lat = r["latency"]
        print(f"  loop, {mode:7s}: {r['achieved_rate_hz']:.1f} Hz, {r['late_frames']} late of {r['frames']}, "
              f"latency p50 {lat['p50_ms']:.2f} p99 {lat['p99_ms']:.2f} ms")
    if args.json_out:
        write_json(args.json_out, "monitor", results)
    return 0
