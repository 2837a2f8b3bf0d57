"""Experiments: budgets, the grid of runs behind each figure (``GRID``, data), and a run cache.

A figure is a ``Figure`` entry: curves of TrainConfig settings, each trained on every seed of
a budget. Runs are trained by an executor (``executors``: this machine's processes, or a Ray
cluster); the driver writes each run's evaluation rows to ``<data>/runs/<run id>.csv``
atomically once the run has finished, so a reproduction that is interrupted resumes by
skipping what is on disk; a figure's CSV is the concatenation of its runs, with a ``label``
column naming the curve each row belongs to.
"""
from __future__ import annotations

import hashlib
import json
import os
import sys
from dataclasses import dataclass, field, replace
from pathlib import Path

import pandas as pd

from oapo_lite.envs import registry as env_registry
from oapo_lite.envs.maps import load_maze
from oapo_lite.train import TrainConfig, atomic_write

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
    "paper20": Budget(seeds=tuple(range(20)), steps=240_000, eval_every=2, eval_episodes=32),
}


def get_budget(name: str) -> Budget:
    if name not in BUDGETS:
        raise ValueError(f"unknown budget {name!r}; choose from {sorted(BUDGETS)}")
    return BUDGETS[name]


def figures_dir(budget: str) -> Path:
    """The paper budget's figures are the committed ones; others go to a side folder.

    ``OAPO_FIGURES`` moves the whole tree elsewhere (the timing benchmark uses it so as not
    to touch the committed results).
    """
    root = Path(os.environ.get("OAPO_FIGURES", ROOT / "figures"))
    return root if budget == "paper" else root / budget


def data_dir(budget: str) -> Path:
    return figures_dir(budget) / "data"


# Section 6.1's figures: which curves, with which settings.
SIGMAS = (0.01, 0.1, 1.0, 10.0)
LAMBDAS = (0.2, 0.4, 0.7, 1.0)
SCHEMES = ("NR", "UR", "RR", "AR")
# Within a sharing group every member's experience weighs the same, as in MAPPO's M = 1/n:
# lambda = 1 / group size (NR's learners keep everything for themselves anyway).
SCHEME_LAM = {"NR": 1.0, "UR": 1 / 2, "RR": 1 / 2, "AR": 1 / 3}
# SEAC / SePS (A2C, 5-step rollouts) run 16 env copies: 80 env steps an update, 20 updates per
# PPO iteration of 32 x 50 steps; their evaluations and checkpoints are spaced 20 x as many
# iterations apart, so every curve is evaluated at the same env steps. SePS pre-trains for the
# first tenth of the budget, counted in its env steps.
A2C_ENVS = 16
A2C_ALGOS = ("seac", "seps")
BASELINE_ALGOS = ("seac", "seps", "mappo", "happo", "oappo")
MAZES = ("black_red", "black_blue_red")


@dataclass(frozen=True)
class Figure:
    """The runs behind one figure, as data: every curve is trained on every seed of the budget.

    ``curves``: (label, TrainConfig fields of that curve); ``common``: fields every curve shares
    (env, batch shape, ...); ``seeds``: how many of the budget's seeds (None: all);
    ``budgets``: per-budget overrides of ``Budget`` fields for this figure (a real engine needs
    more env steps than a maze), e.g. ``{"paper": {"steps": 10_000_000}}``; ``cpus``, ``gpus``,
    ``memory_gb``: what one run asks a Ray cluster for.
    """

    id: str
    curves: tuple[tuple[object, dict], ...]
    common: dict = field(default_factory=dict)
    seeds: int | None = None
    budgets: dict = field(default_factory=dict)
    cpus: float = 1.0
    gpus: float = 0.0
    memory_gb: float = 0.0

    def budget(self, name: str) -> Budget:
        return replace(get_budget(name), **self.budgets.get(name, {}))


# Every figure the project reproduces; a new figure is a new entry here.
GRID = (
    Figure("fig3b", tuple((a, dict(algo=a)) for a in ("oappo", "oatrpo", "mappo", "happo")),
           common=dict(env="black_red")),
    Figure("fig3c", tuple((s, dict(algo="oappo", sigma=s)) for s in SIGMAS), common=dict(env="black_red")),
    Figure("fig3d", tuple((lam, dict(algo="oappo", lam=lam)) for lam in LAMBDAS), common=dict(env="black_red")),
    # A scheme fixes who may reuse whom; the KL gate is opened (sigma = inf) so that the mask
    # alone decides, as in the paper's "modified OAPPO parameters".
    Figure("fig5b", tuple((s, dict(algo="oappo", allowed=s, sigma=float("inf"), lam=SCHEME_LAM[s]))
                          for s in SCHEMES), common=dict(env="black_blue_red")),
    Figure("fig1", (("oappo", dict(algo="oappo")),), common=dict(env="black_blue_red"), seeds=1),
    # label: the algorithm; the maze is the ``env`` column
    Figure("fig_baselines_mazes", tuple((a, dict(algo=a, env=m)) for m in MAZES for a in BASELINE_ALGOS)),
)
FIGURES = tuple(f.id for f in GRID)


def get_figure(figure: "Figure | str") -> Figure:
    if isinstance(figure, Figure):
        return figure
    known = {f.id: f for f in GRID}
    if figure not in known:
        raise ValueError(f"unknown figure {figure!r}; choose from {sorted(known)}")
    return known[figure]


@dataclass(frozen=True)
class Run:
    """One training run of a figure and what it needs (for a Ray cluster)."""

    figure: str
    label: object
    cfg: TrainConfig
    cpus: float = 1.0
    gpus: float = 0.0
    memory_gb: float = 0.0


def runs_of(figure: "Figure | str", budget: str) -> list[Run]:
    """A figure's runs at a budget: curve by curve, seed by seed."""
    fig = get_figure(figure)
    b = fig.budget(budget)
    seeds = b.seeds if fig.seeds is None else b.seeds[:fig.seeds]
    return [Run(fig.id, label, _config(b, seed=s, **fig.common, **kw), fig.cpus, fig.gpus, fig.memory_gb)
            for label, kw in fig.curves for s in seeds]


def _config(b: Budget, **kw) -> TrainConfig:
    """A run's config at budget ``b``; A2C runs are evaluated and checkpointed at the same env
    steps as the PPO family's (see ``A2C_ENVS``)."""
    if kw["algo"] not in A2C_ALGOS:
        return TrainConfig(steps=b.steps, eval_every=b.eval_every, eval_episodes=b.eval_episodes, **kw)
    ratio = (TrainConfig.n_envs * TrainConfig.rollout_len) // (A2C_ENVS * TrainConfig.n_step)
    if kw["algo"] == "seps":
        kw["seps_pretrain_steps"] = b.steps // 10
    return TrainConfig(steps=b.steps, eval_every=b.eval_every * ratio, eval_episodes=b.eval_episodes,
                       n_envs=A2C_ENVS, checkpoint_every=TrainConfig.checkpoint_every * ratio, **kw)


def figure_runs(figure: "Figure | str", budget: str) -> list[tuple[object, TrainConfig]]:
    """(label, config) of every run of a figure."""
    return [(r.label, r.cfg) for r in runs_of(figure, budget)]


def _changed(cfg: TrainConfig) -> dict:
    """The config fields that differ from ``TrainConfig``'s defaults."""
    defaults = TrainConfig().flat()
    return {k: v for k, v in cfg.flat().items() if str(v) != str(defaults[k])}


def run_id(cfg: TrainConfig) -> str:
    """Name of a run's cached result: the algorithm, env and seed, and a hash of the fields that
    differ from ``TrainConfig``'s defaults. Hashing only those keeps every cached run valid when
    a new field is added with a default that reproduces the old behaviour; changing an existing
    default, on the other hand, must come with a new cache (delete ``runs/``)."""
    blob = json.dumps(_changed(cfg), sort_keys=True, default=str)
    return f"{cfg.algo}-{cfg.env}-s{cfg.seed}-{hashlib.sha1(blob.encode()).hexdigest()[:10]}"


def run_path(cfg: TrainConfig, budget: str) -> Path:
    return data_dir(budget) / "runs" / f"{run_id(cfg)}.csv"


def write_csv_atomic(df: pd.DataFrame, path: Path) -> None:
    atomic_write(lambda p: df.to_csv(p, index=False), path)


def grid_runs(budget: str, figures=FIGURES) -> list[Run]:
    """The distinct runs of some figures (a run shared by two figures is trained once)."""
    runs, seen = [], set()
    for fig in figures:
        for run in runs_of(fig, budget):
            if run_id(run.cfg) not in seen:
                seen.add(run_id(run.cfg))
                runs.append(run)
    return runs


@dataclass
class Failure:
    run: Run
    error: str  # the traceback

    def report(self) -> str:
        return (f"run {run_id(self.run.cfg)} of {self.run.figure} (curve {self.run.label!r}) failed\n"
                f"  config (non-default fields): {_changed(self.run.cfg)}\n{self.error.rstrip()}")


def _cost(cfg: TrainConfig) -> int:
    maze = cfg.env_fn is None and env_registry.split(cfg.env)[0] is None
    return cfg.steps * (load_maze(cfg.env).n_agents if maze else 1)


@dataclass
class RunCount:
    done: int
    cached: int
    failed: list[Failure] = field(default_factory=list)


def run_all(budget: str, figures=FIGURES, workers: int = 2, progress: bool | str = True,
            executor: str = "local", address: str | None = None) -> RunCount:
    """Train every run of the given figures that is not on disk yet, on ``executor``: "local"
    (``workers`` processes of this machine) or "ray" (a Ray cluster at ``address``; None starts
    one on this machine). Whatever trains a run, this driver writes its CSV. A run that fails
    is reported (config and traceback) and the others go on; see ``RunCount.failed``.
    ``progress``: True (a bar), "lines" (one line per run, for logs) or False."""
    from tqdm import tqdm

    from oapo_lite import executors

    if executor not in executors.EXECUTORS:
        raise ValueError(f"unknown executor {executor!r}; choose from {sorted(executors.EXECUTORS)}")
    todo = grid_runs(budget, figures)
    # longest first (steps x agents), so that no long run starts last while the other worker idles
    missing = sorted((r for r in todo if not run_path(r.cfg, budget).exists()), key=lambda r: _cost(r.cfg),
                     reverse=True)
    checkpoints = data_dir(budget) / "checkpoints"
    if missing:  # made here, so that a worker can tell whether it shares this file system
        checkpoints.mkdir(parents=True, exist_ok=True)
    jobs = [(run, str(checkpoints / run_id(run.cfg))) for run in missing]
    failed = []
    with tqdm(total=len(missing), desc=f"runs ({budget}, {executor})", disable=progress is not True) as bar:
        for k, (run, rows, error) in enumerate(executors.EXECUTORS[executor](jobs, workers=workers,
                                                                              address=address), 1):
            if error is None:
                write_csv_atomic(rows, run_path(run.cfg, budget))
            else:
                failed.append(Failure(run, error))
                tqdm.write(failed[-1].report(), file=sys.stderr)
            bar.set_postfix_str(run_id(run.cfg))
            bar.update()
            if progress == "lines":
                print(f"runs ({budget}, {executor}): {k}/{len(missing)} {'done' if error is None else 'FAILED'} "
                      f"{run_id(run.cfg)}", flush=True)
    return RunCount(done=len(missing) - len(failed), cached=len(todo) - len(missing), failed=failed)


def load_figure(figure: str, budget: str, run_missing: bool = True, skip_missing: bool = False) -> pd.DataFrame:
    """The tidy rows of one figure (training its missing runs first, if asked; or, with
    ``skip_missing``, leaving out the runs not on disk and naming them)."""
    if run_missing:
        failed = run_all(budget, figures=(figure,), progress=False).failed
        if failed:
            raise RuntimeError(f"{len(failed)} run(s) of {figure} failed (reported above)")
    frames, missing = [], []
    for label, cfg in figure_runs(figure, budget):
        if skip_missing and not run_path(cfg, budget).exists():
            missing.append(run_id(cfg))
            continue
        df = pd.read_csv(run_path(cfg, budget))
        frames.append(df.assign(label=label, figure=figure))
    df = pd.concat(frames, ignore_index=True)
    write_csv_atomic(df, data_dir(budget) / f"{figure}.csv")
    if missing:
        print(f"warning: {figure} leaves out {len(missing)} runs not on disk: {missing}")
    revisions = sorted(df["git_rev"].astype(str).unique())
    if len(revisions) > 1:  # cached runs outlive code changes; say so rather than mix silently
        print(f"warning: {figure} mixes runs from git revisions {revisions}")
    return df
