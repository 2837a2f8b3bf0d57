"""Verdicts are functions of the data: synthetic curves and samples with a known answer."""
import numpy as np
import pandas as pd
import pytest
from scipy import stats

from oapo_lite.study.catalogue import figures
from oapo_lite.study.catalogue.metrics import RETURN, WIN_RATE
from oapo_lite.study.catalogue.tests import Claim
from oapo_lite.study.judge import evidence as ev_, statistics, verdicts as v
from oapo_lite.study.judge.records import Status
from oapo_lite.study.report import words
from oapo_lite.study.studies import tables

judge = v.judge
REPRODUCED, WITHIN_NOISE, NOT, CONTRADICTED = Status.REPRODUCED, Status.WITHIN_NOISE, Status.NOT, Status.CONTRADICTED
NOT_TESTABLE, NOT_RUN, NOT_REUSE, SHARING, NO_SELECTION = (Status.NOT_TESTABLE, Status.NOT_RUN, Status.NOT_REUSE,
                                                           Status.SHARING, Status.NO_SELECTION)


def curves(spec, seeds=5, steps=np.arange(0, 100_001, 5_000), noise=0.0):
    """spec: label -> (steps at which the curve hits 1.0 (linear ramp from 0), plateau)."""
    rng = np.random.default_rng(0)
    rows = []
    for label, (reach, plateau) in spec.items():
        for seed in range(seeds):
            r = reach * (1 + noise * rng.standard_normal())
            frac = np.minimum(steps / r, 1.0) * plateau
            rows += [dict(label=label, seed=seed, step=s, frac_opt=f) for s, f in zip(steps, frac)]
    return pd.DataFrame(rows)


def evidence(spec, **kw):
    return ev_.Evidence(curves(spec, **kw))


def check(ev, test, curves_, text="x"):
    """``test`` on ``curves_`` judged on ``ev``."""
    return v.check(ev, Claim(text, test, tuple(curves_)))


# --- the statistics against hand computations ---------------------------------------------

def test_iqm_is_the_mean_of_the_middle_half():
    assert statistics.iqm(np.array([7.0, 1, 100, 3, 5, 2, 4, 6])) == pytest.approx((3 + 4 + 5 + 6) / 4)
    assert statistics.iqm(np.array([0.0, 10, 1, 2, 3])) == pytest.approx((1 + 2 + 3) / 3)  # 5 seeds: middle three
    assert statistics.iqm(np.array([[1.0, 2, 3, 4], [10, 20, 30, 400]])).tolist() == pytest.approx([2.5, 25.0])


def test_probability_of_improvement_known_cases():
    low, high = np.arange(5.0), np.arange(5.0) + 10
    assert statistics.probability_of_improvement(high, low) == 1.0  # dominating sample
    assert statistics.probability_of_improvement(low, high) == 0.0
    assert statistics.probability_of_improvement(low, low) == 0.5  # identical samples
    # by hand: pairs (x, y) with x > y count 1, ties 1/2: 1 vs {0, 1, 2} -> 1 + .5 + 0; 3 vs it -> 3
    assert statistics.probability_of_improvement([1.0, 3.0], [0.0, 1.0, 2.0]) == pytest.approx(4.5 / 6)


def test_probability_of_improvement_is_the_mann_whitney_statistic():
    rng = np.random.default_rng(1)
    x, y = rng.integers(0, 6, 12).astype(float), rng.integers(0, 6, 9).astype(float)  # with ties
    u = stats.mannwhitneyu(x, y, alternative="greater").statistic
    assert statistics.probability_of_improvement(x, y) == pytest.approx(u / (len(x) * len(y)))


def test_degenerate_samples_give_zero_width_intervals_at_the_true_value():
    est = statistics.bootstrap_interval(statistics.iqm, np.full(5, 0.216))
    assert (est.point, est.low, est.high) == pytest.approx((0.216, 0.216, 0.216))
    p = statistics.bootstrap_interval(statistics.probability_of_improvement, np.full(5, 2.0), np.full(7, 1.0))
    assert (p.point, p.low, p.high) == (1.0, 1.0, 1.0)
    tie = statistics.bootstrap_interval(statistics.probability_of_improvement, np.full(5, 1.0), np.full(5, 1.0))
    assert (tie.point, tie.low, tie.high) == (0.5, 0.5, 0.5)


def test_dominating_sample_keeps_probability_one_under_resampling():
    rng = np.random.default_rng(2)
    p = statistics.bootstrap_interval(statistics.probability_of_improvement, rng.normal(10, 1, 5), rng.normal(0, 1, 5))
    assert (p.point, p.low, p.high) == (1.0, 1.0, 1.0)


@pytest.mark.parametrize("statistic", [np.mean, statistics.iqm])
def test_bootstrap_interval_covers_a_known_mean(statistic):
    # N(1, 1): mean and IQM both estimate 1 (a symmetric distribution). 300 samples of 20,
    # a 95% interval: the coverage should be near 0.95 (binomial sd 0.013; percentile
    # intervals run a little short at n = 20).
    rng = np.random.default_rng(3)
    hits = [est.low <= 1.0 <= est.high for est in
            (statistics.bootstrap_interval(statistic, rng.normal(1.0, 1.0, 20), n_resamples=2000, seed=i) for i in range(300))]
    assert 0.89 <= np.mean(hits) <= 0.99


def test_bootstrap_is_reproducible_and_seeded():
    x = np.random.default_rng(4).normal(size=10)
    assert statistics.bootstrap_interval(statistics.iqm, x) == statistics.bootstrap_interval(statistics.iqm, x)
    assert statistics.bootstrap_interval(statistics.iqm, x, seed=1) != statistics.bootstrap_interval(statistics.iqm, x, seed=2)


def test_one_run_has_no_interval():
    est = statistics.bootstrap_interval(statistics.iqm, [0.5])
    assert est.point == 0.5 and np.isnan(est.low) and np.isnan(est.high)
    assert "no interval" in est.fmt()


def test_bad_confidence_statistic_and_label_raise():
    with pytest.raises(ValueError, match="confidence must lie in"):
        statistics.bootstrap_interval(statistics.iqm, [1.0, 2.0], confidence=95)
    ev = evidence({"a": (10_000, 1.0)})
    with pytest.raises(ValueError, match="unknown run statistic 'reward'.*final"):
        ev.run_values("a", "reward")
    with pytest.raises(ValueError, match="no runs labelled 'b'"):
        ev.run_values("b", "final")


# --- per-run numbers and verdicts ---------------------------------------------------------

def test_per_run_steps_and_censoring():
    df = curves({"a": (40_000, 1.0), "b": (40_000, 0.5)}, seeds=1)
    runs = ev_.per_run(df).set_index("label")
    assert runs.loc["a", "steps_to_threshold"] == 40_000  # first grid point with 40k/40k >= 0.95
    assert runs.loc["a", "reached"] and not runs.loc["b", "reached"]
    assert runs.loc["b", "steps_to_threshold"] == 100_000  # censored at the last step
    assert runs.loc["b", "final"] == pytest.approx(0.5)


def test_intervals_table_matches_per_run_values():
    df = curves({"fast": (20_000, 1.0), "low": (20_000, 0.5)}, noise=0.05)
    table = ev_.intervals(df)
    runs = ev_.per_run(df)
    fast = runs.loc[runs["label"] == "fast", "steps_to_threshold"]
    assert table.loc["fast", "steps_iqm"] == pytest.approx(stats.trim_mean(fast, 0.25))
    assert table.loc["low", ["final_iqm", "final_low", "final_high"]].tolist() == pytest.approx([0.5] * 3)
    assert (table["steps_low"] <= table["steps_iqm"]).all() and (table["steps_iqm"] <= table["steps_high"]).all()


def test_faster_and_higher_directions():
    ev = evidence({"fast": (20_000, 1.0), "slow": (80_000, 1.0), "low": (20_000, 0.5)}, noise=0.05)
    assert check(ev, "faster", ("fast", "slow")).status == REPRODUCED
    assert check(ev, "faster", ("slow", "fast")).status == CONTRADICTED  # the whole interval says the opposite
    assert check(ev, "higher", ("fast", "low")).status == REPRODUCED
    assert check(ev, "higher", ("low", "fast")).status == CONTRADICTED
    assert words.lead_estimate(check(ev, "faster", ("fast", "slow"))) == "P(fast faster) 1.000 [1.000, 1.000]"


def test_within_noise_is_the_point_estimate_alone():
    ev = evidence({"a": (50_000, 1.0), "b": (51_000, 1.0)}, noise=0.3)
    verdict = check(ev, "faster", ("a", "b"))
    assert verdict.status in (WITHIN_NOISE, NOT) and not verdict.held


def test_better_uses_final_then_speed():
    ev = evidence({"hi": (80_000, 1.0), "lo": (10_000, 0.6), "twin": (20_000, 1.0)})
    assert check(ev, "better", ("hi", "lo")).held  # higher plateau wins despite being slower
    assert not check(ev, "better", ("lo", "hi")).held
    tie = check(ev, "better", ("twin", "hi"))
    assert tie.held and tie.by_speed  # same plateau: decided by speed
    assert words.lead_estimate(tie).startswith("P(twin faster)") and "so speed decides" in words.reason(tie)


def test_stuck_and_optimal():
    ev = evidence({"stuck": (10_000, 0.5), "ok": (10_000, 1.0)})
    assert check(ev, "stuck", ("stuck",)).held and not check(ev, "stuck", ("ok",)).held
    assert check(ev, "optimal", ("ok",)).held and not check(ev, "optimal", ("stuck",)).held


def test_stuck_with_some_seeds_escaping_is_within_noise():
    # 3 seeds stuck at half the optimum, 2 reach it: IQM (0.5 + 0.5 + 1) / 3 < 0.95, but
    # resamples with 4 or 5 escaping seeds (probability 0.087 > 2.5%) put the interval above.
    df = pd.concat([curves({"a": (10_000, 0.5)}, seeds=3),
                    curves({"a": (10_000, 1.0)}, seeds=2).assign(seed=lambda d: d["seed"] + 3)])
    verdict = check(ev_.Evidence(df), "stuck", ("a",))
    assert verdict.status == WITHIN_NOISE
    assert words.lead_estimate(verdict).startswith("IQM final 0.667 [")


def test_figure_claims_follow_the_data():
    good = curves({"mappo": (20_000, 0.5), "happo": (90_000, 1.0), "oappo": (50_000, 1.0),
                   "oatrpo": (30_000, 1.0), "hatrpo": (60_000, 1.0)})
    assert all(x.held for x in judge("fig3b", good))
    bad = curves({"mappo": (20_000, 1.0), "happo": (30_000, 1.0), "oappo": (50_000, 1.0),
                  "oatrpo": (90_000, 1.0)})
    held = {x.claim.text: x.held for x in judge("fig3b", bad)}
    assert not held["MAPPO (shared parameters) stays below the optimum"]
    assert not held["OATRPO converges faster than OAPPO"]
    sentence = words.sentence(judge("fig3b", bad)[0])
    assert "contradicted" in sentence and "mappo 1.000 [1.000, 1.000]" in sentence


def test_one_seed_is_never_more_than_the_point_estimate():
    ev = evidence({"fast": (20_000, 1.0), "slow": (80_000, 1.0)}, seeds=1)
    assert v.ESTIMATORS["improvement"](ev, Claim("x", "faster", ("fast", "slow"))).status == WITHIN_NOISE
    assert check(ev, "faster", ("fast", "slow")).status == NOT_TESTABLE  # fewer than 2 seeds: step 1


def test_speed_reads_censored_times_alone_and_reliability_is_its_own_question():
    # a: 3 seeds converge at 20k, 2 never do; b: every seed converges, later.
    a = curves({"a": (20_000, 1.0)}, seeds=3)
    a_stuck = curves({"a": (20_000, 0.5)}, seeds=2).assign(seed=lambda d: d["seed"] + 3)
    b = curves({"b": (70_000, 1.0)})
    ev = ev_.Evidence(pd.concat([a, a_stuck, b]))
    s = ev.summary
    assert s.loc["a", "reached"] == 3 and s.loc["a", "steps_mean"] < s.loc["b", "steps_mean"]
    # a censored seed ranks behind every seed that got there: P = (3 x 5 wins) / 25 pairs
    verdict = check(ev, "faster", ("a", "b"))
    assert words.lead_estimate(verdict).startswith("P(a faster) 0.600 ") and verdict.status == WITHIN_NOISE
    assert "3/5 seeds reached" in words.evidence(verdict)
    # "as reliably": 3/5 against 5/5, a difference of -0.4 whose interval reaches 0: not reproduced; a tie holds
    late = check(ev, "reliable", ("a", "b"))
    assert late.status == NOT and words.lead_estimate(late).startswith("share reached, a minus b: -0.400 [")
    assert check(ev, "reliable", ("b", "b")).status == REPRODUCED
    never = pd.concat([curves({"a": (20_000, 0.5)}, seeds=8), curves({"b": (70_000, 1.0)}, seeds=8)])
    assert check(ev_.Evidence(never), "reliable", ("a", "b")).status == CONTRADICTED
    # with no seed of either curve there, neither question can be asked
    nowhere = check(evidence({"a": (20_000, 0.5), "b": (20_000, 0.6)}), "reliable", ("a", "b"))
    assert nowhere.status == NOT_TESTABLE and nowhere.gap.kind == "reached"


def test_unknown_figure_and_claims_that_do_not_fit_their_test_raise():
    with pytest.raises(ValueError, match="fig9"):
        judge("fig9", curves({"a": (1, 1.0)}))
    with pytest.raises(ValueError, match="unknown test 'quicker'"):
        Claim("x", "quicker", ("a", "b"))
    with pytest.raises(ValueError, match="test 'selects' compares 3 curve"):
        Claim("x", "selects", ("a", "b"))


def win_curves(spec, seeds=5, env="smax:2s3z"):
    """spec: label -> list of win rates at evaluation points 0, 10k, 20k, ..."""
    rows = [dict(label=label, seed=seed, env=env, step=10_000 * k, eval_success=w + 0.01 * seed)
            for label, wins in spec.items() for seed in range(seeds) for k, w in enumerate(wins)]
    return pd.DataFrame(rows)


def test_stabler_compares_the_largest_drop_below_an_earlier_peak():
    df = win_curves({"steady": [0, 0.3, 0.6, 0.8, 0.8], "shaky": [0, 0.6, 0.1, 0.7, 0.8]})
    ev = ev_.Evidence(df, WIN_RATE)
    runs = ev.runs.set_index("label")
    assert runs.loc["shaky", "drawdown"].tolist() == pytest.approx([0.5] * 5)
    assert check(ev, "stabler", ("steady", "shaky")).held
    assert check(ev, "stabler", ("shaky", "steady")).status == CONTRADICTED


def test_win_rate_claims_are_not_testable_where_the_data_cannot_decide():
    learned = {"oappo": [0, 0.6, 0.9, 0.9], "mappo": [0, 0.1, 0.2, 0.3], "happo": [0, 0.1, 0.6, 0.7]}
    out = {x.claim.text: x for x in judge("fig4_smax", win_curves(learned))}
    assert out["2s3z: OAPPO (a net per agent) ends above MAPPO (heterogeneous agents)"].held
    assert out["2s3z: OAPPO (a net per agent) converges faster than HAPPO"].held
    assert out["6h_vs_8z: OAPPO (a net per agent) ends above MAPPO"].status == NOT_RUN  # no run on that map
    assert out["2s3z: OAPPO (a net per type) ends above MAPPO (heterogeneous agents)"].status == NOT_TESTABLE
    nothing = win_curves({k: [0, 0.0, 0.01, 0.0] for k in learned})  # peaks <= 0.05
    assert {x.status for x in judge("fig4_smax", nothing)} == {NOT_TESTABLE, NOT_RUN}  # maps without runs: not run
    one_seed = {x.claim.text: x for x in judge("fig4_smax", win_curves(learned, seeds=1))}
    verdict = one_seed["2s3z: OAPPO (a net per agent) ends above HAPPO (heterogeneous agents)"]
    assert verdict.status == NOT_TESTABLE and "fewer than 2 seeds" in words.reason(verdict)
    never_half = win_curves({"oappo": [0, 0.2, 0.3, 0.4], "happo": [0, 0.1, 0.3, 0.3], "mappo": [0, 0.1, 0.1, 0.1]})
    out = {x.claim.text: x for x in judge("fig4_smax", never_half)}
    assert out["2s3z: OAPPO (a net per agent) converges faster than HAPPO"].status == NOT_TESTABLE
    assert out["2s3z: OAPPO (a net per agent) ends above HAPPO (heterogeneous agents)"].status != NOT_TESTABLE


def test_returns_figures_are_judged_on_the_return_and_absent_curves_have_no_data():
    # App. A: HAPPO plateaus at 1000, MAPPO at 400 (and OAPPO at 900); SEAC has no runs
    df = curves({"happo": (50_000, 1000.0), "mappo": (50_000, 400.0), "oappo": (50_000, 900.0)}, noise=0.1)
    df = df.rename(columns={"frac_opt": "eval_return"}).assign(frac_opt=np.nan)
    out = {x.claim.text: x for x in judge("figA_mamujoco", df)}
    sharing = out["full sharing (MAPPO) ends below no reuse (HAPPO)"]
    assert sharing.held and "final evaluation return, IQM [95% CI] over seeds: happo 1000.000" in words.evidence(sharing)
    assert out["OAPPO (a net per agent) ends above full sharing (MAPPO)"].held
    seac = out["direct reuse (SEAC) ends below no reuse (HAPPO)"]
    assert seac.status == NOT_TESTABLE and "seac (0)" in words.reason(seac) and not seac.held
    swapped = df.assign(label=df["label"].replace({"happo": "mappo", "mappo": "happo"}))
    assert not {x.claim.text: x for x in judge("figA_mamujoco", swapped)}[
        "full sharing (MAPPO) ends below no reuse (HAPPO)"].held
    assert all(x.status == NOT_RUN for x in judge("figA_mamujoco", pd.DataFrame()))


def test_grf_claims_are_judged_per_scenario_on_the_score():
    rows = [dict(label=label, seed=seed, env=f"grf:academy_{scenario}", step=10_000 * k, eval_success=w)
            for scenario, spec in {"3_vs_1_with_keeper": {"happo": [0, 0.5, 0.95, 0.97, 0.96, 0.98]},
                                   "counterattack_easy": {"oappo": [0, 0.4, 0.8, 0.8, 0.8, 0.8],
                                                          "mappo": [0, 0.1, 0.2, 0.2, 0.2, 0.2]}}.items()
            for label, wins in spec.items() for seed in range(5) for k, w in enumerate(wins)]
    out = {x.claim.text: x for x in judge("fig6b", pd.DataFrame(rows))}
    assert out["3_vs_1_with_keeper: own experience alone (HAPPO) scores nearly perfectly"].held
    assert out["counterattack_easy: OAPPO ends above MAPPO"].held
    assert "final score" in words.evidence(out["counterattack_easy: OAPPO ends above MAPPO"])
    assert out["counterattack_easy: OAPPO ends above SEAC"].status == NOT_TESTABLE  # no SEAC run there
    assert out["counterattack_hard: OATRPO ends above HAPPO"].status == NOT_RUN  # no run of that scenario
    assert out["pass_and_shoot_with_keeper: own experience alone (HAPPO) scores nearly perfectly"].status == NOT_RUN


# --- the rule judges only what learned ------------------------------------------------------

def _fig3b(spec, seeds=5):
    return pd.concat([curves({k: val}, seeds=seeds) if isinstance(val, tuple) else val.assign(label=k)
                      for k, val in spec.items()])


def flat(level, seeds=5, steps=np.arange(0, 100_001, 5_000), lucky=None):
    """A curve that never leaves ``level``; ``lucky``: (seed, step, value) of one outlier evaluation."""
    df = pd.DataFrame([dict(seed=s, step=t, frac_opt=level) for s in range(seeds) for t in steps])
    if lucky is not None:
        seed, step, value = lucky
        df.loc[(df["seed"] == seed) & (df["step"] == step), "frac_opt"] = value
    return df


def test_a_flat_curve_is_not_testable_and_says_which_curve():
    df = _fig3b({"mappo": flat(-0.5), "happo": (90_000, 1.0), "oappo": (50_000, 1.0), "oatrpo": (30_000, 1.0)})
    out = {x.claim.text: x for x in judge("fig3b", df)}
    stuck = out["MAPPO (shared parameters) stays below the optimum"]
    assert stuck.status == NOT_TESTABLE  # below the optimum, but because it learned nothing
    assert ("mappo did not learn (initial -0.5, final -0.5: gain +0 +- 0 s.e. over 5 seeds, not above 2 s.e.)"
            in words.reason(stuck))
    assert out["OAPPO converges faster than HAPPO"].status == REPRODUCED  # both learned


def test_one_lucky_evaluation_is_not_learning():
    lucky = flat(-0.5, lucky=(2, 50_000, 1.0))
    df = _fig3b({"mappo": lucky, "happo": (90_000, 1.0), "oappo": (50_000, 1.0), "oatrpo": (30_000, 1.0)})
    ev = ev_.Evidence(df)
    assert ev.runs.loc[ev.runs["label"] == "mappo", "peak"].max() == 1.0
    assert not ev_.learned(ev, "mappo")
    assert judge("fig3b", df)[0].status == NOT_TESTABLE
    one_seed = flat(-0.5)
    one_seed.loc[(one_seed["seed"] == 0) & (one_seed["step"] >= 90_000), "frac_opt"] = 1.0
    assert not ev_.learned(ev_.Evidence(one_seed.assign(label="x")), "x")


def test_win_rates_below_the_floor_did_not_learn():
    ev = ev_.Evidence(win_curves({"a": [0, 0.01, 0.02, 0.02, 0.02, 0.02, 0.02]}), WIN_RATE)
    why = ev_.not_learned(ev, "a")
    assert why.failures == ("floor",)  # the reason names the test that failed, not the one that passed
    assert words.not_learned(why).endswith(": final IQM 0.04, not above the floor 0.05)")


def test_two_learned_curves_with_p_above_one_half_are_reproduced():
    ev = evidence({"fast": (20_000, 1.0), "slow": (80_000, 1.0)}, noise=0.05)
    assert ev_.learned(ev, "fast") and ev_.learned(ev, "slow")
    verdict = check(ev, "faster", ("fast", "slow"))
    assert verdict.status == REPRODUCED and words.reason(verdict).endswith("wholly above 0.5")


def test_the_printed_rule_names_every_step():
    for word in ("Not testable", "did not learn", "reproduced", "contradicted", "within noise", "not reproduced",
                 "not a test of reuse", "a test of sharing", "not a test of selection", "never shut", "25%", "90%",
                 "without each seed", "one peer"):
        assert word in v.RULE


def test_a_paired_difference_is_the_iqm_of_each_seeds_own_difference():
    """The pairs differ by exactly 1 while the seeds spread over hundreds, so an interval over
    pairs is the point 1, which an unpaired comparison could not show; a seed with one run only
    is left out; one seed far off moves the IQM of the differences no more than a curve's IQM."""
    steps = np.arange(10) * 100
    rows = []
    for seed, (level, gap) in enumerate([(1000.0, 1.0), (1300.0, 1.0), (800.0, 1.0), (1900.0, 1.0), (1050.0, 500.0),
                                         (1007.0, None)]):
        for label, shift in (("a", gap), ("b", 0.0)):
            if shift is None:
                continue
            y = np.r_[np.zeros(7), level + shift + np.arange(3)]
            rows += [{"label": label, "seed": seed, "step": s, "eval_return": x} for s, x in zip(steps, y)]
    ev = ev_.Evidence(pd.DataFrame(rows), RETURN)
    pairs = ev.pairs("a", "b")
    assert pairs.index.tolist() == [0, 1, 2, 3, 4] and pairs["difference"].tolist() == pytest.approx([1, 1, 1, 1, 500])
    d = ev.paired("a", "b")
    assert d.point == pytest.approx(1.0)  # IQM of five: the middle three, all 1 (the mean would be 100.8)
    verdict = check(ev, "paired_higher", ("a", "b"))
    assert verdict.status == REPRODUCED and verdict.estimates[0].higher_on == 5


def test_reuse_table_reads_reuse_and_final_values_per_env_and_label():
    shared, own = [[0.5, 0.5], [0.5, 0.5]], [[1.0, 0.0], [0.0, 1.0]]
    rows = []
    for env, mappo_owner in (("e1", [0, 0]), ("e2", [0, 1])):
        for label, m, every, owner in (("mappo", shared, 1.0, mappo_owner), ("happo", own, 0.0, [0, 1])):
            for seed in (0, 1):
                rows += [{"env": env, "label": label, "seed": seed, "step": s, "reuse_matrix": m, "owner": owner,
                          "iterations_reusing": every, "eval_return": float(s >= 7) * (seed + 1)} for s in range(10)]
    t = tables.reuse_table(pd.DataFrame(rows), RETURN)
    assert t.index.tolist() == [("e1", "mappo"), ("e1", "happo"), ("e2", "mappo"), ("e2", "happo")]
    assert t["seeds"].tolist() == [2] * 4 and t["all_iterations"].tolist() == [1.0, 0.0, 1.0, 0.0]
    assert t["mean_peer_share"].tolist() == [0.5, 0.0, 0.5, 0.0]
    assert t["mean_across_nets"].tolist() == [0.0, 0.0, 0.5, 0.0]  # one net on e1: no reuse across nets
    assert t["across_reusing"].tolist() == [0.0, 0.0, 1.0, 0.0]
    assert tables.reuse_table(pd.DataFrame(rows).assign(reuse_matrix=None), RETURN).empty  # SEAC-like runs
    assert t["final"].tolist() == [1.5] * 4  # seeds' last fifth (at least 3 evaluations): 1 and 2


def test_sweep_table_chooses_the_best_final_value_and_breaks_ties_by_speed():
    rows = []
    for label, level, reach in (("a", 0.9, 7), ("b", 0.89, 2), ("c", 0.5, 9), ("d", 0.3, 10)):
        for seed in (0, 1):
            rows += [{"label": label, "seed": seed, "step": s * 10, "eval_success": level if s >= reach else 0.0}
                     for s in range(10)]
    t = tables.sweep_table(pd.DataFrame(rows), {"a": "f", "b": "f", "c": "f", "d": "g"}, WIN_RATE)
    assert t["chosen"].to_dict() == {"a": False, "b": True, "c": False, "d": True}
    assert t.loc["b", "steps"] == 20 and t.loc["d", "steps"] == 90  # never reached 0.5: counted at its end
    assert t.loc["a", "final"] == pytest.approx(0.9) and t["seeds"].tolist() == [2] * 4


# --- what the runs tested: reuse across networks, read the same on every metric --------------

SHARED, OWN = np.array([[0.7, 0.3], [0.3, 0.7]]), np.eye(2)


def with_reuse(df, reusing, owner=(0, 1)):
    """``df`` with each curve's algorithm (its label), its seats' networks ``owner`` and its reuse
    matrix M per evaluation: ``reusing[label]`` picks the steps at which M gave a peer weight."""
    df = df.assign(algo=df["label"])
    df["reuse_matrix"] = [SHARED if label in reusing and reusing[label](step) else OWN
                          for label, step in zip(df["label"], df["step"])]
    df["owner"] = [np.array(owner)] * len(df)
    return df


def test_a_claim_about_oappo_is_no_test_of_reuse_when_its_gate_closed_early():
    # OAPPO's ramp starts at 0.05 (its first tenth: 0 and 0.1) and ends at 1: 90% of that way, 0.905, is
    # first reached at 50k, evaluation 11 of 21; it gave peers weight at the first 2 (0 and 5k): 2 of 11 < 25%
    base = _fig3b({"mappo": (90_000, 0.6), "happo": (90_000, 1.0), "oappo": (50_000, 1.0), "oatrpo": (30_000, 1.0)})
    closed = with_reuse(base, {"oappo": lambda s: s <= 5_000, "oatrpo": lambda s: True})
    out = {x.claim.text: x for x in judge("fig3b", closed)}
    verdict = out["OAPPO converges faster than HAPPO"]
    assert verdict.status == NOT_REUSE and verdict.interval_status == REPRODUCED
    r = verdict.reuse[0]
    assert (r.while_learning, r.last_open, r.networks, r.sharing) == (pytest.approx(2 / 11), 5_000, 2, False)
    assert words.reason(verdict).startswith("the gate last opened across networks at 5,000 steps; oappo reused across "
                                            "networks at 18.2% of its evaluated iterations while it learned")
    assert "by the interval alone reproduced: P(oappo faster) 1.000" in words.reason(verdict)
    assert out["OAPPO ends above MAPPO"].status == NOT_REUSE
    assert out["OATRPO converges faster than HAPPO"].status == REPRODUCED  # OATRPO reused throughout
    opened = with_reuse(base, {"oappo": lambda s: True, "oatrpo": lambda s: True})
    assert {x.claim.text: x for x in judge("fig3b", opened)}["OAPPO converges faster than HAPPO"].status == REPRODUCED


def test_reuse_while_learning_ends_at_ninety_percent_of_the_gain_on_every_metric():
    """The same curve, scaled to a fraction of the optimum, a win rate or a return, reads the same
    share: the learning phase ends at its first evaluation at 90% of its way to its final value."""
    ramp = curves({"oappo": (50_000, 1.0)})  # reaches 90% of its gain at 50k: evaluations 0-50k, 11 of them
    shares = []
    for metric, scale in ((None, 1.0), (WIN_RATE, 0.9), (RETURN, 3000.0)):
        df = ramp.assign(frac_opt=ramp["frac_opt"] * scale)
        if metric is not None:
            df = df.rename(columns={"frac_opt": metric.column})
        ev = ev_.Evidence(with_reuse(df, {"oappo": lambda s: s <= 10_000}), *(() if metric is None else (metric,)))
        shares.append(ev.reuse("oappo").while_learning)
    assert shares == pytest.approx([3 / 11] * 3)  # 3 of the 11 evaluations (0, 5k, 10k)
    # reuse after the learning ended counts overall, not while learning
    after = ev_.Evidence(with_reuse(ramp, {"oappo": lambda s: s > 50_000})).reuse("oappo")
    assert (after.while_learning, after.last_open) == (0.0, 100_000) and after.overall == pytest.approx(10 / 21)


def test_a_curve_whose_seats_share_a_network_is_a_test_of_sharing():
    base = _fig3b({"mappo": (90_000, 0.6), "happo": (90_000, 1.0), "oappo": (50_000, 1.0), "oatrpo": (30_000, 1.0)})
    one_net = with_reuse(base, {}, owner=(0, 0))
    verdict = {x.claim.text: x for x in judge("fig3b", one_net)}["OAPPO ends above MAPPO"]
    assert verdict.status == SHARING and verdict.reuse[0].sharing
    assert "its seats share networks, so the claim tests parameter sharing" in words.reason(verdict)


def test_only_claims_that_an_eq9_curve_beats_another_check_reuse():
    base = _fig3b({"mappo": (90_000, 0.6), "happo": (90_000, 1.0), "oappo": (50_000, 1.0), "oatrpo": (30_000, 1.0)})
    ev = ev_.Evidence(with_reuse(base, {}))  # nobody reuses
    assert check(ev, "higher", ("happo", "mappo")).status == REPRODUCED  # HAPPO does not reuse by Eq. 9
    assert check(ev, "optimal", ("oappo",)).status == REPRODUCED  # "optimal" checks no mechanism
    assert check(ev, "faster", ("oatrpo", "oappo")).status == NOT_REUSE
    assert check(ev_.Evidence(base), "faster", ("oappo", "happo")).status == REPRODUCED  # no algorithm named


def test_not_testable_comes_before_the_mechanism():
    df = with_reuse(_fig3b({"mappo": (90_000, 0.6), "happo": flat(-0.5), "oappo": (50_000, 1.0),
                            "oatrpo": (30_000, 1.0)}), {})
    out = {x.claim.text: x for x in judge("fig3b", df)}
    assert out["OAPPO converges faster than HAPPO"].status == NOT_TESTABLE
    assert out["OAPPO ends above MAPPO"].status == NOT_REUSE


def test_a_returns_final_value_is_its_last_fifth_and_its_initial_its_first_tenth():
    steps = np.arange(0, 21)
    df = pd.DataFrame(dict(label="a", seed=0, step=steps, eval_return=steps.astype(float)))
    run = ev_.Evidence(df, RETURN).runs.iloc[0]
    assert run["final"] == np.mean([17, 18, 19, 20]) and run["initial"] == np.mean([0, 1])
    assert ev_.Evidence(df.rename(columns={"eval_return": "frac_opt"})).runs.iloc[0]["final"] == np.mean([18, 19, 20])


def test_steadier_is_judged_over_the_seeds_that_learned_and_faster_says_who_never_got_there():
    df = win_curves({"steady": [0, 0.3, 0.6, 0.8, 0.8], "shaky": [0, 0.6, 0.1, 0.7, 0.8]})
    df.loc[(df["label"] == "steady") & (df["seed"] == 0), "eval_success"] = 0.0
    verdict = check(ev_.Evidence(df, WIN_RATE), "stabler", ("steady", "shaky"))
    assert verdict.held and [lv.seeds for lv in verdict.levels] == [4, 5]
    df.loc[(df["label"] == "steady") & (df["seed"] > 0), "eval_success"] = 0.0
    lone = v.ESTIMATORS["improvement_of_learned"](ev_.Evidence(df, WIN_RATE), Claim("x", "stabler", ("steady", "shaky")))
    assert words.gap(lone, None) == "fewer than 2 seeds that learned: steady (0 of 5)"
    slow = win_curves({"fast": [0, 0.6, 0.8, 0.8, 0.8], "slow": [0, 0.1, 0.3, 0.4, 0.45]})
    said = check(ev_.Evidence(slow, WIN_RATE), "faster", ("fast", "slow"))
    assert said.never_reached == ("slow",)
    assert words.reason(said).endswith("; slow did not reach a win rate of 50% in the budget (counted at its end)")


# --- selection, and the seed that carries a verdict ------------------------------------------

def selection_runs(gated_final, always_final, never_final, gated_open, owner=(0, 1, 2), seeds=6):
    """Returns on three curves ramping to per-seed finals; the gated curve's M gives peers weight
    where ``gated_open(step)``, always-on's always, HAPPO's never."""
    steps = np.arange(0, 101) * 10_000
    rows = []
    for label, finals in (("oappo gated", gated_final), ("happo", never_final), ("oappo always", always_final)):
        for seed in range(seeds):
            y = np.minimum(steps / 500_000, 1.0) * finals[seed]
            n = len(owner)
            for s, x in zip(steps, y):
                m = np.eye(n) if label == "happo" or (label == "oappo gated" and not gated_open(s)) else \
                    np.full((n, n), 0.3 / (n - 1)) + np.eye(n) * (0.7 - 0.3 / (n - 1))
                rows.append({"label": label, "seed": seed, "step": s, "eval_return": x, "reuse_matrix": m,
                             "owner": np.array(owner), "algo": "happo" if label == "happo" else "oappo"})
    return pd.DataFrame(rows)


SELECTS = Claim("x", "selects", ("oappo gated", "happo", "oappo always"))


def test_selection_needs_the_gated_curve_above_both_ends():
    base = [1000, 1100, 1200, 1300, 1400, 1500]
    ev = ev_.Evidence(selection_runs([b + 200 for b in base], base, base, lambda s: True), RETURN)
    v_ = v.check(ev, SELECTS)
    assert v_.status == REPRODUCED and [e.interval.point for e in v_.estimates] == pytest.approx([200, 200, 0])
    # above no reuse but not above always-on: not reproduced; below always-on on every seed: contradicted
    ev = ev_.Evidence(selection_runs([b + 200 for b in base], [b + 400 for b in base], base, lambda s: True), RETURN)
    assert v.check(ev, SELECTS).status == CONTRADICTED


def test_a_gate_with_one_peer_or_shut_early_is_a_test_of_reuse_switched_off():
    base = [1000, 1100, 1200, 1300, 1400, 1500]
    two = ev_.Evidence(selection_runs([b + 200 for b in base], base, base, lambda s: True, owner=(0, 1)), RETURN)
    switch = v.check(two, SELECTS)
    assert switch.status == NO_SELECTION and switch.interval_status == REPRODUCED and switch.reuse[0].peers == 1
    assert "has one peer to choose: it is a switch" in words.reason(switch)
    early = ev_.Evidence(selection_runs([b + 200 for b in base], [b - 300 for b in base], base,
                                        lambda s: s <= 100_000), RETURN)
    shut = v.check(early, SELECTS)
    assert shut.status == NO_SELECTION and shut.reuse[0].shut_early == 6
    text = words.reason(shut)
    assert "on all 6 seeds its gate last let another network in within the first 25% of the run" in text
    assert "(reuse lowered the final value)" in text and "the gate helped by switching reuse off" in text
    # always-on reuse lower on some seeds and higher on others: no effect is claimed from a point estimate
    mixed = ev_.Evidence(selection_runs([b + 200 for b in base], [b + d for b, d in zip(base, (-300, 300) * 3)], base,
                                        lambda s: s <= 100_000), RETURN)
    text = words.reason(v.check(mixed, SELECTS))
    assert "the interval is across 0: no effect of reuse on the final value shown" in text and "lowered" not in text


def test_a_gate_that_never_shut_is_always_on_reuse_not_a_selection():
    base = [1000, 1100, 1200, 1300, 1400, 1500]
    df = selection_runs([b + 200 for b in base], base, base, lambda s: True)
    k = np.full((3, 3), 0.01)
    df["kl_matrix"], df["sigma"] = [k] * len(df), 0.34  # every pair within sigma at every evaluation
    never = v.check(ev_.Evidence(df, RETURN), SELECTS)
    assert never.status == NO_SELECTION and never.reuse[0].never_shut == 6
    assert "its gate never shut: its runs tested always-on reuse" in words.reason(never)
    df["kl_matrix"] = [np.where(np.eye(3, dtype=bool), 0.0, 0.5 if s % 20_000 else 0.01) for s in df["step"]]
    assert v.check(ev_.Evidence(df, RETURN), SELECTS).status == REPRODUCED  # it shuts at times: it chose


def test_a_verdict_one_seed_carries_names_that_seed():
    base = [1000, 1100, 1200, 1300, 1400, 1500]
    ev = ev_.Evidence(selection_runs([b + 1 for b in base], base, base, lambda s: True), RETURN)
    steady = check(ev, "paired_higher", ("oappo gated", "happo"))
    assert steady.status == REPRODUCED and not steady.one_seed  # every seed above: no seed decides
    # differences 3, 3, 3, 3, -1, -1: the IQM of six keeps one -1, and resamples with four or more
    # -1 (probability 0.10) put the interval's low end at 0 or below; without either -1 seed the IQM
    # of five keeps none, and only resamples with four or more -1 of five (0.007) go below
    shaky = selection_runs([b + d for b, d in zip(base, (3, 3, 3, 3, -1, -1))], base, base, lambda s: True)
    verdict = check(ev_.Evidence(shaky, RETURN), "paired_higher", ("oappo gated", "happo"))
    assert verdict.status == WITHIN_NOISE and verdict.one_seed
    assert dict(verdict.robustness.flips) == {4: REPRODUCED, 5: REPRODUCED}
    for seed, status in verdict.robustness.flips:  # recomputed: without that seed the interval reads the record's
        again = check(ev_.Evidence(shaky[shaky["seed"] != seed], RETURN), "paired_higher", ("oappo gated", "happo"))
        assert again.interval_status == status
    assert words.seeds(verdict) == ("6 seeds, higher on 4 of 6; rests on one seed: without any one of seeds 4 or 5 the "
                                    "interval reads reproduced")


def test_a_curve_without_an_owner_map_beside_one_with_it_counts_no_seats():
    # a single-agent anchor has no owner map; beside a multi-agent curve its rows carry NaN there
    df = curves({"marl": (20_000, 1.0), "anchor": (40_000, 1.0)})
    df["owner"] = [(0, 1, 2) if label == "marl" else np.nan for label in df["label"]]
    assert ev_.Evidence(df).seats == {"marl": 3}
