"""GPU buffers of a scene's meshes: one vertex/index buffer in world coordinates, split into spatial chunks
with levels of detail. Per frame each of the six views draws, with one multi-draw-indirect call, the chunks
whose bounding spheres meet its frustum, each at the coarsest level whose error stays under a fraction of a
texel at the chunk's distance.

Vertices are stored relative to an origin near the content (`MeshArrays.origin`, float64), and only the eye's
offset from it enters the view matrices: float32 world coordinates far from (0, 0, 0) (georeferenced worlds,
tens of kilometres and more) would lose the millimetres the near plane (1 mm) and the depth test need.

Levels of detail are made by vertex clustering: level k >= 1 merges the vertices of a chunk that fall in the
same cube of side LOD_CELLS[k-1] (metres) into their mean (position and colour) and drops the triangles that
collapse. A merged vertex moves by at most the cube's diagonal, sqrt(3) cells; a chunk at distance D (to its
bounding sphere) uses the coarsest level whose cell is below `lod_angle * D / LOD_REACH`, so that no vertex moves
by more than half of `lod_angle` as seen from the eye (`Renderer`'s default `lod_angle`: one texel at a face's
centre). Textured meshes keep level 0 only.
"""

from __future__ import annotations

import abc
import dataclasses
import math

import numpy as np

from .cubemap import FACES

#: Objects with more triangles than this are split into chunks on a grid of cubes.
CHUNK_MIN_TRIANGLES = 256
#: Side (texels) of every layer of the mesh texture array.
MAX_TEXTURE_ARRAY_SIDE = 1024
#: Cluster cells (m) of the levels of detail 1, 2, ...
LOD_CELLS = (0.005, 0.01, 0.02, 0.04, 0.08, 0.16, 0.32)
#: lod_angle * D / LOD_REACH bounds the cell at distance D: a vertex moves at most sqrt(3) cells, half lod_angle * D
LOD_REACH = 2.0 * math.sqrt(3.0)
_FLOATS_PER_VERTEX = 9  # position 3, colour 3, uv 2, texture layer 1


def _chunk_order(mesh, chunk_size: float) -> tuple[np.ndarray, np.ndarray]:
    """Triangle order grouping triangles by grid cell, and the chunk index of each (sorted) triangle."""
    if mesh.n_triangles <= CHUNK_MIN_TRIANGLES:
        return np.arange(mesh.n_triangles), np.zeros(mesh.n_triangles, dtype=np.int64)
    centroid = mesh.vertices[mesh.faces].mean(axis=1)
    cell = np.floor(centroid / chunk_size).astype(np.int64)
    cell -= cell.min(axis=0)
    span = cell.max(axis=0) + 1
    key = (cell[:, 0] * span[1] + cell[:, 1]) * span[2] + cell[:, 2]
    order = np.argsort(key, kind="stable")
    _, chunk = np.unique(key[order], return_inverse=True)
    return order, chunk


def cluster_vertices(vertices, colours, faces, tri_chunk, cell: float):
    """One level of detail: vertices merged per (chunk, cube of side `cell`).

    vertices (V, 3), colours (V, 3), faces (F, 3) int, tri_chunk (F,) chunk of each triangle (sorted).
    Returns new vertices (V', 3) float32, colours (V', 3) float32, faces (F', 3) int64 into them, and
    tri_chunk (F',), triangles still sorted by chunk; collapsed and duplicate triangles are dropped.
    Returns None when a chunk spans more than 2^14 cells or there are more than 2^20 chunks (the cube
    indices would not fit the 64-bit key): the caller keeps the finer level.
    """
    corners = faces.ravel()
    pos = vertices[corners].astype(np.float64)
    q = np.floor(pos / cell).astype(np.int64)
    chunk = np.repeat(tri_chunk, 3).astype(np.int64)
    lo = np.full((int(chunk.max()) + 1, 3), np.iinfo(np.int64).max)
    np.minimum.at(lo, chunk, q)
    q -= lo[chunk]  # cube indices relative to each chunk's corner
    if q.max() >= 1 << 14 or chunk.max() >= 1 << 20:
        return None
    key = ((chunk << 14 | q[:, 0]) << 14 | q[:, 1]) << 14 | q[:, 2]
    uniq, inv = np.unique(key, return_inverse=True)
    count = np.bincount(inv, minlength=len(uniq)).astype(np.float64)
    new_v = np.stack([np.bincount(inv, pos[:, k], len(uniq)) for k in range(3)], axis=1) / count[:, None]
    col = colours[corners].astype(np.float64)
    new_c = np.stack([np.bincount(inv, col[:, k], len(uniq)) for k in range(3)], axis=1) / count[:, None]
    tri = inv.reshape(-1, 3)
    keep = (tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 0] != tri[:, 2])
    tri, tri_chunk = tri[keep], tri_chunk[keep]
    _, first = np.unique(np.sort(tri, axis=1), axis=0, return_index=True)
    first.sort()
    return new_v.astype(np.float32), new_c.astype(np.float32), tri[first], tri_chunk[first]


class MeshArrays:
    """The CPU half of `MeshBuffers`: interleaved vertices, indices, per-chunk draw ranges and bounding spheres
    of a scene's objects. Needs no GL context: built in any thread, uploaded by `MeshBuffers` in the GL one.

    vertices (V, 9) float32 [position (world, m, relative to `origin`), colour, uv, texture layer]; indices (I,)
    uint32; first, count (n_chunks, levels) uint32 index ranges per level of detail; origin (3,) float64 world
    position (m) of the vertices' (0, 0, 0): the middle of the objects' bounding boxes; centre (n_chunks, 3)
    float64 (world), radius (n_chunks,) m;
    texels: the texture array's layers (`texture_layers`), None when no object has a texture.
    """

    def __init__(self, objects: dict, chunk_size: float = 2.0):
        self.n_chunks = 0
        self.ranges = {}  # name -> vertex start, object-space vertices, colours, uv, layer, order, chunks
        self.texels = None
        self.origin = np.zeros(3)
        if not objects:
            return
        self.origin = content_origin(objects)
        self.texels = texture_layers([o.mesh.texture for o in objects.values() if o.mesh.texture is not None])
        n_levels = 1 + len(LOD_CELLS)
        vert_blocks, idx_blocks = [], []
        first, count, sided = [], [], []  # per chunk: (n_levels,) index offsets and counts; back-face culling
        v0 = i0 = c0 = 0
        layer = 0
        for name, obj in objects.items():
            mesh = obj.mesh
            order, tri_chunk = _chunk_order(mesh, chunk_size)
            n_chunks = int(tri_chunk[-1]) + 1
            tex_layer = -1.0
            if mesh.texture is not None:
                tex_layer, layer = float(layer), layer + 1
            levels = [(mesh.faces[order].astype(np.int64), tri_chunk)]
            verts, cols = [mesh.vertices], [mesh.colours]
            base = len(mesh.vertices)
            if mesh.texture is None:
                for cell in LOD_CELLS:
                    lod = cluster_vertices(mesh.vertices, mesh.colours, *levels[0], cell)
                    if lod is None:  # too many cells for this object: keep the finer level
                        levels.append(levels[-1])
                        continue
                    v, c, f, tc = lod
                    levels.append((f + base, tc))
                    verts.append(v)
                    cols.append(c)
                    base += len(v)
            local = np.concatenate(verts)
            colours = np.concatenate(cols)
            uv = mesh.uv if mesh.uv is not None else np.zeros((len(local), 2), np.float32)
            f_obj = np.zeros((n_chunks, n_levels), dtype=np.int64)
            n_obj = np.zeros((n_chunks, n_levels), dtype=np.int64)
            for k in range(n_levels):
                f, tc = levels[min(k, len(levels) - 1)]
                per_chunk = np.bincount(tc, minlength=n_chunks)
                starts = np.concatenate([[0], np.cumsum(per_chunk)[:-1]])
                if k < len(levels) and (k == 0 or levels[k] is not levels[k - 1]):
                    idx_blocks.append((f + v0).ravel())
                    f_obj[:, k] = i0 + 3 * starts
                    i0 += 3 * len(f)
                else:  # the same triangles as the level before (textured, or too large to cluster)
                    f_obj[:, k] = f_obj[:, k - 1]
                n_obj[:, k] = 3 * per_chunk
            first.append(f_obj)
            count.append(n_obj)
            sided.append(np.full(n_chunks, not mesh.double_sided))
            self.ranges[name] = (v0, local, colours, uv, tex_layer, order, tri_chunk, c0, c0 + n_chunks)
            vert_blocks.append(interleave(obj, local, colours, uv, tex_layer, self.origin))
            v0 += len(local)
            c0 += n_chunks
        self.vertices = np.concatenate(vert_blocks)
        self.indices = np.concatenate(idx_blocks).astype(np.uint32)
        self.n_chunks = c0
        self.first = np.concatenate(first).astype(np.uint32)
        self.count = np.concatenate(count).astype(np.uint32)
        self.single_sided = np.concatenate(sided)
        self.centre = np.zeros((self.n_chunks, 3))
        self.radius = np.zeros(self.n_chunks)
        for name, obj in objects.items():
            self.bounds(name, obj)

    def bounds(self, name: str, obj) -> None:
        """Set the bounding spheres of an object's chunks (`chunk_bounds`)."""
        *_, c0, c1 = self.ranges[name]
        self.centre[c0:c1], self.radius[c0:c1] = self.chunk_bounds(name, obj)

    def chunk_bounds(self, name: str, obj) -> tuple[np.ndarray, np.ndarray]:
        """(n, 3) float64 centres (m, world) and (n,) radii (m) of the bounding spheres of the named object's n
        chunks, placed as `obj`, from its full-detail triangles; changes nothing (any thread)."""
        *_, order, tri_chunk, c0, c1 = self.ranges[name]
        tri = relative_to(obj, self.origin).world_vertices()[obj.mesh.faces[order]]
        n = c1 - c0
        lo = np.full((n, 3), np.inf)
        hi = np.full((n, 3), -np.inf)
        np.minimum.at(lo, tri_chunk, tri.min(axis=1))
        np.maximum.at(hi, tri_chunk, tri.max(axis=1))
        return (lo + hi) / 2 + self.origin, np.linalg.norm(hi - lo, axis=1) / 2

    def near_chunks(self, eye: np.ndarray, radius: float) -> np.ndarray:
        """(n_chunks,) bool: some of the chunk's bounding sphere lies within `radius` (m) of `eye` (m)."""
        return np.linalg.norm(self.centre - eye, axis=1) - self.radius < radius


def content_origin(objects: dict) -> np.ndarray:
    """(3,) float64 (m): the middle of the objects' world bounding boxes (from their object-space boxes' corners)."""
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for obj in objects.values():
        v = obj.mesh.vertices
        box = np.stack([v.min(axis=0), v.max(axis=0)], axis=1).astype(np.float64)  # (3 axes, min max)
        corners = np.stack(np.meshgrid(*box, indexing="ij"), axis=-1).reshape(8, 3)
        world = relative_to(obj, obj.position).to_world(corners) + np.asarray(obj.position, dtype=np.float64)
        lo, hi = np.minimum(lo, world.min(axis=0)), np.maximum(hi, world.max(axis=0))
    return (lo + hi) / 2


def relative_to(obj, origin: np.ndarray):
    """The object placed relative to `origin` (3,) m: its `to_world` gives float32 coordinates near 0 for
    content near the origin, however far both lie from (0, 0, 0) (computed in float64 before rounding)."""
    return dataclasses.replace(obj, position=tuple(np.asarray(obj.position, dtype=np.float64) - origin))


def interleave(obj, local, colours, uv, tex_layer: float, origin: np.ndarray) -> np.ndarray:
    """(V, 9) float32 vertex block of an object: positions (world, relative to `origin` (3,) m), colours, uv,
    texture layer."""
    v = np.empty((len(local), _FLOATS_PER_VERTEX), dtype=np.float32)
    v[:, 0:3] = relative_to(obj, origin).to_world(local)
    v[:, 3:6] = colours
    v[:, 6:8] = uv
    v[:, 8] = tex_layer
    return v


def texture_layers(textures: list[np.ndarray]) -> np.ndarray | None:
    """(L, side, side, C) float16 layers of the mesh texture array, from textures (H, W, 3) of linear G, B, UV or
    (H, W, 4) with a cut-out mask; C = 4 when some texture has a mask (1 for those without: drawn everywhere),
    else 3 (GL samples alpha 1). Each is resized to the largest side among them, at most MAX_TEXTURE_ARRAY_SIDE
    texels, its rows bottom up as GL reads them; None for no texture."""
    if not textures:
        return None
    import cv2

    side = min(MAX_TEXTURE_ARRAY_SIDE, max(max(t.shape[:2]) for t in textures))
    out = np.ones((len(textures), side, side, max(t.shape[2] for t in textures)), dtype=np.float16)
    for layer, t in zip(out, textures, strict=True):
        t = np.asarray(t, dtype=np.float32)
        layer[..., :t.shape[2]] = cv2.resize(t, (side, side), interpolation=cv2.INTER_AREA)[::-1]
    return out


#: bytes a staged upload's step copies (`StagedUpload`, `gpu_path.StagedTable`): well under a millisecond, so that
#: a step fits the idle end of a frame
UPLOAD_SLICE_BYTES = 2 << 20


class SlicedWrite:
    """Arrays copied into GL buffers about `UPLOAD_SLICE_BYTES` per `step` (GL thread).

    parts: (buffer, offset in bytes, C-contiguous array) triples, copied in order.
    """

    def __init__(self, parts: list):
        self._parts = [(buf, offset, memoryview(np.ascontiguousarray(a)).cast("B")) for buf, offset, a in parts]
        self._part = self._offset = 0

    @property
    def done(self) -> bool:
        return self._part == len(self._parts)

    def step(self, nbytes: int | None = None) -> bool:
        """Copy about `nbytes` (default `UPLOAD_SLICE_BYTES`) of the current part; True once all are copied."""
        if self.done:
            return True
        buf, base, data = self._parts[self._part]
        end = min(data.nbytes, self._offset + (UPLOAD_SLICE_BYTES if nbytes is None else nbytes))
        if end > self._offset:
            buf.write(data[self._offset:end], offset=base + self._offset)
        self._offset = end
        if end == data.nbytes:
            self._part, self._offset = self._part + 1, 0
        return self.done


class Staged(abc.ABC):
    """GL objects filled a slice at a time in the GL thread (`step`), which another thread may `discard`.

    discard: where `discard()` hands it for release in the GL thread (it may be called from any thread).
    """

    def __init__(self, discard=None):
        self._discard = discard
        self.discarded = False

    @abc.abstractmethod
    def step(self, nbytes: int | None = None) -> bool:
        """Fill about `nbytes` more (GL thread); True once everything is in."""

    def _fill(self) -> None:
        """Copy what is left now (GL thread)."""
        while not self.step(1 << 62):
            pass

    def discard(self) -> None:
        """Not needed after all (any thread): released in the GL thread, or here when no one takes it."""
        self.discarded = True
        if self._discard is not None:
            self._discard(self)
        else:
            self.release()

    @abc.abstractmethod
    def release(self) -> None:
        """Free the GL objects (GL thread)."""


class StagedUpload(Staged):
    """The vertex and index buffers and the texture array of a `MeshArrays`, filled a slice at a time in the GL
    thread (`step`), so that loading a large scene never holds a frame for its whole upload; `MeshBuffers` takes
    them (`finish`). The texture array's mipmaps are made in one step of their own, after its last layer.
    """

    def __init__(self, ctx, arrays: MeshArrays, discard=None):
        super().__init__(discard)
        self.ctx = ctx
        self._data = (arrays.vertices, arrays.indices)
        self._texels = arrays.texels
        self.buffers: list = []
        self.texture = None
        self._writes: SlicedWrite | None = None
        self._row = 0  # texture rows written, over all layers
        self._mipmapped = self._texels is None

    @property
    def done(self) -> bool:
        return self._writes is not None and self._writes.done and self._mipmapped

    def step(self, nbytes: int | None = None) -> bool:
        """Copy about `nbytes` more (default `UPLOAD_SLICE_BYTES`; the first step creates the buffers and the
        texture array); True once everything is up. GL thread."""
        if self.discarded or self.done:
            return True
        nbytes = UPLOAD_SLICE_BYTES if nbytes is None else nbytes
        if self._writes is None:
            self.buffers = [self.ctx.buffer(reserve=max(1, a.nbytes)) for a in self._data]
            self.texture = self._new_texture()
            self._writes = SlicedWrite([(b, 0, a) for b, a in zip(self.buffers, self._data, strict=True)])
        elif not self._writes.done:
            self._writes.step(nbytes)
        elif self._row < self._texels.shape[0] * self._texels.shape[1]:
            self._write_rows(nbytes)
        else:
            self.texture.build_mipmaps()
            self._mipmapped = True
        return self.done

    def _new_texture(self):
        """The texture array, its layers still to write (one white texel when there is no texture)."""
        if self._texels is None:
            return self.ctx.texture_array((1, 1, 1), 3, np.ones(3, dtype=np.float16).tobytes(), dtype="f2")
        n_layers, side, _, components = self._texels.shape
        return self.ctx.texture_array((side, side, n_layers), components, dtype="f2")

    def _write_rows(self, nbytes: int) -> None:
        """About `nbytes` of texture rows, within one layer."""
        side = self._texels.shape[1]
        layer, y = divmod(self._row, side)
        rows = min(side - y, max(1, nbytes // self._texels[0, 0].nbytes))
        self.texture.write(self._texels[layer, y:y + rows].tobytes(), viewport=(0, y, layer, side, rows, 1))
        self._row += rows

    def finish(self) -> tuple:
        """The filled vertex buffer, index buffer and texture array, copying what is left now. GL thread."""
        self._fill()
        return (*self.buffers, self.texture)

    def release(self) -> None:
        for res in (*self.buffers, self.texture):
            if res is not None:
                res.release()
        self.buffers, self.texture = [], None


class MeshBuffers:
    """All objects of a scene on the GPU. Per frame, `draw` culls chunks per face and renders them.

    lod_angle: radians; a chunk at distance D uses level-of-detail cells up to lod_angle * D / LOD_REACH (0: no
    LOD), its vertices moving by up to half of lod_angle.
    arrays: the objects' `MeshArrays`, made beforehand in another thread (default: made here); only the GL
    uploads then run here, or only what is left of them when `upload` (a `StagedUpload` of those arrays) is given.
    gpu_cull: cull and choose levels in a compute pass (`gpu_cull.GpuCulling`, GL 4.3) instead of numpy here,
    except for a frame that draws only some chunks (a far layer's near set).
    """

    def __init__(self, ctx, prog, objects: dict, chunk_size: float = 2.0, lod_angle: float = 0.0,
                 arrays: MeshArrays | None = None, upload: StagedUpload | None = None, gpu_cull: bool = False):
        self.ctx, self.prog = ctx, prog
        self.lod_angle = float(lod_angle)
        self._resources = []
        self.n_chunks = 0
        self._culling = None
        if not objects:
            return
        import moderngl

        self._mgl = moderngl
        a = MeshArrays(objects, chunk_size) if arrays is None else arrays
        self._arrays = a
        self._ranges, self._centre, self._radius = a.ranges, a.centre, a.radius
        self._shift = np.eye(4)  # the vertices' coordinates -> world, in float64 before the product is rounded
        self._shift[:3, 3] = a.origin
        if upload is None:
            upload = StagedUpload(ctx, a)
        self._vbo, self._ibo, self._textures = upload.finish()
        a.texels = None  # on the GPU now: not kept twice (up to 6 MB a layer)
        self._vao = ctx.vertex_array(prog, [(self._vbo, "3f 3f 2f 1f", "in_pos", "in_col", "in_uv", "in_layer")],
                                     self._ibo, index_element_size=4)
        self.n_chunks = a.n_chunks
        self._first, self._count, self._single_sided = a.first, a.count, a.single_sided
        self._active = np.ones(self.n_chunks, dtype=bool)
        self._indirect = ctx.buffer(reserve=6 * self.n_chunks * 20)
        self._cmds = np.zeros((6 * self.n_chunks, 5), dtype=np.uint32)
        self._cmds[:, 1] = 1
        self._resources += [self._vao, self._vbo, self._ibo, self._textures, self._indirect]
        if gpu_cull:
            from .gpu_cull import GpuCulling

            self._culling = GpuCulling(ctx, self._first, self._count, self._single_sided, self.lod_angle,
                                       LOD_REACH * LOD_CELLS[0])
            self._resources.append(self._culling)
            self._chunks_changed = True  # bounds or shown chunks to upload before the next frame

    def update_object(self, name: str, obj) -> None:
        """Re-upload a moved object's vertices (all levels) and recompute its chunks' bounds."""
        self.apply_move(name, self.moved(name, obj))

    def moved(self, name: str, obj) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What placing the named object as `obj` writes, for `apply_move`: its (V, 9) float32 vertex block (all
        levels) and its chunks' bounds (`MeshArrays.chunk_bounds`). Numpy only, changes nothing: any thread."""
        _, local, colours, uv, tex_layer, *_ = self._ranges[name]
        return (interleave(obj, local, colours, uv, tex_layer, self._arrays.origin),
                *self._arrays.chunk_bounds(name, obj))

    def apply_move(self, name: str, moved: tuple[np.ndarray, np.ndarray, np.ndarray]) -> None:
        """Write `moved(name, obj)`'s vertices and bounds (GL thread)."""
        v0, *_, c0, c1 = self._ranges[name]
        block, centre, radius = moved
        self._vbo.write(block, offset=v0 * _FLOATS_PER_VERTEX * 4)
        self._centre[c0:c1], self._radius[c0:c1] = centre, radius
        self._chunks_changed = True

    @property
    def drawable(self) -> bool:
        """Whether any chunk is left to draw."""
        return self.n_chunks > 0 and bool(self._active.any())

    def hide(self, name: str) -> None:
        """Stop drawing the named object's chunks."""
        self._show(name, False)

    def show(self, name: str) -> None:
        """Draw the named object's chunks again (a hide undone)."""
        self._show(name, True)

    def _show(self, name: str, shown: bool) -> None:
        *_, c0, c1 = self._ranges[name]
        self._active[c0:c1] = shown
        self._chunks_changed = True

    def visible_chunks(self, q: np.ndarray, eye: np.ndarray, ids: np.ndarray | None = None) -> np.ndarray:
        """(n, 6) bool: the bounding sphere of chunk ids[i] (default: every chunk) meets face k's 90° frustum."""
        ids = slice(None) if ids is None else ids
        radius = self._radius[ids]
        rel = (self._centre[ids] - eye) @ q  # dome (cube) frame
        f = rel @ FACES[:, 0].T
        r = np.abs(rel @ FACES[:, 1].T)
        u = np.abs(rel @ FACES[:, 2].T)
        slack = -math.sqrt(2.0) * radius[:, None]
        return (f - r >= slack) & (f - u >= slack) & self._active[ids, None]

    def levels(self, eye: np.ndarray, ids: np.ndarray | None = None) -> np.ndarray:
        """(n,) level of detail of chunks `ids` (default: every chunk) for an eye position (m)."""
        ids = slice(None) if ids is None else ids
        dist = np.maximum(np.linalg.norm(self._centre[ids] - eye, axis=1) - self._radius[ids], 1e-6)
        if self.lod_angle <= 0:
            return np.zeros(len(dist), dtype=np.int64)
        allowed = self.lod_angle * dist / (LOD_REACH * LOD_CELLS[0])
        return np.clip(np.floor(np.log2(np.maximum(allowed, 1e-9))) + 1, 0, len(LOD_CELLS)).astype(np.int64)

    def near_chunks(self, eye: np.ndarray, radius: float) -> np.ndarray:
        """(n_chunks,) bool: some of the chunk's bounding sphere lies within `radius` (m) of `eye` (m)."""
        return self._arrays.near_chunks(eye, radius)

    def commands(self, q: np.ndarray, eye: np.ndarray, chunks: np.ndarray | None = None) -> tuple:
        """The indirect draw commands of a frame, computed here: ((m, 5) uint32 commands, (12,) commands per batch).
        Batch 2k + s holds face k's visible chunks (only those where `chunks` is set, if given) that are
        single-sided (s = 1) or not, each at its level of detail, front to back (distance to the bounding
        sphere), ties by chunk."""
        ids = np.arange(self.n_chunks) if chunks is None else np.flatnonzero(chunks)
        level = self.levels(eye, ids)
        counts = self._count[ids, level]
        firsts = self._first[ids, level]
        vis = self.visible_chunks(q, eye, ids) & (counts > 0)[:, None]
        face, local = np.nonzero(vis.T)
        chunk = ids[local]
        batch = 2 * face + self._single_sided[chunk]
        # front to back within each batch, so that hidden fragments fail the depth test early
        near = np.linalg.norm(self._centre[chunk] - eye, axis=1) - self._radius[chunk]
        order = np.lexsort((near, batch))
        local, batch = local[order], batch[order]
        cmds = self._cmds[:len(local)]
        cmds[:, 0] = counts[local]
        cmds[:, 2] = firsts[local]
        return cmds, np.bincount(batch, minlength=12)

    def draw(self, fbo, views: np.ndarray, proj: np.ndarray, q: np.ndarray, eye: np.ndarray, n: int,
             chunks: np.ndarray | None = None) -> int:
        """Draw every face's visible chunks (only those where `chunks` (n_chunks,) bool is set, if given) into
        the atlas; returns the number of draw commands issued."""
        if self._culling is not None and chunks is None:
            return self._draw_culled_on_gpu(fbo, views, proj, q, eye, n)
        cmds, per_batch = self.commands(q, eye, chunks)
        if len(cmds) == 0:
            return 0
        self._indirect.write(cmds.tobytes())
        offsets = np.concatenate([[0], np.cumsum(per_batch)[:-1]])
        self._draw_faces(fbo, views, proj, n, self._indirect, [
            ((int(offsets[2 * k]), int(per_batch[2 * k])), (int(offsets[2 * k + 1]), int(per_batch[2 * k + 1])))
            for k in range(6)])
        return len(cmds)

    def _draw_culled_on_gpu(self, fbo, views: np.ndarray, proj: np.ndarray, q: np.ndarray, eye: np.ndarray,
                            n: int) -> int:
        """`draw` with the commands written by the culling pass: per face, the double-sided chunks' slots and
        the single-sided ones', every chunk's command issued (empty when not drawn)."""
        culling = self._culling
        if self._chunks_changed:
            culling.set_chunks(self._centre, self._radius, self._active)
            self._chunks_changed = False
        culling.run(q, eye)
        self._draw_faces(fbo, views, proj, n, culling.commands, culling.batches)
        return 6 * self.n_chunks

    def _draw_faces(self, fbo, views: np.ndarray, proj: np.ndarray, n: int, commands, batches: list) -> None:
        """Face k's commands in `commands`: batches[k] = ((first, count) double-sided, (first, count) single-sided,
        drawn with back faces culled)."""
        self._textures.use(1)
        for k, face in enumerate(batches):
            if face[0][1] + face[1][1] == 0:
                continue
            fbo.viewport = (0, k * n, n, n)
            self.prog["view_proj"].write((proj @ views[k] @ self._shift).T.astype("f4").tobytes())
            for single_sided, (first, count) in enumerate(face):
                if count:
                    self.ctx.cull_face = "back"
                    if single_sided:
                        self.ctx.enable(self._mgl.CULL_FACE)
                    else:
                        self.ctx.disable(self._mgl.CULL_FACE)
                    self._vao.render_indirect(commands, self._mgl.TRIANGLES, count=count, first=first)
        self.ctx.disable(self._mgl.CULL_FACE)

    def detach(self) -> list:
        """Hand over the GL objects (each with `release()`): this object no longer releases them."""
        resources, self._resources = self._resources, []
        return resources

    def release(self) -> None:
        for res in self.detach():
            res.release()
