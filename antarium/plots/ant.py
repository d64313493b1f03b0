"""Pictures of virtual-ant runs: paths over a top view of the world, and familiarity traces (matplotlib, Agg)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from antarium.plots import style

if TYPE_CHECKING:  # plots sit below the ant: they draw its records, never import it
    from antarium.ant.agent import Track
    from antarium.ant.routes import Route

_TRACE_KEYS = ("lambda_left", "lambda_right", "lambda_diff", "lambda_max", "lambda_nest", "lambda_feeder",
               "motivation", "novelty", "image_difference")


def scene_top_view(scene, min_height: float = 0.01) -> np.ndarray:
    """(M, 3) x, y, height (m) of the vertices of a `Scene`'s objects above `min_height`, ground left out."""
    parts = [obj.world_vertices() for name, obj in getattr(scene, "objects", {}).items() if name != "ground"]
    if not parts:
        return np.zeros((0, 3))
    v = np.concatenate(parts).astype(np.float64)
    return v[v[:, 2] > min_height]


def _draw_top_view(ax, top: np.ndarray | None, lo, hi) -> None:
    if top is None or len(top) == 0:
        return
    inside = np.all((top[:, :2] >= lo) & (top[:, :2] <= hi), axis=1)
    t = top[inside]
    ax.scatter(t[:, 0], t[:, 1], s=2, c=np.minimum(t[:, 2], 1.0), cmap="Greens", vmin=-0.3, vmax=1.0, lw=0,
               label="objects (top view)")


def plot_paths(path: str | Path, route: Route, tracks: dict[str, Track], title: str = "",
               top: np.ndarray | None = None, margin: float = 0.3, notes: str = "") -> Path:
    """The learned route and the followed paths (world frame, metres) over the world's top view (`top`, from
    `scene_top_view`), each path's release point marked; `notes` (e.g. the error figures) under the title. The
    figure takes the shape of the area drawn, so that it is not left blank; writes a PNG."""
    xys = {label: track.arrays()[0] for label, track in tracks.items()}
    drawn = [route.points] + [xy for xy in xys.values() if len(xy)]
    lo = np.min([p.min(0) for p in drawn], axis=0) - margin
    hi = np.max([p.max(0) for p in drawn], axis=0) + margin
    span = hi - lo
    aspect = float(np.clip(span[1] / span[0], 0.3, 3.0))
    width = 6.5 if aspect < 1 else 4.5  # of the axes; the legend goes right of them
    fig, ax = style.figure((width + 3.2, max(3.5, width * aspect + 1.4)))
    _draw_top_view(ax, top, lo, hi)
    ax.plot(*route.points.T, color="tab:red", lw=4, alpha=0.5, label="learned route")
    ax.plot(*route.start, "o", color="tab:red", ms=8, label="route start (nest)")
    ax.plot(*route.end, "*", color="tab:red", ms=12, label="route end (feeder)")
    for i, (label, track) in enumerate(tracks.items()):
        xy = xys[label]
        colour = f"C{i % 10}" if i % 10 != 3 else "C9"
        if len(xy) == 0:  # in the legend all the same, so that a run without a path is not missed
            ax.plot([], [], color=colour, lw=1.2, label=f"{label}: no position recorded (0 decisions)")
            continue
        # Ardin's protocol: at decision k the ant, too far from the route, was picked up at xy[k] and put back on
        # the nearest route point; the line breaks there and goes on from the put-back point.
        picked = np.asarray(track.put_back, int)
        put = route.at(route.project(xy[picked])[0])[0] if picked.size else np.zeros((0, 2))
        cuts = [0, *(picked + 1), len(xy)]
        for j, (a, b) in enumerate(zip(cuts[:-1], cuts[1:], strict=True)):
            part = xy[a:b] if j == 0 else np.vstack([put[j - 1], xy[a:b]])
            ax.plot(*part.T, color=colour, lw=1.2, label=label if j == 0 else None)
        ax.plot(*xy[0], "^", color=colour, ms=8, mec="k", label=f"{label}: release point")
        if picked.size:
            ax.plot(*xy[picked].T, "x", color=colour, ms=7, mew=1.5, ls="none",
                    label=f"{label}: picked up (off the route)")
            ax.plot(*put.T, "o", mfc="w", mec=colour, ms=6, mew=1.5, ls="none",
                    label=f"{label}: put back on the route")
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    style.label(ax, title + (f"\n{notes}" if notes else ""), "world x (m)", "world y (m)")
    style.legend(ax, "right")
    return style.save(fig, path)


#: the trace panels, top to bottom: name -> (trace keys, y-axis label); a signed difference gets its own axis
_TRACE_PANELS = {"familiarity": (tuple(k for k in _TRACE_KEYS if k.startswith("lambda") and k != "lambda_diff"),
                                 "λ (1: 0 familiar .. 1 novel)"),
                 "left - right": (("lambda_diff",), "λ left − λ right (1: > 0, the left more novel)"),
                 "other": (tuple(k for k in _TRACE_KEYS if not k.startswith("lambda")), "signal (1)")}


def plot_traces(path: str | Path, track: Track, title: str = "") -> Path:
    """The model's signals against the decision since release (0, 1, ...): familiarities (λ, 0 familiar .. 1
    novel) above, their signed left - right difference on its own axis around a zero line, the other signals
    below, each panel shown when it has a finite value (none: a picture that says so); put-backs marked; writes a
    PNG. (The decision, not the
    rig's clock: the emulated rig runs one frame per decision, whatever the model's decision takes.)"""
    n = len(track.traces)
    shown = {g: [k for k in keys if np.isfinite(track.trace(k)).any()] for g, (keys, _) in _TRACE_PANELS.items()}
    shown = {g: keys for g, keys in shown.items() if keys}
    fig, axes = style.figure((9.0, 2.4 + 2.2 * max(1, len(shown))), nrows=max(1, len(shown)), sharex=True,
                             squeeze=False)
    for ax, (group, keys) in zip(axes[:, 0], shown.items(), strict=False):
        for key in keys:
            values = track.trace(key)
            flat = np.nanmax(values) == np.nanmin(values)
            ax.plot(np.arange(len(values)), values, lw=1,
                    label=key.replace("_", " ") + (f" (constant {np.nanmax(values):g})" if flat else ""))
        if group == "left - right":
            ax.axhline(0.0, color="k", lw=0.6)
        for k in track.put_back:
            ax.axvline(k, color="0.6", lw=0.8, ls="--")
        style.label(ax, f"{title}: {group}" if title else group, "", _TRACE_PANELS[group][1])
        style.legend(ax, "right")
    if not shown:
        style.no_data(axes[0, 0], f"no model signal with a finite value in {n} decisions")
        axes[0, 0].set_title(f"{title}: model signals" if title else "model signals")
    axes[-1, 0].set_xlabel(f"decision since release (count; {n} decisions"
                           + (", dashed: put back on the route)" if track.put_back else ")"))
    for ax in axes[:-1, 0]:
        ax.set_xlabel("decision since release (count)")
        ax.xaxis.label.set_visible(False)
    return style.save(fig, path)
