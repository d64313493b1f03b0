"""Pictures of the LED layout: an equal-area (Mollweide) map of LED directions and a 3D view of the dome."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from antarium.plots import style


def _panel_colours(panel: np.ndarray) -> np.ndarray:
    """A colour per panel that differs between neighbours in a pentagon and between pentagons."""
    import matplotlib

    cmap = matplotlib.colormaps["tab20"]
    return cmap(((panel // 5) * 7 + (panel % 5) * 3) % 20)


def mollweide_map(dome, path: str | Path) -> Path:
    """LED directions on a Mollweide (equal-area) map seen from inside, coloured by panel, panel numbers at the
    panel centres; UV pixels as black rings."""
    from matplotlib.lines import Line2D

    fig = style.pyplot().figure(figsize=(12, 7.2))
    ax = fig.add_subplot(projection="mollweide")
    gb, uv = dome.gb_index, dome.uv_index
    ax.scatter(-dome.azimuth[gb], dome.elevation[gb], s=0.6, c=_panel_colours(dome.panel[gb]), linewidths=0)
    ax.scatter(-dome.azimuth[uv], dome.elevation[uv], s=14, facecolors="none", edgecolors="k", linewidths=0.7)
    centres = dome.panel_corners.mean(axis=1)
    for p, c in enumerate(centres):
        az, el = np.arctan2(c[1], c[0]), np.arcsin(c[2] / np.linalg.norm(c))
        ax.text(-az, el, str(p), fontsize=6, ha="center", va="center", color="k",
                bbox={"boxstyle": "round,pad=0.05", "fc": "white", "ec": "none", "alpha": 0.7})
    style.dome_axes(ax, float(np.degrees(dome.elevation.min())))
    ax.set_facecolor("white")
    key = [Line2D([], [], marker="o", ms=4, ls="none", mfc="tab:blue", mec="none",
                  label=f"{gb.size} GB pixels, one colour per panel (number: panel = pentagon × 5 + slot)"),
           Line2D([], [], marker="o", ms=6, ls="none", mfc="none", mec="k", label=f"{uv.size} UV pixels"),
           Line2D([], [], marker="^", ms=8, ls="none", mfc="none", mec="red", mew=1.5,
                  label="front (azimuth 0°, +x)")]
    style.legend(ax, "below", handles=key)
    ax.set_title(f"Antarium LED layout: {dome.panel_corners.shape[0]} panels, equal-area map seen from inside")
    return style.save(fig, path, dpi=150)


def dome_3d(dome, path: str | Path) -> Path:
    """A 3D view of the 55 panels with their LEDs, seen from outside and below."""
    plt = style.pyplot()
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
    ax.scatter([r], [0], [0], marker="^", s=60, c="red", depthshade=False, label="front (+x, azimuth 0°)")
    ax.set_title("Antarium dome: 55 panels, GB (green) and UV (purple) pixels, seen from outside and below")
    style.legend(ax, "below", ncol=1)
    return style.save(fig, path, dpi=120)
