"""Experiments of Section 6.1: budgets, the runs behind each figure, and a run cache.

A figure is a list of (label, TrainConfig). Every run's evaluation rows are written to
``<data>/runs/<run id>.csv`` atomically once the run has finished, so a reproduction that
is interrupted resumes by skipping what is on disk; a figure's CSV is the concatenation of
its runs, with a ``label`` column naming the curve each row belongs to.
"""
from __future__ import annotations

import hashlib
import json
import os
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from oapo_lite.train import TrainConfig, atomic_write, train

ROOT = Path(__file__).resolve().parent.parent


@dataclass(frozen=True)
class Budget:
    """How much to spend on each curve of each figure."""

    seeds: tuple[int, ...]
    steps: int  # env steps per run
    eval_every: int  # iterations between evaluations
    eval_episodes: int


BUDGETS = {
    "smoke": Budget(seeds=(0,), steps=3_200, eval_every=1, eval_episodes=8),
    "paper": Budget(seeds=(0, 1, 2, 3, 4), steps=240_000, eval_every=2, eval_episodes=32),
}


def get_budget(name: str) -> Budget:
    if name not in BUDGETS:
        raise ValueError(f"unknown budget {name!r}; choose from {sorted(BUDGETS)}")
    return BUDGETS[name]


COMMITTED = ("paper", "cpu")  # "cpu": the real engines' budget that fits this machine


def figures_dir(budget: str) -> Path:
    """The paper (and cpu) budget's figures are the committed ones; others go to a side folder.

    ``OAPO_FIGURES`` moves the whole tree elsewhere (the timing benchmark uses it so as not
    to touch the committed results).
    """
    root = Path(os.environ.get("OAPO_FIGURES", ROOT / "figures"))
    return root if budget in COMMITTED else root / budget


def data_dir(budget: str) -> Path:
    return figures_dir(budget) / "data"


# Section 6.1's figures: which curves, with which settings.
SIGMAS = (0.01, 0.1, 1.0, 10.0)
LAMBDAS = (0.2, 0.4, 0.7, 1.0)
SCHEMES = ("NR", "UR", "RR", "AR")
# Within a sharing group every member's experience weighs the same, as in MAPPO's M = 1/n:
# lambda = 1 / group size (NR's learners keep everything for themselves anyway).
SCHEME_LAM = {"NR": 1.0, "UR": 1 / 2, "RR": 1 / 2, "AR": 1 / 3}


@dataclass(frozen=True)
class EngineBudget:
    """A real engine's budget: the usual Budget, the TrainConfig fields every run shares, and
    per env its own fields. An env left out is not run at this budget."""

    budget: Budget
    train: dict
    envs: dict  # env spec -> its own TrainConfig fields


# Fig. 6b (GRF academy). The algorithms of the paper's table that the project has; SEAC and
# SePS join by adding their names here.
FIG6B_ALGOS = ("oappo", "oatrpo", "mappo", "happo")
GRF = "grf:academy_"
# HARL's tuned GRF settings (ANCHORS.md); the engine itself ends academy episodes (<= 400 steps)
GRF_HARL = dict(hidden=(64, 64), ppo_epochs=15, n_minibatch=2, clip=0.2, max_steps=400)
FIG6B = {
    "smoke": EngineBudget(Budget((0,), 64, 1, 2), dict(n_envs=2, rollout_len=16, max_steps=32),
                          {GRF + "3_vs_1_with_keeper": {}}),
    # at most 2 hours on 2 cores at the engine's ~300 steps/s per core (ANCHORS.md): 12 runs of
    # 96k steps; 3_vs_1 only, the scenario HARL learns fastest (whether it learns here is open)
    "cpu": EngineBudget(Budget((0, 1, 2), 96_000, 5, 16), dict(GRF_HARL, n_envs=8, rollout_len=200),
                        {GRF + "3_vs_1_with_keeper": {}}),
    "paper": EngineBudget(Budget((0, 1, 2, 3, 4), 25_000_000, 25, 32), dict(GRF_HARL, n_envs=50, rollout_len=200),
                          {GRF + "pass_and_shoot_with_keeper": {}, GRF + "3_vs_1_with_keeper": {},
                           GRF + "counterattack_easy": {},
                           GRF + "counterattack_hard": dict(steps=50_000_000, rollout_len=1000)}),
}
ENGINE_FIGURES = {"fig6b": (FIG6B, FIG6B_ALGOS)}


def engine_budget(figure: str, budget: str) -> EngineBudget:
    budgets = ENGINE_FIGURES[figure][0]
    if budget not in budgets:
        raise ValueError(f"unknown budget {budget!r} for {figure}; choose from {sorted(budgets)}")
    return budgets[budget]


def figure_runs(figure: str, budget: str) -> list[tuple[object, TrainConfig]]:
    if figure in ENGINE_FIGURES:
        e, algos = engine_budget(figure, budget), ENGINE_FIGURES[figure][1]
        b = e.budget
        return [(algo, TrainConfig(**{"steps": b.steps, "eval_every": b.eval_every, "eval_episodes": b.eval_episodes,
                                      **e.train, **own, "algo": algo, "env": env, "seed": s}))
                for env, own in e.envs.items() for s in b.seeds for algo in algos]  # seed 0 of every cell first
    b = get_budget(budget)

    def cfg(**kw) -> TrainConfig:
        return TrainConfig(steps=b.steps, eval_every=b.eval_every, eval_episodes=b.eval_episodes, **kw)

    grids = {
        "fig3b": [(a, dict(algo=a, env="black_red")) for a in ("oappo", "oatrpo", "mappo", "happo")],
        "fig3c": [(s, dict(algo="oappo", env="black_red", sigma=s)) for s in SIGMAS],
        "fig3d": [(lam, dict(algo="oappo", env="black_red", lam=lam)) for lam in LAMBDAS],
        # A scheme fixes who may reuse whom; the KL gate is opened (sigma = inf) so that
        # the mask alone decides, as in the paper's "modified OAPPO parameters".
        "fig5b": [(s, dict(algo="oappo", env="black_blue_red", allowed=s, sigma=float("inf"),
                           lam=SCHEME_LAM[s])) for s in SCHEMES],
        "fig1": [("oappo", dict(algo="oappo", env="black_blue_red"))],
    }
    if figure not in grids:
        raise ValueError(f"unknown figure {figure!r}; choose from {sorted(grids) + sorted(ENGINE_FIGURES)}")
    seeds = b.seeds[:1] if figure == "fig1" else b.seeds
    return [(label, cfg(seed=s, **kw)) for label, kw in grids[figure] for s in seeds]


FIGURES = ("fig3b", "fig3c", "fig3d", "fig5b", "fig1")


def run_id(cfg: TrainConfig) -> str:
    """Name of a run's cached result: the algorithm, env and seed, and a hash of the fields that
    differ from ``TrainConfig``'s defaults. Hashing only those keeps every cached run valid when
    a new field is added with a default that reproduces the old behaviour; changing an existing
    default, on the other hand, must come with a new cache (delete ``runs/``)."""
    defaults = TrainConfig().flat()
    changed = {k: v for k, v in cfg.flat().items() if str(v) != str(defaults[k])}
    blob = json.dumps(changed, sort_keys=True, default=str)
    env = cfg.env.replace(":", "-")  # "grf:x" -> "grf-x": a colon is no file name on every system
    return f"{cfg.algo}-{env}-s{cfg.seed}-{hashlib.sha1(blob.encode()).hexdigest()[:10]}"


def run_path(cfg: TrainConfig, budget: str) -> Path:
    return data_dir(budget) / "runs" / f"{run_id(cfg)}.csv"


def write_csv_atomic(df: pd.DataFrame, path: Path) -> None:
    atomic_write(lambda p: df.to_csv(p, index=False), path)


def _run_one(cfg: TrainConfig, budget: str) -> str:
    path = run_path(cfg, budget)
    rows = train(cfg, path.parent.parent / "checkpoints" / run_id(cfg), progress=False)
    write_csv_atomic(rows, path)
    return run_id(cfg)


@dataclass
class RunCount:
    done: int
    cached: int


def run_all(budget: str, figures=FIGURES, workers: int = 2, progress: bool = True) -> RunCount:
    """Train every run of the given figures that is not on disk yet, ``workers`` at a time."""
    from tqdm import tqdm

    todo, seen = [], set()
    for fig in figures:
        for _, cfg in figure_runs(fig, budget):
            if run_id(cfg) not in seen:
                seen.add(run_id(cfg))
                todo.append(cfg)
    missing = [c for c in todo if not run_path(c, budget).exists()]
    with tqdm(total=len(missing), desc=f"runs ({budget})", disable=not progress) as bar:
        if workers <= 1:
            for c in missing:
                bar.set_postfix_str(run_id(c))
                _run_one(c, budget)
                bar.update()
        else:
            with ProcessPoolExecutor(max_workers=workers) as pool:
                futures = [pool.submit(_run_one, c, budget) for c in missing]
                for f in as_completed(futures):
                    bar.set_postfix_str(f.result())
                    bar.update()
    return RunCount(done=len(missing), cached=len(todo) - len(missing))


def figure_csv(figure: str, budget: str) -> Path:
    """Where a figure's tidy rows go; the cpu budget shares the committed folder, so it is named."""
    return data_dir(budget) / (f"{figure}_{budget}.csv" if budget == "cpu" else f"{figure}.csv")


def missing_runs(figure: str, budget: str) -> list[TrainConfig]:
    """The runs of a figure that are not on disk yet."""
    return [cfg for _, cfg in figure_runs(figure, budget) if not run_path(cfg, budget).exists()]


def load_figure(figure: str, budget: str, run_missing: bool = True) -> pd.DataFrame:
    """The tidy rows of one figure: its missing runs are trained first if ``run_missing``,
    otherwise left out (``missing_runs`` lists them)."""
    if run_missing:
        run_all(budget, figures=(figure,), progress=False)
    frames = [pd.read_csv(run_path(cfg, budget)).assign(label=label, figure=figure)
              for label, cfg in figure_runs(figure, budget) if run_path(cfg, budget).exists()]
    if not frames:
        return pd.DataFrame()
    df = pd.concat(frames, ignore_index=True)
    write_csv_atomic(df, figure_csv(figure, budget))
    revisions = sorted(df["git_rev"].astype(str).unique())
    if len(revisions) > 1:  # cached runs outlive code changes; say so rather than mix silently
        print(f"warning: {figure} mixes runs from git revisions {revisions}")
    return df
