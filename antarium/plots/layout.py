"""Pictures of the LED layout: an equal-area (Mollweide) map of LED directions and a 3D view of the dome."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _panel_colours(panel: np.ndarray) -> np.ndarray:
    """A colour per panel that differs between neighbours in a pentagon and between pentagons."""
    import matplotlib

    cmap = matplotlib.colormaps["tab20"]
    return cmap(((panel // 5) * 7 + (panel % 5) * 3) % 20)


def mollweide_map(dome, path: str | Path) -> Path:
    """LED directions on a Mollweide (equal-area) map, coloured by panel; UV pixels as black rings."""
    plt = _pyplot()
    fig = plt.figure(figsize=(12, 6.5))
    ax = fig.add_subplot(projection="mollweide")
    gb, uv = dome.gb_index, dome.uv_index
    # Mollweide longitude runs left to right; show azimuth increasing to the left (as seen from inside)
    ax.scatter(-dome.azimuth[gb], dome.elevation[gb], s=0.6, c=_panel_colours(dome.panel[gb]), linewidths=0)
    ax.scatter(-dome.azimuth[uv], dome.elevation[uv], s=14, facecolors="none", edgecolors="k", linewidths=0.7,
               label="UV pixel")
    centres = dome.panel_corners.mean(axis=1)
    for p, c in enumerate(centres):
        az, el = np.arctan2(c[1], c[0]), np.arcsin(c[2] / np.linalg.norm(c))
        ax.text(-az, el, str(p), fontsize=6, ha="center", va="center", color="k")
    ticks = np.radians(np.arange(-150, 181, 30))
    ax.set_xticks(ticks)
    ax.set_xticklabels([f"{int(v)}°" for v in -np.degrees(ticks)], fontsize=7)
    ax.grid(True, lw=0.3)
    ax.set_title(f"Antarium: {gb.size} GB pixels (colour = panel), {uv.size} UV pixels (rings); azimuth, elevation")
    ax.legend(loc="lower right", fontsize=8)
    path = Path(path)
    fig.savefig(path, dpi=150, bbox_inches="tight")
    plt.close(fig)
    return path


def dome_3d(dome, path: str | Path) -> Path:
    """A 3D view of the 55 panels with their LEDs, seen from outside and below."""
    plt = _pyplot()
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    fig = plt.figure(figsize=(8, 8))
    ax = fig.add_subplot(projection="3d")
    colours = _panel_colours(np.arange(len(dome.panel_corners)))
    ax.add_collection3d(Poly3DCollection(dome.panel_corners, facecolors=colours, alpha=0.25, edgecolors="k",
                                         linewidths=0.4))
    p = dome.positions
    ax.scatter(*p[dome.gb_index].T, s=0.3, c="tab:green", depthshade=False)
    ax.scatter(*p[dome.uv_index].T, s=6, c="tab:purple", depthshade=False)
    r = dome.solid.circumradius
    ax.set(xlim=(-r, r), ylim=(-r, r), zlim=(-r, r), xlabel="x (m)", ylabel="y (m)", zlabel="z (m)")
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=-15, azim=30)
    ax.set_title("Antarium dome: 55 panels, GB (green) and UV (purple) pixels")
    path = Path(path)
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)
    return path
