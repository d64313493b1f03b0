"""`antarium bench ant`, central-complex part: the sky compass, the CX, CXMB and One Ring from an LED frame.

The frames show a rendered-in-numpy sky on the UV pixels (`renderers.sky.Sky` at the LED directions, the
polarisers at the sky's e-vectors, as the renderer sends them) and seeded random green/blue pixels, so the compass
reads a real cue. Goals (issue 16): >= 1,000 decisions/s per model, >= 10,000/s for the compass + CX step alone.
"""

from __future__ import annotations

import numpy as np

GOAL_DECISIONS_PER_S = 1000.0
GOAL_COMPASS_CX_PER_S = 10000.0


def sky_frames(dome, n: int, seed: int = 0) -> tuple[list[np.ndarray], np.ndarray]:
    """n (N, 2) uint16 LED frames (the sky on the UV pixels, noise on the others) and the (55, 9) polariser angles."""
    from antarium.renderers.output import polariser_angles
    from antarium.renderers.sky import Sky, e_vector

    sky = Sky()
    uv = np.asarray(dome.uv_index)
    d = np.asarray(dome.directions)[uv]
    radiance = sky.evaluate(d)
    gain = np.asarray(dome.gain)[uv]
    plain = np.clip((radiance[:, 2] - radiance[:, 3]) * gain * 65535, 0, 65535)
    pol = np.clip(radiance[:, 3] * gain * 65535, 0, 65535)
    axes = np.asarray(dome.panel_axes)[np.asarray(dome.panel)[uv]]
    angles = polariser_angles(d, e_vector(d, sky.sun), axes).reshape(55, 9)
    rng = np.random.default_rng(seed)
    frames = []
    for _ in range(n):
        f = rng.integers(0, 30000, size=(dome.directions.shape[0], 2), dtype=np.uint16)
        f[uv, 0], f[uv, 1] = plain.astype(np.uint16), pol.astype(np.uint16)
        frames.append(f)
    return frames, angles


def measure(rate, seconds: float, n_frames: int) -> dict:
    """Rates (per second) of the compass + CX step, and of each CX model's decision from an LED frame."""
    from antarium.ant.compass import SkyCompass
    from antarium.ant.eye import Eye
    from antarium.ant.models import make_model
    from antarium.ant.navigation import Senses
    from antarium.ant.storage import mbon_bytes
    from antarium.geometry import load_dome

    dome = load_dome()
    frames, angles = sky_frames(dome, n_frames)
    compass = SkyCompass.from_dome(dome)
    eye = Eye.from_dome(dome)
    out: dict = {}
    cx = make_model("cx", eye.params.n_pn)

    def compass_cx(f):
        cx.observe(Senses(None, compass.read(f, angles, 0.3), 0.01, f, 0.3))

    out["compass_cx_step_per_s"] = rate(compass_cx, frames, seconds)
    out["compass_per_s"] = rate(lambda f: compass.read(f, angles, 0.3), frames, seconds)
    for kind in ("cx", "cxmb", "one_ring"):
        model = make_model(kind, eye.params.n_pn, avoid=kind == "cxmb")

        def decide(f, m=model):
            view = eye.look(f, 0.3) if m.needs_view else None
            return m.decide(Senses(view, compass.read(f, angles, 0.3), 0.01, f, 0.3))

        if kind != "cx":
            model.learning = True
            for f in frames:
                decide(f)
            model.learning = False
        out[f"{kind}_decisions_per_s"] = rate(decide, frames, seconds)
        out[f"{kind}_memory_bytes"] = sum(mbon_bytes(model).values())
    out["ratios_cx"] = {
        "compass_cx_vs_goal_10000": out["compass_cx_step_per_s"] / GOAL_COMPASS_CX_PER_S,
        **{f"{k}_vs_goal_1000": out[f"{k}_decisions_per_s"] / GOAL_DECISIONS_PER_S for k in ("cx", "cxmb", "one_ring")},
    }
    return out
