"""Pictures of model experiments at scale: a metric against a parameter, the best and worst runs' paths."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from antarium.plots import style

#: the unit of a results column, by the end of its name (the project names quantities `*_m`, `*_deg`, `*_s`)
_UNITS = {"_m": "m", "_cm": "cm", "_deg": "°", "_s": "s", "_ms": "ms"}


def _axis_label(column: str) -> str:
    """`column` as an axis label with its unit in parentheses: "lateral median (m)" for lateral_median_m,
    "errors (count)" for errors, "(as set)" for a model parameter whose unit its name does not say."""
    name = column.removeprefix("param.")
    for suffix, unit in _UNITS.items():
        if name.endswith(suffix):
            return f"{name.removesuffix(suffix).replace('_', ' ')} ({unit})"
    if column == "errors":
        return "errors (count)"
    return f"{name.replace('_', ' ')} ({'as set' if column.startswith('param.') else '1'})"


def plot_metric_vs_parameter(df, metric: str, param: str, path: str | Path, ci: Callable,
                             conditions: Sequence[str]) -> Path:
    """Mean of `metric` (with the interval `ci(values) -> (lo, hi)`, NaN when it has none) against parameter
    `param` (a `param.*` column of the results table `df`): one line per combination of the other condition
    columns (`conditions` and every other `param.*` column), so that no condition is pooled with another. A
    point of one run (or without an interval) is a hollow marker without a bar; runs without a finite `metric`
    are left out (none left: a picture that says so); PNG."""
    done = df[(df.status == "done") & df[param].notna()]
    done = done[np.isfinite(done[metric].astype(float))]
    keys = [c for c in dict.fromkeys([*conditions, *(c for c in df.columns if c.startswith("param."))])
            if c != param and c in done.columns]
    varied = [c for c in keys if done[c].nunique(dropna=False) > 1]  # what tells the lines apart
    fig, ax = style.figure((7.0, 4.2))
    hollow = False
    if done.empty:
        style.no_data(ax, f"no done run with {param.removeprefix('param.')} set and a finite {metric} "
                          f"(of {len(df)} runs)")
    groups = [] if done.empty else done.groupby(keys, dropna=False, sort=True) if keys else [((), done)]
    for i, (key, g) in enumerate(groups):
        row = dict(zip(keys, key if isinstance(key, tuple) else (key,), strict=True))
        name = ", ".join(f"{c.removeprefix('param.')} = {row[c]}" for c in varied) \
            or f"{row.get('model', '')} ({row.get('protocol', '')})"
        colour = f"C{i % 10}"
        xs = sorted(g[param].unique())
        values = [g.loc[g[param] == x, metric].astype(float).to_numpy() for x in xs]
        values = [v[np.isfinite(v)] for v in values]
        means = np.array([v.mean() if v.size else np.nan for v in values])
        cis = np.array([ci(v) for v in values], dtype=float).reshape(-1, 2)
        bar = np.isfinite(cis).all(axis=1) & np.array([v.size >= 2 for v in values])
        ax.plot(xs, means, "-", color=colour, lw=1.2, label=name)
        xs = np.asarray(xs)
        if bar.any():
            ax.errorbar(xs[bar], means[bar], yerr=[means[bar] - cis[bar, 0], cis[bar, 1] - means[bar]], fmt="o",
                        color=colour, capsize=3)
        if (~bar).any():
            ax.plot(xs[~bar], means[~bar], "o", mfc="white", mec=colour, mew=1.5, ms=7)
            hollow = True
    if hollow:  # one key entry, after the lines'
        ax.plot([], [], "o", mfc="white", mec="0.3", mew=1.5, ms=7, ls="none", label="hollow: n = 1 run (no interval)")
    title = f"{metric} vs {param.removeprefix('param.')}: mean over runs, 95 % bootstrap interval"
    style.label(ax, title, _axis_label(param), _axis_label(metric))
    if not done.empty:
        style.legend(ax, "right")
    return style.save(fig, path)


def _halves(done, n: int) -> tuple[list, list]:
    """(best, worst) rows of `done` (sorted best first): disjoint, each at most `n`, every run in at most one."""
    rows = [r for _, r in done.iterrows()]
    best = rows[:min(n, (len(rows) + 1) // 2)]
    worst = rows[len(best):][::-1][:n]
    return best, worst


def plot_worst_and_best(df, routes: dict, path: str | Path, metric: str = "lateral_median_m", n: int = 3) -> Path:
    """Paths of the `n` best (top row) and `n` worst (bottom row) done runs by `metric`, each over its route
    (routes: (route_set, route) -> RouteInput). With fewer than 2n runs the best half and the worst half are
    shown, each run once; runs without a finite `metric` are not ranked, and counted in the title; PNG."""
    done = df[df.status == "done"]
    ranked = done[np.isfinite(done[metric].astype(float))].sort_values(metric)
    best, worst = _halves(ranked, n)
    cols = max(1, len(best))  # the best half is never the smaller
    fig, axes = style.figure((4 * cols + 0.5, 8.6), nrows=2, ncols=cols, squeeze=False)
    for ax in axes.ravel():
        ax.set_visible(False)
    for row, (label, picks) in enumerate((("best", best), ("worst", worst))):
        for i, r in enumerate(picks):
            ax = axes[row, i]
            ax.set_visible(True)
            ri = routes.get((r.route_set, r.route))
            if ri is not None:
                ax.plot(*ri.route.points.T, "k-", lw=2, label="route (learned)")
            ax.plot(r.track_x, r.track_y, "-", color="tab:red" if label == "worst" else "tab:green", lw=1,
                    label=f"followed ({label})")
            ax.set_aspect("equal", "datalim")
            params = ", ".join(f"{k.removeprefix('param.')}={r[k]}" for k in r.index
                               if k.startswith("param.") and r[k] == r[k])
            release = (r.get("lateral_cm", 0), r.get("heading_deg", 0))
            how = "".join([f"{r.protocol}'s protocol" if "protocol" in r else "",
                           f", released {release[0]:g} cm {release[1]:g} deg off" if release != (0, 0) else ""])
            style.label(ax, f"{label} {i + 1} of {len(ranked)}: {r.model} on {r.route} {params}\n"
                        f"{how + '; ' if how else ''}{metric} = {r[metric]:.3g}, errors {r.errors}, seed {r.seed}",
                        "x (m)", "y (m)")
            ax.title.set_fontsize(8)
    handles = {h.get_label(): h for ax in axes.ravel() if ax.get_visible() for h in ax.get_lines()}
    unranked = len(done) - len(ranked)
    if not best:
        axes[0, 0].set_visible(True)
        style.no_data(axes[0, 0], f"no done run with a finite {metric}")
    fig.suptitle(f"best and worst runs by {metric} ({len(best)} best, {len(worst)} worst of {len(done)} done runs, "
                 "each shown once" + (f"; {unranked} without a finite {metric} not ranked" if unranked else "") + ")",
                 wrap=True)
    fig.tight_layout()
    if handles:
        fig.legend(handles=list(handles.values()), loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=3)
    return style.save(fig, path)
