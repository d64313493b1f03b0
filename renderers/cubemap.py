"""Cube-map geometry: the six 90° faces, texel directions and solid angles (pure numpy).

Atlas convention (what `Renderer` renders and reads back): face k of `FACES` occupies rows k*N..k*N+N-1 of
an (6N, N) image, rows bottom-up as OpenGL reads them. Texel (row j, column i) of face k looks along

    forward + a * right + b * up,   a = 2 (i + 0.5) / N - 1,   b = 2 (j + 0.5) / N - 1

in the frame the cube was rendered in. `gl_cube_directions` gives the same for OpenGL's own cube-map
texture layout (used for far-field textures sampled with `samplerCube`).
"""

from __future__ import annotations

import numpy as np

#: (forward, right, up) of each face; right = forward x up, so every face camera is right-handed.
FACES = np.array(
    [
        [[1, 0, 0], [0, -1, 0], [0, 0, 1]],
        [[-1, 0, 0], [0, 1, 0], [0, 0, 1]],
        [[0, 1, 0], [1, 0, 0], [0, 0, 1]],
        [[0, -1, 0], [-1, 0, 0], [0, 0, 1]],
        [[0, 0, 1], [0, -1, 0], [-1, 0, 0]],
        [[0, 0, -1], [0, -1, 0], [1, 0, 0]],
    ],
    dtype=np.float64,
)


def texel_coordinates(face_size: int) -> np.ndarray:
    """(N,) face coordinates of texel centres in (-1, 1)."""
    return (np.arange(face_size) + 0.5) * (2.0 / face_size) - 1.0


def atlas_directions(face_size: int) -> np.ndarray:
    """(6*N*N, 3) float64 unit directions of the atlas texels in readback order (face, row, column)."""
    c = texel_coordinates(face_size)
    b, a = np.meshgrid(c, c, indexing="ij")  # row j -> b, column i -> a
    f, r, u = FACES[:, 0], FACES[:, 1], FACES[:, 2]
    d = f[:, None, None, :] + a[None, :, :, None] * r[:, None, None, :] + b[None, :, :, None] * u[:, None, None, :]
    d = d.reshape(-1, 3)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def atlas_solid_angles(face_size: int) -> np.ndarray:
    """(6*N*N,) float64 solid angle of each atlas texel in steradians (sums to 4 pi)."""
    c = texel_coordinates(face_size)
    b, a = np.meshgrid(c, c, indexing="ij")
    delta = 2.0 / face_size
    w = delta * delta / (1.0 + a * a + b * b) ** 1.5
    return np.tile(w.ravel(), 6)


def largest_texel_deg(face_size: int) -> float:
    """Angular width (degrees) of the largest texel: the one at a face centre."""
    return float(np.degrees(2.0 * np.arctan(1.0 / face_size)))


#: (forward, s axis, t axis) of each OpenGL cube-map face (+X, -X, +Y, -Y, +Z, -Z): a texel at face coordinates
#: (sc, tc) looks along forward + sc * s + tc * t (spec table "Selection of cube map images": for +X, sc = -z, tc = -y)
GL_FACES = np.array(
    [
        [[1, 0, 0], [0, 0, -1], [0, -1, 0]],
        [[-1, 0, 0], [0, 0, 1], [0, -1, 0]],
        [[0, 1, 0], [1, 0, 0], [0, 0, 1]],
        [[0, -1, 0], [1, 0, 0], [0, 0, -1]],
        [[0, 0, 1], [1, 0, 0], [0, -1, 0]],
        [[0, 0, -1], [-1, 0, 0], [0, -1, 0]],
    ],
    dtype=np.float64,
)


def gl_face_directions(face: np.ndarray, tc: np.ndarray, sc: np.ndarray) -> np.ndarray:
    """(..., 3) unit directions at face coordinates (tc, sc) in [-1, 1] of OpenGL cube faces `face` (0..5 in
    `GL_FACES` order); the three arrays broadcast together."""
    f = GL_FACES[np.asarray(face)]
    d = f[..., 0, :] + np.asarray(sc)[..., None] * f[..., 1, :] + np.asarray(tc)[..., None] * f[..., 2, :]
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def gl_cube_directions(face_size: int) -> np.ndarray:
    """(6, N, N, 3) unit directions of OpenGL cube-map texels, in upload order (+X,-X,+Y,-Y,+Z,-Z; row t, col s)."""
    c = texel_coordinates(face_size)
    return gl_face_directions(np.arange(6)[:, None, None], c[None, :, None], c[None, None, :])


def face_view_matrices(rotation: np.ndarray, eye: np.ndarray) -> np.ndarray:
    """(6, 4, 4) float64 world -> face-camera matrices (row-major, for column vectors).

    rotation: (3, 3) cube frame -> world frame; eye: (3,) metres. The face camera looks along -z with
    x = right and y = up, as OpenGL expects.
    """
    basis = np.einsum("kij,lj->kil", FACES, rotation)  # face axes in world coordinates
    m = np.zeros((6, 4, 4))
    m[:, 0, :3] = basis[:, 1]
    m[:, 1, :3] = basis[:, 2]
    m[:, 2, :3] = -basis[:, 0]
    m[:, :3, 3] = -np.einsum("kij,j->ki", m[:, :3, :3], eye)
    m[:, 3, 3] = 1.0
    return m


def projection_matrix(near: float, far: float) -> np.ndarray:
    """(4, 4) OpenGL perspective matrix of a 90° square face, near/far planes in metres."""
    p = np.zeros((4, 4))
    p[0, 0] = p[1, 1] = 1.0
    p[2, 2] = -(far + near) / (far - near)
    p[2, 3] = -2.0 * far * near / (far - near)
    p[3, 2] = -1.0
    return p
