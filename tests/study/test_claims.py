"""The claims tables, the README's copies and the conclusion are rendered from the verdict records
the committed runs give; the records do not depend on what is installed."""
import json
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from oapo_lite.study.catalogue import figures
from oapo_lite.study.catalogue.metrics import WIN_RATE
from oapo_lite.study.judge import verdicts
from oapo_lite.study.judge.records import MEANINGS, Status
from oapo_lite.study.report import claims, words
from oapo_lite.study.runs import experiments, readme
from oapo_lite.study.studies import tables

import fakes


def write_runs(figure, budget, plateau):
    """A fake finished run per (label, seed): a ramp to ``plateau[label]`` of the optimum."""
    for label, cfg in figures.figure_runs(figure, budget):
        fakes.write_run(cfg, budget, lambda steps: np.minimum(steps / 80_000, 1.0) * plateau[label])


def test_table_uses_complete_budgets_only(tmp_path, monkeypatch):
    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    with pytest.raises(FileNotFoundError, match="no budget"):
        claims.table(("fig5b",))
    write_runs("fig5b", "paper", {"NR": 1.0, "UR": 0.4, "RR": 1.0, "AR": 0.4})
    assert verdicts.on_disk("fig5b", "paper") and not verdicts.on_disk("fig5b", "paper20")
    table = claims.table(("fig5b",))
    assert set(table["budget"]) == {"paper (5 seeds)"}
    assert (table["verdict"] == Status.REPRODUCED.value).all()  # every claim of Fig. 5b holds in this fake data
    assert len(table) == len(figures.get_figure("fig5b").claims)
    with pytest.raises(TypeError, match="the string 'fig5b'"):  # a name, not a sequence of names
        claims.table("fig5b")


def test_the_readme_carries_the_claims_table_the_data_gives():
    block, table = claims.readme_block(), claims.glance_table()
    assert block == claims.readme_markdown(table), \
        "the README's claims table is stale: run python -m oapo_lite.study.report.conclusion"
    assert block.endswith(claims.markdown(table[claims.GLANCE_COLUMNS]))
    assert all(f"- *{status}*: {meaning}." in block for status, meaning in MEANINGS.items())


def test_glance_names_the_runs_it_is_missing(tmp_path, monkeypatch):
    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    first = next(f for f in figures.GRID if f.claims and f.runs_at is None)
    with pytest.raises(FileNotFoundError, match=rf"run\(s\) of {first.id} at budget 'cpu' are not on disk .*reproduce"):
        verdicts.glance()
    engine = next(f for f in figures.GRID if f.claims and f.runs_at is not None and "paper20" not in f.runs_at)
    with pytest.raises(ValueError, match=rf"figure '{engine.id}' has no runs at budget 'paper20'"):
        verdicts.at_budget(engine, "paper20", required=True)


def test_glance_budgets_are_shares_of_the_paper():
    assert claims.budget_share("fig3b", None) == "240k steps x 5 seeds; our budget, the paper gives none"
    assert claims.budget_share("fig6b", "grf:academy_3_vs_1_with_keeper") == \
        "32k steps x 3 seeds = 0.13% of 25M (HARL's tuned GRF steps)"
    assert claims.budget_share("fig4_smax", "smax:6h_vs_8z") == "1M steps x 5 seeds = 2.5% of 40M (HARL's steps for the map)"
    assert claims.budget_share("fig4_smax", "smax:3s5z_vs_3s6z") == "3M steps x 3 seeds = 15% of 20M (HARL's steps for the map)"
    assert claims.budget_share("fig4_smax", "smax:MMM2_like_7m2M_vs_8m3M").startswith("not run at `cpu`")
    assert claims.budget_share("figA_mamujoco", None, "student").startswith("not run at `student`")
    for env in ("smax:2s3z", None):  # a figure on one env needs no env named: its claims name none
        assert claims.budget_share("fig_dose_smax", env) == "1M steps x 10 seeds = 20% of 5M (HARL's steps for the map)"
    with pytest.raises(ValueError, match="differs by env: name one of"):  # which of its maps' steps?
        claims.budget_share("fig_selection_smax", None)
    for figure in figures.FIGURES:  # a share is of a budget the figure names, never the default's steps
        fig = figures.get_figure(figure)
        assert not fig.reference or "paper" in fig.budgets, figure
    for figure, env in (("fig4_smax", "smax:9m"), ("fig3b", "nonexistent_map"), ("figA_mamujoco", "mamujoco:Nope-1x1")):
        with pytest.raises(ValueError, match=f"has no curve on env {env!r}"):  # a name that names nothing
            claims.budget_share(figure, env)


def test_the_a2c_settings_are_what_their_committed_sweep_chooses():
    """``figures.smax.A2C_CHOSEN`` is the setting ``tables.sweep_table``'s rule picks from the committed
    SEAC / SePS sweep on 3m, per algorithm."""
    df = experiments.read_figure("fig_a2c_smax", "cpu")[0]
    family = {label: label.split()[0] for label in df["label"].unique()}
    chosen = tables.sweep_table(df, family, WIN_RATE).query("chosen")
    assert {f: tuple(df.loc[df["label"] == label, ["a2c_lr", "entropy_coef"]].iloc[0])
            for label, f in chosen["family"].items()} == figures.smax.A2C_CHOSEN


def test_each_familys_smax_setting_is_what_its_committed_sweep_chooses():
    df = experiments.read_figure("fig_sweep_2s3z", "cpu")[0]
    family = {label: label.split(" lr=")[0] for label in df["label"].unique()}
    chosen = tables.sweep_table(df, family, WIN_RATE).query("chosen")
    assert {f: tuple(df.loc[df["label"] == label, ["lr", "entropy_coef", "clip"]].iloc[0])
            for label, f in chosen["family"].items()} == figures.smax.SWEEP_CHOSEN


def test_every_row_says_what_its_record_holds_and_the_summary_counts_every_claim():
    judged = verdicts.glance()
    table = claims.glance_table(judged)
    leads = {j.lead.claim.text: j.lead for j in judged if j.lead.status != Status.NOT_RUN}
    for _, row in table[table["verdict"] != Status.NOT_RUN.value].iterrows():
        v = leads[row["claim"]]
        assert row["verdict"] == v.status.value and row["why"] == words.reason(v)
        if v.status in (Status.REPRODUCED, Status.WITHIN_NOISE, Status.NOT, Status.CONTRADICTED):
            assert v.interval_status == v.status  # no mechanism status: the interval decides
            assert all(words.estimate(e) in row["why"] for e in v.estimates[:2])
        elif v.status in (Status.NOT_REUSE, Status.SHARING, Status.NO_SELECTION):
            assert f"by the interval alone {v.interval_status}" in row["why"]
        assert ("rests on one seed" in row["seeds"]) == v.one_seed
    counts = claims.summary(table)
    assert counts.drop(columns="resting on one seed").to_numpy().sum() == \
        sum(len(f.claims) for f in figures.GRID if f.claims)
    assert counts["resting on one seed"].sum() == sum(j.lead.one_seed for j in judged)


ENGINES = ("jax", "jaxlib", "jaxmarl", "mujoco", "gymnasium_robotics", "gfootball")
RECORDS = """
import importlib.abc, json, sys


class NotInstalled(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name.split(".")[0] in {engines}:  # as where the engine is not installed
            raise ImportError(f"No module named {{name!r}}")


sys.meta_path.insert(0, NotInstalled())
for name in {engines}:
    try:
        __import__(name)
        raise SystemExit(f"{{name}} is still importable")
    except ImportError:
        pass
from oapo_lite.study.judge import verdicts
from oapo_lite.study.report import words
print(json.dumps([[j.lead.claim.text, j.lead.status.value, words.reason(j.lead)] for j in verdicts.glance()]))
"""


def test_the_verdicts_are_the_same_with_every_engine_unimportable():
    """Each run recorded its seats' networks, so judging needs no engine: the same records, word
    for word, where JAX, MuJoCo and GRF cannot be imported."""
    out = subprocess.run([sys.executable, "-c", RECORDS.format(engines=ENGINES)], capture_output=True, text=True,
                         check=True).stdout
    here = [[j.lead.claim.text, j.lead.status.value, words.reason(j.lead)] for j in verdicts.glance()]
    assert json.loads(out.splitlines()[-1]) == here


def test_the_conclusion_and_its_headlines_are_the_readmes():
    from oapo_lite.study.report import conclusion

    judged = verdicts.glance()
    assert readme.block(conclusion.BEGIN, conclusion.END) == conclusion.opening(judged), \
        "the README's opening is stale: run python -m oapo_lite.study.report.conclusion"
    assert readme.block(*conclusion.HEADLINES) == conclusion.headlines(judged)


def test_the_ablation_table_prints_every_estimate_a_verdict_read():
    """A selection claim reads two intervals (against no reuse and against always-on) and holds
    only if both do: its row prints both, so no verdict stands beside half of its evidence."""
    from oapo_lite.study.report import conclusion

    judged = verdicts.glance()
    table = conclusion.ablation_table(judged)
    both = table["claim"].str.contains("before both|ends above both")
    assert both.any() and (table.loc[both, "estimate"].str.count("vs ") == 2).all()
    assert (table.loc[~both, "estimate"].str.count("vs ") <= 1).all()


def test_the_opening_counts_what_an_interval_decided_and_the_layouts_runs():
    """The opening's numbers recomputed from their sources: the layout study's runs below 95% at
    the end (a run's final level is the mean of its last tenth of evaluations, at least 3), and
    the heterogeneous SMAX maps where an interval decided OAPPO against MAPPO (the whole interval
    on one side: ties are not decided)."""
    from oapo_lite.study.report import conclusion
    from oapo_lite.study.studies import layout_study

    judged = verdicts.glance()
    text = conclusion.opening(judged)
    rows = layout_study.load(conclusion.LAYOUT_BUDGET).sort_values("step")
    below = {}
    for (label, _, _), run in rows.groupby(["label", "layout", "seed"]):
        k = max(3, int(round(0.1 * len(run))))
        below.setdefault(label, []).append(run["frac_opt"].iloc[-k:].mean() < 0.95)
    assert (f"on {sum(below['oappo'])} of {len(below['oappo'])} runs against HAPPO's {sum(below['happo'])} of "
            f"{len(below['happo'])}") in text
    heads = [j.lead for j in judged if j.figure.id == "fig4_smax" and j.lead.claim.headline]
    decided = [v for v in heads if v.status in (Status.REPRODUCED, Status.CONTRADICTED)]
    ran = [v for v in heads if v.status != Status.NOT_RUN]
    assert f"held on {sum(v.status == Status.REPRODUCED for v in decided)} of the {len(ran)} maps with runs" in text
    assert (f"the 95% interval decided it on {len(decided)}, "
            f"{sum(v.status == Status.CONTRADICTED for v in decided)} of them against the claim") in text
