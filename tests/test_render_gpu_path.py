"""The GPU frame path (compute shaders, run here on llvmpipe) against the CPU path, the reference: every kind of
scene and every scene edit gives the same LED frame within 1 LSB, and the packed datagrams are the VIDEO encoding
of that frame and show it on the emulated dome."""

from __future__ import annotations

import math

import numpy as np
import pytest

from antarium.core.pose import Pose
from antarium.firmware_proto.video import VIDEO_PAYLOAD_SIZE, encode_frame, video_info
from antarium.geometry import load_dome
from antarium.renderers.gpu_path import check_path, default_path
from antarium.renderers.library import build_scene
from antarium.renderers.renderer import Renderer
from antarium.renderers.scene import MeshData, SceneObject

FACE = 96
POSES = [Pose(0.0, 0.0, 0.25, 0.0), Pose(0.3, -0.2, 0.1, 1.2)]


@pytest.fixture(scope="module")
def pair():
    dome = load_dome()
    cpu, gpu = Renderer(dome, face_size=FACE, path="cpu"), Renderer(dome, face_size=FACE, path="gpu")
    yield cpu, gpu
    cpu.release()
    gpu.release()


def box(size=0.5, colour=(0.8, 0.1, 0.3)) -> MeshData:
    import trimesh

    m = trimesh.creation.box(extents=(size, size, size))
    v = np.asarray(m.vertices) + [0, 0, size / 2]
    return MeshData(v.astype(np.float32), np.asarray(m.faces), np.tile(colour, (len(v), 1)), double_sided=False)


def with_box(spec: dict, position=(1.0, 0.5, 0.0)):
    scene = build_scene(spec)
    scene.objects["box"] = SceneObject(box(), position=position)
    scene.__post_init__()
    return scene


def assert_same(pair, t: float = 0.5, poses=POSES, what: str = "") -> None:
    """Both paths render every pose to frames within 1 LSB; the frames are not blank."""
    cpu, gpu = pair
    for pose in poses:
        a = cpu.render(pose, t=t).astype(np.int64)
        b = gpu.render(pose, t=t).astype(np.int64)
        assert a.max() > 1000, "a blank frame proves nothing"
        diff = np.abs(a - b)
        bad = int((diff > 1).sum())
        assert bad == 0, f"{bad} LED values differ by more than 1 LSB (max {diff.max()}) {what}"
        assert (b[:, 0] + b[:, 1]).max() <= 65535


def both(pair, method: str, *args, **kwargs) -> None:
    for r in pair:
        getattr(r, method)(*args, **kwargs)


SCENES = {
    "uniform": lambda tmp: {"scene": "uniform", "colour": [0.4, 0.2, 0.3]},
    "bars": lambda tmp: {"scene": "bars", "azimuth_deg": 30, "width_deg": 10, "colour": [0.6, 0.3, 0.2]},
    "drifting grating": lambda tmp: {"scene": "grating", "period_deg": 20, "speed_deg_s": 30,
                                     "colour": [0.7, 0.3, 0.6]},
    "sky (polarised)": lambda tmp: {"scene": "sky"},
    "panorama": lambda tmp: {"scene": "panorama", "path": _stripes(tmp)},
    "mesh over the far-field table": lambda tmp: with_box({"scene": "horizon", "sky": 0.45, "ground": 0.2}),
    "mesh over a drifting far field": lambda tmp: with_box({"scene": "grating", "period_deg": 30, "speed_deg_s": 40}),
    "habitat": lambda tmp: "habitat",
}


def _stripes(tmp) -> str:
    import cv2

    img = np.zeros((90, 180, 3), np.uint8)
    img[:, ::12] = [40, 255, 120]
    img[:45, :, 0] = 200
    path = tmp / "stripes.png"
    cv2.imwrite(str(path), img)
    return str(path)


@pytest.mark.parametrize("name", list(SCENES))
def test_every_kind_of_scene_matches_the_cpu_path(pair, name, tmp_path):
    scene = SCENES[name](tmp_path)
    for r in pair:
        r.set_scene(scene if not hasattr(scene, "objects") else _copy(scene))
    assert_same(pair)


def _copy(scene):
    from antarium.renderers.scene import Scene

    return Scene(far=scene.far, objects=dict(scene.objects), name=scene.name)


def test_the_far_field_table_looked_up_on_the_gpu_matches_the_cpu_at_every_heading(pair):
    """The table is uploaded once and looked up in the sample pass, its yaw shift split in whole and fractional
    columns: headings on both sides of 0 and of a turn, and between grid columns, with and without meshes."""
    headings = [-7.0, -1e-9, 0.0, 1e-4, math.radians(0.125), math.pi, 2 * math.pi - 1e-6, 12.5, 1e4]
    poses = [Pose(0.1, 0.2, 0.05, h) for h in headings]
    for spec in ({"scene": "sky"}, with_box({"scene": "horizon", "sky": 0.45, "ground": 0.2})):
        for r in pair:
            r.set_scene(spec if isinstance(spec, dict) else _copy(spec))
        assert_same(pair, poses=poses, what=f"in {spec if isinstance(spec, dict) else 'horizon + box'}")
    assert pair[1]._gpu._table_source is pair[1]._table


def test_the_culling_pass_writes_the_cpu_paths_commands_in_its_order(pair):
    """Per face and sidedness: the same chunks, levels of detail and front-to-back order as
    `MeshBuffers.commands` (the order decides depth ties), then the chunks not drawn, with empty commands."""
    gpu = pair[1]
    scene = build_scene("habitat")
    scene.objects["box"] = SceneObject(box(), position=(0.2, 0.1, 0.0))  # single-sided beside the habitat's
    scene.__post_init__()
    gpu.set_scene(_copy(scene))
    meshes = gpu._meshes
    m, d = meshes.n_chunks, meshes._culling.n_double
    assert 0 < d < m
    for pose in POSES:
        gpu.render(pose, t=0.0)
        eye = gpu._scene_eye(gpu.scene, pose)
        expected, per_batch = meshes.commands(gpu._last_q, eye)
        expected = np.split(expected[:, [0, 2]], np.cumsum(per_batch)[:-1])
        with gpu.ctx:
            written = np.frombuffer(meshes._culling.commands.read(), np.uint32).reshape(6, m, 5)
        for k in range(6):
            for s, (a, b) in enumerate(((0, d), (d, m))):
                cmds = written[k, a:b]
                n = len(expected[2 * k + s])
                assert np.array_equal(cmds[:n][:, [0, 2]], expected[2 * k + s]), (k, s)
                assert (cmds[:n, 1] == 1).all() and not cmds[n:, :2].any()


def test_a_far_layer_on_the_gpu_path_matches_the_cpu_path():
    """A far layer's tables are rewritten in place: on the GPU path they are looked up on the CPU and uploaded."""
    dome = load_dome()
    layered = [Renderer(dome, face_size=FACE, path=p, far_layer="sync") for p in ("cpu", "gpu")]
    try:
        for r in layered:
            r.set_scene("habitat")
            assert r.wait_far_layer(POSES[1])
        assert_same(layered, poses=[POSES[1]])
        assert [r.layer_frames for r in layered] == [1, 1]
    finally:
        for r in layered:
            r.release()


def test_every_scene_edit_matches_the_cpu_path(pair, tmp_path):
    scene = with_box({"scene": "sky"})
    for r in pair:
        r.set_scene(_copy(scene))
    assert_same(pair)
    for method, args in [("rotate_scene", (math.radians(70),)), ("move_object", ("box",)),
                         ("add_object", ("tree", SceneObject(box(colour=(0.1, 0.9, 0.2)), position=(-1.0, 0, 0)))),
                         ("remove_object", ("box",)), ("scale_channel", ("blue", 0.4)), ("scale_channel", ("uv", 0.7)),
                         ("swap_green_blue", (True,)), ("set_contrast", (0.4,)), ("set_contrast", (1.6,)),
                         ("set_brightness", (0.5,)), ("set_lowpass", (12.0,)), ("set_lowpass", (None,)),
                         ("set_brightness", (1.0,))]:
        kwargs = {"position": (0.0, -1.0, 0.0), "yaw": 0.5} if method == "move_object" else {}
        both(pair, method, *args, **kwargs)
        assert_same(pair, poses=POSES[:1], what=f"after {method}{args}")


def test_low_pass_on_meshes_samples_a_mipmap_level_on_both_paths(pair):
    scene = with_box({"scene": "grating", "period_deg": 10, "speed_deg_s": 20})
    for r in pair:
        r.set_scene(_copy(scene))
        r.set_lowpass(25.0)
    assert_same(pair)
    assert pair[1]._gpu.matrix_key[1] > 0  # the wide footprint came from a coarser mipmap level
    # every low-passed frame shows its own pose (the atlas's mipmaps were once built from a stale level 0)
    fresh = Renderer(load_dome(), face_size=FACE, path="cpu")
    try:
        fresh.set_scene(_copy(scene))
        fresh.set_lowpass(25.0)
        expected = fresh.render(POSES[0], t=0.5).astype(np.int64)
    finally:
        fresh.release()
    for r in pair:
        assert np.abs(r.render(POSES[0], t=0.5).astype(np.int64) - expected).max() <= 1


def test_packed_datagrams_are_the_video_encoding_and_show_the_frame_on_the_emulator(pair):
    from antarium.core.clock import SimulatedClock
    from antarium.firmware_proto.emulator import Emulator
    from antarium.firmware_proto.video import decode_frame

    cpu, gpu = pair
    for r in pair:
        r.set_scene(_copy(with_box({"scene": "sky"})))
    frame = gpu.render(POSES[1], t=0.0)
    reference = cpu.render(POSES[1], t=0.0)
    packed = gpu.datagrams.copy()
    assert packed.shape == (55, VIDEO_PAYLOAD_SIZE)
    assert np.array_equal(packed, encode_frame(frame, seq=0))
    packed[:, 1] = video_info(5, immediate=True)
    emu = Emulator(clock=SimulatedClock())
    for row in packed:
        emu.handle_datagram(row.tobytes())
    shown = emu.led_values().astype(np.int64)
    assert np.array_equal(shown, decode_frame(packed).astype(np.int64))
    # the wire's 8-bit share costs at most L / 510 + 1/2 LSB per LED; the paths differ by at most 1 more
    lum = reference.astype(np.int64).sum(axis=1, keepdims=True)
    assert np.all(np.abs(shown - reference) <= lum / 510 + 1.5)


def test_path_choice_and_bad_input():
    assert default_path("llvmpipe (LLVM 15.0.6, 256 bits), 4.5 (Core Profile) Mesa 22.3.6") == "cpu"
    assert default_path("softpipe") == "cpu" and default_path("Mesa swrast") == "cpu"
    assert default_path("NVIDIA H100 80GB HBM3/PCIe/SSE2, 4.6.0 NVIDIA 550.54") == "gpu"
    assert check_path(None) is None and check_path("gpu") == "gpu"
    with pytest.raises(ValueError, match="render path must be one of gpu, cpu"):
        check_path("cuda")
    with pytest.raises(ValueError, match="render path must be one of gpu, cpu"):
        Renderer(path="fast")
    from antarium.config import ConfigError, resolve

    render = resolve({"render": {"path": "gpu", "far_layer": "auto"}}).render
    assert render.path == "gpu" and render.far_layer == "auto"
    with pytest.raises(ConfigError, match=r"\[render\] path must be one of 'auto', 'gpu', 'cpu'"):
        resolve({"render": {"path": "cuda"}})


def test_the_frame_loop_sends_the_gpu_paths_packed_datagrams(pair):
    from antarium.core.clock import SimulatedClock
    from antarium.firmware_proto.link import open_link
    from antarium.firmware_proto.video import decode_frame
    from antarium.server.frame_loop import FrameLoop

    gpu = pair[1]
    gpu.set_scene("sky")
    with open_link("virtual") as link:
        loop = FrameLoop(clock=SimulatedClock(), source=None, renderer=gpu, link=link, closed_loop=False)
        for _ in range(3):
            loop.step()
        assert link.counters["frames_sent"] == 3
        expected = gpu.datagrams.copy()
        expected[:, 1] = 2  # the third frame's sequence
        assert np.array_equal(link.emulator.led_values(), decode_frame(expected))
        assert np.array_equal(loop.last_frame, gpu.render(loop.pose, t=gpu.clock.now() - gpu._t0))


class _Recorder:
    """A renderer seam that records the loop's busy-wait calls and renders through the real GPU path; `hardware`
    stands for the GL renderer string of a hardware GPU (this machine's is llvmpipe)."""

    def __init__(self, renderer, hardware: bool = False):
        self.renderer, self.calls, self.on_hardware_gpu = renderer, [], hardware

    def __getattr__(self, name):
        return getattr(self.renderer, name)

    def keep_gpu_busy(self, clock, until):
        self.calls.append((clock.now(), until))
        return self.renderer.keep_gpu_busy(clock, until)


def test_keep_gpu_busy_runs_between_frames_and_leaves_them_unchanged(pair):
    from antarium.core.clock import MonotonicClock, SimulatedClock
    from antarium.firmware_proto.link import open_link
    from antarium.server.frame_loop import GPU_BUSY_MARGIN_S, FrameLoop

    cpu, gpu = pair
    clock = MonotonicClock()
    assert gpu.keep_gpu_busy(clock, clock.now() + 0.02) >= 1
    assert cpu.keep_gpu_busy(clock, clock.now() + 0.02) == 0  # nothing to keep busy
    assert gpu.keep_gpu_busy(SimulatedClock(), 1.0) == 1  # a clock that stands still ends it after one pass
    # a software driver (llvmpipe here, without a GPU) is no hardware GPU; the CPU path never runs on one
    software = any(name in gpu.gl_renderer.lower() for name in ("llvmpipe", "softpipe", "swrast"))
    assert gpu.on_hardware_gpu is not software and not cpu.on_hardware_gpu

    gpu.set_scene("sky")
    gpu._busy_s = 0.0  # the wall-clock passes above (several ms each on a loaded machine) leave the slots below alone
    frames = {}
    for busy, hardware, realtime, kept in ((False, True, True, False), (True, False, False, True),
                                           ("auto", False, True, False), ("auto", True, False, False),
                                           ("auto", True, True, True)):
        rec = _Recorder(gpu, hardware)
        sim = SimulatedClock()
        sim.realtime = realtime  # stands for wall time in "auto"; the frames still run on simulated time
        with open_link("virtual") as link:
            loop = FrameLoop(clock=sim, source=None, renderer=rec, link=link, closed_loop=False, keep_gpu_busy=busy)
            assert loop.gpu_kept_busy is kept
            targets = []
            for _ in range(3):
                targets.append(loop._next_t if loop._next_t is not None else sim.now())
                loop.step()
            frames[busy, hardware, realtime] = link.emulator.led_values().copy()
        assert [u for _, u in rec.calls] == ([t - GPU_BUSY_MARGIN_S for t in targets] if kept else [])
        # the first frame's slot is now; then one pass before each, as the simulated clock stands still
        assert loop.stats()["gpu_busy_passes"] == (2 if kept else 0)
    first = frames[False, True, True]
    assert all(np.array_equal(first, f) for f in frames.values())
    with pytest.raises(ValueError, match='keep_gpu_busy must be true, false or "auto", got \'on\''):
        FrameLoop(clock=SimulatedClock(), source=None, keep_gpu_busy="on")


def test_keep_gpu_busy_from_the_rig_config():
    from antarium.config import ConfigError, resolve
    from antarium.core.clock import SimulatedClock
    from antarium.server.frame_loop import FrameLoop

    assert resolve({}).loop.keep_gpu_busy == "auto"
    for value in (False, True, "auto"):
        loop = FrameLoop.from_config(resolve({"loop": {"keep_gpu_busy": value}}).loop, clock=SimulatedClock(),
                                     source=None)
        assert loop.keep_gpu_busy == value and loop.gpu_kept_busy is (value is True)  # no renderer: "auto" is off
    with pytest.raises(ConfigError, match=r"\[loop\] keep_gpu_busy must be true, false or \"auto\", got 'yes'"):
        resolve({"loop": {"keep_gpu_busy": "yes"}})
