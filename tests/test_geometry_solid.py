"""The biscribed pentakis dodecahedron and the panel numbering."""

import itertools

import numpy as np
import pytest

from antarium.geometry.constants import BASE_EDGE_M, N_PANELS, VERTEX_RTOL
from antarium.geometry.solid import Solid, dome_panels


@pytest.fixture(scope="module")
def solid():
    return Solid()


def test_counts(solid):
    assert solid.vertices.shape == (32, 3)
    assert solid.facets.shape == (60, 3)
    assert len({tuple(sorted(f)) for f in solid.facets.tolist()}) == 60


def test_every_vertex_on_the_sphere(solid):
    r = np.linalg.norm(solid.vertices, axis=1)
    np.testing.assert_allclose(r, solid.circumradius, rtol=VERTEX_RTOL, atol=0)


def test_sizes_match_the_paper(solid):
    # base 368 mm gives a device "roughly 1 m in diameter"
    assert solid.circumradius == pytest.approx(0.5157, abs=1e-4)
    assert 0.95 < 2 * solid.circumradius < 1.1
    v = solid.vertices[solid.facets]
    base = np.linalg.norm(v[:, 1] - v[:, 2], axis=1)
    legs = np.linalg.norm(v[:, [1, 2]] - v[:, [0]], axis=2)
    np.testing.assert_allclose(base, BASE_EDGE_M, rtol=1e-12)
    np.testing.assert_allclose(legs, solid.leg, rtol=1e-12)


def test_all_facets_congruent_and_tangent_to_the_insphere(solid):
    v = solid.vertices[solid.facets]
    sides = np.sort(np.linalg.norm(v - np.roll(v, 1, axis=1), axis=2), axis=1)
    np.testing.assert_allclose(sides, sides[0][None, :].repeat(60, 0), rtol=1e-12)
    dist = np.einsum("ij,ij->i", solid.normals, v[:, 0])
    np.testing.assert_allclose(dist, solid.inradius, rtol=1e-12)
    # every facet plane holds its three vertices
    np.testing.assert_allclose(np.einsum("ij,ikj->ik", solid.normals, v), solid.inradius, rtol=1e-12)


def test_top_apex_up_and_opening_symmetric_about_minus_z(solid):
    frames = dome_panels(solid)
    np.testing.assert_allclose(frames.apex_dir[0], [0, 0, 1], atol=1e-15)
    used = set(solid.facets[:N_PANELS].ravel())
    missing = solid.vertices[sorted(set(range(32)) - used)]
    np.testing.assert_allclose(missing / solid.circumradius, [[0, 0, -1]], atol=1e-15)
    # the five vertices around the opening lie on a circle about -z
    ring = solid.vertices[solid.facets[N_PANELS:, 1:].ravel()]
    np.testing.assert_allclose(np.hypot(ring[:, 0], ring[:, 1]), np.hypot(ring[0, 0], ring[0, 1]), rtol=1e-12)
    np.testing.assert_allclose(ring[:, 2], ring[0, 2], rtol=1e-12)


def test_panel_frames_right_handed_and_inward(solid):
    f = dome_panels(solid)
    x, y, n = f.axes[:, 0], f.axes[:, 1], f.axes[:, 2]
    np.testing.assert_allclose(np.cross(x, y), n, atol=1e-14)
    assert np.all(np.einsum("ij,ij->i", n, f.origin) < 0)
    np.testing.assert_allclose(np.einsum("ij,ij->i", x, y), 0, atol=1e-14)


def test_panel_numbering_is_a_bijection_onto_the_dome_facets(solid):
    f = dome_panels(solid)
    keys = {tuple(sorted(map(tuple, np.round(c, 9)))) for c in f.corners}
    assert len(keys) == N_PANELS
    # pentagon p's five panels share its apex, in slot order counter-clockwise seen from the centre
    for p in range(11):
        apex = f.corners[5 * p : 5 * p + 5, 0]
        np.testing.assert_allclose(apex, apex[0][None].repeat(5, 0), atol=1e-15)
        mids = f.origin[5 * p : 5 * p + 5] - apex[0]
        a = f.apex_dir[p]
        turn = [np.cross(mids[i], mids[(i + 1) % 5]) @ a for i in range(5)]
        assert all(t < 0 for t in turn)  # clockwise about +a seen from outside = CCW seen from the centre


def test_neighbouring_panels_share_edges(solid):
    f = dome_panels(solid)
    edges = {}
    for p, c in enumerate(f.corners):
        for i, j in itertools.combinations(range(3), 2):
            key = tuple(sorted((tuple(np.round(c[i], 9)), tuple(np.round(c[j], 9)))))
            edges.setdefault(key, []).append(p)
    shared = [v for v in edges.values() if len(v) == 2]
    assert len(shared) == (55 * 3 - 5) // 2  # the five base edges around the opening are unshared


def test_bad_size_rejected():
    with pytest.raises(ValueError, match="base_edge"):
        Solid(base_edge=-1.0)
    with pytest.raises(ValueError, match="base_edge"):
        Solid(base_edge=float("nan"))
