"""`antarium render SCENE --pos X Y Z --heading DEG --out view.png`: what the dome would show, as a picture."""

from __future__ import annotations

import argparse
import json
import math

#: the widest map `render` draws (pixels): wider ones only cost memory (the image library refuses 2**23)
MAX_WIDTH_PX = 8192

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
    from antarium.plots.dome_map import MIN_WIDTH_PX

    parser.add_argument("scene", help="scene name (habitat, grating, bars, ...), mesh/panorama file, or JSON table")
    parser.add_argument("--set", dest="settings", action="append", metavar="KEY=VALUE",
                        help="scene parameter, e.g. --set period_deg=20 (repeatable; values are JSON)")
    parser.add_argument("--pos", nargs=3, type=float, default=(0.0, 0.0, 0.01), metavar=("X", "Y", "Z"),
                        help="eye position in metres, Z the height above the ground, >= 0 (default: 0 0 0.01)")
    parser.add_argument("--heading", type=float, default=0.0, help="heading in degrees (default %(default)s)")
    parser.add_argument("--time", type=float, default=0.0,
                        help="stimulus time in seconds, for drifting stimuli (default %(default)s)")
    parser.add_argument("--out", default="view.png", metavar="FILE.png",
                        help="equal-area map of the LED colours (PNG; default %(default)s; folders made, an existing "
                             "file is overwritten)")
    parser.add_argument("--cube", default=None, metavar="FILE.png",
                        help="also save the raw cube map (six faces, top to bottom looking the eye's forward (+x), "
                             "back, left (+y), right, up, down; PNG; folders made, an existing file is overwritten)")
    parser.add_argument("--face-size", type=int, default=None,
                        help="cube face side in texels (default: the renderer's; allowed: from the smallest that "
                             "samples every LED's footprint, 55 at the dome's 1.5 degree pitch, to 2048)")
    parser.add_argument("--width", type=int, default=1200,
                        help=f"picture width in pixels, {MIN_WIDTH_PX}..{MAX_WIDTH_PX}: narrower maps have illegible "
                             "text (default %(default)s)")


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from antarium.commands import check_output
    from antarium.core.numbers import check_number
    from antarium.core.pose import Pose
    from antarium.geometry import load_dome
    from antarium.plots.dome_map import MIN_WIDTH_PX, atlas_image, dome_picture, save_png
    from antarium.renderers.library import build_scene
    from antarium.renderers.renderer import MAX_FACE_SIZE, Renderer, smallest_face_size

    x, y, z = (check_number(f"--pos {axis} (metres)", v) for axis, v in zip("XYZ", args.pos, strict=True))
    pose = Pose.from_deg(x, y, z, heading_deg=check_number("--heading (degrees)", args.heading))
    if not MIN_WIDTH_PX <= args.width <= MAX_WIDTH_PX:
        raise ValueError(f"--width must be at least {MIN_WIDTH_PX} pixels (narrower maps have illegible text) and at "
                         f"most {MAX_WIDTH_PX}, got {args.width}")
    if z < 0:
        raise ValueError(f"--pos Z is the eye's height above the ground (z = 0) in metres and must be >= 0, "
                         f"got {z:g}")
    if not math.isfinite(args.time):
        raise ValueError(f"--time must be a finite number of seconds, got {args.time:g}")
    if args.face_size is not None:
        check_number("--face-size (cube face_size, texels)", args.face_size, smallest_face_size(), MAX_FACE_SIZE,
                     integer=True)
    # both names checked before anything is rendered or written
    check_output(args.out, "--out", suffixes=(".png",))
    if args.cube:
        check_output(args.cube, "--cube", suffixes=(".png",))
        if Path(args.cube).expanduser().resolve() == Path(args.out).expanduser().resolve():
            raise ValueError(f"--cube and --out name the same file {args.out!r}; give two names")
    try:  # bad scenes fail before GL starts
        scene = build_scene(parse_scene_spec(args.scene, args.settings))
    except ValueError as exc:
        if not args.settings:
            raise
        raise ValueError(f"{exc} (scene {args.scene!r} with --set {' --set '.join(args.settings)})") from None
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
