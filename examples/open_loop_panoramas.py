"""Open loop: a sequence of static panoramas, each shown for a fixed time while the ball is only recorded.

The panoramas are equirectangular images (PNG/JPEG/EXR; 2:1, elevation +90 at the top row, azimuth 0 at the
left edge increasing to the right — see the renderer's panorama docs). Without `--panorama` the script writes
three of its own (a single dark landmark, two landmarks, a skyline) so that it runs anywhere. Each image is
shown in open loop (the ant's walking does not move the scene) for `--seconds`, all in one trial log, which
opens on the first image; its scene table holds when each image went on and its SHA-256. An image stays on while
the next one loads, so each but the last is on for `--seconds` plus the next one's load time (a panorama took
20 s to load with the embedded default's far layer on a 2-core machine without a GPU): the script prints how long
each image was on.

    antarium serve &
    python examples/open_loop_panoramas.py --panorama pano1.png --panorama pano2.png --seconds 30
    python examples/open_loop_panoramas.py --start-server --short --out panoramas
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from antarium.client import ScriptArgumentError, add_script_arguments, check_script_arguments, run_script, script_rig


def write_panoramas(folder: Path, width: int = 720) -> list[Path]:
    """Three simple 8-bit RGB panoramas: bright sky, dark ground, dark landmarks at chosen azimuths."""
    import cv2

    h = width // 2
    el = (0.5 - (np.arange(h) + 0.5) / h) * 180.0  # degrees, top row +90
    az = (np.arange(width) + 0.5) / width * 360.0
    layouts = {
        "one_landmark": [(90.0, 20.0, 30.0)],  # (azimuth_deg, width_deg, height_deg)
        "two_landmarks": [(45.0, 15.0, 25.0), (225.0, 30.0, 15.0)],
        "skyline": [(a, 12.0, 5.0 + 10.0 * abs(np.sin(np.radians(3 * a)))) for a in range(0, 360, 20)],
    }
    paths = []
    for name, landmarks in layouts.items():
        img = np.empty((h, width, 3), np.uint8)
        img[:] = (235, 215, 190)  # sky (BGR for OpenCV)
        img[el < 0] = (60, 80, 95)  # ground
        for centre, w, top in landmarks:
            d = np.abs((az - centre + 180.0) % 360.0 - 180.0) <= w / 2
            rows = (el >= 0) & (el <= top)
            img[np.ix_(rows, d)] = (30, 35, 30)
        path = folder / f"{name}.png"
        cv2.imwrite(str(path), img)
        paths.append(path)
    return paths


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_script_arguments(parser)
    parser.add_argument("--panorama", action="append", default=[],
                        help="panorama image (repeat for a sequence; default: three generated into --out)")
    parser.add_argument("--seconds", type=float, default=20.0,
                        help="seconds each panorama is shown (default %(default)g)")
    parser.add_argument("--out", default="panoramas-output",
                        help="folder for generated panoramas and the trial log (default %(default)s)")
    parser.add_argument("--short", action="store_true", help="quick run: 0.6 s per panorama")
    args = parser.parse_args(argv)
    if args.short:
        args.seconds = 0.6
    check_script_arguments(args, seconds=("seconds",))  # before anything is written or connected
    missing = [p for p in args.panorama if not Path(p).is_file()]
    if missing:
        raise ScriptArgumentError(f"--panorama {missing[0]}: no such file (give an image file: PNG, JPEG or EXR)")
    out = Path(args.out).resolve()  # made by script_rig once the rig answers
    with script_rig(args, out) as rig:
        panoramas = [Path(p).resolve() for p in args.panorama] or write_panoramas(out)
        rig.closed_loop(False)  # open loop: the ball is recorded, the scene does not follow it
        rig.set_pose(0.0, 0.0, heading_deg=0.0)
        rig.load_scene(panoramas[0])  # on before the trial starts: the log opens on the first image
        with rig.trial("open-loop-panoramas", panoramas=[p.name for p in panoramas], seconds=args.seconds) as log:
            on = []  # time.monotonic() when each image went on (load_scene replies once it is shown)
            for i, path in enumerate(panoramas):
                if i:
                    rig.load_scene(path)
                on.append(time.monotonic())
                print(f"showing {path.name} for {args.seconds:g} s")
                rig.wait(args.seconds)
            on.append(time.monotonic())
        status = rig.status()
    for path, start, end in zip(panoramas, on[:-1], on[1:], strict=True):
        print(f"{path.name} was on for {end - start:.2f} s")
    print(f"trial log: {log}")
    print(f"frames so far {status['frames']}, late {status['late_frames']}")
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
