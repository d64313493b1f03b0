"""The per-frame path after the cube map, on the GL device: footprint sampling, channel conversion and VIDEO packing.

Three GL 4.3 compute passes over the same data as the CPU path (`kernels`, `output.FrameConverter`,
`firmware_proto.video.encode_frame`), so that both give the same LED frame within 1 LSB:

1. sample: per LED, the CSR footprint row over the atlas (texel values rounded back to their 16-bit integers and
   weighted in float32, in CSR order, as `kernels.sample_pairs`), optionally over the far field
   (`kernels.sample_over_far`), or the far field alone (a scene without meshes). The far field is the scene's
   table, uploaded once and looked up here (`kernels.lookup_pairs`), or pairs looked up on the CPU (a far layer,
   whose tables are rewritten in place);
2. mean (only when contrast != 1): one work group sums G, B over GB pixels and UV over UV pixels;
3. convert: contrast, gains, green/blue swap, the G + B <= 65535 rule, truncation to 16 bits
   (`kernels.convert_pairs`), written as one uint32 (G | B << 16) per LED: the (20350, 2) uint16 frame;
4. pack: per 32-bit word of the 55 VIDEO datagrams (1,112 bytes each, a multiple of 4), TD, INFO 0 and the
   (L, C) bytes of `video.luma_chroma`.

The CPU reads back one buffer (81,400 frame bytes + 61,160 datagram bytes) into preallocated memory. moderngl 5.13
has no fence objects, so the read-back waits for the GPU (`Buffer.read_into`).

Between frames, `busy()` runs one small work group (`BUSY_ITERATIONS`), so that a loop may keep the GPU from
lowering its clocks while it waits for the next frame's slot (`FrameLoop(keep_gpu_busy=...)`).
"""

from __future__ import annotations

import math

import numpy as np

from antarium.firmware_proto.video import VIDEO_PAYLOAD_SIZE
from antarium.geometry.constants import GB_PER_PANEL, N_PANELS, N_PIXELS, PIXELS_PER_PANEL

from .farfield import STEP
from .meshbuffers import SlicedWrite, Staged

#: renderer strings (lower case) of software GL drivers: the CPU path is the faster there
SOFTWARE_GL = ("llvmpipe", "softpipe", "swrast")
PATHS = ("gpu", "cpu")
#: sample-pass modes
ATLAS, OVER_FAR, FAR_ONLY = 0, 1, 2
_GROUP = 64
_WORDS = N_PANELS * VIDEO_PAYLOAD_SIZE // 4



def _header(group: int) -> str:
    return f"""#version 430
layout(local_size_x = {group}) in;
""" + _CONSTANTS


_CONSTANTS = f"""const int N_LEDS = {N_PIXELS};
const int PIXELS_PER_PANEL = {PIXELS_PER_PANEL};
const int GB_PER_PANEL = {GB_PER_PANEL};
const float FULL = 65535.0;
bool is_uv(int i) {{ return (i % PIXELS_PER_PANEL) >= GB_PER_PANEL; }}
"""

SAMPLE_CS = _header(_GROUP) + """
layout(std430, binding = 0) readonly buffer Indptr { int indptr[]; };
layout(std430, binding = 1) readonly buffer Indices { int indices[]; };
layout(std430, binding = 2) readonly buffer Weights { float weights[]; };
layout(std430, binding = 3) readonly buffer Far { vec2 far_pairs[]; };
layout(std430, binding = 4) writeonly buffer Pairs { vec2 pairs[]; };
// a far-field table (`farfield.FarFieldTable`): its [G, B] grid, then its [UV, polarised UV] grid, each
// (rows, cols + 1) points of two 16-bit values; and per LED the cell it reads at yaw 0
layout(std430, binding = 8) readonly buffer Table { uint table[]; };
struct Cell { int row; int col; float row_frac; float col_frac; };
layout(std430, binding = 9) readonly buffer Cells { Cell cells[]; };
uniform sampler2D atlas;
uniform int level;
uniform int width;   // texels across the atlas at `level`
uniform int mode;    // 0: atlas, 1: atlas over far, 2: far only
uniform bool lookup; // far values from the table (else from far_pairs, looked up on the CPU)
uniform int n_cols;  // table columns (without the repeated one)
uniform int uv_offset;
uniform int shift_i; // yaw shift in table columns: shift_i + shift_f, 0 <= shift_f < 1
uniform float shift_f;
uniform bool clip;   // each average clipped to 1 (a float atlas: a far field brighter than 1)
vec2 point(int k) { uint v = table[k]; return vec2(float(v & 0xFFFFu), float(v >> 16)); }
vec2 far_value(int i) {  // kernels.lookup_pairs
    if (!lookup) return far_pairs[i];
    Cell c = cells[i];
    float s = c.col_frac + shift_f;
    float whole = floor(s);
    float f = s - whole;
    int j = (c.col + shift_i + int(whole)) % n_cols;
    int k = (is_uv(i) ? uv_offset : 0) + c.row * (n_cols + 1) + j;
    vec2 a0 = point(k), b0 = point(k + n_cols + 1);
    vec2 a = a0 + f * (point(k + 1) - a0);
    vec2 b = b0 + f * (point(k + n_cols + 2) - b0);
    return (a + c.row_frac * (b - a)) * (1.0 / 65535.0);
}
void main() {
    int i = int(gl_GlobalInvocationID.x);
    if (i >= N_LEDS) return;
    if (mode == 2) { pairs[i] = far_value(i); return; }
    bool uv = is_uv(i);
    float a0 = 0.0, a1 = 0.0, cov = 0.0;
    for (int k = indptr[i]; k < indptr[i + 1]; ++k) {
        int t = indices[k];
        vec4 v = floor(texelFetch(atlas, ivec2(t % width, t / width), level) * FULL + 0.5);
        float w = weights[k];
        a0 += w * (uv ? v.z : v.x);
        a1 += w * ((uv && mode == 0) ? v.w : v.y);
        cov += w * v.w;
    }
    if (mode == 1) {
        float u = max(1.0 - cov, 0.0);
        vec2 f = far_value(i);
        a0 += u * f.x;
        a1 = uv ? u * f.y : a1 + u * f.y;
    }
    if (clip) { a0 = min(a0, 1.0); a1 = min(a1, 1.0); }
    pairs[i] = vec2(a0, a1);
}
"""

MEAN_CS = _header(256) + """
layout(std430, binding = 4) readonly buffer Pairs { vec2 pairs[]; };
layout(std430, binding = 5) writeonly buffer Means { vec4 means; };
shared vec3 part[256];
void main() {
    uint j = gl_LocalInvocationID.x;
    vec3 s = vec3(0.0);
    for (int i = int(j); i < N_LEDS; i += 256) {
        vec2 p = pairs[i];
        if (is_uv(i)) s.z += p.x; else s.xy += p;
    }
    part[j] = s;
    barrier();
    for (uint h = 128u; h > 0u; h >>= 1) {
        if (j < h) part[j] += part[j + h];
        barrier();
    }
    if (j == 0u) {
        float n_gb = float(N_LEDS / PIXELS_PER_PANEL * GB_PER_PANEL);
        means = vec4(part[0].xy / n_gb, part[0].z / (float(N_LEDS) - n_gb), 0.0);
    }
}
"""

CONVERT_CS = _header(_GROUP) + """
layout(std430, binding = 4) readonly buffer Pairs { vec2 pairs[]; };
layout(std430, binding = 5) readonly buffer Means { vec4 means; };
layout(std430, binding = 6) readonly buffer Gain { vec2 gain[]; };
layout(std430, binding = 7) writeonly buffer Out { uint frame[]; };
uniform float contrast;
uniform bool use_contrast;
uniform bool swap;
void main() {
    int i = int(gl_GlobalInvocationID.x);
    if (i >= N_LEDS) return;
    bool uv = is_uv(i);
    vec2 p = pairs[i];
    if (use_contrast) {
        if (uv) {
            float before = p.x;
            p.x = max(means.z + contrast * (p.x - means.z), 0.0);
            p.y = before > 0.0 ? p.y * (p.x / before) : 0.0;
        } else {
            p = max((p - means.xy) * contrast + means.xy, 0.0);
        }
    }
    if (swap && !uv) p = p.yx;
    float a = max(p.x, 0.0) * gain[i].x;
    float b = max(p.y, 0.0) * gain[i].y;
    if (uv) {
        if (a > FULL) {  // a UV above full drive: both scaled, the degree of polarisation kept
            b *= FULL / a;
            a = FULL;
        }
        b = min(b, a);
        a = a - b;
    } else if (a + b > FULL) {
        float k = FULL / (a + b);
        a *= k;
        b *= k;
    }
    frame[i] = min(uint(a), 65535u) | (min(uint(b), 65535u) << 16);
}
"""

PACK_CS = _header(_GROUP) + f"""
const int WORDS_PER_PANEL = {VIDEO_PAYLOAD_SIZE // 4};
layout(std430, binding = 7) buffer Out {{ uint frame[]; }};
uint wire_byte(int panel, int b) {{
    if (b == 0) return uint(panel);      // TD: class 0 (VIDEO), destination panel
    if (b == 1) return 0u;               // INFO: set on the CPU per frame
    int pix = (b - 2) / 3;
    int i = panel * PIXELS_PER_PANEL + pix;
    uint v = frame[i];
    uint c0 = v & 0xFFFFu, c1 = v >> 16;
    uint share = is_uv(i) ? c1 : c0;     // green, or the polarised LED of a UV pixel
    uint lum = c0 + c1;
    int part = (b - 2) % 3;
    if (part == 0) return lum >> 8;
    if (part == 1) return lum & 0xFFu;
    return lum == 0u ? 0u : (share * 510u + lum) / (2u * lum);
}}
void main() {{
    int w = int(gl_GlobalInvocationID.x);
    if (w >= {_WORDS}) return;
    int panel = w / WORDS_PER_PANEL;
    int b = 4 * (w % WORDS_PER_PANEL);
    uint word = 0u;
    for (int j = 0; j < 4; ++j) word |= wire_byte(panel, b + j) << (8 * j);
    frame[N_LEDS + w] = word;
}}
"""


#: iterations of the busy pass's dependent multiply-add chain: some 40 us at 2 GHz by count (a few cycles each);
#: not timed on a GPU (llvmpipe here: 0.47 ms)
BUSY_ITERATIONS = 20_000
BUSY_CS = _header(_GROUP) + """
layout(std430, binding = 10) buffer Busy { float busy[]; };
uniform int iterations;
void main() {
    float x = float(gl_LocalInvocationID.x);
    for (int k = 0; k < iterations; ++k) x = x * 0.999 + 0.5;
    busy[gl_LocalInvocationID.x] = x;
}
"""


def default_path(renderer_string: str) -> str:
    """'cpu' for a software GL driver (llvmpipe, softpipe, swrast), else 'gpu'."""
    s = renderer_string.lower()
    return "cpu" if any(name in s for name in SOFTWARE_GL) else "gpu"


def check_path(path) -> str | None:
    """None (choose from the GL renderer), 'gpu' or 'cpu'; anything else is refused in one line."""
    if path is None or path in PATHS:
        return path
    raise ValueError(f"render path must be one of {', '.join(PATHS)} (or unset: chosen from the GL renderer), "
                     f"got {path!r}")


class GpuFramePath:
    """Compute passes and buffers of the GPU path for one GL context (use it with that context current).

    GPU memory: the CSR matrix (set_matrix), the scene's far-field table and each LED's cell in it (set_table,
    dropped with drop_table), those of the table shown before (kept for the next), 3 x 20350 x 8 bytes of pairs,
    far pairs and gains, the 142,560-byte output, 16 bytes of means and the busy pass's 256; host: the 142,560-byte
    read-back array (`frame` and `datagrams` are views of it).
    """

    def __init__(self, ctx):
        import moderngl

        self.ctx, self._mgl = ctx, moderngl
        self._sample = ctx.compute_shader(SAMPLE_CS)
        self._mean = ctx.compute_shader(MEAN_CS)
        self._convert = ctx.compute_shader(CONVERT_CS)
        self._pack = ctx.compute_shader(PACK_CS)
        self._busy = ctx.compute_shader(BUSY_CS)
        self._busy["iterations"].value = BUSY_ITERATIONS
        self._sample["atlas"].value = 3
        n = N_PIXELS
        self._far = ctx.buffer(reserve=n * 8)
        self._pairs = ctx.buffer(reserve=n * 8)
        self._means = ctx.buffer(reserve=16)
        self._gain = ctx.buffer(reserve=n * 8)
        self._out = ctx.buffer(reserve=n * 4 + _WORDS * 4)
        self._busy_out = ctx.buffer(reserve=_GROUP * 4)
        self._matrix = None
        self._table = self._cells = None
        self._spare = None  # (table, cells) buffers of the table shown before, reused by the next of their sizes
        self._table_source, self._n_cols = None, 0
        self.host = np.zeros(n * 4 + _WORDS * 4, np.uint8)
        #: the last frame, (20350, 2) uint16, and its 55 VIDEO datagrams (55, 1112) uint8 with INFO 0
        self.frame = self.host[: n * 4].view(np.uint16).reshape(n, 2)
        self.datagrams = self.host[n * 4:].reshape(N_PANELS, VIDEO_PAYLOAD_SIZE)
        self.matrix_key = None

    @property
    def gpu_bytes(self) -> int:
        """Bytes of GPU buffers this path holds."""
        return sum(b.size for b in self._buffers())

    def _buffers(self) -> list:
        return [b for b in (self._far, self._pairs, self._means, self._gain, self._out, self._busy_out,
                            *(self._matrix or ()), self._table, self._cells, *(self._spare or ()))
                if b is not None]

    def set_matrix(self, key, indptr: np.ndarray, indices: np.ndarray, weights: np.ndarray) -> None:
        """Upload a CSR footprint matrix (weights in radiance per 16-bit texel unit), unless `key` is the current."""
        if key == self.matrix_key:
            return
        if self._matrix is not None:
            for b in self._matrix:
                b.release()
        self._matrix = tuple(self.ctx.buffer(np.ascontiguousarray(a, dtype=dt).tobytes())
                             for a, dt in ((indptr, np.int32), (indices, np.int32), (weights, np.float32)))
        self.matrix_key = key

    def set_table(self, table) -> None:
        """Upload a `farfield.FarFieldTable` (its two grids, 2 x rows x (cols + 1) x 4 bytes, and each LED's cell,
        20350 x 16 bytes) at once, unless it is the current one (`stage_table` uploads one a slice at a time). A
        table is never changed in place once made (a new footprint makes a new one); a far layer's are, and go
        through `run(far_pairs=...)` instead."""
        if table is not self._table_source:
            self.adopt_table(self.stage_table(table).finish())

    def stage_table(self, table, discard=None) -> StagedTable:
        """A `StagedTable` of `table`, to fill in steps and then `adopt_table` (GL thread)."""
        return StagedTable(self, table, discard)

    def _table_buffers(self, sizes: tuple[int, int]) -> tuple:
        """Buffers of `sizes` bytes for a table and its cells: the spare ones (the table shown before) when they
        have those sizes, else new ones (the spare ones then released)."""
        spare, self._spare = self._spare, None
        if spare is not None and tuple(b.size for b in spare) == sizes:
            return spare
        for b in spare or ():
            b.release()
        return tuple(self.ctx.buffer(reserve=n) for n in sizes)

    def adopt_table(self, staged: StagedTable) -> None:
        """Make a filled `StagedTable` the table the frames look up: no upload, no allocation; the table shown
        before keeps its buffers as the spare for the next one."""
        table = staged.table
        buffers = staged.take()
        if self._table is not None:
            for b in self._spare or ():
                b.release()
            self._spare = (self._table, self._cells)
        self._table, self._cells = buffers
        self._sample["n_cols"].value = table.grid.n_cols
        self._sample["uv_offset"].value = table.table_gb.size // 2
        self._table_source, self._n_cols = table, table.grid.n_cols

    def drop_table(self) -> None:
        """No far-field table any more (a scene without one): its buffers and the spare ones are released, and the
        reference to its source is dropped."""
        for b in (self._table, self._cells, *(self._spare or ())):
            if b is not None:
                b.release()
        self._table = self._cells = self._spare = None
        self._table_source, self._n_cols = None, 0

    def set_gain(self, gain: np.ndarray) -> None:
        """(20350, 2) float32 per-LED gains of the output columns (`FrameConverter.gain`)."""
        self._gain.write(np.ascontiguousarray(gain, dtype=np.float32))

    def run(self, mode: int, atlas=None, level: int = 0, width: int = 0, far_pairs: np.ndarray | None = None,
            psi: float = 0.0, contrast: float = 1.0, swap: bool = False, clip: bool = False) -> np.ndarray:
        """Run the passes and read the frame and datagrams back into `host`; returns `frame`. The far field (modes
        OVER_FAR, FAR_ONLY): `far_pairs` (20350, 2) float32, or else the table of `set_table` at yaw `psi` (rad).
        clip: each LED's footprint average is clipped to 1 (an atlas of floats: a far field brighter than 1)."""
        mgl = self._mgl
        lookup = far_pairs is None and mode != ATLAS
        self._sample["lookup"].value = lookup
        if lookup:
            shift = (psi / STEP) % self._n_cols  # as FarFieldTable.lookup, split so float32 keeps its fraction
            whole = math.floor(shift)
            self._sample["shift_i"].value = int(whole) % self._n_cols
            self._sample["shift_f"].value = shift - whole
            self._table.bind_to_storage_buffer(8)
            self._cells.bind_to_storage_buffer(9)
        elif far_pairs is not None:
            self._far.write(far_pairs)
        if mode != FAR_ONLY:
            atlas.use(3)
            for b, buf in enumerate(self._matrix):
                buf.bind_to_storage_buffer(b)
            self._sample["level"].value = level
            self._sample["width"].value = width
        else:  # the matrix buffers are not read; bind something valid
            for b in range(3):
                self._far.bind_to_storage_buffer(b)
        self._sample["mode"].value = mode
        self._sample["clip"].value = bool(clip)
        self._far.bind_to_storage_buffer(3)
        self._pairs.bind_to_storage_buffer(4)
        self._means.bind_to_storage_buffer(5)
        self._gain.bind_to_storage_buffer(6)
        self._out.bind_to_storage_buffer(7)
        groups = (N_PIXELS + _GROUP - 1) // _GROUP
        self._sample.run(groups)
        self.ctx.memory_barrier(mgl.SHADER_STORAGE_BARRIER_BIT)
        use_contrast = contrast != 1.0
        if use_contrast:
            self._mean.run(1)
            self.ctx.memory_barrier(mgl.SHADER_STORAGE_BARRIER_BIT)
        self._convert["contrast"].value = float(contrast)
        self._convert["use_contrast"].value = use_contrast
        self._convert["swap"].value = bool(swap)
        self._convert.run(groups)
        self.ctx.memory_barrier(mgl.SHADER_STORAGE_BARRIER_BIT)
        self._pack.run((_WORDS + _GROUP - 1) // _GROUP)
        self.ctx.memory_barrier(mgl.BUFFER_UPDATE_BARRIER_BIT)
        self._out.read_into(self.host)
        return self.frame

    def busy(self) -> None:
        """Run the busy pass (one work group writing a scratch buffer nothing reads) and wait for it."""
        self._busy_out.bind_to_storage_buffer(10)
        self._busy.run(1)
        self.ctx.finish()

    def release(self) -> None:
        for b in self._buffers():
            b.release()
        for p in (self._sample, self._mean, self._convert, self._pack, self._busy):
            p.release()


def _table_arrays(table) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A far-field table as the sample pass reads it: its [G, B] and [UV, polarised UV] grids (uint16, one after
    the other in one buffer) and each LED's cell, (20350, 4) int32 row, column and float32 row and column fractions."""
    g = table.grid
    col = np.floor(g.col0)
    cells = np.empty((len(g.row), 4), np.int32)
    cells[:, 0], cells[:, 1] = g.row, col
    cells[:, 2:].view(np.float32)[:] = np.stack([g.row_frac, g.col0 - col], axis=1)
    return (np.ascontiguousarray(table.table_gb, dtype=np.uint16),
            np.ascontiguousarray(table.table_uv, dtype=np.uint16), cells)


class StagedTable(Staged):
    """A far-field table's GPU buffers filled a slice at a time (`step`, GL thread: `meshbuffers.UPLOAD_SLICE_BYTES`
    each) while frames go on, so that a scene swap adopts it with no upload (`GpuFramePath.adopt_table`); the
    buffers are the path's spare ones when they have the sizes (no allocation either)."""

    def __init__(self, path: GpuFramePath, table, discard=None):
        super().__init__(discard)
        self._path, self.table = path, table
        self._buffers: tuple | None = None
        self._writes = None

    @property
    def done(self) -> bool:
        return self._writes is not None and self._writes.done

    def step(self, nbytes: int | None = None) -> bool:
        """Copy about `nbytes` more (the first step takes the buffers); True once all is up. GL thread."""
        if self.discarded or self.done:
            return True
        if self._writes is None:
            gb, uv, cells = _table_arrays(self.table)
            grids, cell_buf = self._buffers = self._path._table_buffers((gb.nbytes + uv.nbytes, cells.nbytes))
            self._writes = SlicedWrite([(grids, 0, gb), (grids, gb.nbytes, uv), (cell_buf, 0, cells)])
        else:
            self._writes.step(nbytes)
        return self.done

    def finish(self) -> StagedTable:
        """Copy what is left now (GL thread); returns itself."""
        self._fill()
        return self

    def take(self) -> tuple:
        """The filled (table, cells) buffers, handed over: `release` no longer frees them."""
        if self.discarded or not self.done:
            raise RuntimeError("a far-field table not (fully) staged cannot be adopted")
        buffers, self._buffers = self._buffers, None
        return buffers

    def release(self) -> None:
        for b in self._buffers or ():
            b.release()
        self._buffers = None
