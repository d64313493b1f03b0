"""The LED layout: counts, symmetry, spacing statistics, regeneration, bad parameters."""

import hashlib

import numpy as np
import pytest

from antarium.geometry import LayoutParams, generate_layout, load_layout
from antarium.geometry.constants import GB_PER_PANEL, N_GB, N_PIXELS, N_UV, UV_PER_PANEL
from antarium.geometry.lattice import edge_distance
from antarium.geometry.layout import SHIPPED_LAYOUT, save_layout
from antarium.geometry.spacing import layout_summary


@pytest.fixture(scope="module")
def summary(dome):
    return layout_summary(dome)


def test_counts(dome):
    assert dome.positions.shape == (N_PIXELS, 3)
    assert dome.gb_index.size == N_GB == 19855
    assert dome.uv_index.size == N_UV == 495
    assert np.all(dome.is_uv[dome.uv_index]) and not np.any(dome.is_uv[dome.gb_index])


def test_panel_layout_symmetric_and_inside_with_margin(dome):
    layout = dome.layout
    s = dome.solid
    for pts in (layout.gb, layout.uv):
        assert edge_distance(pts, s.base_edge, s.height).min() >= layout.params.margin - 1e-12
        mirrored = pts * [-1, 1]
        d = np.linalg.norm(mirrored[:, None] - pts[None], axis=2).min(axis=1)
        assert d.max() < 1e-12
    gb_pitch = np.linalg.norm(layout.gb[:, None] - layout.gb[None], axis=2) + np.eye(GB_PER_PANEL)
    assert gb_pitch.min() >= layout.params.gb_min_pitch
    clearance = np.linalg.norm(layout.uv[:, None] - layout.gb[None], axis=2).min()
    assert clearance >= layout.params.uv_clearance - 1e-12


def test_leds_lie_on_their_panels(dome):
    n = dome.panel_normals[dome.panel]
    np.testing.assert_allclose(-np.einsum("ij,ij->i", dome.positions, n), dome.solid.inradius, rtol=1e-12)


def test_coverage_and_spacing_statistics(summary):
    # the paper: elevation about -50 deg to +90 deg, GB pitch about 1.5 deg, UV about 6.7 deg
    assert -60 < summary["elevation_min_deg"] < -50
    assert summary["elevation_max_deg"] > 85
    gb, uv = summary["gb_spacing"], summary["uv_spacing"]
    assert 1.3 < gb["all"]["mean_deg"] < 1.6
    assert gb["all"]["cv"] < 0.06
    assert gb["within"]["cv"] < 0.04
    assert 1.3 < gb["seam"]["median_deg"] < 1.7  # seams continue the lattice spacing
    assert gb["all"]["min_deg"] > 0.9
    assert 5.5 < uv["all"]["mean_deg"] < 8.0
    assert uv["all"]["min_deg"] > 2.5


def test_photometric_gain_darkens_panel_centres(dome):
    g, d = dome.gain, dome.distance
    assert g.max() == pytest.approx(1.0) and 0.7 < g.min() < 1.0
    # nearer LEDs are darker: gain grows with distance within a panel
    p0 = dome.panel == 0
    assert np.corrcoef(d[p0], g[p0])[0, 1] > 0.99
    np.testing.assert_allclose(np.cos(dome.emission_angle), dome.solid.inradius / d, rtol=1e-12)


#: SHA-256 of the shipped layout file: any change to it, deliberate or not, must show up here. After a deliberate
#: `antarium layout --regenerate`, update it (`sha256sum geometry/data/layout.npz`) in the same commit.
SHIPPED_LAYOUT_SHA256 = "17cf9bf8f2bde79b7b66eb962411492fda1fa5da1fce08b952a78d2c32e3ffbd"

#: How far a regenerated LED may lie from the shipped one (m). The search is deterministic only up to the last bit
#: of floating point (numpy's SIMD paths differ between CPUs: 3.5e-18 m seen between Intel and AMD); a nanometre is
#: far below what a layout means (LEDs are placed to about 0.1 mm) and far above that noise.
LAYOUT_TOLERANCE_M = 1e-9


def test_shipped_layout_file_unchanged():
    assert hashlib.sha256(SHIPPED_LAYOUT.read_bytes()).hexdigest() == SHIPPED_LAYOUT_SHA256


def test_regenerated_layout_matches_shipped():
    shipped = load_layout()
    fresh = generate_layout(shipped.params)
    assert fresh.gb.shape == shipped.gb.shape and fresh.uv.shape == shipped.uv.shape
    np.testing.assert_allclose(fresh.gb, shipped.gb, rtol=0, atol=LAYOUT_TOLERANCE_M)
    np.testing.assert_allclose(fresh.uv, shipped.uv, rtol=0, atol=LAYOUT_TOLERANCE_M)
    for a, b in ((fresh.gb_lattice, shipped.gb_lattice), (fresh.uv_lattice, shipped.uv_lattice)):
        assert a.variant == b.variant
        assert a.pitch == pytest.approx(b.pitch, rel=0, abs=LAYOUT_TOLERANCE_M)
        assert a.offset == pytest.approx(b.offset, rel=0, abs=LAYOUT_TOLERANCE_M)
    # the addresses follow from the row order: the same LED must sit at the same local index
    nearest = np.linalg.norm(fresh.local_xy[:, None] - shipped.local_xy[None], axis=2).argmin(axis=1)
    np.testing.assert_array_equal(nearest, np.arange(len(nearest)))


def test_save_load_round_trip(tmp_path):
    layout = load_layout()
    save_layout(layout, tmp_path / "l.npz")
    again = load_layout(tmp_path / "l.npz")
    np.testing.assert_array_equal(again.local_xy, layout.local_xy)
    assert again.params == layout.params


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"margin": 0.0}, "margin"),
        ({"margin": -0.001}, "margin"),
        ({"gb_min_pitch": float("nan")}, "gb_min_pitch"),
        ({"uv_clearance": 1.0}, "uv_clearance"),
        ({"grid_pitches": 1}, "grid_pitches"),
    ],
)
def test_impossible_parameters_rejected(kwargs, match):
    with pytest.raises(ValueError, match=match):
        LayoutParams(**kwargs)


def test_too_many_leds_for_pitch_and_margin_rejected():
    with pytest.raises(ValueError, match="do not fit at min_pitch 20.0 mm"):
        generate_layout(LayoutParams(gb_min_pitch=0.020))
    with pytest.raises(ValueError, match="margin"):
        generate_layout(LayoutParams(margin=0.06))


def test_missing_layout_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="layout file not found"):
        load_layout(tmp_path / "nope.npz")


def test_layout_constants_match():
    assert UV_PER_PANEL == 9 and GB_PER_PANEL == 361
