"""Virtual displacement: the ant walks in closed loop, then is moved instantly to another place in its world.

The classic displacement experiment without catching the ant: after `--before` seconds at the start the ant
is put at (`--to-x`, `--to-y`) with the same heading mapping, and walks on for `--after` seconds. The trial
log holds the path; the plot shows it in the world, with the jump dashed.

    antarium serve &
    python examples/virtual_displacement.py --to-x 4 --to-y -3 --out displacement
    python examples/virtual_displacement.py --start-server --short --out displacement
"""

from __future__ import annotations

import argparse
import sys
import threading
from pathlib import Path

import numpy as np

from antarium.client import add_script_arguments, check_script_arguments, run_script, script_rig


def plot(updates, png: Path) -> Path:
    """The world path, written to the PNG `png`; the displacement is the one step far longer than walking allows."""
    from antarium.plots import style

    xy = np.array([(u.pose.x, u.pose.y) for u in updates])
    steps = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    jump = int(np.argmax(steps)) + 1 if len(steps) else len(xy)
    index = np.arange(len(xy))
    before, after = index < jump, index >= jump
    fig, ax = style.figure((7.5, 5))
    ax.plot(*xy[before].T, color="tab:orange", label="before displacement")
    ax.plot(*xy[after].T, color="tab:green", label="after displacement")
    if before.any() and after.any():
        a, b = xy[before][-1], xy[after][0]
        ax.plot([a[0], b[0]], [a[1], b[1]], "k--", lw=0.8, label="virtual displacement")
    ax.plot(*xy[0], "ko", ms=4, label="start")
    ax.set_aspect("equal", adjustable="datalim")
    style.label(ax, "Virtual displacement: the ant's path in the world", "world x (m)", "world y (m)")
    style.legend(ax, "right")
    return style.save(fig, png)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_script_arguments(parser)
    parser.add_argument("--to-x", type=float, default=4.0, help="x of the new place (m, default %(default)g)")
    parser.add_argument("--to-y", type=float, default=-3.0, help="y of the new place (m, default %(default)g)")
    parser.add_argument("--before", type=float, default=30.0,
                        help="seconds before the displacement (default %(default)g)")
    parser.add_argument("--after", type=float, default=30.0, help="seconds after it (default %(default)g)")
    parser.add_argument("--out", default="displacement-output",
                        help="folder for the plot and the trial logs (default %(default)s)")
    parser.add_argument("--short", action="store_true", help="quick run: 1 s before and after")
    args = parser.parse_args(argv)
    if args.short:
        args.before = args.after = 1.0
    check_script_arguments(args, seconds=("before", "after"), numbers=("to_x", "to_y"))  # before connecting
    out = Path(args.out).resolve()  # made by script_rig once the rig answers
    updates, lock = [], threading.Lock()

    def keep(update):
        with lock:
            updates.append(update)

    with script_rig(args, out) as rig:
        rig.load_scene("habitat")
        rig.closed_loop(True)
        rig.reset_origin(0.0, 0.0, 0.0)
        with rig.trial("virtual-displacement", to=[args.to_x, args.to_y]) as log:
            poses = rig.on_pose(keep)  # the plot shows the trial's path, as its log holds it
            rig.wait(args.before)
            state = rig.set_pose(args.to_x, args.to_y)
            rig.wait(args.after)
            poses.undeclare()
        print(f"displaced to ({state['pose']['x']:.2f}, {state['pose']['y']:.2f}) m; trial log: {log}")
    with lock:
        done = list(updates)
    print(f"plot: {plot(done, out / (Path(log).stem + '_path.png'))}")  # named after its log: a reused --out keeps both
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
