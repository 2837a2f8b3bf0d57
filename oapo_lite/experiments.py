"""Experiments of Section 6: budgets, the grid of runs behind each figure (``GRID``, data), and a run cache.

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
from oapo_lite.store import DamagedFile, atomic_write
from oapo_lite.config import TrainConfig

ROOT = Path(__file__).resolve().parent.parent


@dataclass(frozen=True)
class Budget:
    """How much to spend on each curve of each figure."""

    seeds: tuple[int, ...]
    steps: int  # env steps per run
    eval_every: int  # iterations between evaluations
    eval_episodes: int
    config: dict = field(default_factory=dict)  # further TrainConfig fields (batch shape, episode length)


BUDGETS = {
    "smoke": Budget(seeds=(0,), steps=3_200, eval_every=1, eval_episodes=8),
    "paper": Budget(seeds=(0, 1, 2, 3, 4), steps=240_000, eval_every=2, eval_episodes=32),
    "paper20": Budget(seeds=tuple(range(20)), steps=240_000, eval_every=2, eval_episodes=32),
}
# "cpu": the largest budget this machine (2 cores) can honestly run. The mazes' paper scale
# fits a CPU, so for them it is the paper budget (same runs, same cache); the real engines
# override it per figure (``Figure.budgets``) with what fits in one or two hours.
BUDGETS["cpu"] = BUDGETS["paper"]
COMMITTED = ("paper", "cpu")  # the budgets whose figures and runs are committed under figures/
# paper20's figures go to figures/paper20/, but its runs share the committed cache: a run id
# hashes the run's whole config, so its seeds 0-4 are the paper budget's runs, trained once.
SHARED_RUNS = COMMITTED + ("paper20",)


def get_budget(name: str) -> Budget:
    if name not in BUDGETS:
        raise ValueError(f"unknown budget {name!r}; choose from {sorted(BUDGETS)}")
    return BUDGETS[name]


def figures_dir(budget: str) -> Path:
    """The committed budgets' figures live in figures/; others go to a side folder.

    ``OAPO_FIGURES`` moves the whole tree elsewhere (the timing benchmark uses it so as not
    to touch the committed results).
    """
    root = Path(os.environ.get("OAPO_FIGURES", ROOT / "figures"))
    return root if budget in COMMITTED else root / budget


def data_dir(budget: str) -> Path:
    return figures_dir(budget) / "data"


def runs_dir(budget: str) -> Path:
    """Where a budget's finished runs (``<run id>.csv``) and their checkpoints are cached."""
    return data_dir(COMMITTED[0] if budget in SHARED_RUNS else budget)


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
ADAPTIVE_CURVES = (("oappo adaptive", dict(algo="oappo", reuse_adapt="gradient_test")),
                   ("oappo", dict(algo="oappo")), ("happo", dict(algo="happo")))


@dataclass(frozen=True)
class Figure:
    """The runs behind one figure, as data: every curve is trained on every seed of the budget.

    ``curves``: (label, TrainConfig fields of that curve); ``common``: fields every curve shares
    (env, batch shape, ...); ``seeds``: how many of the budget's seeds (None: all);
    ``budgets``: per-budget overrides of ``Budget`` fields for this figure (a real engine needs
    more env steps than a maze), e.g. ``{"paper": {"steps": 10_000_000}}``; under the key
    ``envs``, overrides for one env alone, and then only the curves on those envs run at that
    budget; ``runs_at``: the budgets the figure has runs at (None: every budget); ``cpus``,
    ``gpus``, ``memory_gb``: what one run asks a Ray cluster for.
    """

    id: str
    curves: tuple[tuple[object, dict], ...]
    common: dict = field(default_factory=dict)
    seeds: int | None = None
    budgets: dict = field(default_factory=dict)
    runs_at: tuple[str, ...] | None = None
    cpus: float = 1.0
    gpus: float = 0.0
    memory_gb: float = 0.0

    def budget(self, name: str, env: str | None = None) -> Budget:
        """This figure's budget ``name`` (for the curves on ``env``, if it has its own)."""
        own = dict(self.budgets.get(name, {}))
        envs = own.pop("envs", {})
        return replace(get_budget(name), **{**own, **envs.get(env, {})})

    def envs(self, name: str) -> tuple[str, ...] | None:
        """The envs this figure runs at budget ``name`` (None: every curve's)."""
        envs = self.budgets.get(name, {}).get("envs")
        return None if envs is None else tuple(envs)


# Fig. 4 (Section 6.2) on SMAX. Per-map settings every budget shares: HARL's tuned SMAC settings
# (ANCHORS.md) on the paper's maps, TrainConfig's (HARL's defaults) on the small ones. 64 copies
# x 50 steps is HARL's batch of 20 threads x 160 steps (3,200 transitions).
SMAX_ALGOS = ("oappo", "oatrpo", "mappo", "happo", "seac", "seps")
SMAX_BATCH = dict(n_envs=64, rollout_len=50, max_steps=100, checkpoint_every=10)
_PAPER_MAP = dict(gamma=0.95, hidden=(64, 64, 64))
SMAX_MAPS = {
    "3m": {},
    "2s3z": {},
    "6h_vs_8z": dict(_PAPER_MAP, clip=0.05, ppo_epochs=10, n_minibatch=2, kl_threshold=0.001),
    "3s5z_vs_3s6z": dict(_PAPER_MAP, clip=0.1, ppo_epochs=5, n_minibatch=2, kl_threshold=0.005),
    "MMM2_like_7m2M_vs_8m3M": dict(_PAPER_MAP, clip=0.2, ppo_epochs=5, n_minibatch=1, kl_threshold=0.06),
}


# App. A on multi-agent MuJoCo: no reuse (HAPPO), full sharing (MAPPO), gated reuse (OAPPO) and
# direct reuse (SEAC) on homogeneous agents.
FIGA_ALGOS = ("happo", "mappo", "oappo", "seac")
# Fig. 6b on GRF academy scenarios: every algorithm of the paper's table the project has.
FIG6B_ALGOS = ("oappo", "oatrpo", "mappo", "happo", "seac", "seps")
GRF_SCENARIOS = ("pass_and_shoot_with_keeper", "3_vs_1_with_keeper", "counterattack_easy", "counterattack_hard")
# HARL's tuned GRF settings (ANCHORS.md); the engine itself ends academy episodes (<= 400 steps)
GRF_HARL = dict(hidden=(64, 64), ppo_epochs=15, n_minibatch=2, clip=0.2, max_steps=400)
ENGINE_BUDGETS = ("smoke", "cpu", "paper")

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
    # Issue 12's adaptive reuse rule against the fixed Eq. 9 (sigma 0.1, lambda 0.7: the best of
    # Fig. 3c-d's grid) and no reuse, on both paper mazes; and both at lambda 0.4 on Black-Red,
    # where the fixed rule is trapped (Fig. 3d)
    Figure("fig_adaptive", tuple((label, dict(env=m, **kw)) for m in MAZES for label, kw in ADAPTIVE_CURVES)
           + tuple((f"{label} lambda=0.4", dict(env="black_red", lam=0.4, **kw)) for label, kw in ADAPTIVE_CURVES[:2])),
    # label: the algorithm; the map is the ``env`` column. ``cpu`` is what fits 2 hours on 2
    # cores (benchmarks/smax_speed.py): the two small maps, on which learning shows within it;
    # the paper's maps need millions of steps and run at ``paper`` (HARL's steps per map).
    Figure("fig4_smax", tuple((a, dict(algo=a, env=f"smax:{m}", **kw)) for m, kw in SMAX_MAPS.items()
                              for a in SMAX_ALGOS),
           common=SMAX_BATCH, runs_at=ENGINE_BUDGETS, budgets={
               "smoke": dict(eval_episodes=8, envs={"smax:3m": dict(steps=6_400, eval_every=1)}),
               "cpu": dict(eval_episodes=64, envs={"smax:3m": dict(steps=300_000, eval_every=10),
                                                   "smax:2s3z": dict(steps=500_000, eval_every=10)}),
               "paper": dict(eval_episodes=64, eval_every=25, envs={
                   "smax:3m": dict(steps=2_000_000), "smax:2s3z": dict(steps=5_000_000),
                   "smax:6h_vs_8z": dict(steps=40_000_000), "smax:3s5z_vs_3s6z": dict(steps=20_000_000),
                   "smax:MMM2_like_7m2M_vs_8m3M": dict(steps=20_000_000)}),
           }),
    # App. A's own settings are not public; ``paper`` is HARL's MaMuJoCo scale (10M steps).
    Figure("figA_mamujoco", tuple((a, dict(algo=a)) for a in FIGA_ALGOS), common=dict(env="mamujoco:HalfCheetah-2x3"),
           runs_at=ENGINE_BUDGETS, budgets={
               "smoke": dict(steps=200, eval_episodes=2, config=dict(n_envs=2, rollout_len=50, max_steps=100)),
               "cpu": dict(steps=200_000, eval_every=5, eval_episodes=3,
                           config=dict(n_envs=8, rollout_len=250, max_steps=1000, checkpoint_every=10)),
               "paper": dict(steps=10_000_000, eval_every=25, eval_episodes=10,
                             config=dict(n_envs=10, rollout_len=400, max_steps=1000, checkpoint_every=10)),
           }),
    # label: the algorithm; the scenario is the ``env`` column. ``cpu``: the training loop ran
    # ~60 env steps/s per run here (a 96k-step OAPPO run took 28 min beside a SMAX run), so 18
    # runs of 32k steps on 3_vs_1_with_keeper (the scenario HARL learns fastest) fit 2 hours.
    Figure("fig6b", tuple((a, dict(algo=a, env=f"grf:academy_{s}")) for s in GRF_SCENARIOS for a in FIG6B_ALGOS),
           runs_at=ENGINE_BUDGETS, budgets={
               "smoke": dict(steps=160, eval_episodes=2, config=dict(n_envs=2, rollout_len=16, max_steps=32),
                             envs={"grf:academy_3_vs_1_with_keeper": {}}),
               "cpu": dict(seeds=(0, 1, 2), steps=32_000, eval_every=4, eval_episodes=16,
                           config=dict(GRF_HARL, n_envs=8, rollout_len=200),
                           envs={"grf:academy_3_vs_1_with_keeper": {}}),
               "paper": dict(steps=25_000_000, eval_every=25, config=dict(GRF_HARL, n_envs=50, rollout_len=200),
                             envs={f"grf:academy_{s}": {} for s in GRF_SCENARIOS[:3]}
                             | {"grf:academy_counterattack_hard": dict(
                                 steps=50_000_000, config=dict(GRF_HARL, n_envs=50, rollout_len=1000))}),
           }),
)
FIGURES = tuple(f.id for f in GRID)
MAZE_FIGURES = tuple(f.id for f in GRID if f.runs_at is None)  # Section 6.1; the others run real engines


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
    get_budget(budget)  # a bad name fails here, even for a figure without runs at it
    if fig.runs_at is not None and budget not in fig.runs_at:
        return []
    envs, runs = fig.envs(budget), []
    for label, kw in fig.curves:
        env = {**fig.common, **kw}.get("env", TrainConfig.env)
        if envs is not None and env not in envs:
            continue
        b = fig.budget(budget, env)
        seeds = b.seeds if fig.seeds is None else b.seeds[:fig.seeds]
        runs += [Run(fig.id, label, _config(b, seed=s, **fig.common, **kw), fig.cpus, fig.gpus, fig.memory_gb)
                 for s in seeds]
    return runs


def _config(b: Budget, **kw) -> TrainConfig:
    """A run's config at budget ``b``; A2C runs are evaluated and checkpointed at the same env
    steps as the PPO family's (see ``A2C_ENVS``)."""
    kw = {**b.config, **kw}
    if kw["algo"] not in A2C_ALGOS:
        return TrainConfig(steps=b.steps, eval_every=b.eval_every, eval_episodes=b.eval_episodes, **kw)
    batch = kw.get("n_envs", TrainConfig.n_envs) * kw.get("rollout_len", TrainConfig.rollout_len)
    ratio = max(1, batch // (A2C_ENVS * TrainConfig.n_step))
    if kw["algo"] == "seps":
        kw["seps_pretrain_steps"] = max(b.steps // 10, A2C_ENVS * TrainConfig.n_step)  # >= one update
    kw |= dict(n_envs=A2C_ENVS, checkpoint_every=kw.get("checkpoint_every", TrainConfig.checkpoint_every) * ratio)
    return TrainConfig(steps=b.steps, eval_every=b.eval_every * ratio, eval_episodes=b.eval_episodes, **kw)


def figure_runs(figure: "Figure | str", budget: str) -> list[tuple[object, TrainConfig]]:
    """(label, config) of every run of a figure."""
    return [(r.label, r.cfg) for r in runs_of(figure, budget)]


def _changed(cfg: TrainConfig) -> dict:
    """The config fields that differ from ``TrainConfig``'s defaults."""
    defaults = TrainConfig().flat()
    return {k: v for k, v in cfg.flat().items() if str(v) != str(defaults[k])}


def run_id(cfg: TrainConfig, env_name: str | None = None) -> str:
    """Name of a run's cached result (and of a command-line run's folder): the algorithm, env
    (``env_name`` if given: a map file's name) and seed, and a hash of the fields that differ
    from ``TrainConfig``'s defaults. Hashing only those keeps every cached run valid when a new
    field is added with a default that reproduces the old behaviour; changing an existing
    default, on the other hand, must come with a new cache (delete ``runs/``)."""
    blob = json.dumps(_changed(cfg), sort_keys=True, default=str)
    env = env_name or ("map" if "\n" in cfg.env else cfg.env)
    env = env.replace(":", "_")  # an engine's env spec ("smax:3m") as a portable file name
    return f"{cfg.algo}-{env}-s{cfg.seed}-{hashlib.sha1(blob.encode()).hexdigest()[:10]}"


def run_path(cfg: TrainConfig, budget: str) -> Path:
    return runs_dir(budget) / "runs" / f"{run_id(cfg)}.csv"


def read_run(cfg: TrainConfig, budget: str) -> pd.DataFrame:
    """A finished run's rows from the cache, checked against its config: every evaluation row
    of the run, in order, with its seed and algorithm. A file that is not whole raises
    ``DamagedFile`` naming it (``run_all`` then trains the run again)."""
    path = run_path(cfg, budget)
    try:
        df = pd.read_csv(path)
    except FileNotFoundError:
        raise
    except Exception as err:  # not text, not CSV, empty
        raise DamagedFile(f"run file {path} is damaged ({type(err).__name__}: {err}); {RETRAIN}") from None
    needed = ["algo", "seed", "iteration", "step", "eval_return", "frac_opt", "eval_success", "git_rev"]
    if [c for c in needed if c not in df.columns]:
        raise DamagedFile(f"run file {path} lacks the columns {[c for c in needed if c not in df.columns]}; {RETRAIN}")
    steps = pd.to_numeric(df["step"], errors="coerce")
    if len(df) != len(cfg.eval_steps) or steps.isna().any() or list(steps) != cfg.eval_steps:
        raise DamagedFile(f"run file {path} is not the whole run: its steps are not the {len(cfg.eval_steps)} "
                          f"evaluation steps of its config ({cfg.eval_steps[0]} to {cfg.eval_steps[-1]}), found "
                          f"{len(df)} rows; {RETRAIN}")
    if (df["seed"].astype(str) != str(cfg.seed)).any() or (df["algo"].astype(str) != cfg.algo).any():
        raise DamagedFile(f"run file {path} holds another run's rows (seed or algo differ); {RETRAIN}")
    return df


RETRAIN = "delete it, or let `python -m oapo_lite reproduce` train the run again"


def on_disk(cfg: TrainConfig, budget: str) -> bool:
    """Whether a run is in the cache and whole; a damaged file is named (and counts as missing)."""
    try:
        read_run(cfg, budget)
    except FileNotFoundError:
        return False
    except DamagedFile as err:
        print(f"warning: {err}", file=sys.stderr)
        return False
    return True


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


def _missing_engine(cfg: TrainConfig) -> tuple[str, str] | None:
    """(engine, how to install it) for a run whose engine is not installed here, else None."""
    engine = env_registry.split(cfg.env)[0] if cfg.env_fn is None else None
    hint = env_registry.missing_engine(engine) if engine else None
    return (engine, hint) if hint else None


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
    todo, skipped = [], {}
    for run in grid_runs(budget, figures):
        missing_engine = _missing_engine(run.cfg)
        if missing_engine:
            skipped.setdefault(*missing_engine)
        else:
            todo.append(run)
    for engine, hint in skipped.items():
        print(f"skipping the {engine} runs: {hint}", file=sys.stderr)
    # seed by seed, so that an interrupted grid has every curve at a few seeds before any at many;
    # within a seed longest first (steps x agents), so that no long run starts last while the
    # other worker idles
    missing = sorted((r for r in todo if not on_disk(r.cfg, budget)), key=lambda r: (r.cfg.seed, -_cost(r.cfg)))
    checkpoints = runs_dir(budget) / "checkpoints"
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


def missing_runs(figure: str, budget: str) -> list[Run]:
    """The runs of ``figure`` at ``budget`` that are not on disk yet (or damaged)."""
    return [r for r in runs_of(figure, budget) if not on_disk(r.cfg, budget)]


def load_figure(figure: str, budget: str, run_missing: bool = True, skip_missing: bool = False) -> pd.DataFrame:
    """The tidy rows of one figure (training its missing runs first, if asked; or, with
    ``skip_missing``, leaving out the runs not on disk: ``missing_runs`` names them, and with
    none on disk the frame is empty and no CSV is written)."""
    if run_missing:
        failed = run_all(budget, figures=(figure,), progress=False).failed
        if failed:
            raise RuntimeError(f"{len(failed)} run(s) of {figure} failed (reported above)")
    frames, missing = [], []
    for label, cfg in figure_runs(figure, budget):
        if skip_missing and not on_disk(cfg, budget):
            missing.append(run_id(cfg))
            continue
        frames.append(read_run(cfg, budget).assign(label=label, figure=figure))
    if not frames:
        return pd.DataFrame()
    df = pd.concat(frames, ignore_index=True)
    write_csv_atomic(df, data_dir(budget) / f"{figure}.csv")
    if missing:
        print(f"warning: {figure} at budget {budget!r} leaves out {len(missing)} runs not on disk (missing_runs)")
    revisions = sorted(df["git_rev"].astype(str).unique())
    if len(revisions) > 1:  # cached runs outlive code changes; say so rather than mix silently
        print(f"warning: {figure} mixes runs from git revisions {[r[:7] for r in revisions]}")
    return df
