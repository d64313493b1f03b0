"""Angular spacing statistics of the LED layout, as a user checks them first."""

from __future__ import annotations

import numpy as np


def _summary_deg(angles: np.ndarray) -> dict[str, float]:
    a = np.degrees(angles)
    return {
        "n": int(a.size),
        "mean_deg": float(a.mean()),
        "median_deg": float(np.median(a)),
        "min_deg": float(a.min()),
        "max_deg": float(a.max()),
        "cv": float(a.std() / a.mean()),
    }


def _chord_to_angle(chord: np.ndarray) -> np.ndarray:
    return 2 * np.arcsin(np.clip(chord / 2, 0, 1))


def spacing_statistics(directions: np.ndarray, panel: np.ndarray) -> dict[str, dict[str, float]]:
    """Nearest-neighbour angles of a pixel set: overall, within panels, and across seams.

    directions: (N, 3) unit vectors; panel: (N,) int panel of each pixel.
    - all:     each pixel's angle to its nearest neighbour anywhere;
    - within:  each pixel's angle to its nearest neighbour on the same panel;
    - seam:    for the pixels whose nearest neighbour on another panel is nearer than 1.5x their within-panel
               spacing (the rows along the panel edges), the angle to that neighbour across the seam.
    """
    from scipy.spatial import cKDTree

    within = np.empty(len(directions))
    other = np.empty(len(directions))
    for p in np.unique(panel):
        mine = panel == p
        within[mine] = cKDTree(directions[mine]).query(directions[mine], k=2)[0][:, 1]
        other[mine] = cKDTree(directions[~mine]).query(directions[mine], k=1)[0]
    seam = other < 1.5 * within
    return {
        "all": _summary_deg(_chord_to_angle(np.minimum(within, other))),
        "within": _summary_deg(_chord_to_angle(within)),
        "seam": _summary_deg(_chord_to_angle(other[seam])),
    }


def layout_summary(dome) -> dict:
    """The figures `antarium layout` prints: counts, elevation coverage, GB and UV spacing, gains, size."""
    gb, uv = dome.gb_index, dome.uv_index
    el = np.degrees(dome.elevation)
    return {
        "panels": int(dome.panel.max() + 1),
        "gb_pixels": int(gb.size),
        "uv_pixels": int(uv.size),
        "circumradius_m": dome.solid.circumradius,
        "inradius_m": dome.solid.inradius,
        "triangle_base_m": dome.solid.base_edge,
        "triangle_leg_m": dome.solid.leg,
        "elevation_min_deg": float(el.min()),
        "elevation_max_deg": float(el.max()),
        "gb_pitch_mm": dome.layout.gb_lattice.pitch * 1e3,
        "uv_pitch_mm": dome.layout.uv_lattice.pitch * 1e3,
        "gb_spacing": spacing_statistics(dome.directions[gb], dome.panel[gb]),
        "uv_spacing": spacing_statistics(dome.directions[uv], dome.panel[uv]),
        "gain_min": float(dome.gain.min()),
        "gain_max": float(dome.gain.max()),
        "distance_min_m": float(dome.distance.min()),
        "distance_max_m": float(dome.distance.max()),
    }
