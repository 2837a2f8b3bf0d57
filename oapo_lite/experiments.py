"""Experiments of Section 6: budgets, the runs behind each figure, and a run cache.

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
BUDGETS["cpu"] = BUDGETS["paper"]  # the mazes' paper scale fits a CPU (same runs, same cache)
# The budget whose figures are committed: the mazes run at the paper's scale on a CPU; the
# real engines' committed figures come from the ``cpu`` budget (see SMAX_BUDGETS).
COMMITTED = ("paper", "cpu")


def get_budget(name: str) -> Budget:
    if name not in BUDGETS:
        raise ValueError(f"unknown budget {name!r}; choose from {sorted(BUDGETS)}")
    return BUDGETS[name]


def figures_dir(budget: str) -> Path:
    """The committed budgets' figures are the committed ones; others go to a side folder.

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


# Fig. 4 (Section 6.2) on SMAX. Settings per map that every budget shares: HARL's tuned SMAC
# settings (ANCHORS.md) on the paper's maps, TrainConfig's (HARL's defaults) on the small ones.
# 64 copies x 50 steps is HARL's batch of 20 threads x 160 steps (3,200 transitions).
SMAX_ALGOS = ("oappo", "oatrpo", "mappo", "happo")  # the SEAC branch adds "seac", "seps" here
SMAX_BATCH = dict(n_envs=64, rollout_len=50, max_steps=100, eval_episodes=64, checkpoint_every=10)
_PAPER_MAP = dict(gamma=0.95, hidden=(64, 64, 64))
SMAX_MAPS = {
    "3m": {},
    "2s3z": {},
    "6h_vs_8z": dict(_PAPER_MAP, clip=0.05, ppo_epochs=10, n_minibatch=2, kl_threshold=0.001),
    "3s5z_vs_3s6z": dict(_PAPER_MAP, clip=0.1, ppo_epochs=5, n_minibatch=2, kl_threshold=0.005),
    "MMM2_like_7m2M_vs_8m3M": dict(_PAPER_MAP, clip=0.2, ppo_epochs=5, n_minibatch=1, kl_threshold=0.06),
}
# budget -> map -> (seeds, env steps per run, iterations between evaluations). ``cpu``: what
# fits in 2 hours on 2 cores (speeds measured in benchmarks/smax_speed.py); ``paper``: the
# paper's steps per map (HARL's tuned SMAC runs), for a GPU machine or a cluster.
SMAX_BUDGETS = {
    "smoke": {"3m": (1, 6_400, 1)},
    "cpu": {"3m": (5, 300_000, 10), "2s3z": (5, 500_000, 10), "6h_vs_8z": (3, 100_000, 5),
            "3s5z_vs_3s6z": (3, 100_000, 5), "MMM2_like_7m2M_vs_8m3M": (3, 100_000, 5)},
    "paper": {"3m": (5, 2_000_000, 25), "2s3z": (5, 5_000_000, 25), "6h_vs_8z": (5, 40_000_000, 25),
              "3s5z_vs_3s6z": (5, 20_000_000, 25), "MMM2_like_7m2M_vs_8m3M": (5, 20_000_000, 25)},
}


def smax_runs(budget: str) -> list[tuple[str, TrainConfig]]:
    """Fig. 4's grid: every algorithm on every map of the budget, seeds outermost, so a
    budget run in pieces has every curve at a few seeds before any at many."""
    if budget not in SMAX_BUDGETS:
        raise ValueError(f"unknown budget {budget!r} for SMAX; choose from {sorted(SMAX_BUDGETS)}")
    table = SMAX_BUDGETS[budget]
    return [(algo, TrainConfig(algo=algo, env=f"smax:{m}", seed=s, steps=steps, eval_every=every,
                               **SMAX_BATCH, **SMAX_MAPS[m]))
            for s in range(max(n for n, _, _ in table.values()))
            for m, (n, steps, every) in table.items() if s < n for algo in SMAX_ALGOS]


def figure_runs(figure: str, budget: str) -> list[tuple[object, TrainConfig]]:
    if figure == "fig4_smax":
        return smax_runs(budget)
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
        raise ValueError(f"unknown figure {figure!r}; choose from {sorted(grids)}")
    seeds = b.seeds[:1] if figure == "fig1" else b.seeds
    return [(label, cfg(seed=s, **kw)) for label, kw in grids[figure] for s in seeds]


FIGURES = ("fig3b", "fig3c", "fig3d", "fig5b", "fig1")  # the mazes: Section 6.1


def figures_for(budget: str) -> tuple[str, ...]:
    """Every figure that has runs at ``budget``."""
    return (FIGURES if budget in BUDGETS else ()) + (("fig4_smax",) if budget in SMAX_BUDGETS else ())


def run_id(cfg: TrainConfig) -> str:
    """Name of a run's cached result: the algorithm, env and seed, and a hash of the fields that
    differ from ``TrainConfig``'s defaults. Hashing only those keeps every cached run valid when
    a new field is added with a default that reproduces the old behaviour; changing an existing
    default, on the other hand, must come with a new cache (delete ``runs/``)."""
    defaults = TrainConfig().flat()
    changed = {k: v for k, v in cfg.flat().items() if str(v) != str(defaults[k])}
    blob = json.dumps(changed, sort_keys=True, default=str)
    env = cfg.env.replace(":", "-")  # "smax:3m": no colon in file names
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


def missing_runs(figure: str, budget: str) -> list[TrainConfig]:
    """The runs of ``figure`` at ``budget`` that are not on disk yet."""
    return [cfg for _, cfg in figure_runs(figure, budget) if not run_path(cfg, budget).exists()]


def load_figure(figure: str, budget: str, run_missing: bool = True) -> pd.DataFrame:
    """The tidy rows of one figure: training its missing runs first if ``run_missing``,
    otherwise only the runs on disk (``missing_runs`` names the others)."""
    if run_missing:
        run_all(budget, figures=(figure,), progress=False)
    frames = []
    for label, cfg in figure_runs(figure, budget):
        if run_path(cfg, budget).exists():
            frames.append(pd.read_csv(run_path(cfg, budget)).assign(label=label, figure=figure))
    if not frames:
        raise FileNotFoundError(f"no run of {figure} at budget {budget!r} is on disk; train them with "
                                f"run_all({budget!r}, figures=({figure!r},)) or load_figure(..., run_missing=True)")
    df = pd.concat(frames, ignore_index=True)
    write_csv_atomic(df, data_dir(budget) / f"{figure}.csv")
    revisions = sorted(df["git_rev"].astype(str).unique())
    if len(revisions) > 1:  # cached runs outlive code changes; say so rather than mix silently
        print(f"warning: {figure} mixes runs from git revisions {revisions}")
    return df
