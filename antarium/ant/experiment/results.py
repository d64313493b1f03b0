"""Results of an experiment: one table with every metric per run, a summary per condition with bootstrap
confidence intervals, and pictures (metric vs parameter; paths of the worst and best runs)."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

from antarium.ant.experiment.runner import RUNS_DIR
from antarium.plots.experiments import plot_metric_vs_parameter, plot_worst_and_best

#: bootstrap resamples of the summary's confidence intervals, and their level
BOOTSTRAP = 2000
CI_LEVEL = 0.95
#: the columns that name a condition (what repetitions over routes and seeds share)
CONDITION = ["world", "route_set", "model", "protocol", "lateral_cm", "heading_deg"]


def load_results(out: str | Path, run_ids: Iterable[str] | None = None):
    """The rows under `out/runs/` as one pandas DataFrame (done and failed runs; see column `status`): those of
    `run_ids` (a spec's runs; the others, of specs run into `out` before, are left out), or every row. Integer and
    boolean columns (errors, decisions, arrived, ...) are pandas' nullable Int64 and boolean, NA in a failed run's
    row, which has no metrics; a `param.` column is as pandas reads it: float with NaN where a model lacks the
    parameter."""
    import pandas as pd
    import pyarrow as pa
    import pyarrow.parquet as pq

    files = sorted((Path(out) / RUNS_DIR).glob("*.parquet"))
    if run_ids is not None:
        wanted = set(run_ids)
        files = [f for f in files if f.stem in wanted]
    if not files:
        raise FileNotFoundError(f"no run results under {Path(out) / RUNS_DIR}"
                                + (" of this spec's runs" if run_ids is not None else ""))
    table = pa.concat_tables([pq.read_table(f) for f in files], promote_options="permissive")
    nullable = {pa.int64(): pd.Int64Dtype(), pa.bool_(): pd.BooleanDtype()}
    return table.to_pandas().astype({f.name: nullable[f.type] for f in table.schema
                                     if f.type in nullable and not f.name.startswith("param.")})


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
    """Per condition (world, route set, model, its parameters, release, protocol): runs, failed, and per metric the
    mean over routes and seeds with its bootstrap 95 % interval (columns `<metric>`, `<metric>_lo`, `<metric>_hi`)."""
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


def report(out: str | Path, routes: dict, metrics, run_ids: Iterable[str] | None = None) -> str:
    """Write `results.parquet` (every run of `run_ids`, or every run under `out/runs/`), `summary.csv` /
    `summary.md` and the pictures into `out`; returns the summary as markdown, after a line saying how many of
    the runs have a row and how many rows of other specs (other run ids) sit in `out/runs/`, not summarised."""
    out = Path(out)
    df = load_results(out, run_ids)
    done = int((df.status == "done").sum())
    counts = f"{done} done, {len(df) - done} failed"
    if run_ids is None:
        head = f"{len(df)} runs: {counts}"
    else:
        ids = set(run_ids)
        others = sum(1 for f in (out / RUNS_DIR).glob("*.parquet") if f.stem not in ids)
        head = (f"{len(ids)} runs of this spec: {counts}, {len(ids) - len(df)} without a result yet"
                + (f"; {others} rows of other specs in {out / RUNS_DIR} not summarised" if others else ""))
    df.to_parquet(out / "results.parquet", index=False)
    table = summary(df, tuple(m for m in metrics if m in df.columns) or ("errors",))
    table.to_csv(out / "summary.csv", index=False)
    text = head + "\n\n" + (table.to_markdown(index=False) if _has_tabulate() else table.to_string(index=False))
    (out / "summary.md").write_text(text + "\n")
    if (df.status == "done").any():
        plot_worst_and_best(df, routes, out / "worst_and_best_paths.png")
        for param in (c for c in df.columns if c.startswith("param.")):
            if df[param].nunique() > 1:
                for metric in ("errors", "lateral_median_m"):
                    name = f"{metric}_vs_{param.removeprefix('param.').replace('.', '_')}.png"
                    plot_metric_vs_parameter(df, metric, param, out / name, ci=bootstrap_ci,
                                             conditions=CONDITION)
    return text


def _has_tabulate() -> bool:
    try:
        import tabulate  # noqa: F401
    except ImportError:
        return False
    return True
