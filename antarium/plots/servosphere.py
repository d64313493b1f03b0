"""Pictures of a servosphere run: the distribution of the ant's offset from the apex (as Goulard et al. 2021,
Fig. 1F) and the ant's true path against the one the ball's rotation gives back."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from antarium.plots import style


def _density(ax, values: np.ndarray, bins: np.ndarray, name: str, kind: str, lim: float) -> None:
    """Histogram of `values` (mm) as a probability density (1/mm) over all of them, those outside `bins` counted
    in the legend entry; `kind`: "step" (a line) or "stepfilled"."""
    width = float(bins[1] - bins[0])
    beyond = int(np.sum((values < bins[0]) | (values > bins[-1])))
    label = name
    if name == "distance" and values.size:
        label += f": median {np.median(values):.2f} mm, p99 {np.percentile(values, 99):.2f} mm"
    if beyond:
        label += f" ({beyond} of {values.size} beyond {lim:.2f} mm, not drawn)"
    weights = np.full(values.size, 1.0 / (values.size * width)) if values.size else None
    ax.hist(values, bins=bins, weights=weights, histtype=kind, lw=1.5, alpha=0.3 if kind == "stepfilled" else 1.0,
            label=label)


def error_figure(err_x_mm: np.ndarray, err_y_mm: np.ndarray, true_path_m: np.ndarray | None,
                 ball_path_m: np.ndarray | None, out: str | Path, title: str = "") -> Path:
    """Write a PNG: left, probability density of the error from the apex (x, y and distance, mm) over a range
    that covers 99.9 % of all three (the few beyond it counted in the legend, not drawn; each density is over
    every frame, so that those few lower it rather than raise the rest); right, the paths (m, (N, 2) each) if
    given. NaN errors (frames with a fault) are left out and counted in the title."""
    ex, ey = np.asarray(err_x_mm, float), np.asarray(err_y_mm, float)
    ok = np.isfinite(ex) & np.isfinite(ey)
    dist = np.hypot(ex[ok], ey[ok])
    paths = true_path_m is not None and ball_path_m is not None
    fig, axes = style.figure((12 if paths else 6.5, 5.2), ncols=2 if paths else 1, squeeze=False)
    ax = axes[0, 0]
    sizes = np.concatenate([np.abs(ex[ok]), np.abs(ey[ok]), dist])
    lim = max(1.0, float(np.percentile(sizes, 99.9)) * 1.2) if ok.any() else 1.0
    for values, bins, name, kind in ((ex[ok], np.linspace(-lim, lim, 121), "x error", "step"),
                                     (ey[ok], np.linspace(-lim, lim, 121), "y error", "step"),
                                     (dist, np.linspace(0.0, lim, 61), "distance", "stepfilled")):
        _density(ax, values, bins, name, kind, lim)
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
