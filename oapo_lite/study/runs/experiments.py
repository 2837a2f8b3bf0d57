"""Running the grid: where results live (``figures/``, ``figures/data/``), the run cache
(``<data>/runs/<run id>.csv``, checked when read), training what is missing and loading a
figure's rows.

Runs are trained by an executor (``executors``: this machine's processes, or a Ray cluster);
the driver writes each run's evaluation rows to the cache atomically once the run has
finished, so a reproduction that is interrupted resumes by skipping what is on disk; a
figure's CSV is the concatenation of its runs, with a ``label`` column naming the curve each
row belongs to. What the runs are is the grid's (``figures.GRID``).
"""
from __future__ import annotations

import csv
import functools
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from oapo_lite.algorithms import ALGOS
from oapo_lite.cli import boolean, names, output_folder, workers as cli_workers
from oapo_lite.envs import registry as env_registry
from oapo_lite.envs.maps import load_maze
from oapo_lite.neural import results
from oapo_lite.neural.config import TrainConfig
from oapo_lite.store import DamagedFile, is_file, read_arrays, regular_file, write_frame
from oapo_lite.study.catalogue.figures import FIGURES, figure_runs, get_figure, required_runs, runs_of
from oapo_lite.study.catalogue.grid import COMMITTED, SHARED_RUNS, Run

ROOT = Path(__file__).resolve().parents[3]


def figures_dir(budget: str) -> Path:
    """The committed budgets' figures live in figures/; others go to a side folder.

    ``OAPO_FIGURES`` moves the whole tree elsewhere (the timing benchmark uses it so as not
    to touch the committed results); set but empty, it counts as unset (not the working folder).
    A relative one is resolved against the working folder; a command resolves it once at its
    start (``reproduce.main``), so that notebooks, which run in ``notebooks/``, read the same tree.
    """
    moved = os.environ.get("OAPO_FIGURES")
    root = output_folder(moved, "OAPO_FIGURES") if moved else ROOT / "figures"
    return root if budget in COMMITTED else root / budget


def data_dir(budget: str) -> Path:
    return figures_dir(budget) / "data"


def runs_dir(budget: str) -> Path:
    """Where a budget's finished runs (``<run id>.csv``) and their checkpoints are cached."""
    return data_dir(COMMITTED[0] if budget in SHARED_RUNS else budget)


def run_path(cfg: TrainConfig, budget: str) -> Path:
    return runs_dir(budget) / "runs" / f"{cfg.run_id()}.csv"


def read_run(cfg: TrainConfig, budget: str) -> pd.DataFrame:
    """A finished run's rows from the cache, checked against its config: every evaluation row
    of the run, in order, with its seed and algorithm, each value within its column's range
    (``results.COLUMNS``). A file that is not whole raises ``DamagedFile`` naming it (``run_all``
    then trains the run again). A file read before and unchanged since is not read again."""
    path = run_path(cfg, budget)
    # FileNotFoundError: not on disk; a folder, a FIFO or a device is not a damaged result but
    # something the cache must neither read nor overwrite (NotAFile)
    stat = regular_file(path, "run file")
    version = (path, stat.st_mtime_ns, stat.st_size)  # the path names the config
    if version not in _CHECKED:
        if len(_CHECKED) > 4096:
            _CHECKED.clear()
        _CHECKED[version] = _read_checked(path, cfg)
    return _CHECKED[version].copy()


_CHECKED: dict[tuple, pd.DataFrame] = {}  # run files already read and checked, by version


def _read_checked(path: Path, cfg: TrainConfig) -> pd.DataFrame:
    """``read_run``'s work."""
    try:
        df = pd.read_csv(path)
    except FileNotFoundError:
        raise
    except Exception as err:  # not text, not CSV, empty
        raise DamagedFile(f"run file {path} is damaged ({type(err).__name__}: {err}); {RETRAIN}") from None
    with open(path, newline="") as f:  # pandas renames a second "step" to "step.1" and reads on
        header = next(csv.reader(f), [])
    twice = sorted({c for c in header if header.count(c) > 1})
    if twice:
        raise DamagedFile(f"run file {path} names the columns {twice} twice in its header (line 1); {RETRAIN}")
    needed = ["algo", "seed", "iteration", "step", "eval_return", "frac_opt", "eval_success", "git_rev"]
    if [c for c in needed if c not in df.columns]:
        raise DamagedFile(f"run file {path} lacks the columns {[c for c in needed if c not in df.columns]}; {RETRAIN}")
    steps = pd.to_numeric(df["step"], errors="coerce")
    if len(df) != len(cfg.eval_steps) or steps.isna().any() or list(steps) != cfg.eval_steps:
        wrong = next((i for i, (a, b) in enumerate(zip(steps, cfg.eval_steps)) if a != b), min(len(df), len(steps)))
        at = (f"its step column at row {wrong + 1} holds {df['step'].iloc[wrong]!r} where the config evaluates at "
              f"{cfg.eval_steps[wrong]}" if wrong < min(len(df), len(cfg.eval_steps)) else
              f"it has {len(df)} rows where the config has {len(cfg.eval_steps)} evaluations")
        raise DamagedFile(f"run file {path} is not the whole run: {at} (its evaluation steps run from "
                          f"{cfg.eval_steps[0]} to {cfg.eval_steps[-1]} every {cfg.eval_every * cfg.iteration_steps}); "
                          f"{RETRAIN}")
    older = [c for c in results.STRUCTURE if c not in df.columns]
    if older:  # not damaged: written before runs recorded what they are
        raise OlderRun(f"run file {path} lacks the columns {older}, which runs record since the study stopped reading "
                       "them from the installed engines; add them with `python -m oapo_lite.study.runs.migrate`")
    missing = [c for c in FAMILY_COLUMNS[ALGOS[cfg.algo].a2c] if c not in df.columns]
    if missing:  # what every run of its algorithm's family writes
        raise DamagedFile(f"run file {path} lacks the columns {missing} that every {cfg.algo} run writes; {RETRAIN}")
    if df["git_rev"].isna().any():
        raise DamagedFile(f"run file {path} has a row without its git revision (row "
                          f"{int(np.flatnonzero(df['git_rev'].isna())[0]) + 1}); {RETRAIN}")
    differ = _config_differs(df, cfg)
    if differ:
        raise DamagedFile(f"run file {path} holds another run's rows: its {differ} column does not say "
                          f"{cfg.flat()[differ]!r}; {RETRAIN}")
    try:
        df = read_arrays(df, MATRICES)
    except ValueError as err:  # not JSON
        raise DamagedFile(f"run file {path} is damaged: {err}; {RETRAIN}") from None
    try:
        _check_iterations(df, cfg)
        results.check(df, cfg.flat())
        check_levels(df, cfg.env if cfg.env_fn is None else None)
    except results.BadRows as err:
        raise DamagedFile(f"run file {path} is damaged: {err}; {RETRAIN}") from None
    return df


MATRICES = ("kl_matrix", "reuse_matrix", "agreement", "kl_nearest", "owner")  # per-row arrays, JSON in the file


class OlderRun(ValueError):
    """A whole run file written before runs recorded what they are (``results.STRUCTURE``)."""


# the columns every run of a family writes (the PPO / TRPO family's, the A2C family's); the others
# came later, so an older run file may lack them
FAMILY_COLUMNS = {False: ("objective", "value_loss", "kl_matrix", "reuse_matrix"),
                  True: ("policy_loss", "value_loss", "entropy")}


def _check_iterations(df: pd.DataFrame, cfg: TrainConfig) -> None:
    """Every row's iteration is its step's (``results.check`` reads it)."""
    for i, (it, step) in enumerate(zip(pd.to_numeric(df["iteration"], errors="coerce"), df["step"])):
        if not it * cfg.iteration_steps == step:  # NaN (text) too
            it = df["iteration"].iloc[i]
            it = it.item() if isinstance(it, np.generic) else it
            raise results.BadRows(f"its iteration column at row {i + 1} (step {step}) holds {it!r}; allowed: step / "
                                  f"(n_envs x rollout length) = {step / cfg.iteration_steps:g}")


def check_levels(df: pd.DataFrame, env: str | None = "column", rows: np.ndarray | None = None) -> None:
    """What a row's env fixes beyond ``results.check``: on a maze, whose episodes always end and
    whose optimum the oracle knows, every evaluation has a return, a success rate and that
    return's fraction of the optimum. ``env``: the env of every row (None: no maze's), or by
    default each row's ``env`` column (a figure's runs, handed to ``verdicts.judge``); ``rows``:
    the rows' numbers in the messages (by default their positions)."""
    rows = np.arange(len(df)) if rows is None else rows
    if env == "column":
        for each in (df["env"].dropna().unique() if "env" in df else ()):
            mine = (df["env"] == each).to_numpy()
            check_levels(df[mine], each, rows[mine])
        return
    if env is None or env_registry.maze_of(env) is None:
        return
    steps = df["step"].tolist() if "step" in df else [None] * len(df)
    for name in (c for c in ("eval_return", "frac_opt", "eval_success") if c in df):
        empty = np.flatnonzero(df[name].isna().to_numpy())
        if len(empty):
            i = empty[0]
            raise results.BadRows(f"its {name} column at row {rows[i] + 1} (step {steps[i]}) is empty; allowed: a "
                                  "number (a maze's evaluation episodes always end)")
    if {"eval_return", "frac_opt"} <= set(df):
        optimum = _optimum(env)
        ret, frac = (pd.to_numeric(df[c], errors="coerce").to_numpy(float) for c in ("eval_return", "frac_opt"))
        wrong = np.flatnonzero(~np.isclose(frac * optimum, ret, rtol=1e-9, atol=1e-9))
        if len(wrong):
            i = wrong[0]
            raise results.BadRows(f"its frac_opt column at row {rows[i] + 1} (step {steps[i]}) holds {float(frac[i])!r}; "
                                  f"allowed: eval_return / the maze's optimum = {float(ret[i] / optimum)!r}")


@functools.cache
def _optimum(env: str) -> float:
    from oapo_lite.envs.oracle import optimal_return

    return optimal_return(env_registry.maze_of(env))


def _config_differs(df: pd.DataFrame, cfg: TrainConfig) -> str | None:
    """The first config field whose column in a run file disagrees with ``cfg``, or None. A
    column the file lacks is a field added since it was written: its default is what ran."""
    changed = cfg.changed()
    for name, value in cfg.flat().items():
        if name not in df:
            if name in changed:
                return name
            continue
        column = df[name]
        if value is None:
            same = column.isna().all()
        elif isinstance(value, (bool, np.bool_)) or isinstance(value, str):
            same = (column.astype(str) == str(value)).all()
        else:
            numbers = pd.to_numeric(column, errors="coerce")
            same = numbers.notna().all() and np.allclose(numbers.to_numpy(float), float(value), rtol=1e-12, atol=0)
        if not same:
            return name
    return None


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


def grid_runs(budget: str, figures=FIGURES) -> list[Run]:
    """The distinct runs of some figures (a run shared by two figures is trained once)."""
    runs, seen = [], set()
    for fig in names(figures, "figures"):
        for run in runs_of(fig, budget):
            if run.cfg.run_id() not in seen:
                seen.add(run.cfg.run_id())
                runs.append(run)
    return runs


@dataclass
class Failure:
    run: Run
    error: str  # the traceback

    def report(self) -> str:
        return (f"run {self.run.cfg.run_id()} of {self.run.figure} (curve {self.run.label!r}) failed\n"
                f"  config (non-default fields): {self.run.cfg.changed()}\n{self.error.rstrip()}")


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
    done: int  # trained by this call
    cached: int  # on disk before it, or finished by another process while it waited (``train_job``)
    failed: list[Failure] = field(default_factory=list)


def run_all(budget: str, figures=None, workers: int = 2, progress: bool | str = True,
            executor: str = "local", address: str | None = None) -> RunCount:
    """Train every run of the given figures that is not on disk yet, on ``executor``: "local"
    (``workers`` processes of this machine) or "ray" (a Ray cluster at ``address``; None starts
    one on this machine). Whatever trains a run, this driver writes its CSV. A run that fails
    is reported (config and traceback) and the others go on; see ``RunCount.failed``.
    ``progress``: True (a bar), "lines" (one line per run, for logs) or False. ``figures``: None
    for every figure (one without runs at ``budget`` has nothing to train), else figures that
    have runs there (``required_runs``), or one figure's name."""
    from tqdm import tqdm

    from oapo_lite.study.runs import executors

    if executor not in executors.EXECUTORS:
        raise ValueError(f"unknown executor {executor!r}; choose from {sorted(executors.EXECUTORS)}")
    workers = cli_workers(workers, "workers")
    if progress != "lines" and not isinstance(progress, (bool, np.bool_)):
        raise TypeError(f"run_all's progress must be True, False or \"lines\", got {progress!r}")
    if figures is None:
        figures = FIGURES
    else:
        figures = (figures,) if isinstance(figures, str) else figures  # one figure's name
        for figure in figures:
            required_runs(figure, budget)
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
    jobs = [(run, str(checkpoints / run.cfg.run_id())) for run in missing]
    failed, elsewhere = [], 0
    with tqdm(total=len(missing), desc=f"runs ({budget}, {executor})", disable=progress is not True) as bar:
        for k, (run, rows, error, trained) in enumerate(executors.EXECUTORS[executor](jobs, workers=workers,
                                                                                       address=address), 1):
            elsewhere += error is None and not trained
            if error is None:
                write_frame(rows, run_path(run.cfg, budget))
            elif error.startswith(executors.RESOURCE):  # every other run would fail alike: stop them all
                raise OSError(error.removeprefix(executors.RESOURCE))
            else:
                failed.append(Failure(run, error))
                tqdm.write(failed[-1].report(), file=sys.stderr)
            bar.set_postfix_str(run.cfg.run_id())
            bar.update()
            if progress == "lines":
                print(f"runs ({budget}, {executor}): {k}/{len(missing)} {'done' if error is None else 'FAILED'} "
                      f"{run.cfg.run_id()}", flush=True)
    for figure in figures:
        export_figure(figure, budget)
    return RunCount(done=len(missing) - len(failed) - elsewhere, cached=len(todo) - len(missing) + elsewhere,
                    failed=failed)


def export_figure(figure, budget: str) -> Path | None:
    """Write a grid figure's rows to ``<data>/<figure>.csv`` (what a researcher opens) once every
    run of it is on disk; the writer of the run cache does this, so that reading never writes.
    An unchanged file is left alone. Returns the path written, or None."""
    name = getattr(figure, "id", figure)
    if name not in FIGURES or not runs_of(name, budget) or missing_runs(name, budget):
        return None  # not a grid figure, no runs at this budget, or not all of them yet
    df, _ = read_figure(name, budget)
    path = data_dir(budget) / f"{name}.csv"
    old = path.read_bytes() if is_file(path, "figure file") else None
    staged = path.with_name(f".{path.name}.new")
    write_frame(df, staged)
    if staged.read_bytes() == old:
        staged.unlink()
        return None
    os.replace(staged, path)
    return path


def missing_runs(figure: str, budget: str) -> list[Run]:
    """The runs of ``figure`` at ``budget`` that are not on disk yet (or damaged); none for a
    figure without runs there (notebook 20 asks at every budget)."""
    return [r for r in runs_of(figure, budget) if not on_disk(r.cfg, budget)]


def train_runs(budget: str, figures, workers: int = 2) -> None:
    """Train the runs of ``figures`` at ``budget`` that are not on disk yet, and raise if any
    failed: loading a figure never trains, so a notebook that may train says so with this call."""
    figures = names(figures, "train_runs' figures")
    failed = run_all(budget, figures=figures, workers=workers, progress=False).failed
    if failed:
        raise RuntimeError(f"{len(failed)} run(s) of {[get_figure(f).id for f in figures]} failed "
                           "(reported above)")


def versions(figure: str, budget: str) -> tuple:
    """(path, modification time, size) of every run file of ``figure`` at ``budget`` (absent:
    None): what a result computed from them is keyed by, so that it is computed again when a
    run file changes."""
    out = []
    for _, cfg in figure_runs(figure, budget):
        path = run_path(cfg, budget)
        try:
            stat = path.stat()
            out.append((str(path), stat.st_mtime_ns, stat.st_size))
        except FileNotFoundError:
            out.append((str(path), None))
    return tuple(out)


def read_figure(figure: str, budget: str, skip_missing: bool = False) -> tuple[pd.DataFrame, list[str]]:
    """The tidy rows of one figure from the run cache, and the ids of the runs left out (only
    with ``skip_missing``; otherwise a run not on disk raises naming it): those not on disk and,
    in a ``paired`` figure, those on a seed that another curve of their env has not run yet. A
    figure with no runs at ``budget`` is refused, or with ``skip_missing`` read as empty (the
    tables that show what is on disk at any budget). Reads only."""
    if not boolean(skip_missing, "skip_missing"):
        required_runs(figure, budget)
    frames, missing = [], []
    runs = figure_runs(figure, budget)
    if get_figure(figure).paired:
        runs, unpaired = _paired(runs, budget)
        missing += unpaired
    for label, cfg in runs:
        try:
            frames.append(read_run(cfg, budget).assign(label=label, figure=figure))
            continue
        except FileNotFoundError:
            if not skip_missing:
                raise FileNotFoundError(f"run {cfg.run_id()} of {figure} (curve {label!r}) is not on disk; train it "
                                        f"with `python -m oapo_lite reproduce --budget {budget} --figures {figure}` "
                                        "or experiments.train_runs") from None
        except DamagedFile as err:
            if not skip_missing:
                raise
            print(f"warning: {err}", file=sys.stderr)
        missing.append(cfg.run_id())
    return (pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()), missing


def _paired(runs: list, budget: str) -> tuple[list, list[str]]:
    """The (label, config) pairs of ``runs`` on the (env, seed)s whose every run is on disk, and
    the ids of the others that are on disk (a seed-paired figure reads a seed whole or not at all)."""
    there = {cfg.run_id(): on_disk(cfg, budget) for _, cfg in runs}
    whole: dict[tuple, bool] = {}
    for _, cfg in runs:
        whole[cfg.env, cfg.seed] = whole.get((cfg.env, cfg.seed), True) and there[cfg.run_id()]
    keep = [(label, cfg) for label, cfg in runs if whole[cfg.env, cfg.seed]]
    return keep, [cfg.run_id() for _, cfg in runs if not whole[cfg.env, cfg.seed] and there[cfg.run_id()]]


def load_figure(figure: str, budget: str, skip_missing: bool = False) -> pd.DataFrame:
    """``read_figure``, saying what it left out. A figure with no runs at ``budget`` is refused,
    naming the budgets it has runs at; with ``skip_missing`` (a notebook that shows what is on
    disk at any budget) it is an empty frame and a warning that says so. Reads only: nothing is
    trained (``train_runs``) and nothing written (``export_figure``)."""
    if boolean(skip_missing, "skip_missing") and not runs_of(figure, budget):  # a bad name still raises here
        try:
            required_runs(figure, budget)
        except ValueError as err:
            print(f"warning: {err}")
            return pd.DataFrame()
    required_runs(figure, budget)
    df, missing = read_figure(figure, budget, skip_missing)
    if df.empty:
        return df
    if missing:
        print(f"warning: {figure} at budget {budget!r} leaves out {len(missing)} runs not on disk (missing_runs)")
    revisions = sorted(df["git_rev"].astype(str).unique())
    if len(revisions) > 1:  # cached runs outlive code changes; say so rather than mix silently
        print(f"warning: {figure} mixes runs from git revisions {[r[:7] for r in revisions]}")
    return df
