"""Put a virtual ant on an emulated rig: renderer -> encoder -> virtual link (emulated panels) -> the ant's eye.

    with virtual_rig(model, scene="habitat") as ant:
        learning_walk(ant, route, spacing=0.01)
        result = follow_route(ant, route, max_decisions=500)

The rig is the real one: `antarium.renderers.Renderer` renders the scene at the loop's pose, the frame loop
sends it over `open_link("virtual")`, and the ant reads `link.emulator.led_values()` — what the panels show.
Everything runs on a `SimulatedClock` unless a clock is given, so it runs as fast as the computer allows.
The ant walks through the "ant" locomotion source, ball rotations on the bus (`bus=`) or the emulated USB
trackball read by the real driver (`trackball=`), in either tether.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from antarium.ant.agent import VirtualAnt
from antarium.ant.eye import Eye, EyeParams
from antarium.ant.locomotion import AntLocomotion, BusLegs, TrackballLegs
from antarium.core.ball import BALL_RADIUS_M
from antarium.core.clock import Clock, SimulatedClock
from antarium.core.rates import DOME_RATE_HZ, FRAME_PERIOD_S

#: eye height above the ground at ant scale (m)
EYE_HEIGHT_M = 0.01


@contextlib.contextmanager
def virtual_rig(model, scene: Any = "habitat", eye_params: EyeParams | None = None, tether: str = "free_yaw",
                clock: Clock | None = None, log_path: str | Path | None = None, log_metadata: dict | None = None,
                frames_per_decision: int = 1, eye_height: float = EYE_HEIGHT_M,
                renderer_kwargs: dict | None = None, bus: dict | None = None,
                rig: str = "rig1", trackball: Any = None, compass: str | None = None,
                renderer: Any = None, cue_wait_frames: int = 0) -> Iterator[VirtualAnt]:
    """A `VirtualAnt` with `model` in a frame loop on an emulated dome showing `scene`.

    log_path: write an HDF5 trial log there (like a real trial's), or None.
    bus: a `[bus]` section: the ant's steps then travel as ball rotations over zenoh (`BusLegs`) to the frame
    loop's "bus" locomotion source for rig `rig`, as a trackball's would; None: the in-process "ant" source.
    compass: "sky" (read from the emulated panels' UV pixels and polarisers) or "ideal" (the true heading), for
    the central-complex models; default: the model's `params.compass` if it has one.
    trackball: True, or a `[trackball]` section (dict, file, `TrackballConfig`): the ant's steps move the ball of
    an emulated USB trackball on the loop's clock, and the real driver reading it is the loop's source
    (`TrackballLegs`); its default reports at 950 Hz, five per frame.
    cue_wait_frames: frames the ant stands still waiting for a sky compass cue (`VirtualAnt`).
    renderer: a `Renderer` to reuse (its GL context, and its scene when that is `scene` already); it is left
    open for the next run. None: a new one, released at the end.
    """
    from antarium.config import LoopSection
    from antarium.firmware_proto.link import open_link
    from antarium.geometry import load_dome
    from antarium.renderers import Renderer
    from antarium.server.frame_loop import FrameLoop
    from antarium.trial_log import TrialLog

    clock = clock or SimulatedClock()
    dome = load_dome()
    eye = Eye.from_dome(dome, eye_params)
    if eye.params.n_pn != model.n_pn:
        raise ValueError(f"the model expects {model.n_pn} PNs but the eye gives {eye.params.n_pn}")
    with contextlib.ExitStack() as stack:
        if renderer is None:
            renderer = Renderer(dome, clock=clock, **(renderer_kwargs or {}))
            stack.callback(renderer.release)
        else:
            renderer.use_clock(clock)
        if renderer.scene is not scene:
            renderer.set_scene(scene)
        link = open_link("virtual", clock=clock)
        stack.callback(link.close)
        log = None
        if log_path is not None:
            config = {"ant": {"model": model.kind, "tether": tether, "scene": str(scene), "eye": eye.params.channel}}
            log = stack.enter_context(TrialLog(log_path, config, name="virtual ant", metadata=log_metadata))
        if bus is not None and trackball is not None:
            raise ValueError("virtual_rig: give bus= (legs on the bus) or trackball= (the emulated USB trackball), "
                             "not both")
        if trackball is not None:
            legs = TrackballLegs(tether, trackball=None if trackball is True else trackball, clock=clock,
                                 step_s=FRAME_PERIOD_S)
            legs.start()
            stack.callback(legs.stop)
            source = legs.source
        elif bus is None:
            legs = source = AntLocomotion(tether, clock=clock)
        else:
            from antarium.bus import open_session
            from antarium.locomotion import open_source

            session = stack.enter_context(open_session(bus, role="server"))
            source = open_source("bus", rig=rig, session=session, clock=clock)
            source.start()
            stack.callback(source.stop)
            legs = BusLegs(session, rig, tether, clock=clock)
            stack.callback(legs.close)
        loop_cfg = LoopSection(tether=tether, eye_height_m=eye_height, rate_hz=DOME_RATE_HZ,
                               ball_radius_m=legs.driver.config.ball_radius if trackball is not None else BALL_RADIUS_M)
        loop = FrameLoop.from_config(loop_cfg, clock=clock, source=source, renderer=renderer, link=link, log=log)
        yield VirtualAnt(eye, model, loop, legs, link.emulator.led_values, frames_per_decision,
                         compass=make_compass(compass or getattr(model.params, "compass", "sky"), dome),
                         read_polarisers=link.emulator.polariser_angles, cue_wait_frames=cue_wait_frames)


def make_compass(kind: str, dome):
    """The ant's compass: "sky" (`SkyCompass` on `dome`) or "ideal"."""
    from antarium.ant.compass import COMPASSES, IdealCompass, SkyCompass

    if kind not in COMPASSES:
        raise ValueError(f"compass {kind!r} not known; allowed: {', '.join(COMPASSES)}")
    return SkyCompass.from_dome(dome) if kind == "sky" else IdealCompass()
