"""The Antarium paper's proof of concept (Kócsi et al. 2020, Figure 4): scene rotations in closed loop.

Four conditions, as in the paper: the view half-way from the nest towards a tree (Familiar), the view from
the nest (Nest), a view 5 m off that route (Unfamiliar) — all in the default habitat — and a horizon line
only (Unstructured). In each, the ant walks in closed loop (tether free in yaw) and the scene is rotated
instantly by +90 or -90 degrees at seeded random times. One trial log per condition; the plot shows the
ant's path on the ball (dome frame) 15 s before (red) and after (blue) each rotation, a dot where it happened.

With the embedded default the walker is scripted and blind, so its path does not answer the rotations; a
real ant on the trackball (or a virtual ant publishing on the bus) does.

    antarium serve &                                  # the embedded default rig
    python examples/proof_of_concept.py --out poc     # about 8 minutes
    python examples/proof_of_concept.py --start-server --short --out poc   # a quick run, server included
"""

from __future__ import annotations

import argparse
import math
import random
import sys
import threading
from pathlib import Path

import numpy as np

from antarium.client import ScriptArgumentError, add_script_arguments, check_script_arguments, run_script, script_rig


def condition_poses(seed: int = 0) -> dict[str, tuple[object, float, float, float]]:
    """condition -> (scene, x, y, heading_deg): positions taken from the seeded default habitat."""
    from antarium.renderers.habitat import habitat_objects

    tree = np.asarray(habitat_objects(seed)["tree_0"].position[:2])
    to_tree = math.degrees(math.atan2(tree[1], tree[0]))
    half = tree / 2
    side = np.array([-tree[1], tree[0]]) / np.linalg.norm(tree) * 5.0  # 5 m off the route, to its left
    return {
        "familiar": ("habitat", *half, to_tree),
        "nest": ("habitat", 0.0, 0.0, to_tree),
        "unfamiliar": ("habitat", *(half + side), to_tree),
        "unstructured": ({"scene": "horizon"}, 0.0, 0.0, to_tree),
    }


def dome_path(updates) -> np.ndarray:
    """(N, 2) path on the ball in the dome frame (m) from pose updates (free-yaw tether: heading = mapping)."""
    xy = np.array([(u.pose.x, u.pose.y) for u in updates])
    heading = np.array([u.pose.heading for u in updates])
    d = np.diff(xy, axis=0)
    c, s = np.cos(-heading[:-1]), np.sin(-heading[:-1])
    steps = np.stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1]], axis=1)
    return np.vstack([[0.0, 0.0], np.cumsum(steps, axis=0)])


def rotation_indices(updates) -> list[int]:
    """Indices of the pose updates right after each instant scene rotation."""
    rot = np.array([u.scene_rotation for u in updates])
    jumps = np.abs(np.remainder(np.diff(rot) + math.pi, 2 * math.pi) - math.pi) > 1e-6
    return [int(i) + 1 for i in np.flatnonzero(jumps)]


def run_condition(rig, name, scene, x, y, heading_deg, rng, duration, window, seed, load=True):
    """One trial; returns the pose updates it streamed and the log path. `load`: the scene is not on yet."""
    if load:
        rig.load_scene(scene)
    rig.closed_loop(True)
    rig.tether("free_yaw")
    rig.reset_origin(x, y, heading_deg)  # the condition's place becomes the virtual origin
    updates, lock = [], threading.Lock()

    def keep(update):
        with lock:
            updates.append(update)

    sub = rig.on_pose(keep)
    with rig.trial(f"poc-{name}", condition=name, seed=seed, scene=scene, origin=[x, y, heading_deg]) as path:
        t = 0.0
        while True:
            gap = rng.uniform(window, 2 * window)  # rotations at least one window apart
            if t + gap + window > duration:
                break
            rig.wait(gap)
            t += gap
            rig.rotate_scene(rng.choice((-90.0, 90.0)))
        rig.wait(max(duration - t, window))
    sub.undeclare()
    with lock:
        return list(updates), path


def plot(results, window, png: Path) -> Path:
    """The conditions' paths on the ball side by side, written to the PNG `png`."""
    from antarium.plots import style

    fig, axes = style.figure((4 * len(results), 4.2), ncols=len(results))
    for ax, (name, updates) in zip(np.atleast_1d(axes), results.items(), strict=True):
        if len(updates) < 2:
            ax.set_title(f"{name}: no poses")
            continue
        path = dome_path(updates)
        t = np.array([u.t for u in updates])
        ax.plot(path[:, 0] * 100, path[:, 1] * 100, color="0.8", lw=0.8)
        for i in rotation_indices(updates):
            before = (t >= t[i] - window) & (t < t[i])
            after = (t >= t[i]) & (t <= t[i] + window)
            ax.plot(path[before, 0] * 100, path[before, 1] * 100, color="tab:red", lw=1.2)
            ax.plot(path[after, 0] * 100, path[after, 1] * 100, color="tab:blue", lw=1.2)
            ax.plot(path[i, 0] * 100, path[i, 1] * 100, "o", color="tab:blue", ms=5)
        ax.set_title(name.capitalize())
        ax.set_xlabel("x on the ball (cm)")
        ax.set_ylabel("y on the ball (cm)")
        ax.set_aspect("equal", adjustable="datalim")
    fig.suptitle(f"Paths {window:g} s before (red) and after (blue) each 90° scene rotation (dot)")
    return style.save(fig, png)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_script_arguments(parser)
    parser.add_argument("--out", default="poc-output",
                        help="folder for the plot and the trial logs (default %(default)s)")
    parser.add_argument("--seed", type=int, default=1,
                        help="seed of the rotation times and directions (default %(default)s)")
    parser.add_argument("--duration", type=float, default=120.0, help="seconds per condition (default %(default)g)")
    parser.add_argument("--window", type=float, default=15.0,
                        help="seconds plotted before and after a rotation, and the least time between rotations; "
                             "--duration is at least 3 x this (default %(default)g)")
    parser.add_argument("--short", action="store_true", help="quick run: 1.2 s per condition, 0.4 s windows")
    args = parser.parse_args(argv)
    if args.short:
        args.duration, args.window = 1.2, 0.4
    check_script_arguments(args, seconds=("duration", "window"))  # before anything is written or connected
    if args.duration < 3 * args.window and not math.isclose(args.duration, 3 * args.window):  # --short: 1.2, 0.4
        # a rotation comes 1 to 2 windows in, then a window after it
        raise ScriptArgumentError(f"--duration {args.duration:g} s must be at least 3 x --window ({args.window:g} s) "
                                  "so that every condition has a rotation with a whole window before and after it")
    out = Path(args.out).resolve()  # made by script_rig once the rig answers
    rng = random.Random(args.seed)
    results, logs = {}, []
    with script_rig(args, out) as rig:
        shown = None
        for name, (scene, x, y, heading) in condition_poses().items():
            updates, log = run_condition(rig, name, scene, x, y, heading, rng, args.duration, args.window, args.seed,
                                         load=scene != shown)
            shown = scene
            results[name] = updates
            logs.append(log)
            print(f"{name}: {len(updates)} poses, {len(rotation_indices(updates))} rotations, log {log}")
    run = Path(logs[0]).stem.rsplit("_", 1)[0]  # <rig>_<UTC time> of the first log: a reused --out keeps both
    print(f"plot: {plot(results, args.window, out / f'{run}_proof_of_concept_paths.png')}")
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
