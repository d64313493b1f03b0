"""Pictures of the central-complex experiments: homing trips, distance to the nest, the cluttered arena."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from antarium.plots import style

if TYPE_CHECKING:  # plots sit below the ant: they draw its records, never import it
    from antarium.ant.homing import Trip

#: the arena run's trips, drawn in this order: name -> (colour, line style, line width (pt), legend; {model}: the
#: model's name in ARENA_MODELS). CX alone walks trip 1 again (common random numbers), often on the very same path:
#: it is drawn dashed and thinner over it, so that both stay visible
ARENA_TRIPS = {"outbound": ("0.6", "-", 0.9, "outbound (random walk + optic flow)"),
               "cx": ("C0", "-", 1.8, "home 1: CX (MBONs learn to the nest)"),
               "cxmb": ("C3", "-", 0.9, "home 2: {model} (same start)"),
               "cx_again": ("C2", "--", 0.9, "home 2: CX alone (same start)")}
#: model kind -> its name in the legend
ARENA_MODELS = {"cxmb": "CXMB", "one_ring": "One Ring"}
#: legend of the marks on the trip maps (one entry per kind of mark)
TURNED_HOME = "turned home: end of the outbound route"
PUT_DOWN = "put down: start of a trip home away from the end of its outbound route"
LOST_CUE = "no compass cue: trip ended"


def _once(ax, label: str) -> str | None:
    """`label` the first time it is drawn on `ax`, None after: one legend entry per kind of mark."""
    return None if any(a.get_label() == label for a in ax.get_lines()) else label


def _mark_lost_cue(ax, *trips: Trip, start=None) -> None:
    """A black cross where a trip ended because the compass lost its cue: at its last position, or at `start`
    ((2,) m, where it began) when it lost the cue before its first step."""
    for trip in trips:
        end = trip.xy[-1] if len(trip.xy) else start
        if trip.lost_cue is not None and end is not None:
            ax.plot(*end, "x", color="k", ms=9, mew=2, label=_once(ax, LOST_CUE))


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
               marks: dict[str, tuple[float, float]] | None = None,
               starts: dict[str, tuple[float, float]] | None = None) -> Path:
    """Outbound routes (grey), homeward trips (one colour each, each from where it began), where each began (a
    filled square where it turned home at the end of its outbound route; a hollow diamond where the ant was put
    down elsewhere: `starts`, trip label -> (x, y) m, e.g. a displaced release point) and labelled places `marks`
    (label -> (x, y) m, e.g. the fictive nest of a displaced ant) as crosses; PNG."""
    def draw(ax) -> None:
        drawn = set()
        for i, (label, (out, home)) in enumerate(trips.items()):
            colour = f"C{i % 10}"
            if id(out) not in drawn:  # trips that share their outbound route draw it once
                ax.plot(*out.xy.T, color="0.6", lw=0.8, label=_once(ax, "outbound"))
                drawn.add(id(out))
            put_down = starts is not None and label in starts
            start = np.asarray(starts[label], float) if put_down else (out.xy[-1] if len(out.xy) else None)
            ax.plot(*(home.xy if start is None else np.vstack([start, home.xy])).T, color=colour, lw=1.0,
                    label=label)
            if start is not None:
                kind = PUT_DOWN if put_down else TURNED_HOME
                ax.plot(*start, "D" if put_down else "s", mfc="w" if put_down else colour, mec=colour, mew=1.5,
                        ms=6 if put_down else 5, ls="none", label=_once(ax, kind))
            _mark_lost_cue(ax, out)
            _mark_lost_cue(ax, home, start=start)
        for label, (x, y) in (marks or {}).items():
            ax.plot(x, y, "X", color="k", mfc="w", ms=11, label=label)

    return _map(path, title, draw)


def plot_distance(path: str | Path, trips: dict[str, tuple[Trip, Trip]], title: str, step_m: float) -> Path:
    """Distance from the nest over the homeward trip, as a share of the outbound path length, against the
    homeward decision (each a step of `step_m` metres); a trip without a homeward decision or an outbound path
    says so in the legend; PNG."""
    fig, ax = style.figure((8.5, 4.5))
    for i, (label, (out, home)) in enumerate(trips.items()):
        length = float(np.linalg.norm(np.diff(np.vstack([(0, 0), out.xy]), axis=0), axis=1).sum())
        why = "no homeward decision" if len(home.xy) == 0 else "no outbound path (length 0)" if length <= 0 else ""
        share = 100 * np.hypot(*home.xy.T) / length if not why else []  # in the legend all the same
        ax.plot(share, color=f"C{i % 10}", lw=0.8, label=f"{label}: {why}" if why else label)
    ax.axhline(5.0, color="k", ls="--", lw=0.8, label="goal: 5 % of the outbound path")
    style.label(ax, title, f"homeward decision (count; one step of {100 * step_m:g} cm each)",
                "distance to the nest (% of the outbound path)")
    style.legend(ax, "right", fontsize=7)
    return style.save(fig, path)


def plot_arena(path: str | Path, clutter, trips: dict[str, Trip], title: str, model: str = "cxmb") -> Path:
    """Cylinders (grey discs) and the four trips of one arena run of `model` (an ARENA_MODELS kind), in
    ARENA_TRIPS order and style; a trip on the same path as home 1 says so in the legend; PNG."""
    def draw(ax) -> None:
        import matplotlib.patches as mpatches

        unknown = sorted(set(trips) - set(ARENA_TRIPS))
        if unknown:
            raise ValueError(f"arena trips {unknown} unknown; allowed: {sorted(ARENA_TRIPS)}")
        for (x, y), r in zip(clutter.centres, clutter.radii, strict=True):
            ax.add_patch(mpatches.Circle((x, y), r, color="0.4"))
        for trip_name, (colour, ls, lw, label) in ARENA_TRIPS.items():
            trip = trips.get(trip_name)
            if trip is None:
                continue
            label = label.format(model=ARENA_MODELS[model])
            first = trips.get("cx")
            if trip_name != "cx" and first is not None and np.array_equal(trip.xy, first.xy) and len(trip.xy):
                label += ": same path as home 1, drawn over it"
            ax.plot(*trip.xy.T, color=colour, ls=ls, lw=lw, label=label)
            _mark_lost_cue(ax, trip)

    return _map(path, title, draw)
