"""Pictures of the central-complex experiments: homing trips, distance to the nest, the cluttered arena."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from antarium.plots import style

if TYPE_CHECKING:  # plots sit below the ant: they draw its records, never import it
    from antarium.ant.homing import Trip

#: the arena run's trips: name -> (colour, legend; {model}: the model's name in ARENA_MODELS)
ARENA_TRIPS = {"outbound": ("0.6", "outbound (random walk + optic flow)"),
               "cx": ("C0", "home 1: CX (MBONs learn to the nest)"),
               "cxmb": ("C3", "home 2: {model} (same start)"), "cx_again": ("C2", "home 2: CX alone (same start)")}
#: model kind -> its name in the legend
ARENA_MODELS = {"cxmb": "CXMB", "one_ring": "One Ring"}


def _mark_lost_cue(ax, *trips: Trip) -> None:
    """A black cross where a trip ended because the compass lost its cue."""
    for trip in trips:
        if trip.lost_cue is not None and len(trip.xy):
            ax.plot(*trip.xy[-1], "x", color="k", ms=9, mew=2, label="no compass cue: trip ended")


def _map(path: str | Path, title: str, draw) -> Path:
    """A top view in metres with the nest marked; `draw(ax)` adds the trips."""
    fig, ax = style.figure((7.5, 7.0))
    draw(ax)
    ax.plot(0, 0, "*", color="k", ms=14, label="nest")
    ax.set_aspect("equal")
    style.label(ax, title, "world x (m)", "world y (m)")
    style.legend(ax, "below", ncol=2, fontsize=7)
    return style.save(fig, path)


def plot_trips(path: str | Path, trips: dict[str, tuple[Trip, Trip]], title: str,
               marks: dict[str, tuple[float, float]] | None = None) -> Path:
    """Outbound routes (grey), homeward trips (one colour each), where each turned home (squares), and labelled
    places `marks` (label -> (x, y) m, e.g. the fictive nest of a displaced ant) as crosses; PNG."""
    def draw(ax) -> None:
        for i, (label, (out, home)) in enumerate(trips.items()):
            ax.plot(*out.xy.T, color="0.6", lw=0.8, label="outbound" if i == 0 else None)
            ax.plot(*home.xy.T, color=f"C{i % 10}", lw=1.0, label=label)
            if len(out.xy):
                ax.plot(*out.xy[-1], "s", color=f"C{i % 10}", ms=4)
            _mark_lost_cue(ax, out, home)
        for label, (x, y) in (marks or {}).items():
            ax.plot(x, y, "X", color="k", mfc="w", ms=11, label=label)

    return _map(path, title, draw)


def plot_distance(path: str | Path, trips: dict[str, tuple[Trip, Trip]], title: str) -> Path:
    """Distance from the nest over the homeward trip, as a share of the outbound path length; PNG."""
    fig, ax = style.figure((8.5, 4.5))
    for i, (label, (out, home)) in enumerate(trips.items()):
        length = float(np.linalg.norm(np.diff(np.vstack([(0, 0), out.xy]), axis=0), axis=1).sum())
        ax.plot(100 * np.hypot(*home.xy.T) / length, color=f"C{i % 10}", lw=0.8, label=label)
    ax.axhline(5.0, color="k", ls="--", lw=0.8, label="goal: 5 % of the outbound path")
    style.label(ax, title, "homeward decision (steps of 1 cm)", "distance to the nest (% of the outbound path)")
    style.legend(ax, "right", fontsize=7)
    return style.save(fig, path)


def plot_arena(path: str | Path, clutter, trips: dict[str, Trip], title: str, model: str = "cxmb") -> Path:
    """Cylinders (grey discs) and the four trips of one arena run of `model` (an ARENA_MODELS kind); PNG."""
    def draw(ax) -> None:
        import matplotlib.patches as mpatches

        for (x, y), r in zip(clutter.centres, clutter.radii, strict=True):
            ax.add_patch(mpatches.Circle((x, y), r, color="0.4"))
        for trip_name, trip in trips.items():
            colour, label = ARENA_TRIPS[trip_name]
            ax.plot(*trip.xy.T, color=colour, lw=0.9, label=label.format(model=ARENA_MODELS[model]))
            _mark_lost_cue(ax, trip)

    return _map(path, title, draw)
