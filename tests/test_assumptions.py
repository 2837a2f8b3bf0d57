"""ASSUMPTIONS.md quotes numbers measured on the committed runs; these tests recompute some of
them from ``figures/data/`` with the package and fail when the text no longer says what the data
gives (a rerun, a changed window or rule, or an edit of the text). Each test builds the exact
string the text quotes, so a stale number is named in the failure. Nothing is trained."""
from __future__ import annotations

import functools
import re
from pathlib import Path

import numpy as np
import pytest

from oapo_lite.study.catalogue import figures
from oapo_lite.study.catalogue.metrics import RETURN, WIN_RATE
from oapo_lite.study.judge import evidence as ev_
from oapo_lite.study.judge.statistics import iqm
from oapo_lite.study.runs import experiments
from oapo_lite.study.studies import tables

ASSUMPTIONS = Path(__file__).resolve().parents[1] / "ASSUMPTIONS.md"


@pytest.fixture(autouse=True)
def _committed_figures(monkeypatch):
    monkeypatch.delenv("OAPO_FIGURES", raising=False)  # the committed runs, whatever the shell says


@functools.cache
def text() -> str:
    """ASSUMPTIONS.md with every run of white space as one space (quotes may wrap)."""
    return " ".join(ASSUMPTIONS.read_text().split())


@functools.cache
def load(figure: str, budget: str):
    return experiments.load_figure(figure, budget)


def metric_rows(figure: str, budget: str, env: str | None = None):
    """A figure's rows with the metric's columns alone: what a final level or a step count reads."""
    column, df = figures.get_figure(figure).metric.column, load(figure, budget)
    return df.loc[df["env"] == env if env else slice(None), ["label", "seed", "step", column]]


def evidence(figure: str, budget: str, env: str | None = None) -> ev_.Evidence:
    df = load(figure, budget)
    if env is not None:
        df = df[df["env"] == env]
    return ev_.Evidence(df, figures.get_figure(figure).metric)


def quoted(expected: str) -> None:
    assert " ".join(expected.split()) in text(), f"ASSUMPTIONS.md does not say {expected!r} (what the data gives)"


def pct(x: float) -> str:
    return f"{x:.0%}"


def test_mappo_trap_on_black_red():
    levels = {b: evidence("fig3b", b).level("mappo", "final").point for b in ("paper", "paper20")}
    assert f"{levels['paper']:.3f}" == f"{levels['paper20']:.3f}"
    quoted(f"MAPPO ends at a final IQM of {levels['paper']:.3f} of the optimum")


def test_reuse_while_learning_on_black_red():
    five, twenty = evidence("fig3b", "paper").summary, evidence("fig3b", "paper20").summary
    last = {five.loc["oatrpo", "last_reuse_step"], twenty.loc["oatrpo", "last_reuse_step"]}
    assert len(last) == 1
    quoted(f"Black-Red OAPPO {pct(five.loc['oappo', 'reusing'])} at 5 seeds, OATRPO "
           f"{pct(five.loc['oatrpo', 'reusing'])} at 5 and {pct(twenty.loc['oatrpo', 'reusing'])} at 20 seeds "
           f"(last open at {last.pop():,.0f} steps)")


def finals(figure: str, budget: str, env: str) -> dict:
    """Per curve on ``env``, the final IQM a verdict reads (``Evidence.level(label, "final")``'s
    point), from the metric's columns alone: the seats' networks, which need the engine, do not
    enter a final level."""
    metric = figures.get_figure(figure).metric
    runs = ev_.per_run(metric_rows(figure, budget, env), metric)
    return {label: float(iqm(part["final"].to_numpy())) for label, part in runs.groupby("label", sort=False)}


def test_fig4_final_levels():
    level = finals("fig4_smax", "cpu", "smax:2s3z")
    names = {"oappo type": "per type", "oappo one seat": "one seat", "mappo": "MAPPO", "oatrpo": "OATRPO",
             "oappo": "per agent", "happo": "HAPPO"}
    quoted(", ".join(f"{name} {level[label]:.3f}" for label, name in names.items()))
    level = finals("fig4_smax", "cpu", "smax:3s5z_vs_3s6z")
    quoted(f"MAPPO {level['mappo']:.3f}, per type {level['oappo type']:.3f}, HAPPO {level['happo']:.3f}")
    level = finals("fig4_smax", "cpu", "smax:3m")
    quoted(f"final IQM SePS {level['seps']:.3f}, SEAC {level['seac']:.3f}")


def _sweep(figure: str):
    family = {label: re.split(r" lr=", label)[0] for label, _ in figures.get_figure(figure).curves}
    return tables.sweep_table(metric_rows(figure, "cpu"), family, WIN_RATE)


def test_sweep_on_2s3z():
    t = _sweep("fig_sweep_2s3z")
    lrs = {5e-4: "5e-4", 1e-3: "1e-3", 2e-3: "2e-3"}
    for family, (lr, ent, clip) in figures.smax.SWEEP_CHOSEN.items():
        rows = t[t["family"] == family]
        final = {label: rows.loc[label, "final"] for label in rows.index}
        grid_cells = " | ".join(f"{final[f'{family} lr={x:g} ent=0']:.3f} / {final[f'{family} lr={x:g} ent=0.01']:.3f}"
                                for x in figures.smax.SWEEP_LRS)
        clips = " / ".join(f"{final[f'{family} lr={lr:g} ent={ent:g} clip={c:g}']:.3f}" for c in figures.smax.SWEEP_CLIPS)
        chosen = rows[rows["chosen"]]
        assert list(chosen.index) == [f"{family} lr={lr:g} ent={ent:g}"], f"{family}: the rule chose {list(chosen.index)}"
        steps = chosen["steps"].iloc[0]
        quoted(f"| {family} | {grid_cells} | {lrs[lr]}, {ent:g}, {clip:g} ({steps:,.0f}")
        quoted(f"| {clips} |")


def test_a2c_sweep_on_3m():
    t = _sweep("fig_a2c_smax")
    seac, seps = t.loc["seac lr=0.003 ent=0.01", "final"], t.loc["seps lr=0.003 ent=0.01", "final"]
    ref_seac, ref_seps = t.loc["seac lr=0.0003 ent=0.01", "final"], t.loc["seps lr=0.0003 ent=0.01", "final"]
    assert t.loc["seac lr=0.003 ent=0.01", "chosen"] and t.loc["seps lr=0.003 ent=0.01", "chosen"]
    quoted(f"final win rate SEAC {seac:.3f}, SePS {seps:.3f} there, {ref_seac:.3f} and {ref_seps:.3f} at the "
           "reference settings")


def test_entropy_weight():
    ev = ev_.Evidence(metric_rows("fig_entropy_weight", "paper"))
    weighted = figures.get_figure("fig_entropy_weight").curves[1][0]
    p = ev.improvement(weighted, "oappo", "steps")
    quoted(f"steps to 95% IQM {ev.level('oappo', 'steps').point:,.0f} unweighted against "
           f"{ev.level(weighted, 'steps').point:,.0f} weighted, P(weighted faster) {p.fmt('.2f')}")


def test_early_reuse_on_halfcheetah():
    ev = ev_.Evidence(metric_rows("fig_early_reuse", "cpu"), RETURN)
    runs, d = ev.pairs("oappo", "happo"), ev.paired("oappo", "happo")
    quoted(f"OAPPO - HAPPO = {d.fmt('.0f')}, the IQM of the seed pairs' differences (OAPPO lower on "
           f"{(runs['difference'] < 0).sum()} of {len(runs)}")


def test_halfcheetah_settings_and_anchor():
    runs = ev_.per_run(metric_rows("fig_mamujoco_settings", "cpu"), RETURN)
    final = runs.groupby("label", sort=False)["final"]
    mean, std = final.mean(), final.std(ddof=1)
    names = {"happo": "ours", "happo clip 0.05": "clip 0.05", "happo 15 epochs": "15 epochs",
             "happo 128x3": "128-128-128", "happo feature norm": "feature normalisation", "happo 20 x 200": "20 x 200",
             "happo HARL": "all together"}
    quoted("; ".join(f"{name} {mean[label]:.0f} +- {std[label]:.0f}" for label, name in names.items()))
    ev = ev_.Evidence(metric_rows("fig_single_agent", "cpu"), RETURN)
    quoted(f"HAPPO two legs {ev.level('happo two legs', 'final').fmt('.0f')}")
    quoted(f"our PPO with one agent {ev.level('ppo one agent', 'final').fmt('.0f')}")
