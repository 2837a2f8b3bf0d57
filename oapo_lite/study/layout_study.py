"""The layout study: which runs, on which generated layouts, at a budget, and the
tables its figure and notebook 16 read from them.

For every layout of ``envs.layouts.LAYOUTS``: OAPPO (sigma 0.1, lambda 0.7) against HAPPO for
steps to 95% of the optimum, MAPPO's final level, OAPPO at lambda in {0.2, 0.4, 0.7, 1}, and
the adaptive reuse rule (``adaptive.py``) with its one setting for all layouts.
Runs share the cache of ``experiments`` (``<data>/runs/<run id>.csv``), so a run is trained
once whichever family lists its layout. Training is one process at a time.
"""
from __future__ import annotations

import pandas as pd

from oapo_lite import store
from oapo_lite.envs.layouts import FAMILIES, LAYOUTS, load_layout, measure
from oapo_lite.neural.config import TrainConfig
from oapo_lite.study import experiments, figures, grid, verdicts

LAMBDAS = figures.mazes.LAMBDAS
ADAPTIVE = figures.mazes.ADAPTIVE_CURVES[0][0]  # gradient_test at the default sigma and lambda: one setting
# curve label -> the TrainConfig fields that make it; OAPPO's lambda = 0.7 is the "oappo" curve
CURVES = {"oappo": dict(algo="oappo"), "happo": dict(algo="happo"), "mappo": dict(algo="mappo")} | {
    f"oappo lambda={lam:g}": dict(algo="oappo", reuse_lambda=lam) for lam in LAMBDAS if lam != TrainConfig.reuse_lambda} | {
    ADAPTIVE: dict(figures.mazes.ADAPTIVE_CURVES[0][1])}


def layout_figures(layouts=None) -> list[grid.Figure]:
    """One grid entry per layout (not in ``figures.GRID``: the study is run on request)."""
    layouts = sorted(LAYOUTS) if layouts is None else list(layouts)
    unknown = sorted(set(layouts) - set(LAYOUTS))
    if unknown:
        raise ValueError(f"unknown layouts {unknown}; the study's layouts are {sorted(LAYOUTS)}")
    return [grid.Figure(f"layout_{name}", tuple(CURVES.items()), common=dict(env=f"layout:{name}"))
            for name in layouts]


def study_runs(budget: str, layouts=None) -> list[tuple[str, str, TrainConfig]]:
    """(layout, curve label, config) for every run of the study at ``budget``."""
    return [(fig.common["env"].removeprefix("layout:"), label, cfg)
            for fig in layout_figures(layouts) for label, cfg in figures.figure_runs(fig, budget)]


def load(budget: str, layouts=None) -> pd.DataFrame:
    """Tidy rows of the study, read from the run cache (``experiments.train_runs(budget,
    layout_figures())`` trains what is missing; ``export`` writes the study's table). Reads only."""
    frames = []
    for name, label, cfg in study_runs(budget, layouts):
        if not experiments.run_path(cfg, budget).exists():
            raise FileNotFoundError(f"run {cfg.run_id()} of layout {name} is not on disk: "
                                    f"{experiments.run_path(cfg, budget)}")
        frames.append(experiments.read_run(cfg, budget).assign(layout=name, label=label))
    return pd.concat(frames, ignore_index=True)


def export(df: pd.DataFrame, budget: str) -> None:
    """The whole study's runs, one row each (``per_run``), to ``<data>/fig_layout_study.csv``:
    what its figure is drawn from."""
    store.write_frame(per_run(df), experiments.data_dir(budget) / "fig_layout_study.csv")


RUN_FIELDS = ["algo", "env", "sigma", "reuse_lambda", "reuse_adapt", "steps", "git_rev"]  # what identifies a run


def per_run(df: pd.DataFrame) -> pd.DataFrame:
    """One row per run: layout, curve, seed, its config's defining fields and revision, and
    ``verdicts.per_run``'s steps to 95% of the optimum and final level."""
    runs = pd.concat({name: verdicts.per_run(rows) for name, rows in df.groupby("layout", sort=False)},
                     names=["layout", None]).reset_index(level=0).reset_index(drop=True)
    fields = [c for c in RUN_FIELDS if c in df.columns]
    if fields:
        runs = runs.merge(df.groupby(["layout", "label", "seed"], sort=False)[fields].first().reset_index(),
                          on=["layout", "label", "seed"], how="left")
    return runs


def describe() -> pd.DataFrame:
    """Per layout (row): what the oracle measures on the map, and for each family the value it
    varies there (column "<family> family"; NaN if the layout is not in it)."""
    rows = {name: measure(load_layout(name)) for name in sorted(LAYOUTS)}
    for family, (forks, attribute) in FAMILIES.items():
        for fork in forks:
            rows[fork.name][f"{family} family"] = getattr(fork, attribute)
    return pd.DataFrame.from_dict(rows, orient="index").rename_axis("layout")


def table(df: pd.DataFrame) -> pd.DataFrame:
    """Per layout and curve: seeds that reached 95%, and the IQMs of steps to 95% and of the
    final level with their 95% intervals."""
    return pd.concat({name: verdicts.intervals(rows) for name, rows in df.groupby("layout", sort=False)},
                     names=["layout", "label"])


def oappo_vs_happo(df: pd.DataFrame) -> pd.DataFrame:
    """Per layout: P(OAPPO reaches 95% of the optimum in fewer steps than HAPPO), with its interval."""
    rows = {}
    for name, runs in df.groupby("layout", sort=False):
        p = verdicts.Evidence(runs).improvement("oappo", "happo", "steps")
        rows[name] = {"p_oappo_faster": p.point, "low": p.low, "high": p.high}
    return pd.DataFrame.from_dict(rows, orient="index").rename_axis("layout")


def trapped(df: pd.DataFrame) -> pd.DataFrame:
    """Per layout (rows) and curve (columns): the seeds whose final level stayed below 95% of
    the optimum."""
    runs = per_run(df)
    return (runs["final"] < verdicts.THRESHOLD).groupby([runs["layout"], runs["label"]]).sum().unstack("label")


def fixed_curves() -> list[str]:
    """The fixed Eq. 9 settings of the study's grid: OAPPO at every lambda (sigma 0.1)."""
    return [label for label, kw in CURVES.items() if kw.get("algo") == "oappo" and "reuse_adapt" not in kw]


def adaptive_vs_best_fixed(df: pd.DataFrame, adaptive: str = ADAPTIVE) -> pd.DataFrame:
    """Per layout (or per maze: any frame with a "layout" column): the fixed setting that was
    fastest there (lowest IQM of steps to 95%, chosen on the same seeds, which favours it),
    P(``adaptive`` reaches 95% in fewer steps than it) and P(... than HAPPO) with their
    intervals, and the seeds of each of the three that stayed trapped below 95%."""
    rows = {}
    for name, runs in df.groupby("layout", sort=False):
        ev = verdicts.Evidence(runs)
        fixed = [c for c in fixed_curves() if c in ev.summary.index]
        best = min(fixed, key=lambda c: (ev.level(c, "steps").point, -ev.level(c, "final").point))
        p, p_happo = (ev.improvement(adaptive, other, "steps") for other in (best, "happo"))
        stuck = {c: int((ev.run_values(c, "final") < ev.threshold).sum()) for c in (adaptive, best, "happo")}
        rows[name] = {"best_fixed": best, "p_faster": p.point, "low": p.low, "high": p.high,
                      "p_vs_happo": p_happo.point, "low_happo": p_happo.low, "high_happo": p_happo.high,
                      "adaptive_steps": ev.level(adaptive, "steps").point, "best_steps": ev.level(best, "steps").point,
                      "trapped_adaptive": stuck[adaptive], "trapped_best": stuck[best], "trapped_happo": stuck["happo"],
                      "seeds": len(ev.run_values(adaptive, "final"))}
    return pd.DataFrame.from_dict(rows, orient="index").rename_axis("layout")
