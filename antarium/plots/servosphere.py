"""Pictures of a servosphere run: the distribution of the ant's offset from the apex (as Goulard et al. 2021,
Fig. 1F) and the ant's true path against the one the ball's rotation gives back."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from antarium.plots import style


def error_figure(err_x_mm: np.ndarray, err_y_mm: np.ndarray, true_path_m: np.ndarray | None,
                 ball_path_m: np.ndarray | None, out: str | Path, title: str = "") -> Path:
    """Write a PNG: left, probability density of the error from the apex (x, y and distance, mm); right, the
    paths (m, (N, 2) each) if given. NaN errors (frames with a fault) are left out and counted in the legend."""
    ex, ey = np.asarray(err_x_mm, float), np.asarray(err_y_mm, float)
    ok = np.isfinite(ex) & np.isfinite(ey)
    dist = np.hypot(ex[ok], ey[ok])
    paths = true_path_m is not None and ball_path_m is not None
    fig, axes = style.figure((12 if paths else 6.5, 5.2), ncols=2 if paths else 1, squeeze=False)
    ax = axes[0, 0]
    lim = max(1.0, float(np.percentile(np.abs(np.concatenate([ex[ok], ey[ok]])), 99.9)) * 1.2) if ok.any() else 1.0
    bins = np.linspace(-lim, lim, 121)
    ax.hist(ex[ok], bins=bins, density=True, histtype="step", lw=1.5, label="x error")
    ax.hist(ey[ok], bins=bins, density=True, histtype="step", lw=1.5, label="y error")
    ax.hist(dist, bins=np.linspace(0, lim, 61), density=True, histtype="stepfilled", alpha=0.3,
            label=f"distance: median {np.median(dist):.2f} mm, p99 {np.percentile(dist, 99):.2f} mm"
            if dist.size else "distance")
    ax.set_xlabel("error from the apex (mm)")
    ax.set_ylabel("probability density (1/mm)")
    ax.set_title(f"Tracker error, {ok.sum()} frames ({(~ok).sum()} with a fault)")
    style.legend(ax, "below", ncol=1)
    if paths:
        ax = axes[0, 1]
        tp, bp = np.asarray(true_path_m), np.asarray(ball_path_m)
        ax.plot(tp[:, 0] * 100, tp[:, 1] * 100, lw=2, label="true path of the ant")
        ax.plot(bp[:, 0] * 100, bp[:, 1] * 100, "--", lw=1.2, label="path from the ball's rotation")
        ax.set_xlabel("x (cm)")
        ax.set_ylabel("y (cm)")
        ax.set_aspect("equal", "datalim")
        ax.set_title("Walk")
        style.legend(ax, "below", ncol=1)
    if title:
        fig.suptitle(title)
    return style.save(fig, out)
