"""Pictures of the central-complex experiments: homing trips, distance to the nest, the cluttered arena."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # plots sit below the ant: they draw its records, never import it
    from antarium.ant.homing import Trip


def plot_trips(path: str | Path, trips: dict[str, tuple[Trip, Trip]], title: str,
               marks: dict[str, tuple[float, float]] | None = None) -> Path:
    """Outbound (thin grey) and homeward paths (colour) of several trips from the nest at the origin, and labelled
    places `marks` (label -> (x, y) m, e.g. the fictive nest of a displaced ant) as crosses; PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 7))
    for i, (label, (out, home)) in enumerate(trips.items()):
        ax.plot(*out.xy.T, color="0.6", lw=0.8, label="outbound" if i == 0 else None)
        ax.plot(*home.xy.T, color=f"C{i % 10}", lw=1.0, label=label)
        ax.plot(*out.xy[-1], "s", color=f"C{i % 10}", ms=4)
    ax.plot(0, 0, "*", color="k", ms=14, label="nest")
    for label, (x, y) in (marks or {}).items():
        ax.plot(x, y, "X", color="k", mfc="w", ms=11, label=label)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title)
    ax.legend(fontsize=7, loc="best")
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_distance(path: str | Path, trips: dict[str, tuple[Trip, Trip]], title: str) -> Path:
    """Distance from the nest over the homeward trip, as a share of the outbound path length; PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4))
    for i, (label, (out, home)) in enumerate(trips.items()):
        length = float(np.linalg.norm(np.diff(np.vstack([(0, 0), out.xy]), axis=0), axis=1).sum())
        ax.plot(np.hypot(*home.xy.T) / length, color=f"C{i % 10}", lw=0.8, label=label)
    ax.axhline(0.05, color="k", ls="--", lw=0.8, label="goal: 5 % of the outbound path")
    ax.set_xlabel("homeward decision")
    ax.set_ylabel("distance to nest / outbound length")
    ax.set_title(title)
    ax.legend(fontsize=7, loc="best")
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_arena(path, clutter, trips: dict[str, Trip], title: str) -> Path:
    """Cylinders (grey discs) and the four trips of one arena run; PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 7))
    for (x, y), r in zip(clutter.centres, clutter.radii, strict=True):
        ax.add_patch(plt.Circle((x, y), r, color="0.4"))
    styles = {"outbound": ("0.6", "outbound (random walk + optic flow)"), "cx": ("C0", "home 1: CX (MBONs learn)"),
              "cxmb": ("C3", "home 2: CXMB (memory restored)"), "cx_again": ("C2", "home 2: CX alone (restored)")}
    for name, trip in trips.items():
        colour, label = styles[name]
        ax.plot(*trip.xy.T, color=colour, lw=0.9, label=label)
    ax.plot(0, 0, "*", color="k", ms=14, label="nest")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title)
    ax.legend(fontsize=7, loc="best")
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
