"""Hexagonal lattices inside the panel triangle (2D, panel-local metres).

The triangle: base from (-base/2, 0) to (+base/2, 0), apex at (0, height). A lattice keeps the triangle's
mirror symmetry about x = 0 (one PCB design fits every panel and neighbouring panels meet alike), so it is
one of three variants:
- "rows":      rows parallel to the base, a point on the axis in even rows;
- "rows-half": rows parallel to the base, points straddling the axis in even rows;
- "columns":   columns perpendicular to the base, one column on the axis.
Free parameters: `pitch` (m, nearest-neighbour distance) and `offset` (m, shift of the lattice along y).
"""

from __future__ import annotations

import numpy as np

VARIANTS = ("rows", "rows-half", "columns")


def lattice_points(pitch: float, offset: float, variant: str, base: float, height: float) -> np.ndarray:
    """(M, 2) float64 lattice points covering the triangle's bounding box, in rows of increasing y."""
    if variant not in VARIANTS:
        raise ValueError(f"lattice variant must be one of {VARIANTS}, got {variant!r}")
    if variant == "columns":
        dx, dy = pitch * np.sqrt(3) / 2, pitch  # column spacing, spacing along a column
        nx = int(np.ceil(base / 2 / dx)) + 1
        cols = np.arange(-nx, nx + 1)
        ny = int(np.ceil(height / dy)) + 2
        rows = np.arange(-1, ny)
        c, r = np.meshgrid(cols, rows)
        x = c * dx
        y = offset % dy + r * dy + (np.abs(c) % 2) * dy / 2
    else:
        dx, dy = pitch, pitch * np.sqrt(3) / 2
        x0 = 0.0 if variant == "rows" else pitch / 2
        ny = int(np.ceil(height / dy)) + 2
        rows = np.arange(-1, ny)
        nx = int(np.ceil(base / 2 / dx)) + 2
        cols = np.arange(-nx, nx + 1)
        c, r = np.meshgrid(cols, rows)
        x = x0 + c * dx + (r % 2) * dx / 2
        y = offset % dy + r * dy
    pts = np.column_stack([x.ravel(), y.ravel()])
    order = np.lexsort((pts[:, 0], np.round(pts[:, 1], 12)))
    return pts[order]


def edge_distance(points: np.ndarray, base: float, height: float) -> np.ndarray:
    """(M,) signed distance (m) from each point to the nearest triangle edge, positive inside."""
    x, y = points[:, 0], points[:, 1]
    side = np.hypot(base / 2, height)
    # the slanted edges: from (+-base/2, 0) to (0, height); inward normals (-+height, base/2) / side
    d_right = (height * (base / 2 - x) - (base / 2) * y) / side
    d_left = (height * (base / 2 + x) - (base / 2) * y) / side
    return np.minimum(np.minimum(y, d_right), d_left)


def points_in_triangle(
    pitch: float, offset: float, variant: str, base: float, height: float, margin: float
) -> np.ndarray:
    """(N, 2) lattice points at least `margin` metres inside the triangle, rows from the base up, x ascending."""
    pts = lattice_points(pitch, offset, variant, base, height)
    return pts[edge_distance(pts, base, height) >= margin]


def count_grid(
    pitches: np.ndarray, offsets: np.ndarray, variant: str, base: float, height: float, margin: float
) -> np.ndarray:
    """(P, O) int: the number of points inside for every (pitch, offset) pair (vectorised over offsets)."""
    counts = np.empty((len(pitches), len(offsets)), dtype=np.int64)
    for i, p in enumerate(pitches):
        pts0 = lattice_points(p, 0.0, variant, base, height)
        period = p if variant == "columns" else p * np.sqrt(3) / 2
        # shift by each offset (mod the row period), then test against the triangle
        shifted = pts0[None, :, :] + np.stack([np.zeros_like(offsets), offsets % period], axis=1)[:, None, :]
        d = edge_distance(shifted.reshape(-1, 2), base, height).reshape(len(offsets), -1)
        counts[i] = (d >= margin).sum(axis=1)
    return counts
