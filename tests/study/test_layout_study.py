"""The layout study's grid: every curve on every layout, cached like the figures' runs."""
import numpy as np
import pytest

from oapo_lite.envs.layouts import LAYOUTS
from oapo_lite.study.catalogue import figures
from oapo_lite.study.catalogue.figures import layouts
from oapo_lite.study.studies import layout_study

import fakes


def test_grid_has_every_curve_on_every_layout_once():
    runs = layouts.study_runs("paper")
    assert len(runs) == len(LAYOUTS) * 7 * 5  # 7 curves, 5 seeds
    assert len({cfg.run_id() for *_, cfg in runs}) == len(runs)
    by_label = {label: cfg for _, label, cfg in runs}
    assert {c.reuse_lambda for c in by_label.values() if c.algo == "oappo"} == set(figures.mazes.LAMBDAS)
    assert by_label["happo"].algo == "happo" and by_label["mappo"].algo == "mappo"
    assert by_label[layouts.ADAPTIVE].reuse_adapt == "gradient_test"
    assert sum(c.reuse_adapt is not None for c in by_label.values()) == 1
    assert all(cfg.env == f"layout:{name}" for name, _, cfg in runs)


def test_unknown_layout_and_missing_runs_raise(tmp_path, monkeypatch):
    with pytest.raises(ValueError, match="unknown layouts \\['nowhere'\\]"):
        layouts.study_runs("smoke", ["nowhere"])
    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    with pytest.raises(FileNotFoundError, match="is not on disk"):
        layout_study.load("smoke")


def test_tables_read_the_runs(tmp_path, monkeypatch):
    # fake finished runs: OAPPO reaches the optimum at 32k steps on every seed, the adaptive rule
    # at 48k, lambda = 0.2 stays at 20% of it, every other curve reaches it at 64k
    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    name = sorted(LAYOUTS)[0]
    reach = {"oappo": 32_000, layouts.ADAPTIVE: 48_000}
    for _, label, cfg in layouts.study_runs("paper", [name]):
        fakes.write_run(cfg, "paper", lambda steps: np.minimum(steps / reach.get(label, 64_000), 1.0)
                        * (0.2 if label == "oappo lambda=0.2" else 1.0))
    df = layout_study.load("paper", [name])
    table = layout_study.table(df)
    assert table.loc[(name, "oappo"), "steps_iqm"] == 32_000 and table.loc[(name, "happo"), "steps_iqm"] == 64_000
    assert layout_study.oappo_vs_happo(df).loc[name].tolist() == [1.0, 1.0, 1.0]
    runs = layout_study.per_run(df)
    assert len(runs) == 7 * 5 and set(runs["layout"]) == {name}
    assert (runs.loc[runs["label"] == "oappo", "steps_to_threshold"] == 32_000).all()
    stuck = layout_study.trapped(df).loc[name]
    assert stuck["oappo lambda=0.2"] == 5 and stuck.drop("oappo lambda=0.2").eq(0).all()
    vs = layout_study.adaptive_vs_best_fixed(df).loc[name]
    assert vs["best_fixed"] == "oappo" and (vs["p_faster"], vs["high"]) == (0.0, 0.0)  # slower on every seed
    assert (vs["p_vs_happo"], vs["low_happo"]) == (1.0, 1.0)
    assert (vs["adaptive_steps"], vs["best_steps"], vs["trapped_adaptive"], vs["seeds"]) == (48_000, 32_000, 0, 5)


def test_describe_names_what_each_family_varies():
    desc = layout_study.describe()
    assert sorted(desc.index) == sorted(LAYOUTS)
    base = "fork-p2-c3-b4-s3-h3"  # in every family
    assert desc.loc[base, ["first_move family", "shared_prefix family", "conflicts family"]].tolist() == ["shared", 2, 3]
    assert desc["conflicts family"].dropna().to_dict() == {f"fork-p2-c{c}-b4-s3-h3": c for c in (1, 3, 5, 7)}
    assert (desc["route_red"] == 16).all() and (desc["route_black"] == 16).all()
