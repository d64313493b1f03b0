"""The Antarium's proof of concept, in silico (Kócsi et al. 2020, Fig. 4): a trained virtual ant walks in closed
loop while the scene is rotated by +-90 deg at random times. In a structured scene (the habitat) it turns to
restore its heading in the world; in the horizon-only scene it has nothing to turn by and walks on.

    .venv/bin/python examples/ant_scene_rotation.py --out ant-rotation/

Writes `scene_rotation.png` (the fictive paths walked on the ball, dome frame, rotations marked) and prints,
per rotation, how much the ant's walking direction on the ball turned (restoring = the rotation's angle).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from antarium.ant.agent import learning_walk
from antarium.ant.models import make_model
from antarium.ant.route_following import FACE_SIZE
from antarium.ant.routes import curved_route
from antarium.ant.world import virtual_rig
from antarium.client import run_script

SCENES = {"habitat (structured)": "habitat", "horizon only": "horizon"}
#: rotations per walk, decisions between rotation times, walked before the first and after the last
ROTATIONS, SPACING, BEFORE, AFTER = 3, 40, 25, 35
#: decisions over which the walking direction's turn after a rotation is measured
TURN_WINDOW = 30
MIN_DECISIONS = BEFORE + (ROTATIONS - 1) * SPACING + AFTER + 1


def walk_with_rotations(scene: str, decisions: int, seed: int):
    """Learn a 4 m route in `scene`, release the ant on it and rotate the scene by +-90 deg at random times.

    Returns the fictive path on the ball (dome frame, m), the rotation indices and angles, and the turn of the
    ant's walking direction on the ball across each rotation (rad).
    """
    rng = np.random.default_rng(seed)
    route = curved_route(seed, length=4.0)
    model = make_model("antcar", 800)  # the paper's A = 45 deg: the scene turns by 90 deg, beyond our route's 20
    with virtual_rig(model, scene=scene, renderer_kwargs={"face_size": FACE_SIZE}) as ant:
        learning_walk(ant, route, 0.01)
        model.reset()
        ant.place(*route.start, float(route.at([0.0])[1][0]))
        times = np.sort(rng.choice(np.arange(BEFORE, decisions - AFTER, SPACING), size=ROTATIONS, replace=False))
        angles = rng.choice([-math.pi / 2, math.pi / 2], size=len(times))
        ball_xy, ball_heading = [np.zeros(2)], []
        last = np.array(ant.position)
        for k in range(decisions):
            if k in times:
                ant.loop.rotate_scene(float(angles[list(times).index(k)]))
            ant.decide()
            # The ball moved by the world displacement seen in the dome frame (rotated by -pose.heading).
            here, h = np.array(ant.position), ant.loop.pose.heading
            c, s = math.cos(h), math.sin(h)
            dx, dy = here - last
            ball_xy.append(ball_xy[-1] + [c * dx + s * dy, -s * dx + c * dy])
            ball_heading.append(ant.legs.yaw)
            last = here
    heading = np.unwrap(np.asarray(ball_heading))
    turned = np.array([heading[min(t + TURN_WINDOW, decisions - 1)] - heading[t - 1] for t in times])
    return np.asarray(ball_xy), times, angles, turned


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="ant-rotation", help="folder for scene_rotation.png (default %(default)s)")
    parser.add_argument("--decisions", type=int, default=160, help=f"decisions per walk, at least {MIN_DECISIONS} "
                        "(default %(default)s)")
    parser.add_argument("--seed", type=int, default=3, help="seed of the route and rotations (default %(default)s)")
    args = parser.parse_args(argv)
    if args.decisions < MIN_DECISIONS:
        parser.error(f"--decisions must be >= {MIN_DECISIONS} ({ROTATIONS} rotations {SPACING} decisions apart, "
                     f"{BEFORE} before the first, {AFTER} after the last), got {args.decisions}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    from antarium.plots import style

    fig, axes = style.figure((11, 5.5), ncols=2)
    for ax, (label, scene) in zip(axes, SCENES.items(), strict=True):
        xy, times, angles, turned = walk_with_rotations(scene, args.decisions, args.seed)
        ax.plot(*xy.T, color="k", lw=1)
        for t, a in zip(times, angles, strict=True):
            ax.plot(*xy[t], "o", color="tab:blue", ms=7)
            ax.annotate(f"{math.degrees(a):+.0f}°", xy[t], textcoords="offset points", xytext=(6, 6))
        ax.set_aspect("equal")
        ax.set_title(f"{label}")
        ax.set_xlabel("ball x, dome frame (m)")
        ax.set_ylabel("ball y (m)")
        for a, d in zip(angles, turned, strict=True):
            print(f"{label}: scene rotated {math.degrees(a):+.0f} deg -> the ant turned {math.degrees(d):+.0f} deg")
    fig.suptitle("virtual ant, scene rotated at the blue dots: fictive paths on the ball")
    print(f"wrote {style.save(fig, out / 'scene_rotation.png')}")
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
