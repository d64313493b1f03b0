"""`antarium demo`'s closed loop: a virtual ant learns a short route and follows it on the emulated rig.

The whole rig is in the loop, on a `SimulatedClock` (as fast as the computer allows, the same every run):
the frame loop renders the habitat at the ant's pose, encodes the LED frame and sends it over the virtual link
to the emulated panels; the ant's eye reads what the panels show, Antcar's mushroom body decides, and the ant's
legs turn the ball of the emulated USB trackball, whose reports the real driver decodes for the frame loop.

Writes into `out`: `trials/rig1_<UTC time>_virtual_ant.h5` (the trial log: frames, ball samples, one
`ant_decision` event per decision; a new one every run), `virtual_ant_paths.png` (the learned and the followed
path over the world's top view), `virtual_ant_traces.png` (the model's familiarities) and `virtual_ant_dome.png`
(what the dome showed at the end, as an equal-area map seen from inside).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

#: released this far left of the route's start (m) and turned this much counter-clockwise off it (rad)
START_OFFSET = (0.03, math.radians(15))
#: decisions allowed per metre of route (Antcar steps at most 2 cm per decision): 3x the route's length
DECISIONS_PER_M = 150


def run_ant_demo(out: str | Path, echo: Callable[[str], None] = print, scene: Any = "habitat",
                 route_length: float | None = None, face_size: int | None = None) -> dict[str, Path]:
    """Learn a short curved route, follow it in closed loop; write the outputs and return their paths by name.
    route_length: metres (default: the demo route of `antarium.ant.route_following`); face_size: cube-face texels."""
    from antarium.ant import route_following as ex
    from antarium.ant.agent import follow_route, learning_walk
    from antarium.ant.eye import EyeParams
    from antarium.ant.models import make_model
    from antarium.ant.routes import curved_route
    from antarium.ant.world import virtual_rig
    from antarium.geometry import load_dome
    from antarium.plots.ant import plot_paths, plot_traces, scene_top_view
    from antarium.plots.dome_map import dome_picture
    from antarium.trial_log import check_log_dir, log_path

    out = Path(out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    route = curved_route(ex.DEMO_ROUTE_SEED, length=route_length or ex.DEMO_ROUTE_LENGTH_M)
    model = make_model("antcar", EyeParams().n_pn)
    log = log_path(check_log_dir(out / "trials"), "rig1", "virtual_ant")
    spacing = ex.LEARN_SPACING_M["antcar"]
    wall = time.perf_counter()
    with virtual_rig(model, scene=scene, trackball=True, log_path=log,
                     log_metadata={"route": route.points.tolist(), "model": "antcar"},
                     renderer_kwargs={"face_size": face_size or ex.FACE_SIZE}) as ant:
        ant.loop.event("ant_learning_walk", spacing=spacing, route_length=route.length)
        views = learning_walk(ant, route, spacing)
        ant.loop.event("ant_release", start_offset=list(START_OFFSET))
        result = follow_route(ant, route, int(DECISIONS_PER_M * route.length) + 10, ex.ARRIVE_RADIUS_M,
                              start_offset=START_OFFSET)
        top = scene_top_view(ant.loop.renderer.scene)
        leds = ant.read_leds()
        simulated, reports = ant.loop.clock.now(), ant.legs.driver.status()["reports"]
    wall = time.perf_counter() - wall
    s = result.summary
    echo(f"virtual ant: Antcar learned {views} views along a {route.length:.2f} m route, was released "
         f"{100 * START_OFFSET[0]:.0f} cm off it and turned {math.degrees(START_OFFSET[1]):.0f}°, and "
         f"{'arrived' if s.arrived else 'did not arrive'} after {s.decisions} decisions (lateral error median "
         f"{100 * s.lateral_median:.1f} cm, angular {s.angular_median_deg:.1f}°); {reports} trackball reports; "
         f"{simulated:.1f} s of rig time in {wall:.1f} s")
    title = f"Virtual ant (Antcar) in the closed loop: {'arrived' if s.arrived else 'not arrived'}"
    return {
        "trial log": log,
        "path plot": plot_paths(out / "virtual_ant_paths.png", route, {"followed (Antcar)": result.track},
                                title=title, top=top, notes=(
                                    f"released {100 * START_OFFSET[0]:.0f} cm off the route, turned "
                                    f"{math.degrees(START_OFFSET[1]):.0f}°; error from the route: lateral median "
                                    f"{100 * s.lateral_median:.1f} cm, angular median "
                                    f"{s.angular_median_deg:.1f}°; {s.decisions} decisions")),
        "traces": plot_traces(out / "virtual_ant_traces.png", result.track, title="Antcar: model signals"),
        "dome picture": dome_picture(leds, load_dome(), out / "virtual_ant_dome.png",
                                     "What the dome showed the virtual ant at its last decision"),
    }
