"""The embedded default rig for a short fixed time, leaving what a user wants to see (`antarium demo --rig-seconds`).

Runs `antarium serve`'s embedded default (the emulator as its own process on loopback, the default habitat,
the scripted walker in closed loop), records one trial, rotates the scene by 90 degrees half-way (the
paper's manipulation), and writes into `out`:

- `trials/<rig>_<time>_demo.h5`: the trial log (docs/logs.md);
- `demo_path.png`: the walker's path in the world, with the rotation marked;
- `demo_dome.png`: what the dome showed at the end — the last frame sent, latched by the dome emulator
  (dot correction included), as an equal-area map seen from inside.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np


def run_demo_rig(out: str | Path, seconds: float = 8.0, echo=print, render: dict | None = None) -> dict[str, Path]:
    """Run the embedded default rig for `seconds` and write the outputs; returns their paths by name.
    `render` overrides `[render]` keys (e.g. a lighter scene for a quick check)."""
    import threading

    from antarium.bus import free_tcp_endpoint
    from antarium.config import RenderSection, load_config
    from antarium.server import Server

    out = Path(out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    config = load_config(None)
    config.log.dir = str(out / "trials")
    config.render = RenderSection.read({**config.render.model_dump(), **(render or {})})
    config.bus.listen = [free_tcp_endpoint()]  # never collide with a running `antarium serve`
    server = Server(config, record="demo", echo=lambda line: None)
    not_rotated: list[str] = []

    def rotate_half_way() -> None:
        try:
            server.command("rotate_scene", {"deg": 90})
        except RuntimeError as exc:  # the run ended first (a very short run): said below, not a thread traceback
            not_rotated.append(str(exc))

    rotate = threading.Timer(seconds / 2, rotate_half_way)
    server_ready = threading.Thread(target=lambda: server.wait_ready(120) and rotate.start(), daemon=True)
    server_ready.start()
    try:
        frames = server.run(seconds=seconds)
    finally:
        rotate.cancel()  # a timer started after this never fires
        if rotate.ident is not None:  # started: a rotation under way ends before the outputs are written
            rotate.join()
    log = server.trial_paths[0]
    stats = server.final_stats
    echo(f"demo rig: {frames} frames in {seconds:g} s ({stats['late_frames']} late, target "
         f"{config.loop.rate_hz:g}/s; the renderer sets the pace on a CPU), latency p50 "
         f"{_ms(stats['latency'], 'p50')}, p99 {_ms(stats['latency'], 'p99')}")
    if not _rotated(log):  # the log decides: the rotation failed, never started, or came after the last frame
        why = not_rotated[0] if not_rotated else "the run ended before the rotation reached the loop"
        echo(f"demo rig: the scene was not rotated ({why}); give a longer run to see the rotation")
    paths = {"trial log": log, "path plot": plot_path(log, out / "demo_path.png")}
    if server.final_frame is not None:
        paths["dome picture"] = dome_picture(server.final_frame, out / "demo_dome.png")
    return paths


def _rotated(log: Path) -> bool:
    """Whether any frame of the trial log shows the scene rotated."""
    from antarium.trial_log import read_table

    return bool(np.any(read_table(log, "frames")["scene_rotation"] != 0))


def _ms(p: dict[str, Any] | None, key: str) -> str:
    return "n/a" if not p else f"{p[key] * 1e3:.1f} ms"


def plot_path(log: Path, target: Path) -> Path:
    """The world path from a trial log's frames table, coloured by time, scene rotations marked."""
    from antarium.plots.paths import world_path
    from antarium.trial_log import read_table

    f = read_table(log, "frames")
    turned = np.flatnonzero(np.abs(np.diff(f["scene_rotation"])) > 1e-9) + 1
    return world_path(f["x"], f["y"], f["t_start"] - f["t_start"][0], turned, target,
                      f"Closed-loop path of the scripted walker ({len(f['x'])} frames)", "scene rotated 90°")


def dome_picture(frame: np.ndarray, target: Path) -> Path:
    """What the dome shows for `frame`: sent through the emulator's datagram path, its latched LEDs mapped."""
    from antarium.firmware_proto.link import open_link
    from antarium.geometry import load_dome
    from antarium.plots.dome_map import dome_picture as picture

    link = open_link("virtual")
    try:
        link.send_frame(frame)
        leds = link.emulator.led_values()
    finally:
        link.close()
    return picture(leds, load_dome(), target, "What the dome showed at the end of the demo (latched by the "
                                              "dome emulator)")
