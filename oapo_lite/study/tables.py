"""The study's tables beside the verdicts: how much each curve reused (over its evaluated
iterations, and across networks alone) and what a tuning sweep chose. They read the same runs
as ``verdicts``, whose decision rule they leave alone."""
from __future__ import annotations

import numpy as np
import pandas as pd

from oapo_lite.envs import registry as env_registry
from oapo_lite.neural.nets import owners
from oapo_lite.reuse import peer_share
from oapo_lite.store import read_arrays
from oapo_lite.study import experiments, verdicts
from oapo_lite.study.figures import figure_runs
from oapo_lite.study.statistics import iqm


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
        steps, share = verdicts.peer_shares(run)
        if not len(steps):  # SEAC, SePS: no reuse matrix
            continue
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


def reuse_table(df: pd.DataFrame, y: str, owners: dict, tail: float = 0.2) -> pd.DataFrame:
    """Per env and label: seeds; the share of every iteration with any peer
    weight (``all_iterations``, means over the runs that recorded it; seats that share a
    network always weigh each other); at the evaluated iterations, the mean peer share, and,
    across networks alone (``peer_share`` with ``owners[(env, label)]``, the network of each
    seat: the reuse Eq. 9's gate decided), the share of them with any weight
    (``across_reusing``) and the mean share (``mean_across_nets``); and the final ``y``, a run's
    mean over the last ``tail`` of its evaluation points, as mean and standard deviation over
    seeds. Runs without a reuse matrix (SEAC, SePS) have no row."""
    parts = []
    if "reuse_matrix" not in df:  # no run recorded M (or no run at all)
        return pd.DataFrame()
    lacking = [c for c in ("env", "label", "seed", "step", y) if c not in df]
    if lacking:
        raise ValueError(f"the runs lack the columns {lacking} (experiments.load_figure's rows have them)")
    unknown = sorted({(e, label) for e, label in zip(df["env"], df["label"])} - set(owners))
    if unknown:
        raise ValueError(f"owners names no network of each seat for {unknown} (seat_networks gives them)")
    for env, part in with_across_share(df, owners).groupby("env", sort=False):
        final = verdicts.per_run(part, tail=tail, y=y).groupby("label", sort=False)["final"]
        per_seed = part["across_share"].groupby([part["label"], part["seed"]], sort=False)
        parts.append(reuse_summary(part)[["seeds", "all_iterations", "mean_peer_share"]]
                     .join(per_seed.apply(lambda x: (x > 0).mean()).groupby(level=0, sort=False).mean()
                           .rename("across_reusing"))
                     .join(per_seed.mean().groupby(level=0, sort=False).mean().rename("mean_across_nets"))
                     .join(final.mean().rename("final")).join(final.std().rename("final_std"))
                     .assign(env=env).set_index("env", append=True).swaplevel())
    return pd.concat(parts) if parts else pd.DataFrame()


def with_across_share(df: pd.DataFrame, owners: dict) -> pd.DataFrame:
    """The rows of ``df`` that hold a reuse matrix, with ``across_share``: M's weight on the seats
    of other networks (``peer_share`` with ``owners[(env, label)]``), for runs trained before the
    results recorded it."""
    df = read_arrays(df, ("reuse_matrix",)).dropna(subset=["reuse_matrix"])
    return df.assign(across_share=[peer_share(m, owners[env, label])
                                   for m, env, label in zip(df["reuse_matrix"], df["env"], df["label"])])


def readings_table(figure: str, budget: str, y: str, tail: float = 0.2) -> pd.DataFrame:
    """``reuse_table`` of a readings figure's runs on disk at ``budget`` (empty where it has none),
    each curve's seats mapped to their networks by ``seat_networks``."""
    runs = experiments.load_figure(figure, budget, skip_missing=True)
    return pd.DataFrame() if runs.empty else reuse_table(runs, y, seat_networks(figure, budget), tail)


def sweep_table(df: pd.DataFrame, family: dict, metric: verdicts.Metric, tie: float = 0.02) -> pd.DataFrame:
    """A tuning sweep, one row per setting (curve label): its ``family[label]``, seeds, final
    value (mean over seeds of each run's last fifth of evaluations) and env steps to the
    metric's threshold (IQM over seeds, a run that never gets there counted at its end); and
    ``chosen`` by the sweep's rule: per family the highest final value, where settings within
    ``tie`` of it tie and the fewest steps among them wins."""
    runs = verdicts.per_run(df, metric.threshold, tail=0.2, y=metric.column)
    t = runs.groupby("label", sort=False).agg(seeds=("seed", "size"), final=("final", "mean"),
                                              steps=("steps_to_threshold", lambda s: float(iqm(s.to_numpy()))))
    t.insert(0, "family", [family[label] for label in t.index])
    best = t.groupby("family")["final"].transform("max")
    contenders = t[t["final"] >= best - tie]
    t["chosen"] = t.index.isin(contenders.sort_values("steps", kind="stable").groupby("family").head(1).index)
    return t


def seat_networks(figure: str, budget: str) -> dict[tuple[str, object], list[int]]:
    """(env, curve label) -> the network of each seat in that curve's runs (``nets.owners``), from
    each env's agent types (``registry.agent_types``)."""
    types, out = {}, {}
    for label, cfg in figure_runs(figure, budget):
        if cfg.env not in types:
            types[cfg.env] = env_registry.agent_types(cfg.env, cfg.max_steps)
        out[cfg.env, label] = owners(cfg.networks_used, types[cfg.env])
    return out
