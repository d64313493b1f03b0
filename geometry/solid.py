"""The biscribed pentakis dodecahedron and the numbering of its pentagons and panels.

The solid: the 12 vertices of an icosahedron (the apexes of the pentagonal pyramids) and the 20 vertices of
the dual dodecahedron, all on one sphere; each pentagonal face of the dodecahedron is raised into a pyramid
of 5 congruent isosceles triangles (60 facets). The triangle's base is the dodecahedron edge (0.368 m).

Dome frame: +z up through the apex of the top pyramid; the pyramid whose apex is at -z is removed to admit
the trackball, so the opening is symmetric about -z. The first pyramid of the upper ring has its apex at
azimuth 0 (+x).

Numbering (the distributor's routing key):
- pentagon 0: the top pyramid; 1..5: the upper ring, apexes at azimuth 0, 72, 144, 216, 288 deg (elevation
  +26.6 deg); 6..10: the lower ring, apexes at azimuth 36, 108, 180, 252, 324 deg (elevation -26.6 deg).
- slot 0..4 within a pentagon: seen from the dome centre looking at the apex, counter-clockwise, starting with
  the triangle whose base midpoint lies at or first after "up" (the direction of +z projected onto the
  pentagon; for the top pentagon, +x).
- panel = 5 * pentagon + slot.

Each panel has a local frame: origin at the base midpoint, x along the base, y towards the apex, both in the
panel plane, and the normal x cross y pointing into the dome (towards the centre). Seen from the centre with
the apex up, x runs to the right.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .constants import BASE_EDGE_M, N_PENTAGONS, PANELS_PER_PENTAGON

_ANGLE_TOL = 1e-9  # rad; ties in slot ordering are broken towards "up"


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def icosahedron_apexes() -> np.ndarray:
    """(12, 3) float64 unit vectors: top, upper ring (az 0, 72, ...), lower ring (az 36, 108, ...), bottom."""
    z = 1.0 / np.sqrt(5.0)
    r = 2.0 / np.sqrt(5.0)
    k = np.arange(5)
    upper = np.column_stack([r * np.cos(k * 2 * np.pi / 5), r * np.sin(k * 2 * np.pi / 5), np.full(5, z)])
    az = (k + 0.5) * 2 * np.pi / 5
    lower = np.column_stack([r * np.cos(az), r * np.sin(az), np.full(5, -z)])
    return np.vstack([[0.0, 0.0, 1.0], upper, lower, [0.0, 0.0, -1.0]])


def _icosahedron_faces(apexes: np.ndarray) -> np.ndarray:
    """(20, 3) int: triples of mutually adjacent apexes (the icosahedron's faces)."""
    cos_edge = 1.0 / np.sqrt(5.0)  # neighbouring apexes are 63.4 deg apart
    adjacent = np.abs(apexes @ apexes.T - cos_edge) < 1e-9
    faces = [
        (i, j, k)
        for i in range(12)
        for j in range(i + 1, 12)
        for k in range(j + 1, 12)
        if adjacent[i, j] and adjacent[j, k] and adjacent[i, k]
    ]
    return np.array(faces)


@dataclass(frozen=True)
class Solid:
    """The full 60-facet solid scaled so the triangle base is `base_edge` metres.

    vertices: (32, 3) float64 m — 0..11 apexes (as `icosahedron_apexes`), 12..31 dodecahedron vertices
    facets:   (60, 3) int — (apex, base vertex 0, base vertex 1), ordered by (pyramid, slot)
    """

    base_edge: float = BASE_EDGE_M

    def __post_init__(self) -> None:
        if not (np.isfinite(self.base_edge) and self.base_edge > 0):
            raise ValueError(f"base_edge must be a positive length in metres, got {self.base_edge!r}")

    @cached_property
    def _unit_solid(self) -> tuple[np.ndarray, np.ndarray]:
        apexes = icosahedron_apexes()
        faces = _icosahedron_faces(apexes)
        dodeca = _unit(apexes[faces].sum(axis=1))
        vertices = np.vstack([apexes, dodeca])
        facets = []
        for a in range(12):
            ring = [12 + f for f in range(20) if a in faces[f]]  # the 5 dodecahedron vertices around apex a
            facets.extend(_pyramid_facets(vertices, a, ring))
        return vertices, np.array(facets)

    @cached_property
    def circumradius(self) -> float:
        """Radius (m) of the sphere through all 32 vertices."""
        v, f = self._unit_solid
        unit_edge = np.linalg.norm(v[f[0, 1]] - v[f[0, 2]])
        return self.base_edge / unit_edge

    @cached_property
    def vertices(self) -> np.ndarray:
        return self._unit_solid[0] * self.circumradius

    @cached_property
    def facets(self) -> np.ndarray:
        return self._unit_solid[1]

    @cached_property
    def normals(self) -> np.ndarray:
        """(60, 3) outward unit normals of the facets."""
        v = self.vertices[self.facets]
        n = _unit(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]))
        return np.where((np.einsum("ij,ij->i", n, v[:, 0]) < 0)[:, None], -n, n)

    @cached_property
    def inradius(self) -> float:
        """Distance (m) from the centre to every facet plane (all facets are congruent)."""
        v = self.vertices[self.facets]
        return float(np.einsum("ij,ij->i", self.normals, v[:, 0]).mean())

    @cached_property
    def leg(self) -> float:
        """Length (m) of the two equal sides of the isosceles triangle."""
        v = self.vertices[self.facets[0]]
        return float(np.linalg.norm(v[0] - v[1]))

    @cached_property
    def height(self) -> float:
        """Altitude (m) of the triangle from the base to the apex."""
        return float(np.sqrt(self.leg**2 - (self.base_edge / 2) ** 2))


def _pyramid_facets(vertices: np.ndarray, apex: int, ring: list[int]) -> list[tuple[int, int, int]]:
    """The pyramid's 5 facets (apex, b0, b1) in slot order, b0 -> b1 running to the right seen from inside."""
    a = vertices[apex]
    ring_v = vertices[ring]
    up = np.array([0.0, 0.0, 1.0]) - a[2] * a
    e1 = _unit(up) if np.linalg.norm(up) > 1e-9 else np.array([1.0, 0.0, 0.0])
    left = np.cross(e1, a)  # counter-clockwise seen from the centre, looking along +a

    def angle(p: np.ndarray) -> float:
        phi = np.arctan2(p @ left, p @ e1)
        return (phi + _ANGLE_TOL) % (2 * np.pi)

    # order the ring counter-clockwise, then pair neighbours into triangles
    order = sorted(range(5), key=lambda i: angle(ring_v[i]))
    triangles = []
    for i in range(5):
        p, q = order[i], order[(i + 1) % 5]
        mid = (ring_v[p] + ring_v[q]) / 2
        # right-handed local frame: x = b1 - b0, y = apex - mid, x cross y points inwards (towards -mid)
        b0, b1 = (p, q) if np.cross(ring_v[q] - ring_v[p], a - mid) @ mid < 0 else (q, p)
        triangles.append((angle(mid), (apex, ring[b0], ring[b1])))
    triangles.sort(key=lambda t: t[0])
    return [t for _, t in triangles]


@dataclass(frozen=True)
class PanelFrames:
    """Local frames of the 55 dome panels (the solid minus its bottom pyramid).

    origin: (55, 3) m  base midpoint;  axes: (55, 3, 3) rows = x (along base), y (towards apex), inward normal
    apex_dir: (11, 3) unit vector to each pentagon's apex
    """

    origin: np.ndarray
    axes: np.ndarray
    corners: np.ndarray  # (55, 3, 3) m: apex, base vertex 0, base vertex 1
    apex_dir: np.ndarray


def dome_panels(solid: Solid) -> PanelFrames:
    """The 55 panels in panel order (pentagon 0..10 as documented above; the bottom pyramid removed)."""
    n_panels = N_PENTAGONS * PANELS_PER_PENTAGON
    facets = solid.facets[:n_panels]  # apexes 0..10 in pentagon order; apex 11 (-z) is the removed one
    corners = solid.vertices[facets]
    origin = (corners[:, 1] + corners[:, 2]) / 2
    x = _unit(corners[:, 2] - corners[:, 1])
    y = _unit(corners[:, 0] - origin)
    n = np.cross(x, y)
    axes = np.stack([x, y, n], axis=1)
    return PanelFrames(origin, axes, corners, _unit(solid.vertices[:N_PENTAGONS]))
