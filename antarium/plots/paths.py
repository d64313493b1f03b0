"""A walk through the world from a trial log's frames: the path coloured by time, scene rotations marked."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from antarium.plots import style


def world_path(x_m: np.ndarray, y_m: np.ndarray, t_s: np.ndarray, rotated: np.ndarray, path: str | Path,
               title: str, rotation_label: str = "scene rotated") -> Path:
    """Write a PNG: the path (x_m, y_m: (N,) metres, world frame) coloured by `t_s` (N,) seconds from the start,
    a ring at each frame index in `rotated`, a cross at the first finite position; with no finite position (N = 0
    or all NaN) a picture that says so."""
    fig, ax = style.figure((6.8, 5.2))
    finite = np.flatnonzero(np.isfinite(x_m) & np.isfinite(y_m))
    if finite.size == 0:
        style.no_data(ax, f"no position to draw: {len(x_m)} frames, none with a finite x and y")
        style.label(ax, title, "world x (cm)", "world y (cm)")
        return style.save(fig, path)
    points = ax.scatter(x_m * 100, y_m * 100, c=t_s, s=3, cmap="viridis")
    fig.colorbar(points, ax=ax, label="time since the start (s)")
    ax.plot(x_m[finite[0]] * 100, y_m[finite[0]] * 100, "k+", ms=10, label="start")
    if len(rotated):
        ax.plot(x_m[rotated] * 100, y_m[rotated] * 100, "o", mfc="none", mec="tab:red", ms=10, label=rotation_label)
    ax.set_aspect("equal", adjustable="datalim")
    style.label(ax, title, "world x (cm)", "world y (cm)")
    style.legend(ax, "below", ncol=2)
    return style.save(fig, path)
