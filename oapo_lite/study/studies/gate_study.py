"""The gate-statistic study: which statistic of the per-observation KL should Eq. 9's
gate compare with sigma?

HAPPO (no reuse, so its policies drift apart as they would without the gate's pull) is trained
on SMAX 3m, 2s3z, 6h_vs_8z and HalfCheetah 2x3 at the configs of Fig. 4's and the early-reuse
figure's ``cpu`` budgets; at every iteration the same per-observation KLs
(``ppo_family.pairwise_distances``) are reduced by each statistic of ``reuse.KL_REDUCES``. One CSV
per run goes to ``figures/data/gate_statistic/``, its config and git revision in a JSON beside
it (``benchmarks/gate_statistic.py`` trains what is missing). ``summary`` gives, per env,
statistic and sigma:

- ``any open``: the share of iterations in which some learner has a peer within sigma (the
  share of iterations an OAPPO run would reuse in, had its nets followed HAPPO's path);
- ``last open``: the last env step at which that happened;
- ``open``: the share of (iteration, learner, peer) within sigma (the ablation's gate-open share,
  ``selection.gate_use``: every peer of a HAPPO seat is on another network);
- ``auc`` (maps with two types of seat): the probability that a same-type pair is nearer than a
  cross-type pair of the same iteration, over every iteration (0.5: the distance does not tell
  role partners apart).

The rule that chooses the engine statistic (``choose``) was fixed before any run, and reads K
alone, never a win rate or return: at the paper's sigma = 0.1, a statistic must (1) let the gate
operate, ``any open`` >= 0.25 on every env, and (2) still gate, ``open`` <= 0.9 on every env;
among those, the largest ``auc`` on 2s3z wins. If none passes both, the one passing (2) with the
largest smallest ``any open`` wins.
"""
from __future__ import annotations

import dataclasses
import json
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from oapo_lite import reuse
from oapo_lite.neural.config import TrainConfig
from oapo_lite.neural.learner import Update
from oapo_lite.neural.rollout import make_env
from oapo_lite.neural.runstate import git_revision
from oapo_lite.neural.train import train
from oapo_lite.store import atomic_write, regular_file, write_frame
from oapo_lite.study.catalogue import figures
from oapo_lite.study.runs import experiments
from oapo_lite.study.judge.evidence import REUSE_PART

DATA = experiments.data_dir("cpu") / "gate_statistic"
ENVS = ("smax:3m", "smax:2s3z", "smax:6h_vs_8z", figures.mujoco.HALFCHEETAH)
SIGMA = TrainConfig.sigma  # the paper's, where the rule is read
MIN_ANY_OPEN, MAX_OPEN = REUSE_PART, 0.9  # a gate operates as the verdicts read it; it still gates


def happo_config(env: str, seed: int) -> TrainConfig:
    """HAPPO's config on ``env`` at the ``cpu`` budget of the figure that runs it."""
    figure = "fig_early_reuse" if env == figures.mujoco.HALFCHEETAH else "fig4_smax"
    for run in figures.runs_of(figure, "cpu"):
        if run.cfg.algo == "happo" and run.cfg.env == env:
            return dataclasses.replace(run.cfg, seed=seed)
    raise ValueError(f"no HAPPO run of {figure} on {env}")


def measure(cfg: TrainConfig) -> pd.DataFrame:
    """Train ``cfg`` and return K under every statistic at every iteration, one row per
    (iteration, learner, peer)."""
    rows, types = [], make_env(cfg, 1, seed=0).agent_types

    def record(iteration: int, update: Update) -> None:
        kl, active = update.observed["pairwise_kl"]
        K = {s: reuse.reduce_kl(kl, s, active) for s in reuse.KL_REDUCES}
        for i, j in zip(*np.nonzero(~np.eye(len(kl), dtype=bool))):
            rows.append({"iteration": iteration, "step": iteration * cfg.iteration_steps, "learner": i, "peer": j,
                         "same_kind": types[i] == types[j], **{s: K[s][i, j] for s in K}})

    record.wants = frozenset({"pairwise_kl"})
    with tempfile.TemporaryDirectory() as tmp:
        train(cfg, tmp, resume=False, progress=False, observer=record)
    return pd.DataFrame(rows).assign(env=cfg.env, seed=cfg.seed)


def summary(df: pd.DataFrame, sigmas=figures.mazes.SIGMAS) -> pd.DataFrame:
    """Per env, statistic and sigma: any open, last open, open, auc (see the module docstring),
    each a mean over the seeds on disk."""
    out = []
    for (env, seed), run in df.groupby(["env", "seed"]):
        steps = run.groupby("iteration")["step"].first()
        for stat in reuse.KL_REDUCES:
            nearest = run.groupby("iteration")[stat].min()  # the nearest pair of each iteration
            separation = kind_auc(run, stat) if run["same_kind"].any() and (~run["same_kind"]).any() else np.nan
            for sigma in sigmas:
                open_its = nearest.index[nearest <= sigma]
                out.append({"env": env, "seed": seed, "statistic": stat, "sigma": sigma,
                            "any open": len(open_its) / len(steps), "open": float((run[stat] <= sigma).mean()),
                            "last open": int(steps[open_its].max()) if len(open_its) else 0,
                            "auc": separation})
    return pd.DataFrame(out).groupby(["env", "statistic", "sigma"]).mean(numeric_only=True).drop(columns="seed")


def kind_auc(run: pd.DataFrame, stat: str) -> float:
    """P(a same-type pair's K < a cross-type pair's K of the same iteration), ties counted half."""
    wins = total = 0.0
    for _, it in run.groupby("iteration"):
        same, cross = it.loc[it["same_kind"], stat].to_numpy(), it.loc[~it["same_kind"], stat].to_numpy()
        diff = same[:, None] - cross[None, :]
        wins += (diff < 0).sum() + 0.5 * (diff == 0).sum()
        total += diff.size
    return wins / total


def choose(table: pd.DataFrame) -> tuple[str, str]:
    """The rule of the module docstring, at sigma = ``SIGMA``: (statistic, why)."""
    at = table.xs(SIGMA, level="sigma")
    smallest_open = at["any open"].groupby("statistic").min()
    largest_open = at["open"].groupby("statistic").max()
    auc = at["auc"].xs("smax:2s3z", level="env") if "smax:2s3z" in at.index.get_level_values("env") else None
    gates = largest_open[largest_open <= MAX_OPEN].index
    both = [s for s in gates if smallest_open[s] >= MIN_ANY_OPEN]
    if both:
        best = max(both, key=lambda s: -np.inf if auc is None else auc[s])
        return best, (f"passes both conditions ({', '.join(both)} do); the largest 2s3z auc "
                      f"{'n/a' if auc is None else f'{auc[best]:.2f}'}")
    if len(gates):
        best = max(gates, key=lambda s: smallest_open[s])
        return best, f"none keeps the gate open in {MIN_ANY_OPEN:.0%} of iterations everywhere; the largest smallest any-open share"
    return "max", "no statistic still gates (open <= 0.9 everywhere fails for all): the paper's max is kept"


def run(envs=ENVS, seeds=(0, 1, 2)) -> None:
    """Train and record every (env, seed) not yet in ``DATA``."""
    for env in envs:
        for seed in seeds:
            cfg = happo_config(env, seed)
            path = DATA / f"{cfg.run_id()}.csv"
            if not path.exists():
                print(f"training {env} seed {seed} ...", flush=True)
                record = json.dumps({"config": cfg.flat(), "git_rev": git_revision()}, default=str, indent=1)
                atomic_write(lambda tmp: Path(tmp).write_text(record), path.with_suffix(".json"))
                write_frame(measure(cfg), path)


def load() -> pd.DataFrame:
    """Every recorded run's rows (empty when none is on disk)."""
    paths = sorted(DATA.glob("*.csv"))
    for path in paths:
        regular_file(path, "gate-study record")
    return pd.concat([pd.read_csv(p) for p in paths], ignore_index=True) if paths else pd.DataFrame()
