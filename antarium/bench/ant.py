"""`antarium bench ant`: the virtual ant's model alone (eye + model, no rendering), on one core.

Goals (issue 7): exploitation >= 1,000 model decisions/s; learning with the 19-step in-silico oscillation
>= 100 views/s; <= 2 kB per route MBON. Each figure is also given as a ratio to the dome's 190 frames/s.
Inputs are seeded random LED frames of the real dome layout; a decision starts from the LED frame.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

from antarium.bench import progress, write_json

GOAL_DECISIONS_PER_S = 1000.0
GOAL_LEARN_VIEWS_PER_S = 100.0
GOAL_BYTES_PER_ROUTE_MBON = 2000


def _frames(n: int, n_leds: int, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [rng.integers(0, 30000, size=(n_leds, 2), dtype=np.uint16) for _ in range(n)]


def _rate(fn, items, seconds: float) -> float:
    """Calls per second of fn(item), cycling through items for at least `seconds` (after one warm-up call)."""
    fn(items[0])
    n, t0 = 0, time.perf_counter()
    while True:
        fn(items[n % len(items)])
        n += 1
        dt = time.perf_counter() - t0
        if dt >= seconds and n >= len(items):
            return n / dt


def measure(seconds: float = 2.0, n_frames: int = 20) -> dict:
    from antarium.ant.eye import Eye
    from antarium.ant.models import make_model
    from antarium.ant.storage import mbon_bytes
    from antarium.core.rates import DOME_RATE_HZ
    from antarium.geometry import load_dome

    pinned = False
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
        pinned = True
    eye = Eye.from_dome(load_dome())
    frames = _frames(n_frames, eye.n_leds)
    n_pn = eye.params.n_pn
    out: dict = {"one_core": pinned, "seconds_per_figure": seconds}
    antcar = make_model("antcar", n_pn)
    learn = _rate(lambda f: antcar.learn(eye.look(f)), frames, seconds)
    out["antcar_learn_views_per_s"] = learn
    for kind in ("antcar", "ardin", "perfect_memory"):
        model = antcar if kind == "antcar" else make_model(kind, n_pn)
        if kind != "antcar":
            for f in frames:
                model.learn(eye.look(f))
        rate = _rate(lambda f, m=model: m.decide(eye.look(f)), frames, seconds)
        out[f"{kind}_decisions_per_s"] = rate
        out[f"{kind}_ms_per_decision"] = 1e3 / rate
        out[f"{kind}_learned_views"] = int(model.learned_views)
    views = [eye.look(f) for f in frames]
    out["antcar_model_only_decisions_per_s"] = _rate(antcar.decide, views, seconds)
    out["eye_views_per_s"] = _rate(eye.look, frames, seconds)
    sizes = mbon_bytes(antcar)
    out["bytes_per_route_mbon"] = max(sizes["left"], sizes["right"])
    out["bytes_per_place_mbon"] = max(sizes["nest"], sizes["feeder"])
    from antarium.bench.ant_cx import measure as measure_cx

    out.update(measure_cx(_rate, seconds, n_frames))
    out["ratios"] = {
        "decisions_vs_goal_1000": out["antcar_decisions_per_s"] / GOAL_DECISIONS_PER_S,
        "decisions_vs_dome_190": out["antcar_decisions_per_s"] / DOME_RATE_HZ,
        "learning_vs_goal_100": learn / GOAL_LEARN_VIEWS_PER_S,
        "learning_vs_dome_190": learn / DOME_RATE_HZ,
        "route_mbon_bytes_vs_goal_2000": out["bytes_per_route_mbon"] / GOAL_BYTES_PER_ROUTE_MBON,
    }
    return out


def measure_on_one_core(seconds: float, n_frames: int) -> dict:
    """`measure` in a child process with one BLAS thread, pinned to one CPU."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    code = f"import json; from antarium.bench.ant import measure; print(json.dumps(measure({seconds!r}, {n_frames!r})))"
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"ant benchmark failed: {done.stderr.strip()[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def run(args: argparse.Namespace) -> int:
    seconds = args.seconds if args.seconds is not None else 2.0
    progress("ant", f"11 figures of at least {seconds:g} s each, in a child process on one core")
    result = measure_on_one_core(seconds, args.frames or 20)
    r = result["ratios"]
    print(f"virtual ant, model alone ({'one core' if result['one_core'] else 'all cores'}; shared machine: noisy)")
    print(f"  Antcar decisions (LED frame -> command): {result['antcar_decisions_per_s']:8.0f} /s  "
          f"= {r['decisions_vs_goal_1000']:.2f} x goal 1000/s, {r['decisions_vs_dome_190']:.2f} x dome 190 frames/s")
    print(f"  Antcar decisions (view -> command):      {result['antcar_model_only_decisions_per_s']:8.0f} /s")
    print(f"  Antcar learning, 19-step oscillation:    {result['antcar_learn_views_per_s']:8.0f} views/s "
          f"= {r['learning_vs_goal_100']:.2f} x goal 100/s, {r['learning_vs_dome_190']:.2f} x dome 190 frames/s")
    print(f"  Ardin decisions (61-direction scan):     {result['ardin_decisions_per_s']:8.0f} /s "
          f"({result['ardin_ms_per_decision']:.2f} ms)")
    views = f"perfect memory decisions ({result['perfect_memory_learned_views']} views):"
    print(f"  {views:40s} {result['perfect_memory_decisions_per_s']:8.0f} /s "
          f"({result['perfect_memory_ms_per_decision']:.2f} ms)")
    print(f"  eye (LED frame -> view):                 {result['eye_views_per_s']:8.0f} /s")
    print(f"  memory per route MBON: {result['bytes_per_route_mbon']} B "
          f"= {r['route_mbon_bytes_vs_goal_2000']:.2f} x goal 2000 B, whatever the route length; "
          f"place MBON {result['bytes_per_place_mbon']} B")
    rc = result["ratios_cx"]
    print(f"  sky compass + CX step (LED frame):       {result['compass_cx_step_per_s']:8.0f} /s "
          f"= {rc['compass_cx_vs_goal_10000']:.2f} x goal 10000/s (compass alone {result['compass_per_s']:.0f} /s)")
    for kind, text in (("cx", "CX"), ("cxmb", "CXMB + optic flow"), ("one_ring", "One Ring")):
        print(f"  {text + ' decisions (LED frame):':40s} {result[f'{kind}_decisions_per_s']:8.0f} /s "
              f"= {rc[f'{kind}_vs_goal_1000']:.2f} x goal 1000/s; memory {result[f'{kind}_memory_bytes']} B")
    if args.json_out:
        write_json(args.json_out, "ant", result)
    return 0
