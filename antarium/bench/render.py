"""`antarium bench render`: frames/s of the renderer for five workloads, with the per-stage split.

Workloads: the habitat's distant panorama and sky alone (no meshes), a drifting grating (a drum at 30°/s),
the default habitat, and a 500,000-triangle stress mesh. The eye walks a slow curve at 1 cm above the ground
and turns, so culling and the far field are exercised as in an experiment. Reported against the dome's
190 frames/s and the goals of each path (CPU path: habitat >= 390 frames/s, panorama-only >= 1,900 frames/s; GPU
path, on a GPU: habitat >= 2,000, panorama-only >= 5,000).
"""

from __future__ import annotations

import math
import time

import numpy as np

from antarium.bench import progress, write_json
from antarium.bench.cpu import process_cpu_s
from antarium.core.rates import DOME_RATE_HZ

GOALS_HZ = {"cpu": {"panorama": 1900.0, "habitat": 390.0}, "gpu": {"panorama": 5000.0, "habitat": 2000.0}}


def stress_scene(n_triangles: int = 500_000, seed: int = 1):
    """Habitat far field plus a dense 24 m terrain of about `n_triangles` triangles with tall relief."""
    from antarium.renderers.habitat import habitat_scene
    from antarium.renderers.scene import MeshData, Scene, SceneObject

    base = habitat_scene(seed)
    cells = int(math.sqrt(n_triangles / 2))
    x = np.linspace(-12, 12, cells + 1)
    gx, gy = np.meshgrid(x, x, indexing="ij")
    rng = np.random.default_rng(seed)
    z = 0.02 * np.abs(np.sin(gx * 7) * np.cos(gy * 5)) + 0.01 * rng.random(gx.shape)
    z[np.hypot(gx, gy) < 0.05] = 0.0
    v = np.stack([gx.ravel(), gy.ravel(), z.ravel()], axis=1).astype(np.float32)
    i = (np.arange(cells)[:, None] * (cells + 1) + np.arange(cells)[None, :]).ravel()
    f = np.concatenate([np.stack([i, i + cells + 1, i + 1], 1), np.stack([i + 1, i + cells + 1, i + cells + 2], 1)])
    colours = np.empty((len(v), 3), np.float32)
    colours[:] = [0.2, 0.1, 0.03]
    colours[:, 0] += 5 * z.ravel()
    terrain = SceneObject(MeshData(v, f.astype(np.uint32), colours))
    return Scene(far=base.far, objects={"terrain": terrain}, name=f"stress-{len(f)}")


def workloads():
    """name -> (scene factory, Renderer keyword arguments)."""
    from antarium.renderers.habitat import habitat_scene
    from antarium.renderers.scene import Scene
    from antarium.renderers.stimuli import Grating

    hab = habitat_scene()
    return {
        "panorama": (lambda: Scene(far=hab.far, name="panorama-only"), {}),
        "grating": (lambda: Scene(far=[Grating(period=math.radians(20), speed=math.radians(30))], name="grating"),
                    {}),
        "habitat": (lambda: hab, {}),
        "habitat-layer": (lambda: hab, {"far_layer": "async"}),
        "stress-500k": (stress_scene, {}),
    }


def _poses(n: int):
    from antarium.core.pose import Pose

    t = np.arange(n) / DOME_RATE_HZ
    return [Pose(0.05 * math.sin(0.3 * s) + 0.02 * s, 0.03 * s, 0.01, 0.8 * math.sin(0.7 * s)) for s in t]


def measure(renderer, scene, frames: int, warmup: int = 20) -> dict:
    """Render `frames` frames along the walk; returns frames/s and mean ms per stage. With a far layer, the
    layer for the first pose is awaited first, as the server does."""
    renderer.set_scene(scene)
    renderer.wait_far_layer(_poses(1)[0])
    out = np.empty((20350, 2), np.uint16)
    poses = _poses(frames + warmup)
    split = np.zeros((frames, 3))
    for k, pose in enumerate(poses[:warmup]):
        renderer.render(pose, out=out, t=k / DOME_RATE_HZ)
    pid = renderer.far_layer_status()["pid"]
    b0 = process_cpu_s(pid)
    t0, c0 = time.perf_counter(), time.process_time()
    for k, pose in enumerate(poses[warmup:]):
        renderer.render(pose, out=out, t=(k + warmup) / DOME_RATE_HZ)
        lt = renderer.last_timings
        split[k] = lt["render"], lt["sample"], lt["convert"]
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    builder_cpu = process_cpu_s(pid) - b0
    ms = split.mean(axis=0) * 1e3
    return {"scene": scene.name, "triangles": scene.n_triangles, "frames": frames, "fps": frames / wall,
            "ms_per_frame": wall / frames * 1e3, "cpu_ms_per_frame": cpu / frames * 1e3,
            "builder_cpu_ms_per_frame": builder_cpu / frames * 1e3,
            "render_ms": ms[0], "sample_ms": ms[1], "convert_ms": ms[2]}


def run(args) -> int:
    from antarium.geometry import load_dome
    from antarium.renderers.gl import gl_renderer_string
    from antarium.renderers.gpu_path import default_path
    from antarium.renderers.renderer import Renderer

    frames = args.frames or 300
    if frames < 1:
        raise ValueError(f"--frames must be positive, got {frames}")
    dome = load_dome()
    results = []
    gl = gl_renderer_string()
    paths = getattr(args, "path", None) or [default_path(gl)]
    print(f"GL renderer: {gl}; per-LED path{'s' if len(paths) > 1 else ''}: {', '.join(paths)}")
    progress("render", "building the scenes (the habitat takes a while)")
    loads = workloads()
    print(f"{'path':<5}{'workload':<14}{'triangles':>10}{'frames/s':>10}{'x190 Hz':>9}{'goal':>7}{'render ms':>11}"
          f"{'sample ms':>11}{'convert ms':>12}{'CPU ms':>8}")
    runs = [(path, name, workload) for path in paths for name, workload in loads.items()]
    interrupted = False
    try:
        for i, (path, name, (make, kwargs)) in enumerate(runs):
            progress("render", f"workload {i + 1}/{len(runs)} {name!r} on the {path} path: {frames} frames")
            renderer = Renderer(dome, path=path, **kwargs)
            try:
                r = measure(renderer, make(), frames)
                r["renderer"] = {"face_size": renderer.face_size, "gl": renderer.gl_renderer, "path": path, **kwargs}
                r["far_layer"] = renderer.far_layer_status()
            finally:
                renderer.release()
            r["workload"] = name
            r["x_dome_rate"] = r["fps"] / DOME_RATE_HZ
            goal = GOALS_HZ[path].get(name.split("-")[0])
            r["goal_fps"] = goal
            results.append(r)
            goal_txt = f"{r['fps'] / goal:6.2f}x" if goal else "     -"
            print(f"{path:<5}{name:<14}{r['triangles']:>10}{r['fps']:>10.1f}{r['x_dome_rate']:>9.2f}{goal_txt:>7}"
                  f"{r['render_ms']:>11.2f}{r['sample_ms']:>11.2f}{r['convert_ms']:>12.2f}"
                  f"{r['cpu_ms_per_frame']:>8.2f}", flush=True)
    except KeyboardInterrupt:  # Ctrl-C: the workloads measured so far are reported (none: nothing to report)
        if not results:
            raise
        interrupted = True
        print(f"INTERRUPTED (Ctrl-C): {len(results)} of the {len(runs)} workloads measured")
    device = results[0]["renderer"]["gl"]
    print("sample ms on the gpu path: the compute passes, their wait and the read-back; convert ms: the copy out")
    print(f"GL: {device}. Face size {results[0]['renderer']['face_size']}")
    for layered in (r for r in results if r["workload"] == "habitat-layer"):
        print(f"habitat-layer, {layered['renderer']['path']} path: near meshes at {layered['renderer']['face_size']}, "
              f"far layer at 192 in its own process ({layered['far_layer']['builds']} layers built, "
              f"{layered['builder_cpu_ms_per_frame']:.2f} CPU ms per frame there, not in the CPU column; "
              f"{layered['far_layer']['full_frames']} frames drawn in full)")
    print("goal: frames/s divided by the path's goal (cpu: habitat 390, panorama 1,900; gpu: habitat 2,000, panorama "
          "5,000 frames/s). CPU ms: process CPU time per "
          "frame, all threads (llvmpipe's included) - less sensitive than wall time to other jobs on a shared machine")
    if args.json_out:
        write_json(args.json_out, "render", {"device": device, "interrupted": interrupted, "results": results})
        print(f"figures written to {args.json_out}")
    if interrupted:
        raise KeyboardInterrupt  # the command's exit status, 130, and its line on what was kept
    return 0
