"""Pictures of virtual-ant runs: paths over a top view of the world, and familiarity traces (matplotlib, Agg)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # plots sit below the ant: they draw its records, never import it
    from antarium.ant.agent import Track
    from antarium.ant.routes import Route

_TRACE_KEYS = ("lambda_left", "lambda_right", "lambda_diff", "lambda_max", "lambda_nest", "lambda_feeder",
               "motivation", "novelty", "image_difference")


def _figure(size=(7, 7)):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt, plt.figure(figsize=size)


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
               top: np.ndarray | None = None, margin: float = 0.5) -> Path:
    """The learned route and the followed paths (world frame, metres) over the world's top view (`top`, from
    `scene_top_view`); writes a PNG."""
    plt, fig = _figure()
    ax = fig.add_subplot(111)
    ax.plot(*route.points.T, color="tab:red", lw=4, alpha=0.5, label="learned route")
    ax.plot(*route.start, "o", color="tab:red", ms=8, label="start (nest)")
    ax.plot(*route.end, "*", color="tab:red", ms=12, label="end (feeder)")
    for i, (label, track) in enumerate(tracks.items()):
        xy, _ = track.arrays()
        if len(xy) == 0:
            continue
        colour = f"C{i % 10}" if i % 10 != 3 else "C9"
        # Break the line where the ant was put back on the route (Ardin's protocol).
        cuts = [0, *[k + 1 for k in track.put_back], len(xy)]
        for j, (a, b) in enumerate(zip(cuts[:-1], cuts[1:], strict=True)):
            ax.plot(*xy[a:b].T, color=colour, lw=1.2, label=label if j == 0 else None)
        if track.put_back:
            bad = xy[np.asarray(track.put_back)]
            ax.plot(*bad.T, "x", color=colour, ms=6)
    lo = np.min([route.points.min(0)] + [t.arrays()[0].min(0) for t in tracks.values() if t.xy], axis=0) - margin
    hi = np.max([route.points.max(0)] + [t.arrays()[0].max(0) for t in tracks.values() if t.xy], axis=0) + margin
    _draw_top_view(ax, top, lo, hi)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title)
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_traces(path: str | Path, track: Track, title: str = "") -> Path:
    """The model's signals (familiarities, motivation) against the decision number; writes a PNG."""
    plt, fig = _figure((8, 4))
    ax = fig.add_subplot(111)
    for key in _TRACE_KEYS:
        values = track.trace(key)
        if values.size and np.isfinite(values).any():
            ax.plot(values, lw=1, label=key)
    for k in track.put_back:
        ax.axvline(k, color="0.7", lw=0.8)
    ax.set_xlabel("decision")
    ax.set_ylabel("lambda (1 = novel) / signal")
    ax.set_title(title)
    ax.legend(loc="upper right", fontsize=7, ncol=2)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
