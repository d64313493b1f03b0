"""One run of an experiment, in whatever process runs it (a Dask worker or this one): a row of results.

A run never raises: a failure is a row with status "failed" and the error, so that it does not stop the others.
Worlds and routes are built once per process and reused across its runs.
"""

from __future__ import annotations

import math
import os
import signal
import socket
import threading
import time
import traceback
from functools import lru_cache

from antarium.ant.experiment.inputs import load_route, route_digest, run_world
from antarium.ant.experiment.spec import PROTOCOLS, Run, model_args
from antarium.ant.routes import Route, RouteError, curved_route


def dask_setup(worker) -> None:
    """Dask's preload hook (`runner.local_cluster`): a local worker ignores Ctrl-C. A terminal sends it to the
    command and its workers alike (one process group); the command ends the workers itself, where each would
    otherwise print a KeyboardInterrupt traceback. Runs in the worker process's main thread."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@lru_cache(maxsize=256)
def _route(source: str, digest: str = "") -> Route:
    """The route of `source`, checked against the SHA-1 of its points when the spec was read (`digest`)."""
    if source.startswith("curved:"):
        _, seed, length = source.split(":")
        route = curved_route(int(seed), length=float(length))
    else:
        route = load_route(source).route
    if digest and route_digest(route) != digest:
        raise RouteError(f"route {source!r} changed since the spec was read; read the spec again")
    return route


_RENDERERS: dict = {}


def _renderer(face_size: int, scene, x: float, y: float, z: float):
    """This thread's renderer of `face_size` (one GL context per worker thread, reused across its runs), showing
    `scene`. It renders one frame at (x, y, z) m first: the frame loop keeps the dome's last frame when a render
    fails (as a rig must), so a run would otherwise go on blind; here the run fails with the renderer's error."""
    from antarium.core.pose import Pose
    from antarium.renderers import Renderer

    key = (threading.get_ident(), face_size)
    if key not in _RENDERERS:
        _RENDERERS[key] = Renderer(face_size=face_size)
    renderer = _RENDERERS[key]
    if renderer.scene is not scene:
        renderer.set_scene(scene)
    renderer.render(Pose(x, y, z, 0.0))
    return renderer


#: the Dask event topic on which a worker says that it starts a run ({"run_id", "worker": its address})
RUN_STARTED_TOPIC = "antarium-run-started"


def announce_start(run: Run) -> None:
    """Tell the command (`runner`, which enforces --run-timeout-s) that this worker starts `run` now; nothing
    outside a Dask worker."""
    from distributed import get_worker

    try:
        worker = get_worker()
    except ValueError:  # not in a worker
        return
    worker.log_event(RUN_STARTED_TOPIC, {"run_id": run.run_id, "worker": worker.address})


def run_task(run: Run) -> dict:
    """What a Dask worker runs for `run`: `announce_start`, then `run_row`."""
    announce_start(run)
    return run_row(run)


def run_row(run: Run) -> dict:
    """Learn and follow the run's route; the row of the results table (see `spec.METRICS`)."""
    from antarium.ant.route_following import train_and_follow

    row = {**run.columns(), "worker": f"{socket.gethostname()}:{os.getpid()}"}
    t0 = time.perf_counter()
    try:
        route = _route(run.route_source, run.route_sha1)
        eye_params, overrides, spacing = model_args(run.model, run.params, run.seed)
        scene, floor = run_world(run.world)   # z lowered by `floor` (m): the eye above z = 0, as the loop takes it
        renderer = _renderer(run.face_size, scene, *route.start, run.eye_z_m - floor)
        outcome, track = train_and_follow(
            run.model, route, None, run.run_id, scene=scene, model_params=overrides,
            learn_spacing=spacing, max_decisions=run.max_decisions or None,
            start_offset=(run.lateral_cm / 100.0, math.radians(run.heading_deg + run.route_heading_deg)),
            eye_params=eye_params, save=False, face_size=run.face_size, put_back=PROTOCOLS[run.protocol],
            eye_height=run.eye_z_m - floor, renderer=renderer)
    except Exception as exc:  # a failed run is recorded, not raised: the others go on
        row.update(status="failed", error=f"{type(exc).__name__}: {exc}", traceback=traceback.format_exc(),
                   run_s=time.perf_counter() - t0)
        return row
    s = outcome.summary
    xy, _ = track.arrays()
    row.update(status="done", error="", traceback="", lateral_median_m=s["lateral_median"],
               lateral_mad_m=s["lateral_mad"], angular_median_deg=s["angular_median_deg"],
               angular_mad_deg=s["angular_mad_deg"], arrived=bool(s["arrived"]), errors=int(s["errors"]),
               decisions=int(s["decisions"]), distance_m=s["distance"], stop_distance_m=s["stop_distance"],
               ms_per_decision_model=outcome.model_ms_per_decision,
               ms_per_decision_loop=1e3 * outcome.seconds_per_decision,
               memory_bytes=int(sum(outcome.memory_bytes.values())), learned_views=int(outcome.learned_views),
               route_length_m=route.length, track_x=xy[:, 0].tolist(), track_y=xy[:, 1].tolist(),
               put_back=list(track.put_back), run_s=time.perf_counter() - t0)
    return row
