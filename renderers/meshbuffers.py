"""GPU buffers of a scene's meshes: one vertex/index buffer in world coordinates, split into spatial chunks
that each of the six views culls against its frustum and draws with one multi-draw-indirect call."""

from __future__ import annotations

import math

import numpy as np

from .cubemap import FACES

#: Objects with more triangles than this are split into chunks on an (x, y) grid.
CHUNK_MIN_TRIANGLES = 2048
#: Side (texels) of every layer of the mesh texture array.
MAX_TEXTURE_ARRAY_SIDE = 1024
_FLOATS_PER_VERTEX = 9  # position 3, colour 3, uv 2, texture layer 1


def _chunk_order(mesh, chunk_size: float) -> tuple[np.ndarray, np.ndarray]:
    """Triangle order grouping triangles by grid cell, and the triangle count of each chunk."""
    if mesh.n_triangles <= CHUNK_MIN_TRIANGLES:
        return np.arange(mesh.n_triangles), np.array([mesh.n_triangles])
    centroid = mesh.vertices[mesh.faces].mean(axis=1)
    cell = np.floor(centroid[:, :2] / chunk_size).astype(np.int64)
    cell -= cell.min(axis=0)
    key = cell[:, 0] * (cell[:, 1].max() + 1) + cell[:, 1]
    order = np.argsort(key, kind="stable")
    _, counts = np.unique(key[order], return_counts=True)
    return order, counts


class MeshBuffers:
    """All objects of a scene on the GPU. Per frame, `draw` culls chunks per face and renders them."""

    def __init__(self, ctx, prog, scene, chunk_size: float = 2.0):
        self.ctx, self.prog = ctx, prog
        self._resources = []
        self.n_chunks = 0
        objects = scene.objects
        if not objects:
            return
        import moderngl

        self._mgl = moderngl
        self._textures = self._texture_array(objects)
        vert_blocks, idx_blocks = [], []
        first, count, owner = [], [], []
        self._ranges = {}  # name -> (vertex start, vertex count, chunk start, chunk stop, triangle order)
        v0 = i0 = 0
        layer = 0
        for k, (name, obj) in enumerate(objects.items()):
            mesh = obj.mesh
            order, counts = _chunk_order(mesh, chunk_size)
            tex_layer = -1.0
            if mesh.texture is not None:
                tex_layer, layer = float(layer), layer + 1
            vert_blocks.append(self._interleave(obj, tex_layer))
            idx_blocks.append((mesh.faces[order] + v0).ravel())
            starts = i0 + 3 * np.concatenate([[0], np.cumsum(counts)[:-1]])
            c0 = len(first)
            first.extend(starts.tolist())
            count.extend((3 * counts).tolist())
            owner.extend([k] * len(counts))
            self._ranges[name] = (v0, len(mesh.vertices), c0, len(first), mesh.faces[order], counts, tex_layer)
            v0 += len(mesh.vertices)
            i0 += 3 * mesh.n_triangles
        vertices = np.concatenate(vert_blocks)
        self._vbo = ctx.buffer(vertices.tobytes())
        self._ibo = ctx.buffer(np.concatenate(idx_blocks).astype(np.uint32).tobytes())
        self._vao = ctx.vertex_array(prog, [(self._vbo, "3f 3f 2f 1f", "in_pos", "in_col", "in_uv", "in_layer")],
                                     self._ibo, index_element_size=4)
        self.n_chunks = len(first)
        self._first = np.asarray(first, dtype=np.uint32)
        self._count = np.asarray(count, dtype=np.uint32)
        self._active = np.ones(self.n_chunks, dtype=bool)
        self._centre = np.zeros((self.n_chunks, 3))
        self._radius = np.zeros(self.n_chunks)
        for name, obj in objects.items():
            self._bounds(name, obj.world_vertices())
        self._indirect = ctx.buffer(reserve=6 * self.n_chunks * 20)
        self._cmds = np.zeros((6 * self.n_chunks, 5), dtype=np.uint32)
        self._cmds[:, 1] = 1
        self._resources += [self._vao, self._vbo, self._ibo, self._indirect]

    @staticmethod
    def _interleave(obj, tex_layer: float) -> np.ndarray:
        mesh = obj.mesh
        v = np.empty((len(mesh.vertices), _FLOATS_PER_VERTEX), dtype=np.float32)
        v[:, 0:3] = obj.world_vertices()
        v[:, 3:6] = mesh.colours
        v[:, 6:8] = 0.0 if mesh.uv is None else mesh.uv
        v[:, 8] = tex_layer
        return v

    def _texture_array(self, objects):
        import cv2

        textures = [o.mesh.texture for o in objects.values() if o.mesh.texture is not None]
        if not textures:
            tex = self.ctx.texture_array((1, 1, 1), 3, np.ones(3, dtype=np.float16).tobytes(), dtype="f2")
        else:
            side = min(MAX_TEXTURE_ARRAY_SIDE, max(max(t.shape[:2]) for t in textures))
            layers = [cv2.resize(t, (side, side), interpolation=cv2.INTER_AREA)[::-1] for t in textures]
            data = np.ascontiguousarray(np.stack(layers), dtype=np.float16)
            tex = self.ctx.texture_array((side, side, len(layers)), 3, data.tobytes(), dtype="f2")
            tex.build_mipmaps()
        self._resources.append(tex)
        return tex

    def _bounds(self, name: str, world: np.ndarray) -> None:
        """Bounding spheres (world coordinates) of an object's chunks."""
        _, _, c0, c1, faces, counts, _ = self._ranges[name]
        tri = world[faces]  # (F, 3, 3), chunk by chunk
        lo, hi = tri.min(axis=1), tri.max(axis=1)
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        lo = np.minimum.reduceat(lo, starts, axis=0)
        hi = np.maximum.reduceat(hi, starts, axis=0)
        self._centre[c0:c1] = (lo + hi) / 2
        self._radius[c0:c1] = np.linalg.norm(hi - lo, axis=1) / 2

    def update_object(self, name: str, obj) -> None:
        """Re-upload a moved object's vertices and recompute its chunks' bounds."""
        v0, *_, tex_layer = self._ranges[name]
        block = self._interleave(obj, tex_layer)
        self._vbo.write(block.tobytes(), offset=v0 * _FLOATS_PER_VERTEX * 4)
        self._bounds(name, block[:, :3])

    def hide(self, name: str) -> None:
        _, _, c0, c1, *_ = self._ranges[name]
        self._active[c0:c1] = False

    def visible_chunks(self, q: np.ndarray, eye: np.ndarray) -> np.ndarray:
        """(n_chunks, 6) bool: chunk bounding sphere intersects the face's 90° frustum."""
        rel = (self._centre - eye) @ q  # dome (cube) frame
        f = rel @ FACES[:, 0].T
        r = np.abs(rel @ FACES[:, 1].T)
        u = np.abs(rel @ FACES[:, 2].T)
        slack = -math.sqrt(2.0) * self._radius[:, None]
        return (f - r >= slack) & (f - u >= slack) & self._active[:, None]

    def draw(self, fbo, views: np.ndarray, proj: np.ndarray, q: np.ndarray, eye: np.ndarray, n: int) -> int:
        """Draw every face's visible chunks into the atlas; returns the number of chunk draws."""
        face, chunk = np.nonzero(self.visible_chunks(q, eye).T)
        total = len(chunk)
        if total == 0:
            return 0
        cmds = self._cmds[:total]
        cmds[:, 0] = self._count[chunk]
        cmds[:, 2] = self._first[chunk]
        self._indirect.write(cmds.tobytes())
        per_face = np.bincount(face, minlength=6)
        offsets = np.concatenate([[0], np.cumsum(per_face)[:-1]])
        self._textures.use(1)
        for k in range(6):
            if per_face[k]:
                fbo.viewport = (0, k * n, n, n)
                self.prog["view_proj"].write((proj @ views[k]).T.astype("f4").tobytes())
                self._vao.render_indirect(self._indirect, self._mgl.TRIANGLES, count=int(per_face[k]),
                                          first=int(offsets[k]))
        return total

    def release(self) -> None:
        for res in self._resources:
            res.release()
        self._resources = []
