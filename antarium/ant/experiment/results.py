"""Results of an experiment: one table with every metric per run, a summary per condition with bootstrap
confidence intervals, and pictures (metric vs parameter; paths of the worst and best runs)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from antarium.ant.experiment.runner import RUNS_DIR

#: bootstrap resamples of the summary's confidence intervals, and their level
BOOTSTRAP = 2000
CI_LEVEL = 0.95
#: the columns that name a condition (what repetitions over routes and seeds share)
CONDITION = ["world", "model", "protocol", "lateral_cm", "heading_deg"]


def load_results(out: str | Path):
    """Every run's row under `out/runs/` as one pandas DataFrame (done and failed runs; see column `status`)."""
    import pandas as pd

    files = sorted((Path(out) / RUNS_DIR).glob("*.parquet"))
    if not files:
        raise FileNotFoundError(f"no run results under {Path(out) / RUNS_DIR}")
    return pd.concat([pd.read_parquet(f) for f in files], ignore_index=True)


def bootstrap_ci(values, level: float = CI_LEVEL, n: int = BOOTSTRAP, seed: int = 0) -> tuple[float, float]:
    """Percentile bootstrap interval of the mean of finite `values` (nan, nan when fewer than two)."""
    v = np.asarray(values, np.float64)
    v = v[np.isfinite(v)]
    if v.size < 2:
        return float("nan"), float("nan")
    rng = np.random.default_rng(seed)
    means = v[rng.integers(0, v.size, (n, v.size))].mean(axis=1)
    lo, hi = np.quantile(means, [(1 - level) / 2, (1 + level) / 2])
    return float(lo), float(hi)


def summary(df, metrics=("errors", "lateral_median_m", "angular_median_deg", "arrived", "ms_per_decision_model")):
    """Per condition (world, model, its parameters, release, protocol): runs, failed, and per metric the mean
    over routes and seeds with its bootstrap 95 % interval (columns `<metric>`, `<metric>_lo`, `<metric>_hi`)."""
    import pandas as pd

    params = [c for c in df.columns if c.startswith("param.")]
    keys = CONDITION + params
    rows = []
    for key, group in df.groupby(keys, dropna=False, sort=True):
        done = group[group.status == "done"]
        row = dict(zip(keys, key, strict=True))
        row.update(runs=len(group), failed=int((group.status != "done").sum()))
        for m in metrics:
            vals = done[m].astype(float) if m in done else pd.Series(dtype=float)
            lo, hi = bootstrap_ci(vals)
            row.update({m: float(vals.mean()) if len(vals) else float("nan"), f"{m}_lo": lo, f"{m}_hi": hi})
        rows.append(row)
    return pd.DataFrame(rows)


def plot_metric_vs_parameter(df, metric: str, param: str, path: str | Path) -> Path:
    """Mean of `metric` (95 % bootstrap interval) against parameter `param` (a `param.*` column), one line per
    model and protocol."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    done = df[(df.status == "done") & df[param].notna()]
    fig, ax = plt.subplots(figsize=(6, 4))
    for (model, protocol), g in done.groupby(["model", "protocol"]):
        xs = sorted(g[param].unique())
        means = [g.loc[g[param] == x, metric].astype(float).mean() for x in xs]
        cis = [bootstrap_ci(g.loc[g[param] == x, metric].astype(float)) for x in xs]
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


def report(out: str | Path, routes: dict, metrics) -> str:
    """Write `results.parquet` (every run), `summary.csv` / `summary.md` and the pictures into `out`; returns the
    summary as markdown."""
    out = Path(out)
    df = load_results(out)
    df.to_parquet(out / "results.parquet", index=False)
    table = summary(df, tuple(m for m in metrics if m in df.columns) or ("errors",))
    table.to_csv(out / "summary.csv", index=False)
    text = table.to_markdown(index=False) if _has_tabulate() else table.to_string(index=False)
    (out / "summary.md").write_text(text + "\n")
    if (df.status == "done").any():
        plot_worst_and_best(df, routes, out / "worst_and_best_paths.png")
        for param in (c for c in df.columns if c.startswith("param.")):
            if df[param].nunique() > 1:
                for metric in ("errors", "lateral_median_m"):
                    name = f"{metric}_vs_{param.removeprefix('param.').replace('.', '_')}.png"
                    plot_metric_vs_parameter(df, metric, param, out / name)
    return text


def _has_tabulate() -> bool:
    try:
        import tabulate  # noqa: F401
    except ImportError:
        return False
    return True
