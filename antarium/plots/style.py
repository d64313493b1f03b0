"""The house style of every picture the project writes (matplotlib, Agg), and its check.

A picture has a title; every axis a label with its unit in parentheses ("x (m)", "time (s)", "λ (1)" for a
ratio); a colour key where colour means something; legends outside the data (`legend`); on dome maps the
front (azimuth 0, the dome's +x) and the azimuth and elevation directions marked (`dome_axes`). `save` checks
this with `problems` and refuses a picture that breaks it, so a picture cannot drift from the style unnoticed.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

#: matplotlib settings of every picture
RC = {"font.size": 9, "axes.titlesize": 10, "axes.labelsize": 9, "legend.fontsize": 8, "figure.dpi": 110,
      "axes.grid": False, "savefig.bbox": "tight", "savefig.pad_inches": 0.1}
_UNIT = re.compile(r"\(.+\)\s*$")
#: label of the front mark on dome maps
FRONT = "front"
#: elevation (degrees) of the azimuth ticks on dome maps: the horizon
AZIMUTH_LABEL_ELEVATION_DEG = 0.0
#: gid of the axes that `no_data` marks: nothing to draw, and they say so
NO_DATA = "no data"


def pyplot():
    """matplotlib.pyplot on the Agg back-end with the house settings."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.rcParams.update(RC)
    return plt


def figure(size: tuple[float, float] = (7.0, 5.0), **subplots):
    """(fig, axes) of `plt.subplots(figsize=size, **subplots)` in the house style."""
    return pyplot().subplots(figsize=size, **subplots)


def label(ax, title: str, x: str, y: str) -> None:
    """Title and axis labels; each label ends with its unit in parentheses."""
    ax.set_title(title)
    ax.set_xlabel(x)
    ax.set_ylabel(y)


def legend(ax, where: str = "right", **kw):
    """A legend outside the axes, so that it hides no data: "right" of them or "below" them."""
    if where == "below":  # half an inch under the axes: under their tick labels and axis label
        from matplotlib.transforms import ScaledTranslation

        below = ax.transAxes + ScaledTranslation(0.0, -0.5, ax.figure.dpi_scale_trans)
        kw = {"loc": "upper center", "bbox_to_anchor": (0.5, 0.0), "bbox_transform": below, "ncol": 3, **kw}
    else:
        kw = {"loc": "upper left", "bbox_to_anchor": (1.02, 1.0), "borderaxespad": 0.0, **kw}
    return ax.legend(**kw)


def no_data(ax, why: str) -> None:
    """Say `why` (e.g. "no decisions recorded") in the middle of `ax`, ticks hidden, so that a picture of no data
    says so instead of showing blank axes; `problems` accepts such axes without data."""
    ax.text(0.5, 0.5, why, transform=ax.transAxes, ha="center", va="center", wrap=True, color="0.25")
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_gid(NO_DATA)


def azimuth_label(deg: float) -> str:
    """Azimuth tick text in whole degrees, rounded (never truncated) into (-180, 180]."""
    d = int(round(float(deg))) % 360
    return f"{d - 360 if d > 180 else d}°"


def dome_axes(ax, min_elevation_deg: float = -57.0, step_deg: int = 30) -> None:
    """Mollweide axes seen from inside the dome: azimuth grows to the left (plot longitudes at -azimuth),
    the front (azimuth 0, +x) in the centre marked, each azimuth tick straight under its meridian's point on the
    horizon (elevation `AZIMUTH_LABEL_ELEVATION_DEG`, where the meridians are as far apart as anywhere and the data
    are: reading straight up or down from a tick gives its azimuth; half-transparent, so the LEDs under it show), the
    direction of growing azimuth as an arrow below the lowest LEDs (`min_elevation_deg`), elevation ticks at the
    left edge, axis labels with units."""
    ax.set_facecolor("black")
    ax.grid(True, color="0.55", lw=0.3)
    lons = np.arange(-180 + step_deg, 180, step_deg)
    ax.set_xticks(np.radians(lons))
    ax.set_xticklabels([])
    y = np.radians(AZIMUTH_LABEL_ELEVATION_DEG)
    for lon in lons:  # just under the horizon line, straight below its point on the meridian: the front mark shows
        ax.annotate(azimuth_label(-lon), (np.radians(lon), y), xytext=(0.0, -9.0), textcoords="offset points",
                    ha="center", va="center", fontsize=7, color="0.1",
                    bbox={"boxstyle": "round,pad=0.1", "fc": "white", "ec": "none", "alpha": 0.55})
    ax.set_yticks(np.radians(np.arange(-60, 90, 30)))
    ax.plot([0.0], [0.0], marker="^", ms=9, mfc="none", mec="red", mew=1.5, ls="none",
            label=f"{FRONT} (azimuth 0°, +x)")
    ax.annotate("", xy=(np.radians(-60), np.radians(min_elevation_deg - 22)),
                xytext=(np.radians(60), np.radians(min_elevation_deg - 22)),
                arrowprops={"arrowstyle": "->", "color": "0.8", "lw": 1.2}, annotation_clip=False)
    ax.set_xlabel("azimuth (°, counter-clockwise from above: grows to the left, seen from inside)")
    ax.set_ylabel("elevation (°)")


def problems(fig) -> list[str]:
    """What breaks the house style in `fig`: nothing drawn on any axes (unless `no_data` says why), a missing
    title, axis labels without a unit, a legend over the data (a colour bar's axes and 3D or text-only axes are
    judged by their own label only)."""
    found = []
    titled = bool(fig._suptitle and fig._suptitle.get_text())
    shown = [ax for ax in fig.axes if ax.get_visible()]
    if not any(ax.has_data() or ax.get_gid() == NO_DATA for ax in shown):
        found.append("nothing drawn: no axes has data (say why with plots.style.no_data)")
    for i, ax in enumerate(fig.axes):
        name = f"axes {i} ({ax.get_title() or 'untitled'})"
        if ax.get_visible() and ax.get_gid() == NO_DATA and not (titled or ax.get_title()):
            found.append(f"{name}: no title")
        if not ax.get_visible() or not ax.has_data():
            continue
        labels = [ax.get_xlabel(), ax.get_ylabel()] + ([ax.get_zlabel()] if hasattr(ax, "get_zlabel") else [])
        if getattr(ax, "_colorbar", None) is not None:  # a colour key: one label, with its unit
            labels = [t for t in labels if t] or [""]
        elif not (titled or ax.get_title()):
            found.append(f"{name}: no title")
        for text in labels:
            if not _UNIT.search(text or ""):
                found.append(f"{name}: axis label {text!r} has no unit in parentheses")
        found += _legend_over_data(ax, name)
    return found


def _legend_over_data(ax, name: str) -> list[str]:
    """A legend drawn inside the axes hides data; `legend` puts it outside."""
    leg = ax.get_legend()
    if leg is None or ax.name != "rectilinear":
        return []
    fig = ax.figure
    fig.canvas.draw()
    box, area = leg.get_window_extent(), ax.get_window_extent()
    overlap_w = min(box.x1, area.x1) - max(box.x0, area.x0)
    overlap_h = min(box.y1, area.y1) - max(box.y0, area.y0)
    if overlap_w > 1 and overlap_h > 1:
        return [f"{name}: legend inside the axes (use plots.style.legend)"]
    return []


def save(fig, path: str | Path, dpi: float = 110, width_px: int | None = None) -> Path:
    """Check the house style, write `fig` as PNG (folders made), close it; returns the absolute path.
    `width_px`: the PNG is exactly that many pixels wide (the dpi is chosen for it, `dpi` unused); else the
    figure's tight box at `dpi`. ValueError names what is wrong."""
    plt = pyplot()
    wrong = problems(fig)
    if wrong:
        plt.close(fig)
        raise ValueError(f"picture {Path(path).name} breaks the house style: " + "; ".join(wrong))
    path = Path(path).expanduser().resolve()
    path.parent.mkdir(parents=True, exist_ok=True)
    if width_px is None:
        fig.savefig(path, dpi=dpi)
    else:  # the tight box (inches) fixed, the dpi that makes it width_px wide (rounded down by Agg: + 0.5)
        fig.canvas.draw()
        box = fig.get_tightbbox(fig.canvas.get_renderer()).padded(RC["savefig.pad_inches"])
        fig.savefig(path, dpi=(int(width_px) + 0.5) / box.width, bbox_inches=box)
    plt.close(fig)
    return path
