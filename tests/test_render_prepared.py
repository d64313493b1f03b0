"""Scenes prepared off the frame loop (`renderers.prepared`): built in the scene's own process, handed over in
shared memory, their meshes uploaded a slice at a time in the GL thread; what the dome then shows is exactly what
a scene loaded in one piece shows. Real renderer (EGL)."""

import os
import threading

import numpy as np
import pytest

from antarium.core.pose import Pose
from antarium.renderers.library import build_scene
from antarium.renderers.meshbuffers import MeshArrays, StagedUpload
from antarium.renderers.renderer import Renderer

SMALL_HABITAT = {"scene": "habitat", "n_tussocks": 40, "n_stones": 10, "n_bushes": 2, "n_trees": 1}
POSES = (Pose(0.0, 0.0, 0.01, 0.0), Pose(0.7, -0.4, 0.01, 1.1))


@pytest.fixture(scope="module")
def renderers():
    pair = [Renderer(face_size=64, far_layer="off") for _ in range(2)]
    yield pair
    for r in pair:
        r.release()


def test_a_prepared_scene_uploaded_in_slices_shows_what_a_scene_loaded_at_once_does(renderers):
    staged, direct = renderers
    prepared = staged.prepare_scene(SMALL_HABITAT)
    assert prepared.layer is None and prepared.arrays is not None  # far layer off: the scene's process has ended
    steps = 1
    while not staged.upload_step(prepared):
        steps += 1
    size = prepared.arrays.vertices.nbytes + prepared.arrays.indices.nbytes
    assert steps >= 2 + size // (2 << 20)  # buffers made, then one slice a step
    staged.set_scene(prepared)
    assert prepared.upload is None and prepared.arrays is None  # the meshes own the buffers now
    direct.set_scene(SMALL_HABITAT)
    for pose in POSES:
        np.testing.assert_array_equal(staged.render(pose), direct.render(pose))


@pytest.fixture(scope="module")
def gpu_renderers():
    pair = [Renderer(face_size=64, far_layer="off", path="gpu") for _ in range(2)]
    yield pair
    for r in pair:
        r.release()


def _gl_bytes_made_or_written(r, monkeypatch) -> list:
    """A list that collects the bytes of every GL buffer `r` creates or writes from now on."""
    import moderngl

    counted = []
    make, write = r.ctx.buffer, moderngl.Buffer.write

    def size(data) -> int:
        return 0 if data is None else memoryview(data).nbytes

    monkeypatch.setattr(r.ctx, "buffer", lambda data=None, **kw: counted.append(size(data) or kw.get("reserve", 0))
                        or make(data, **kw))
    monkeypatch.setattr(moderngl.Buffer, "write",
                        lambda self, data, **kw: counted.append(size(data)) or write(self, data, **kw))
    return counted


def test_on_the_gpu_path_the_far_field_table_is_uploaded_before_the_swap_too(gpu_renderers, monkeypatch):
    """The far-field table (7 MB) goes up in slices with the meshes: the swap and the first frame after it upload
    next to nothing (on an H100 that first frame took 6-19 ms: the table made and the one before released), and
    the buffers of the table shown before are reused: GPU memory does not grow with loads."""
    staged, direct = gpu_renderers
    staged.set_scene(SMALL_HABITAT)
    staged.render(POSES[0])
    assert staged._table.table_gb.nbytes + staged._table.table_uv.nbytes > 4 << 20
    tables, held = [staged._gpu._table.glo], []
    for _ in range(2):
        prepared = staged.prepare_scene(SMALL_HABITAT)
        while not staged.upload_step(prepared):
            pass
        counted = _gl_bytes_made_or_written(staged, monkeypatch)
        staged.set_scene(prepared)
        frame = staged.render(POSES[1]).copy()
        monkeypatch.undo()
        assert sum(counted) < 1 << 20
        tables.append(staged._gpu._table.glo)
        held.append(staged._gpu.gpu_bytes)
    # two tables' buffers, used in turn: the one shown and the one before, which the next load fills
    assert tables[2] == tables[0] != tables[1] and held[0] == held[1]
    direct.set_scene(SMALL_HABITAT)
    np.testing.assert_array_equal(frame, direct.render(POSES[1]))
    np.testing.assert_array_equal(staged.render(POSES[0]), direct.render(POSES[0]))


def test_a_swap_that_retires_the_old_scene_releases_nothing_until_asked_one_object_a_call(renderers, monkeypatch):
    """Releasing a large buffer took the NVIDIA driver up to 10 ms (an H100): with `retire`, the swap releases none
    of the old scene's GL objects; `release_retired` then releases them one a call (a frame loop's idle time)."""
    import moderngl

    staged, direct = renderers
    staged.set_scene(SMALL_HABITAT)
    direct.set_scene(SMALL_HABITAT)
    prepared = staged.prepare_scene(SMALL_HABITAT)
    while not staged.upload_step(prepared):
        pass
    released = []
    for cls in (moderngl.Buffer, moderngl.Texture, moderngl.TextureArray, moderngl.VertexArray):
        monkeypatch.setattr(cls, "release", lambda self, _r=cls.release: released.append(self) or _r(self))
    staged.set_scene(prepared, retire=True)
    assert released == [] and staged.retired >= 4  # the far texture or none, vertices, indices, textures, VAO...
    np.testing.assert_array_equal(staged.render(POSES[1]), direct.render(POSES[1]))
    left = staged.retired
    while left:
        before = len(released)
        assert staged.release_retired() == left - 1
        left -= 1
        assert len(released) - before <= 8  # one object: a buffer, texture or VAO (the culling pass: its 7 buffers)
    assert staged.release_retired() == 0
    np.testing.assert_array_equal(staged.render(POSES[0]), direct.render(POSES[0]))


def test_a_prepared_move_is_only_uploaded_in_the_gl_thread_and_shows_what_a_move_does(renderers, monkeypatch):
    from antarium.renderers.meshbuffers import MeshBuffers

    moved, direct = renderers
    for r in renderers:
        r.set_scene(SMALL_HABITAT)
    name = next(n for n in moved.scene.objects if n.startswith("bush"))
    x, y, z = (float(c) for c in moved.scene.objects[name].position)
    prepared = moved.prepare_move(name, position=(x + 0.3, y, z), yaw=0.4)
    calls = []
    compute = MeshBuffers.moved
    monkeypatch.setattr(MeshBuffers, "moved", lambda self, *a: calls.append(a) or compute(self, *a))
    moved.move_object(name, position=(x + 0.3, y, z), yaw=0.4, prepared=prepared)
    assert calls == []
    direct.move_object(name, position=(x + 0.3, y, z), yaw=0.4)
    for pose in POSES:
        np.testing.assert_array_equal(moved.render(pose), direct.render(pose))
    # made before another move of the same object: stale, so computed again here
    stale = moved.prepare_move(name, position=(x - 0.3, y, z))
    for r in renderers:
        r.move_object(name, position=(x + 0.1, y, z))
    calls.clear()
    moved.move_object(name, position=(x - 0.3, y, z), prepared=stale)
    assert len(calls) == 1
    direct.move_object(name, position=(x - 0.3, y, z))
    np.testing.assert_array_equal(moved.render(POSES[1]), direct.render(POSES[1]))


def test_slices_fill_the_buffers_with_the_arrays_bytes(renderers):
    r = renderers[0]
    arrays = MeshArrays(build_scene(dict(SMALL_HABITAT)).objects, r.chunk_size)
    with r.ctx:
        upload = StagedUpload(r.ctx, arrays)
        n = 1
        while not upload.step(5000):
            n += 1
        expected = 1 + -(-arrays.vertices.nbytes // 5000) + -(-arrays.indices.nbytes // 5000)
        assert n == expected
        vbo, ibo, _ = upload.finish()
        assert vbo.read() == arrays.vertices.tobytes() and ibo.read() == arrays.indices.tobytes()
        upload.release()


def _textured_walls(path):
    """A GLB of two textured walls (textures of different sizes), +y up as glTF is."""
    import trimesh
    from PIL import Image

    from antarium.renderers.meshes import GLTF_TO_WORLD

    rng = np.random.default_rng(5)
    scene = trimesh.Scene()
    for k, (h, w) in enumerate([(64, 64), (48, 32)]):
        m = trimesh.creation.box(extents=(0.01, 2.0, 2.0))
        uv = np.stack([(m.vertices[:, 1] + 1) / 2, (m.vertices[:, 2] + 1) / 2], axis=1)
        texture = Image.fromarray(rng.integers(0, 256, (h, w, 3), dtype=np.uint8))
        m.visual = trimesh.visual.TextureVisuals(uv=uv, material=trimesh.visual.material.PBRMaterial(
            baseColorTexture=texture))
        m.apply_translation([2.0, 3.0 * k - 1.5, 0.0])
        scene.add_geometry(m.apply_transform(GLTF_TO_WORLD.T), node_name=f"wall_{k}")
    scene.export(path)
    return str(path)


def test_a_textured_scene_uploads_its_texture_array_in_slices_too(renderers, tmp_path):
    """The texture array is filled in the upload steps, a slice of rows at a time, then mipmapped in a step of
    its own (until 2026-11-26 all of it was made at the swap, in one frame: about 0.5 s for eight 4096-texel
    textures on llvmpipe); the dome then shows what the scene loaded at once does."""
    staged, direct = renderers
    path = _textured_walls(tmp_path / "walls.glb")
    arrays = MeshArrays(build_scene(path).objects, staged.chunk_size)
    assert arrays.texels.shape == (2, 64, 64, 3)
    with staged.ctx:
        upload = StagedUpload(staged.ctx, arrays)
        n = 1
        while not upload.step(5000):
            n += 1
        rows = 2 * -(-64 // (5000 // (64 * 3 * 2)))
        assert n == 1 + -(-arrays.vertices.nbytes // 5000) + -(-arrays.indices.nbytes // 5000) + rows + 1
        *_, texture = upload.finish()
        level0 = np.frombuffer(texture.read(), np.float16).reshape(arrays.texels.shape)
        np.testing.assert_array_equal(level0, arrays.texels)
        upload.release()
    prepared = staged.prepare_scene(path)
    while not staged.upload_step(prepared):
        pass
    staged.set_scene(prepared)
    direct.set_scene(path)
    for pose in POSES:
        np.testing.assert_array_equal(staged.render(pose), direct.render(pose))


def test_an_upload_discarded_in_another_thread_is_released_in_the_gl_thread(renderers):
    r = renderers[0]
    prepared = r.prepare_scene(SMALL_HABITAT)
    r.upload_step(prepared)
    r.upload_step(prepared)
    buffers = list(prepared.upload.buffers)
    assert buffers
    worker = threading.Thread(target=prepared.release)
    worker.start()
    worker.join()
    assert prepared.upload is None and all(type(b.mglo).__name__ != "InvalidObject" for b in buffers)
    assert r.upload_step(prepared)  # nothing left to upload; the discarded buffers go here, in the GL thread
    assert all(type(b.mglo).__name__ == "InvalidObject" for b in buffers)


def test_a_scene_that_fails_in_its_process_raises_its_own_error_here(renderers, tmp_path):
    r = renderers[0]
    with pytest.raises(FileNotFoundError, match="missing.obj"):
        r.prepare_scene(str(tmp_path / "missing.obj"))
    with pytest.raises(ValueError, match="period_deg must be a finite number, got .wide."):
        r.prepare_scene({"scene": "grating", "period_deg": "wide"})


@pytest.mark.skipif(not hasattr(os, "SCHED_IDLE"), reason="Linux scheduling classes")
def test_the_scene_process_prepares_idle_then_builds_layers_at_the_loops_builder_priority():
    r = Renderer(face_size=64, layer_face_size=64, far_layer="async")
    try:
        r.builder_nice = 7  # what the frame loop's thread chose (5 beside an ordinary loop, 10 below a real-time one)
        prepared = r.prepare_scene(SMALL_HABITAT, pose=lambda: POSES[0])
        pid = prepared.layer.pid
        assert prepared.layer.builds == 1 and not prepared.layer.error  # it has built the first layer
        assert os.sched_getscheduler(pid) == os.SCHED_OTHER and os.getpriority(os.PRIO_PROCESS, pid) == 7
        prepared.release()
    finally:
        r.release()


def test_an_upload_made_while_another_thread_releases_the_scene_is_discarded_not_leaked(renderers, monkeypatch):
    """release() in another thread between upload_step's check and its new upload: the upload made then is
    discarded before it makes any GL object (it was kept on the released scene and its buffers made, never freed;
    on the GPU path the same with the far-field table's)."""
    from antarium.renderers import meshbuffers

    r = renderers[0]
    prepared = r.prepare_scene(SMALL_HABITAT)
    made = []

    class ReleasedMeanwhile(meshbuffers.StagedUpload):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            made.append(self)
            worker = threading.Thread(target=prepared.release)
            worker.start()
            worker.join()

    monkeypatch.setattr(meshbuffers, "StagedUpload", ReleasedMeanwhile)
    assert r.upload_step(prepared)  # released: nothing more to upload
    assert prepared.closed and prepared.upload is None and made and made[0].discarded
    monkeypatch.undo()
    assert made[0].buffers == [] and made[0].texture is None  # never stepped: no GL object made for it
    assert r.upload_step(prepared) and prepared.upload is None
