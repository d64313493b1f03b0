"""`antarium render SCENE --pos X Y Z --heading DEG --out view.png`: what the dome would show, as a picture."""

from __future__ import annotations

import argparse
import json
import math

HELP = "render a scene for one eye pose and save the LED frame as an equal-area map (and the raw cube map)"


def parse_scene_spec(scene: str, settings: list[str]) -> dict:
    """SCENE (a name, a file path, or a JSON table) plus KEY=VALUE settings -> a scene spec dict."""
    if scene.lstrip().startswith("{"):
        try:
            spec = json.loads(scene)
        except json.JSONDecodeError as exc:
            raise ValueError(f"scene JSON is not valid: {exc}") from None
        if not isinstance(spec, dict):
            raise ValueError("scene JSON must be a table, e.g. '{\"scene\": \"grating\", \"period_deg\": 20}'")
    else:
        spec = {"scene": scene}
    for item in settings or []:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise ValueError(f"--set expects KEY=VALUE, got {item!r}")
        try:
            spec[key] = json.loads(value)
        except json.JSONDecodeError:
            spec[key] = value
    return spec


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scene", help="scene name (habitat, grating, bars, ...), mesh/panorama file, or JSON table")
    parser.add_argument("--set", dest="settings", action="append", metavar="KEY=VALUE",
                        help="scene parameter, e.g. --set period_deg=20 (repeatable; values are JSON)")
    parser.add_argument("--pos", nargs=3, type=float, default=(0.0, 0.0, 0.01), metavar=("X", "Y", "Z"),
                        help="eye position in metres (default: 0 0 0.01)")
    parser.add_argument("--heading", type=float, default=0.0, help="heading in degrees (default 0)")
    parser.add_argument("--time", type=float, default=0.0, help="stimulus time in seconds (drifting stimuli)")
    parser.add_argument("--out", default="view.png", help="equal-area map of the LED colours (PNG)")
    parser.add_argument("--cube", default=None, help="also save the raw cube map (six faces, PNG)")
    parser.add_argument("--face-size", type=int, default=None, help="cube face size in texels")
    parser.add_argument("--width", type=int, default=1200, help="picture width in pixels (default 1200)")


def run(args: argparse.Namespace) -> int:
    from antarium.core.pose import Pose
    from antarium.geometry import load_dome
    from antarium.plots.dome_map import atlas_image, check_png_path, dome_picture, save_png
    from antarium.renderers.library import build_scene
    from antarium.renderers.renderer import Renderer

    pose = Pose.from_deg(*args.pos, heading_deg=args.heading)
    if args.width < 64:
        raise ValueError(f"--width must be at least 64 pixels, got {args.width}")
    if args.pos[2] < 0:
        raise ValueError(f"--pos Z is the eye's height above the ground (z = 0) in metres and must be >= 0, "
                         f"got {args.pos[2]:g}")
    if not math.isfinite(args.time):
        raise ValueError(f"--time must be a finite number of seconds, got {args.time:g}")
    check_png_path(args.out, "--out")  # both names checked before anything is rendered or written
    if args.cube:
        check_png_path(args.cube, "--cube")
    scene = build_scene(parse_scene_spec(args.scene, args.settings))  # bad scenes fail before GL starts
    dome = load_dome()
    renderer = Renderer(dome, face_size=args.face_size)
    try:
        renderer.set_scene(scene)
        frame = renderer.render(pose, t=args.time)
        title = (f"What the dome shows: scene {renderer.scene.name!r} at ({args.pos[0]:g}, {args.pos[1]:g}, "
                 f"{args.pos[2]:g}) m, heading {args.heading:g}°, t = {args.time:g} s")
        path = dome_picture(frame, dome, args.out, title, width_px=args.width)
        print(f"LED map written to {path}")
        if args.cube:
            print(f"cube map written to {save_png(atlas_image(renderer.cube_map(pose, t=args.time)), args.cube)}")
        t = renderer.last_timings
        print(f"scene {renderer.scene.name!r}, {renderer.scene.n_triangles} triangles; frame: render "
              f"{t['render'] * 1e3:.2f} ms, sample {t['sample'] * 1e3:.2f} ms, convert {t['convert'] * 1e3:.2f} ms")
    finally:
        renderer.release()
    return 0
