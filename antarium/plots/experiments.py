"""Pictures of model experiments at scale: a metric against a parameter, the best and worst runs' paths."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np


def plot_metric_vs_parameter(df, metric: str, param: str, path: str | Path, ci: Callable) -> Path:
    """Mean of `metric` (with the interval `ci(values) -> (lo, hi)`) against parameter `param` (a `param.*`
    column of the results table `df`), one line per model and protocol."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    done = df[(df.status == "done") & df[param].notna()]
    fig, ax = plt.subplots(figsize=(6, 4))
    for (model, protocol), g in done.groupby(["model", "protocol"]):
        xs = sorted(g[param].unique())
        means = [g.loc[g[param] == x, metric].astype(float).mean() for x in xs]
        cis = [ci(g.loc[g[param] == x, metric].astype(float)) for x in xs]
        lo = [m - c[0] if np.isfinite(c[0]) else 0 for m, c in zip(means, cis, strict=True)]
        hi = [c[1] - m if np.isfinite(c[1]) else 0 for m, c in zip(means, cis, strict=True)]
        ax.errorbar(xs, means, yerr=[lo, hi], marker="o", capsize=3, label=f"{model} ({protocol})")
    ax.set_xlabel(param.removeprefix("param."))
    ax.set_ylabel(metric)
    ax.set_title(f"{metric} vs {param.removeprefix('param.')} (mean, 95 % bootstrap CI)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def plot_worst_and_best(df, routes: dict, path: str | Path, metric: str = "lateral_median_m", n: int = 3) -> Path:
    """Paths of the `n` worst and `n` best done runs by `metric`, each over its route (routes: (route_set,
    route) -> RouteInput)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    done = df[df.status == "done"].sort_values(metric)
    picks = [("best", r) for _, r in done.head(n).iterrows()] + [("worst", r) for _, r in done.tail(n).iloc[::-1]
                                                                 .iterrows()]
    fig, axes = plt.subplots(2, n, figsize=(4 * n, 8), squeeze=False)
    for ax in axes.ravel():
        ax.set_visible(False)
    for i, (label, r) in enumerate(picks[: 2 * n]):
        ax = axes[0 if label == "best" else 1, i % n]
        ax.set_visible(True)
        ri = routes.get((r.route_set, r.route))
        if ri is not None:
            ax.plot(*ri.route.points.T, "k-", lw=2, label="route (learned)")
        ax.plot(r.track_x, r.track_y, "-", color="tab:red" if label == "worst" else "tab:green", lw=1,
                label="followed")
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        params = ", ".join(f"{k.removeprefix('param.')}={r[k]}" for k in r.index
                           if k.startswith("param.") and r[k] == r[k])
        ax.set_title(f"{label}: {r.model} on {r.route} {params}\n{metric} = {r[metric]:.3g}, errors {r.errors}, "
                     f"seed {r.seed}", fontsize=8)
        ax.legend(fontsize=7)
    fig.suptitle(f"best and worst runs by {metric}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)
