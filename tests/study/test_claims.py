"""The cross-budget claim table reads only budgets whose runs are all on disk."""
import numpy as np
import pytest

from oapo_lite.study import claims, experiments, figures, tables, verdicts

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
    assert claims.on_disk("fig5b", "paper") and not claims.on_disk("fig5b", "paper20")
    table = claims.table(("fig5b",))
    assert set(table["budget"]) == {"paper (5 seeds)"}
    assert (table["verdict"] == verdicts.REPRODUCED).all()  # every claim of Fig. 5b holds in this fake data
    assert len(table) == len(figures.get_figure("fig5b").claims)


def test_the_readme_carries_the_claims_table_the_data_gives():
    """The README's copy of the claims table is what the committed runs give today."""
    block, table = claims.readme_block(), claims.glance()
    assert block == claims.readme_markdown(table), "the README's claims table is stale: run python -m oapo_lite.study.claims"
    assert block.endswith(claims.markdown(table))
    assert all(f"- *{status}*: {meaning}." in block for status, meaning in verdicts.STATUSES.items())


def test_glance_names_the_runs_it_is_missing(tmp_path, monkeypatch):
    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    first = next(f for f in figures.GRID if f.claims and f.runs_at is None)
    with pytest.raises(FileNotFoundError, match=rf"run\(s\) of {first.id} at budget 'cpu' are not on disk .*reproduce"):
        claims.glance()
    engine = next(f for f in figures.GRID if f.claims and f.runs_at is not None and "paper20" not in f.runs_at)
    with pytest.raises(ValueError, match=rf"{engine.id} has no runs at budget 'paper20'"):
        claims._verdicts(engine, "paper20", required=True)


def test_glance_budgets_are_shares_of_the_paper():
    assert claims.budget_share("fig3b", None) == "240k steps x 5 seeds; our budget, the paper gives none"
    assert claims.budget_share("fig6b", "grf:academy_3_vs_1_with_keeper") == \
        "32k steps x 3 seeds = 0.13% of 25M (HARL's tuned GRF steps)"
    assert claims.budget_share("fig4_smax", "smax:6h_vs_8z") == "1M steps x 5 seeds = 2.5% of 40M (HARL's steps for the map)"
    assert claims.budget_share("fig4_smax", "smax:3s5z_vs_3s6z") == "3M steps x 3 seeds = 15% of 20M (HARL's steps for the map)"
    assert claims.budget_share("fig4_smax", "smax:MMM2_like_7m2M_vs_8m3M").startswith("not run at `cpu`")


def test_the_a2c_settings_are_what_their_committed_sweep_chooses():
    """``figures.smax.A2C_CHOSEN`` is the setting ``tables.sweep_table``'s rule picks from the committed
    SEAC / SePS sweep on 3m, per algorithm."""
    from oapo_lite.study import experiments

    df = experiments.read_figure("fig_a2c_smax", "cpu")[0]
    family = {label: label.split()[0] for label in df["label"].unique()}
    table = tables.sweep_table(df, family, verdicts.WIN_RATE)
    chosen = table[table["chosen"]]
    assert {f: tuple(df.loc[df["label"] == label, ["a2c_lr", "entropy_coef"]].iloc[0])
            for label, f in chosen["family"].items()} == figures.smax.A2C_CHOSEN


def test_each_familys_smax_setting_is_what_its_committed_sweep_chooses():
    """``figures.smax.SWEEP_CHOSEN`` (Fig. 4's learning rate, entropy and clip per family) is what the
    sweep's rule picks from the committed 2s3z sweep."""
    from oapo_lite.study import experiments

    df = experiments.read_figure("fig_sweep_2s3z", "cpu")[0]
    family = {label: label.split(" lr=")[0] for label in df["label"].unique()}
    table = tables.sweep_table(df, family, verdicts.WIN_RATE)
    chosen = table[table["chosen"]]
    assert {f: tuple(df.loc[df["label"] == label, ["lr", "entropy_coef", "clip"]].iloc[0])
            for label, f in chosen["family"].items()} == figures.smax.SWEEP_CHOSEN


# the condition each status's reason states (``verdicts._reason``, ``faster``'s veto, ``_undecidable``,
# ``reuse_gap``), so that a row can be checked to give the reason of its own status and no other's
REASONS = {
    verdicts.REPRODUCED: r": wholly (above|below|at or above) ", verdicts.CONTRADICTED: r": wholly on the other side of ",
    verdicts.WITHIN_NOISE: r": point estimate [^;]*, interval across ", verdicts.NOT: r": point estimate not ",
    verdicts.NOT_REUSE: r"reused across networks at [\d.]+% of its evaluated iterations .* below \d+%$",
    verdicts.SHARING: r"below \d+%: its seats share networks, so the claim tests parameter sharing$",
    verdicts.NOT_TESTABLE: r"(did not learn|fewer than 2 seeds on disk|^no seed of .* reached)", verdicts.NOT_RUN: verdicts.NO_RUN,
}


def test_every_row_of_the_glance_gives_the_reason_of_its_own_status_and_no_other():
    import re

    table = claims.glance()
    pairs = list(zip(table["verdict"], table["why"])) + [
        (v, why) for v, why in zip(table["at 5 seeds"], table["why at 5 seeds"]) if v in verdicts.STATUSES]
    for status, why in pairs:
        if status in (verdicts.NOT_REUSE, verdicts.SHARING) and verdicts.INTERVAL_ALONE in why:
            # why the runs did not test reuse, then what the interval read and its status
            why, inner, interval = re.fullmatch(rf"(.*); {verdicts.INTERVAL_ALONE} ([^:]*): (.*)", why).groups()
            assert re.search(REASONS[inner], interval), (inner, interval)
        assert re.search(REASONS[status], why), (status, why)
        assert not [s for s, pattern in REASONS.items() if s != status and re.search(pattern, why)], (status, why)
    # the summary counts every claim once, a row of claims without runs as its claims
    assert claims.summary(table).to_numpy().sum() == sum(len(f.claims) for f in figures.GRID if f.claims)


def test_the_conclusion_says_what_the_data_gives():
    """The README opens with the conclusion the committed runs give, and the conclusion's numbers
    and outcomes are those of the claims table, the layout study's runs and the ablation's
    verdicts, each recomputed here from its source."""
    from oapo_lite.study import conclusion, readme

    table = claims.glance()
    assert readme.block(conclusion.BEGIN, conclusion.END) == conclusion.opening(table), \
        "the README's opening is stale: run python -m oapo_lite.study.conclusion"
    text = " ".join(conclusion.findings(table))
    counts = claims.summary(table).loc["6.1"]
    assert f"{counts[verdicts.REPRODUCED]} claims reproduced, {counts.get(verdicts.CONTRADICTED, 0)} contradicted" in text
    # the layout study's runs below 95% at the end, counted here from its rows: a run's final level
    # is the mean of its last tenth of evaluations, at least FINAL_MIN of them
    from oapo_lite.study import layout_study
    rows = layout_study.load(conclusion.LAYOUT_BUDGET).sort_values("step")
    below = {}
    for (label, _, _), run in rows.groupby(["label", "layout", "seed"]):
        held = run["frac_opt"].dropna()
        k = max(verdicts.FINAL_MIN, int(round(0.1 * len(run))))
        below.setdefault(label, []).append(held.iloc[-k:].mean() < verdicts.THRESHOLD)
    assert (f"on {sum(below['oappo'])} of {len(below['oappo'])} runs against HAPPO's {sum(below['happo'])} of "
            f"{len(below['happo'])}") in text
    # every verdict of the ablation is named under its own test, with its status and interval or reason
    for figure in conclusion.SELECTION_FIGURES:
        fig = figures.get_figure(figure)
        for claim, v in zip(fig.claims, claims.judge(fig, experiments.load_figure(figure, "cpu", skip_missing=True))):
            key = conclusion.SELECTION_TESTS[tuple(claim[-2])]
            assert f"{key} {v.status} ({v.estimate if v.status in conclusion.DECIDED else v.reason}" in text, (key, v)
        # what reuse cost there: the sampled source against the weights, where both ran
        from oapo_lite.study import selection
        df = experiments.load_figure(figure, "cpu", skip_missing=True)
        for _, row in selection.estimators(df, figure).iterrows():
            assert selection.estimator_sentence(row, figure) in text
    helped, selected, tested = conclusion.outcome(conclusion.selection_results())
    assert set(selected) <= set(tested)
    assert ("Selection helped" in text) == bool(selected)
