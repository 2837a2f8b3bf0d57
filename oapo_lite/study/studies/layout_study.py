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
from oapo_lite.study.catalogue.figures.layouts import ADAPTIVE, CURVES, study_runs
from oapo_lite.study.runs import experiments
from oapo_lite.study.catalogue.metrics import THRESHOLD
from oapo_lite.study.judge import evidence

def load(budget: str, layouts=None) -> pd.DataFrame:
    """Tidy rows of the study, read from the run cache (``experiments.train_runs(budget,
    catalogue.figures.layouts.layout_figures())`` trains what is missing; ``export`` writes the study's table). Reads only."""
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
    ``evidence.per_run``'s steps to 95% of the optimum and final level."""
    runs = pd.concat({name: evidence.per_run(rows) for name, rows in df.groupby("layout", sort=False)},
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
    return pd.concat({name: evidence.intervals(rows) for name, rows in df.groupby("layout", sort=False)},
                     names=["layout", "label"])


def oappo_vs_happo(df: pd.DataFrame) -> pd.DataFrame:
    """Per layout: P(OAPPO reaches 95% of the optimum in fewer steps than HAPPO), with its interval."""
    rows = {}
    for name, runs in df.groupby("layout", sort=False):
        p = evidence.Evidence(runs).improvement("oappo", "happo", "steps")
        rows[name] = {"p_oappo_faster": p.point, "low": p.low, "high": p.high}
    return pd.DataFrame.from_dict(rows, orient="index").rename_axis("layout")


def trapped(df: pd.DataFrame) -> pd.DataFrame:
    """Per layout (rows) and curve (columns): the seeds whose final level stayed below 95% of
    the optimum."""
    runs = per_run(df)
    return (runs["final"] < THRESHOLD).groupby([runs["layout"], runs["label"]]).sum().unstack("label")


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
        ev = evidence.Evidence(runs)
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
