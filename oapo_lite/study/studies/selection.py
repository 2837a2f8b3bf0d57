"""Eq. 9's selection tested on the engines: gated reuse against no reuse (HAPPO) and against
always-on reuse (sigma = inf), seed-paired, and, where seats share a network per type, reuse
across types against none (lambda = 1); and the dose-response, the gated curve at several sigmas
between the two ends (``dose``). The runs are the catalogue's ``fig_selection_*`` and
``fig_dose_*`` figures; every seat-to-network map is the one each run recorded.

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

from oapo_lite.study.catalogue import figures
from oapo_lite.study.catalogue.metrics import Metric
from oapo_lite.study.judge.evidence import Evidence
from oapo_lite.study.judge.statistics import iqm
from oapo_lite.study.runs import experiments

# (env, reading) -> the figure, curve label and seeds of the OAPPO runs the rule reads
RULE_RUNS = {("smax:2s3z", "agent"): ("fig4_smax", "oappo", (0, 1, 2, 3, 4)),
             ("smax:6h_vs_8z", "agent"): ("fig4_smax", "oappo", (0, 1, 2, 3, 4)),
             ("smax:2s3z", "type"): ("fig4_smax", "oappo type", (0, 1, 2, 3, 4)),
             (figures.mujoco.HALFCHEETAH, "agent"): ("fig_selection_mamujoco", "oappo always",
                                                     figures.readings.SELECTION_SEEDS),
             (figures.mujoco.ANT, "agent"): ("fig_ant_learner", "oappo always", (0, 1, 2))}


def across_pairs(kl: np.ndarray, owner) -> np.ndarray:
    """The entries K[i, j] of seats on different networks (the pairs a gate decides)."""
    owner = np.asarray(owner, int)
    return np.asarray(kl)[~np.equal.outer(owner, owner)]


def across_k(rows: pd.DataFrame) -> np.ndarray:
    """Every across-network K[i, j] at the evaluated iterations of ``rows`` (each row's K read
    against the owner map it recorded)."""
    rows = rows[rows["kl_matrix"].notna()]
    parts = [across_pairs(k, o) for k, o in zip(rows["kl_matrix"], rows["owner"])]
    return np.concatenate(parts) if parts else np.zeros(0)


def gate_sigma(env: str, reading: str, quantile: float = 0.5) -> float:
    """The rule (module docstring): sigma for the gated curve of ``reading`` on ``env``; with
    ``quantile``, that quantile of the same K instead of the median (the dose-response's sigmas,
    ``figures.readings.DOSE_QUANTILES``)."""
    figure, label, seeds = RULE_RUNS[env, reading]
    values = [across_k(experiments.read_run(run.cfg, "cpu")) for run in figures.runs_of(figure, "cpu")
              if run.label == label and run.cfg.env == env and run.cfg.seed in seeds]
    return float(f"{np.quantile(np.concatenate(values), quantile):.2g}")


def gate_use(df: pd.DataFrame, sigma_of: dict) -> pd.DataFrame:
    """Per env and curve, from the evaluated iterations' K: the share of across-network
    pair-iterations with K <= the curve's sigma (the gate open) and above it (shut), and M's
    mean weight on other networks' seats (``across_share``)."""
    rows = []
    for (env, label), part in df[df["kl_matrix"].notna()].groupby(["env", "label"], sort=False):
        sigma = sigma_of.get((env, label), float(part["sigma"].iloc[0]))
        k = across_k(part)
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
        ev = Evidence(sub, fig.metric)
        for label in (c for c, kw in fig.curves if kw["env"] == env and c in ev.labels):
            final = ev.level(label, "final")
            rows.append({"env": env, "label": label, "seeds": int(ev.summary.loc[label, "seeds"]), "final": final.point,
                         "final_low": final.low, "final_high": final.high, "sigma": sigmas.get((env, label), np.nan),
                         # no reuse: no gate to be open
                         "open": use.loc[(env, label), "open"] if (env, label) in sigmas else np.nan,
                         "across_share": use.loc[(env, label), "across_share"]})
    return pd.DataFrame(rows, columns=["env", "label", "seeds", "final", "final_low", "final_high", "sigma", "open",
                                       "across_share"])


def dose(df: pd.DataFrame, figure: str) -> pd.DataFrame:
    """The dose-response of a ``fig_dose_*`` figure, one row per curve from no reuse (HAPPO,
    sigma 0: the gate never open) through the gated curves to always-on (sigma inf): sigma, the
    share of across-network pair-iterations with the gate open, M's weight across networks, the
    final value and the steps to the metric's level (IQM over seeds with 95% intervals), and the
    seed-paired final difference against each end (IQM of the differences, its interval and on
    how many seeds the curve was higher)."""
    fig = figures.get_figure(figure)
    ev = Evidence(df, fig.metric)
    sigma = {label: float(kw.get("sigma", 0.0)) if kw.get("algo", fig.common.get("algo")) != "happo" else 0.0
             for label, kw in fig.curves}
    use = gate_use(df, {(e, label): sigma[label] for e, label in df[["env", "label"]].drop_duplicates().itertuples(
        index=False)}).set_index("label") if "kl_matrix" in df else pd.DataFrame()
    rows = []
    for label, _ in fig.curves:
        final, speed = ev.level(label, "final"), ev.level(label, "steps")
        row = {"label": label, "sigma": sigma[label], "seeds": int(ev.summary.loc[label, "seeds"]),
               "open": use["open"].get(label, np.nan) if len(use) else np.nan,
               "across_share": use["across_share"].get(label, np.nan) if len(use) else np.nan,
               "final": final.point, "final_low": final.low, "final_high": final.high, "steps": speed.point,
               "steps_low": speed.low, "steps_high": speed.high,
               "reached": int(ev.summary.loc[label, "reached"])}
        for end, name in (("happo", "never"), ("oappo always", "always")):
            if label != end:
                d, pairs = ev.paired(label, end), ev.pairs(label, end)
                row |= {f"vs {name}": d.point, f"vs {name} low": d.low, f"vs {name} high": d.high,
                        f"higher than {name}": int((pairs["difference"] > 0).sum()), "pairs": len(pairs)}
        rows.append(row)
    return pd.DataFrame(rows)


def cpu_to_level(df: pd.DataFrame, metric: Metric, level: float) -> pd.Series:
    """Per curve: the CPU seconds its runs had spent, by their own cost records, when the curve's
    IQM over seeds first reached ``level`` of ``metric`` (the median over seeds of the runs' CPU
    seconds at that evaluation; NaN: the IQM never got there)."""
    out = {}
    for label, part in df.groupby("label", sort=False):
        values = part.pivot(index="step", columns="seed", values=metric.column)
        cpu = part.pivot(index="step", columns="seed", values="cpu_s")
        curve = pd.Series(iqm(values.to_numpy(float), axis=1), index=values.index)
        hit = curve.index[curve >= level]
        out[label] = float(cpu.loc[hit[0]].median()) if len(hit) else np.nan
    return pd.Series(out, name=f"CPU-s to {metric.reach.format(level)}")


def estimators(df: pd.DataFrame, figure: str) -> pd.DataFrame:
    """Per env and pair of a selection figure's curves trained both ways
    (``figures.readings.SAMPLED``: Algorithm 1's sampled source, Eq. 8's weights): the sampled
    curve's final value minus the weights', seed by seed (the IQM over the paired seeds with its
    95% interval, by the figure's metric); how often each reused across networks while it learned
    (``judge.evidence``'s reading); and what each and HAPPO cost: CPU seconds per 1,000 env steps,
    evaluations included, the median over the runs' own records."""
    metric, rows = figures.get_figure(figure).metric, []
    for env, sub in df.groupby("env", sort=False) if len(df) else []:
        ev = Evidence(sub, metric)
        last = sub.sort_values("step").groupby(["label", "seed"]).tail(1)
        cost = (1000 * last["cpu_s"] / last["step"]).groupby(last["label"]).median()
        for sampled, weighted in figures.readings.SAMPLED.items():
            if not {sampled, weighted} <= set(ev.labels):
                continue
            pairs, d = ev.pairs(sampled, weighted), ev.paired(sampled, weighted)
            rows.append({"env": env, "sampled": sampled, "weights": weighted, "pairs": len(pairs),
                         "sampled minus weights": d.point, "low": d.low, "high": d.high,
                         "sampled higher": int((pairs["difference"] > 0).sum()),
                         "reused sampled": ev.summary.loc[sampled, "reusing"],
                         "reused weights": ev.summary.loc[weighted, "reusing"],
                         "CPU-s happo": cost.get("happo", np.nan), "CPU-s weights": cost[weighted],
                         "CPU-s sampled": cost[sampled]})
    return pd.DataFrame(rows)


def draw_probe() -> dict | None:
    """Why Algorithm 1's draw failed on 2s3z, from seed 10's probed runs
    (``benchmarks/draw_collapse.py``, kept in ``figures/data/draw_collapse/``): in the drawn run,
    the share of learner updates that drew a peer (``peer``) and their share of the distance the
    acting policies moved (``carried``: own-seat KL after the update); the win rate of the last
    11 evaluations of the drawn run (``sampled``) and of its control that keeps the learner's own
    seat beside the drawn peer (``anchored``). None where the probe's files are not on disk."""
    folder = experiments.data_dir("cpu") / "draw_collapse"
    paths = {key: folder / f"{key}_{kind}.csv" for key in ("sampled", "anchored") for kind in ("updates", "rows")}
    if not all(p.exists() for p in paths.values()):
        return None
    up = pd.read_csv(folder / "sampled_updates.csv")
    last = {key: float(pd.read_csv(folder / f"{key}_rows.csv")["eval_success"].iloc[-11:].mean())
            for key in ("sampled", "anchored")}
    return {"peer": float(up["peer"].mean()), "carried": float(up.loc[up["peer"], "own_kl"].sum() / up["own_kl"].sum()),
            **last}
