"""The study's tables beside the verdicts: how much each curve reused (over its evaluated
iterations, and across networks alone) and what a tuning sweep chose. They read the same runs
as ``verdicts``, whose decision rule they leave alone."""
from __future__ import annotations

import numpy as np
import pandas as pd

from oapo_lite.reuse import peer_share
from oapo_lite.store import read_arrays
from oapo_lite.study.catalogue.metrics import Metric
from oapo_lite.study.judge.evidence import per_run
from oapo_lite.study.judge.statistics import iqm
from oapo_lite.study.runs import experiments


def reuse_per_run(df: pd.DataFrame) -> pd.DataFrame:
    """One row per run, from the reuse matrix M of its evaluated iterations: how many there are,
    the share of them in which some learner gave another agent's experience a positive weight
    (``reusing``), the mean peer share (M's off-diagonal mass per learner) over them, and the
    last step at which one did (NaN: never). ``all_iterations``: the share over every iteration,
    where the run recorded it (``iterations_reusing``, at its last evaluation), else NaN. Runs
    without a reuse matrix (SEAC, SePS) have no row."""
    columns = ["label", "seed", "evaluations", "reusing", "mean_peer_share", "last_reuse_step", "all_iterations"]
    rows = []
    groups = df.sort_values("step", kind="stable").groupby(["label", "seed"], sort=False) if len(df) else []
    for (label, seed), run in groups:
        has_m = run[run["reuse_matrix"].notna()] if "reuse_matrix" in run else run.iloc[:0]
        if has_m.empty:  # SEAC, SePS: no reuse matrix
            continue
        steps, share = has_m["step"].to_numpy(float), has_m["reuse_matrix"].map(peer_share).to_numpy(float)
        reusing = steps[share > 0]
        every = run["iterations_reusing"].iloc[-1] if "iterations_reusing" in run else np.nan
        rows.append({"label": label, "seed": seed, "evaluations": len(steps), "reusing": float(np.mean(share > 0)),
                     "mean_peer_share": float(share.mean()),
                     "last_reuse_step": float(reusing.max()) if len(reusing) else np.nan, "all_iterations": float(every)})
    return pd.DataFrame(rows, columns=columns)


def reuse_summary(df: pd.DataFrame) -> pd.DataFrame:
    """``reuse_per_run`` per label: seeds, evaluated iterations per run, the share of them that
    reused and the mean peer share (means over seeds), the last step any seed reused, and the
    share over every iteration where the runs recorded it."""
    return reuse_per_run(df).groupby("label", sort=False).agg(
        seeds=("seed", "size"), evaluations=("evaluations", "first"), reusing=("reusing", "mean"),
        mean_peer_share=("mean_peer_share", "mean"), last_reuse_step=("last_reuse_step", "max"),
        all_iterations=("all_iterations", "mean"))


def reuse_table(df: pd.DataFrame, metric: Metric) -> pd.DataFrame:
    """Per env and label: seeds; the share of every iteration with any peer weight
    (``all_iterations``, means over the runs that recorded it; seats that share a network always
    weigh each other); at the evaluated iterations, the mean peer share, and, across networks
    alone (``peer_share`` with each row's ``owner``, the network of each seat as the run recorded
    it: the reuse Eq. 9's gate decided), the share of them with any weight (``across_reusing``)
    and the mean share (``mean_across_nets``); and the final value by ``metric`` (a run's mean
    over its final window), as mean and standard deviation over seeds. Runs without a reuse
    matrix (SEAC, SePS) have no row."""
    parts = []
    if "reuse_matrix" not in df:  # no run recorded M (or no run at all)
        return pd.DataFrame()
    lacking = [c for c in ("env", "label", "seed", "step", "owner", metric.column) if c not in df]
    if lacking:
        raise ValueError(f"the runs lack the columns {lacking} (experiments.load_figure's rows have them)")
    for env, part in with_across_share(df).groupby("env", sort=False):
        final = per_run(part, metric).groupby("label", sort=False)["final"]
        per_seed = part["across_share"].groupby([part["label"], part["seed"]], sort=False)
        parts.append(reuse_summary(part)[["seeds", "all_iterations", "mean_peer_share"]]
                     .join(per_seed.apply(lambda x: (x > 0).mean()).groupby(level=0, sort=False).mean()
                           .rename("across_reusing"))
                     .join(per_seed.mean().groupby(level=0, sort=False).mean().rename("mean_across_nets"))
                     .join(final.mean().rename("final")).join(final.std().rename("final_std"))
                     .assign(env=env).set_index("env", append=True).swaplevel())
    return pd.concat(parts) if parts else pd.DataFrame()


def with_across_share(df: pd.DataFrame) -> pd.DataFrame:
    """The rows of ``df`` that hold a reuse matrix, with ``across_share``: M's weight on the seats
    of other networks (``peer_share`` with the row's ``owner``), for runs trained before the
    results recorded it."""
    df = read_arrays(df, ("reuse_matrix", "owner")).dropna(subset=["reuse_matrix"])
    return df.assign(across_share=[peer_share(m, list(np.asarray(o, int))) for m, o in zip(df["reuse_matrix"],
                                                                                           df["owner"])])


def readings_table(figure: str, budget: str, metric: Metric) -> pd.DataFrame:
    """``reuse_table`` of a readings figure's runs on disk at ``budget`` (empty where it has none)."""
    runs = experiments.read_figure(figure, budget, skip_missing=True)[0]
    return pd.DataFrame() if runs.empty else reuse_table(runs, metric)


def sweep_table(df: pd.DataFrame, family: dict, metric: Metric, tie: float = 0.02) -> pd.DataFrame:
    """A tuning sweep, one row per setting (curve label): its ``family[label]``, seeds, final
    value (mean over seeds of each run's last fifth of evaluations) and env steps to the
    metric's threshold (IQM over seeds, a run that never gets there counted at its end); and
    ``chosen`` by the sweep's rule: per family the highest final value, where settings within
    ``tie`` of it tie and the fewest steps among them wins."""
    runs = per_run(df, Metric(metric.column, metric.threshold, metric.floor, metric.reach, metric.final, tail=0.2))
    t = runs.groupby("label", sort=False).agg(seeds=("seed", "size"), final=("final", "mean"),
                                              steps=("steps_to_threshold", lambda s: float(iqm(s.to_numpy()))))
    t.insert(0, "family", [family[label] for label in t.index])
    best = t.groupby("family")["final"].transform("max")
    contenders = t[t["final"] >= best - tie]
    t["chosen"] = t.index.isin(contenders.sort_values("steps", kind="stable").groupby("family").head(1).index)
    return t
