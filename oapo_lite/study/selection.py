"""Eq. 9's selection tested on the engines: gated reuse against no reuse (HAPPO) and against
always-on reuse (sigma = inf), seed-paired, and, where seats share a network per type, reuse
across types against none (lambda = 1). The runs are ``grid``'s ``fig_selection_*`` figures.

The gate's sigma was fixed per env and reading before any gated run, by a rule that reads K
alone, never a return (``gate_sigma``): the median of the across-network K[i, j] at the
evaluated iterations of OAPPO runs of that reading, learner and env, to two significant digits.
On SMAX those are the committed ``cpu`` runs of Fig. 4 (seeds 0-4; the engines' gate statistic,
the mean). On HalfCheetah the ablation trains the normalised learner (``fig_mamujoco_normalize``
chose it, by the rule fixed before its runs), of which no OAPPO run was committed; there they
are the ablation's own always-on runs (seeds 10-19), trained and read before any gated run.
(HAPPO's K would not do: with nothing pulling its nets together, the normalised HAPPO's median
K is 91, where a gate at that sigma would never shut once reuse pulls the nets together.) Under
the rule the gate was open on about half of those runs' pair-iterations, so in the gated runs
it can both open and shut; ``gate_use`` measures how often it did.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from oapo_lite.envs import registry as env_registry
from oapo_lite.neural.nets import owners
from oapo_lite.study import experiments, figures, statistics, verdicts

# (env, reading) -> the figure, curve label and seeds of the OAPPO runs the rule reads
RULE_RUNS = {("smax:2s3z", "agent"): ("fig4_smax", "oappo", (0, 1, 2, 3, 4)),
             ("smax:6h_vs_8z", "agent"): ("fig4_smax", "oappo", (0, 1, 2, 3, 4)),
             ("smax:2s3z", "type"): ("fig4_smax", "oappo type", (0, 1, 2, 3, 4)),
             (figures.mujoco.HALFCHEETAH, "agent"): ("fig_selection_mamujoco", "oappo always", figures.readings.SELECTION_SEEDS)}


def across_pairs(kl: np.ndarray, owner: list[int]) -> np.ndarray:
    """The entries K[i, j] of seats on different networks (the pairs a gate decides)."""
    return np.asarray(kl)[~np.equal.outer(owner, owner)]


def gate_sigma(env: str, reading: str, quantile: float = 0.5) -> float:
    """The rule (module docstring): sigma for the gated curve of ``reading`` on ``env``; with
    ``quantile``, that quantile of the same K instead of the median (the dose-response's sigmas,
    ``figures.readings.DOSE_QUANTILES``)."""
    figure, label, seeds = RULE_RUNS[env, reading]
    values = []
    for run in figures.runs_of(figure, "cpu"):
        if run.label == label and run.cfg.env == env and run.cfg.seed in seeds:
            owner = owners(run.cfg.networks_used, env_registry.agent_types(env, run.cfg.max_steps))
            for kl in experiments.read_run(run.cfg, "cpu")["kl_matrix"].dropna():
                values.extend(across_pairs(kl, owner))
    return float(f"{np.quantile(values, quantile):.2g}")


def gate_use(df: pd.DataFrame, sigma_of: dict) -> pd.DataFrame:
    """Per env and curve, from the evaluated iterations' K: the share of across-network
    pair-iterations with K <= the curve's sigma (the gate open) and above it (shut), and M's
    mean weight on other networks' seats (``across_share``)."""
    rows = []
    for (env, label), part in df[df["kl_matrix"].notna()].groupby(["env", "label"], sort=False):
        cfg = part.iloc[0]
        owner = owners(cfg["networks"] if isinstance(cfg["networks"], str) else "agent",
                       env_registry.agent_types(env, int(cfg["max_steps"])))
        sigma = sigma_of.get((env, label), float(cfg["sigma"]))
        k = np.concatenate([across_pairs(m, owner) for m in part["kl_matrix"]]) if len(set(owner)) > 1 else np.zeros(0)
        rows.append({"env": env, "label": label, "sigma": sigma, "pair-iterations": len(k),
                     "open": float(np.mean(k <= sigma)) if len(k) else np.nan,
                     "shut": float(np.mean(k > sigma)) if len(k) else np.nan,
                     "across_share": float(part["across_share"].mean()) if "across_share" in part else np.nan})
    return pd.DataFrame(rows)


def rule_sigma(figure: str) -> dict:
    """(env, curve label) -> the rule's sigma for each reusing curve of a selection figure: the
    gated curve's own, and for the always-on curve the sigma its gate would have had."""
    return {(kw["env"], label): figures.SELECTION_SIGMA[kw["env"], "type" if label.startswith("oappo type") else "agent"]
            for label, kw in figures.get_figure(figure).curves if label != "happo"}


def summary(df: pd.DataFrame, figure: str) -> pd.DataFrame:
    """Per env and curve of a selection figure, in the figure's order: seeds, the final value by
    the figure's metric (IQM over seeds, 95% interval), and from ``gate_use`` at the rule's sigma
    the share of across-network pair-iterations with the gate open and M's weight across networks."""
    fig = figures.get_figure(figure)
    sigmas = rule_sigma(figure)
    use = gate_use(df, sigmas).set_index(["env", "label"]) if len(df) else pd.DataFrame()
    rows = []
    for env, sub in df.groupby("env", sort=False) if len(df) else []:
        ev = verdicts.Evidence(sub, metric=fig.metric)
        for label in (c for c, kw in fig.curves if kw["env"] == env and c in ev.summary.index):
            final = ev.level(label, "final")
            rows.append({"env": env, "label": label, "seeds": int(ev.summary.loc[label, "seeds"]), "final": final.point,
                         "final_low": final.low, "final_high": final.high, "sigma": sigmas.get((env, label), np.nan),
                         # no reuse: no gate to be open
                         "open": use.loc[(env, label), "open"] if (env, label) in sigmas else np.nan,
                         "across_share": use.loc[(env, label), "across_share"]})
    return pd.DataFrame(rows, columns=["env", "label", "seeds", "final", "final_low", "final_high", "sigma", "open",
                                       "across_share"])


def estimators(df: pd.DataFrame, figure: str) -> pd.DataFrame:
    """Per env and pair of a selection figure's curves trained both ways
    (``figures.readings.SAMPLED``: Algorithm 1's sampled source, Eq. 8's weights): the sampled
    curve's final value minus the weights', seed by seed (the mean over the paired seeds with
    its 95% interval, by the figure's metric); how often each reused across networks while it
    learned (the share of its evaluated iterations, as the verdict rule counts it); and what
    each and HAPPO cost: CPU seconds per 1,000 env steps, evaluations included, the median over
    the runs' own records."""
    metric, rows = figures.get_figure(figure).metric, []
    for env, sub in df.groupby("env", sort=False) if len(df) else []:
        ev = verdicts.Evidence(sub, metric=metric)
        last = sub.sort_values("step").groupby(["label", "seed"]).tail(1)
        cost = (1000 * last["cpu_s"] / last["step"]).groupby(last["label"]).median()
        for sampled, weighted in figures.readings.SAMPLED.items():
            if not {sampled, weighted} <= set(sub["label"]):
                continue
            pairs, d = verdicts.paired_difference(sub, sampled, weighted, metric.column, metric.tail)
            rows.append({"env": env, "sampled": sampled, "weights": weighted, "pairs": len(pairs),
                         "sampled minus weights": d.point, "low": d.low, "high": d.high,
                         "sampled higher": int((pairs["difference"] > 0).sum()),
                         "reused sampled": ev.summary.loc[sampled, "reusing"],
                         "reused weights": ev.summary.loc[weighted, "reusing"],
                         "CPU-s happo": cost.get("happo", np.nan), "CPU-s weights": cost[weighted],
                         "CPU-s sampled": cost[sampled]})
    return pd.DataFrame(rows)


def estimator_sentence(row: pd.Series, figure: str) -> str:
    """One line of ``estimators``'s table in words: the paired difference, read against 0, how
    often each curve reused, and what each cost against HAPPO. Where either curve reused across
    networks at fewer than ``verdicts.REUSE_PART`` of its evaluated iterations, the pair compares
    no estimator of reuse, and the line says so."""
    d = statistics.Interval(row["sampled minus weights"], row["low"], row["high"])
    side = ("" if np.isnan(d.low) else "wholly above 0; " if d.low > 0 else "wholly below 0; " if d.high < 0 else
            "interval across 0; ")
    sampled, weights = (row[f"CPU-s {way}"] / row["CPU-s happo"] for way in ("sampled", "weights"))
    few = [way for way in ("sampled", "weights") if row[f"reused {way}"] < verdicts.REUSE_PART]
    hardly = (f"; {' and '.join({'sampled': 'the sampled curve', 'weights': 'the weights curve'}[w] for w in few)} "
              f"reused at below {verdicts.REUSE_PART:.0%}, so the pair compares no estimator of reuse" if few else "")
    return (f"{row['env']}, {row['weights']}: Algorithm 1's sampled source minus Eq. 8's weights, "
            f"{figures.get_figure(figure).metric.final} paired over {row['pairs']} seeds: {d.fmt()} ({side}sampled "
            f"higher on {row['sampled higher']} of {row['pairs']}); reused across networks at "
            f"{row['reused sampled']:.1%} of the evaluated iterations while learning sampled, "
            f"{row['reused weights']:.1%} with the weights{hardly}; CPU per env step "
            f"{sampled:.2f}x HAPPO's sampled, {weights:.2f}x with the weights")
