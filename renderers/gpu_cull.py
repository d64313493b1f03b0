"""Chunk culling and levels of detail on the GL device (the GPU path): one compute pass writes every face's indirect
draw commands, so that a frame does no per-chunk work on the CPU and uploads nothing.

The rules are `MeshBuffers.visible_chunks` and `MeshBuffers.levels` (the CPU path's, and the reference): a chunk
is drawn in face k when its bounding sphere meets the face's 90° frustum widened by sqrt(2) radius, at the
coarsest level of detail whose cell (LOD_CELLS[0] * 2^level) stays under lod_angle * (distance - radius).
Distances and levels are computed in double precision, as numpy does, so that both paths pick the same level.

Commands: for face k, slots k * n .. k * n + n_double hold the double-sided chunks and the rest the single-sided
ones (drawn with back faces culled), in the CPU path's order: front to back by the distance to the sphere, ties
by chunk (a depth tie goes to the chunk drawn first, so the order shows in the image). Chunks not drawn come
last with empty commands. Two `render_indirect` calls per face draw them.
"""

from __future__ import annotations

import numpy as np

from .cubemap import FACES

_GROUP = 64
#: uint32 per indexed indirect command: count, instances, first index, base vertex, base instance
_COMMAND = 5


def _faces_glsl() -> str:
    """FACES (6 faces x 3 axes x 3) as a GLSL constant: face k's axis j is F[3 * k + j]."""
    rows = ", ".join(f"vec3({a[0]:.1f}, {a[1]:.1f}, {a[2]:.1f})" for face in FACES for a in face)
    return f"const vec3 F[18] = vec3[18]({rows});"


def cull_shader(n_levels: int) -> str:
    """Two stages over (face, chunk): 0 decides each chunk's command and its distance key; 1 writes it into the
    slot of its rank."""
    return f"""#version 430
layout(local_size_x = {_GROUP}) in;
const int N_LEVELS = {n_levels};
{_faces_glsl()}
layout(std430, binding = 0) readonly buffer Spheres {{ dvec4 spheres[]; }};  // centre (m), radius (m)
layout(std430, binding = 1) readonly buffer Flags {{ uint flags[]; }};       // shown | single-sided << 1
layout(std430, binding = 2) readonly buffer First {{ uint first[]; }};       // (n, N_LEVELS)
layout(std430, binding = 3) readonly buffer Count {{ uint count[]; }};       // (n, N_LEVELS)
layout(std430, binding = 4) writeonly buffer Commands {{ uint commands[]; }};
layout(std430, binding = 5) buffer Keys {{ double keys[]; }};                 // (6, n): distance, or FAR
layout(std430, binding = 6) buffer Drawn {{ uvec2 drawn[]; }};               // (6, n): count, first index
uniform mat3 q;          // the dome rotation's row-major bytes, read transposed: q * d = d @ rotation
uniform dvec3 eye;
uniform double lod_angle;
uniform double cell0;
uniform int n;
uniform int n_double;
uniform int stage;
const double FAR = 1e300LF;
void main() {{
    int g = int(gl_GlobalInvocationID.x);
    if (g >= 6 * n) return;
    int c = g % n, k = g / n;
    bool single = (flags[c] & 2u) != 0u;
    if (stage == 0) {{
        dvec4 s = spheres[c];
        double near = length(s.xyz - eye) - s.w;
        int level = 0;
        if (lod_angle > 0.0LF) {{
            double allowed = lod_angle * max(near, 1e-6LF) / cell0;
            for (int j = 0; j < N_LEVELS - 1; ++j)
                if (allowed >= double(1 << j)) level = j + 1;
        }}
        vec3 rel = q * vec3(s.xyz - eye);
        float slack = -sqrt(2.0) * float(s.w);
        float f = dot(rel, F[3 * k]);
        bool visible = f - abs(dot(rel, F[3 * k + 1])) >= slack && f - abs(dot(rel, F[3 * k + 2])) >= slack;
        uint m = count[c * N_LEVELS + level];
        bool shown = visible && (flags[c] & 1u) != 0u && m > 0u;
        keys[g] = shown ? near : FAR;
        drawn[g] = uvec2(shown ? m : 0u, first[c * N_LEVELS + level]);
        return;
    }}
    // front to back within the face's double- or single-sided slots, ties by chunk (numpy's stable lexsort)
    double key = keys[g];
    int rank = 0;
    for (int j = 0; j < n; ++j) {{
        double other = keys[k * n + j];
        if (((flags[j] & 2u) != 0u) == single && (other < key || (other == key && j < c))) ++rank;
    }}
    int o = (k * n + (single ? n_double : 0) + rank) * {_COMMAND};
    uvec2 d = drawn[g];
    commands[o] = d.x;
    commands[o + 1] = d.x > 0u ? 1u : 0u;
    commands[o + 2] = d.y;
}}
"""


class GpuCulling:
    """The culling pass and the command buffer for one `MeshBuffers` (use it with its context current).

    first, count: (n, levels) uint32 index offsets and counts per chunk and level; single_sided: (n,) bool;
    lod_angle (rad) and cell0 (m, the finest level's cell) as `MeshBuffers.levels` uses them.
    GPU memory: n x (36 + 8 x levels) bytes of chunk data and 6 x n x 36 bytes of commands and sort keys.
    """

    def __init__(self, ctx, first: np.ndarray, count: np.ndarray, single_sided: np.ndarray, lod_angle: float,
                 cell0: float):
        import moderngl

        self.ctx, self._mgl = ctx, moderngl
        self.n, n_levels = first.shape
        self._single = np.asarray(single_sided, dtype=bool)
        #: per face, the first n_double slots are the double-sided chunks'
        self.n_double = int((~self._single).sum())
        self._prog = ctx.compute_shader(cull_shader(n_levels))
        self._spheres = ctx.buffer(reserve=self.n * 32)
        self._flags = ctx.buffer(reserve=self.n * 4)
        self._first = ctx.buffer(np.ascontiguousarray(first, dtype=np.uint32))
        self._count = ctx.buffer(np.ascontiguousarray(count, dtype=np.uint32))
        self.commands = ctx.buffer(np.zeros(6 * self.n * _COMMAND, np.uint32))
        self._keys = ctx.buffer(reserve=6 * self.n * 8)
        self._drawn = ctx.buffer(reserve=6 * self.n * 8)
        m, d = self.n, self.n_double
        #: per face, the (first, count) of its double-sided and of its single-sided commands
        self.batches = [((k * m, d), (k * m + d, m - d)) for k in range(6)]
        for name, value in (("n", m), ("n_double", d), ("lod_angle", float(lod_angle)), ("cell0", float(cell0))):
            self._prog[name].value = value

    def _buffers(self) -> tuple:
        return self._spheres, self._flags, self._first, self._count, self.commands, self._keys, self._drawn

    def set_chunks(self, centre: np.ndarray, radius: np.ndarray, active: np.ndarray) -> None:
        """Upload the chunks' bounding spheres ((n, 3) and (n,) m) and which are shown ((n,) bool)."""
        spheres = np.empty((self.n, 4), np.float64)
        spheres[:, :3], spheres[:, 3] = centre, radius
        self._spheres.write(spheres)
        self._flags.write(np.asarray(active, dtype=np.uint32) | (self._single.astype(np.uint32) << 1))

    def run(self, q: np.ndarray, eye: np.ndarray) -> None:
        """Write every face's commands for an eye at `eye` (m) with dome rotation `q` (3, 3)."""
        p, mgl = self._prog, self._mgl
        p["q"].write(np.ascontiguousarray(q, dtype="f4"))
        p["eye"].value = tuple(float(v) for v in eye)
        for b, buf in enumerate(self._buffers()):
            buf.bind_to_storage_buffer(b)
        groups = (6 * self.n + _GROUP - 1) // _GROUP
        for stage in (0, 1):
            p["stage"].value = stage
            p.run(groups)
            self.ctx.memory_barrier(mgl.SHADER_STORAGE_BARRIER_BIT if stage == 0 else mgl.COMMAND_BARRIER_BIT)

    def release(self) -> None:
        for res in (*self._buffers(), self._prog):
            res.release()
