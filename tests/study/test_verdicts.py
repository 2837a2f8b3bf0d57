"""Verdicts are functions of the data: synthetic curves and samples with a known answer."""
import numpy as np
import pandas as pd
import pytest
from scipy import stats

from oapo_lite.study import figures, statistics, tables, verdicts as v
from oapo_lite.study.claims import judge


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
    return v.Evidence(curves(spec, **kw))


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
    runs = v.per_run(df).set_index("label")
    assert runs.loc["a", "steps_to_threshold"] == 40_000  # first grid point with 40k/40k >= 0.95
    assert runs.loc["a", "reached"] and not runs.loc["b", "reached"]
    assert runs.loc["b", "steps_to_threshold"] == 100_000  # censored at the last step
    assert runs.loc["b", "final"] == pytest.approx(0.5)


def test_intervals_table_matches_per_run_values():
    df = curves({"fast": (20_000, 1.0), "low": (20_000, 0.5)}, noise=0.05)
    table = v.intervals(df)
    runs = v.per_run(df)
    fast = runs.loc[runs["label"] == "fast", "steps_to_threshold"]
    assert table.loc["fast", "steps_iqm"] == pytest.approx(stats.trim_mean(fast, 0.25))
    assert table.loc["low", ["final_iqm", "final_low", "final_high"]].tolist() == pytest.approx([0.5] * 3)
    assert (table["steps_low"] <= table["steps_iqm"]).all() and (table["steps_iqm"] <= table["steps_high"]).all()


def test_faster_and_higher_directions():
    ev = evidence({"fast": (20_000, 1.0), "slow": (80_000, 1.0), "low": (20_000, 0.5)}, noise=0.05)
    assert v.faster(ev, "fast", "slow", "x").status == v.REPRODUCED
    assert v.faster(ev, "slow", "fast", "x").status == v.CONTRADICTED  # the whole interval says the opposite
    assert v.higher(ev, "fast", "low", "x").status == v.REPRODUCED
    assert v.higher(ev, "low", "fast", "x").status == v.CONTRADICTED
    assert v.faster(ev, "fast", "slow", "x").estimate == "P(fast faster) 1.000 [1.000, 1.000]"


def test_within_noise_is_direction_only():
    ev = evidence({"a": (50_000, 1.0), "b": (51_000, 1.0)}, noise=0.3)
    verdict = v.faster(ev, "a", "b", "a faster")
    assert verdict.status in (v.WITHIN_NOISE, v.NOT) and not verdict.held


def test_better_uses_final_then_speed():
    ev = evidence({"hi": (80_000, 1.0), "lo": (10_000, 0.6), "twin": (20_000, 1.0)})
    assert v.better(ev, "hi", "lo", "x").held  # higher plateau wins despite being slower
    assert not v.better(ev, "lo", "hi", "x").held
    assert v.better(ev, "twin", "hi", "x").held  # same plateau: decided by speed
    assert v.better(ev, "twin", "hi", "x").estimate.startswith("P(twin faster)")


def test_stuck_and_optimal():
    ev = evidence({"stuck": (10_000, 0.5), "ok": (10_000, 1.0)})
    assert v.stuck(ev, "stuck", "x").held and not v.stuck(ev, "ok", "x").held
    assert v.optimal(ev, "ok", "x").held and not v.optimal(ev, "stuck", "x").held


def test_stuck_with_some_seeds_escaping_is_direction_only():
    # 3 seeds stuck at half the optimum, 2 reach it: IQM (0.5 + 0.5 + 1) / 3 < 0.95, but
    # resamples with 4 or 5 escaping seeds (probability 0.087 > 2.5%) put the interval above.
    df = pd.concat([curves({"a": (10_000, 0.5)}, seeds=3),
                    curves({"a": (10_000, 1.0)}, seeds=2).assign(seed=lambda d: d["seed"] + 3)])
    verdict = v.stuck(v.Evidence(df), "a", "x")
    assert verdict.status == v.WITHIN_NOISE
    assert verdict.estimate.startswith("IQM final 0.667 [")


def test_figure_claims_follow_the_data():
    good = curves({"mappo": (20_000, 0.5), "happo": (90_000, 1.0), "oappo": (50_000, 1.0),
                   "oatrpo": (30_000, 1.0), "hatrpo": (60_000, 1.0)})
    assert all(x.held for x in judge("fig3b", good))
    bad = curves({"mappo": (20_000, 1.0), "happo": (30_000, 1.0), "oappo": (50_000, 1.0),
                  "oatrpo": (90_000, 1.0)})
    held = {x.claim: x.held for x in judge("fig3b", bad)}
    assert not held["MAPPO (shared parameters) stays below the optimum"]
    assert not held["OATRPO converges faster than OAPPO"]
    sentence = judge("fig3b", bad)[0].sentence()
    assert "contradicted" in sentence and "mappo 1.000 [1.000, 1.000]" in sentence


def test_claim_table_has_a_row_per_budget_and_claim():
    good = curves({"mappo": (20_000, 0.5), "happo": (90_000, 1.0), "oappo": (50_000, 1.0),
                   "oatrpo": (30_000, 1.0), "hatrpo": (60_000, 1.0)})
    table = v.claim_table({"five": judge("fig3b", good), "one": judge("fig3b", good[good["seed"] == 0])})
    assert len(table) == 2 * len(figures.get_figure("fig3b").claims)
    by = table.set_index("budget")
    assert (by.loc["five", "verdict"] == v.REPRODUCED).all()
    assert (by.loc["one", "verdict"] == v.NOT_TESTABLE).all()  # one seed cannot decide anything


def test_one_seed_is_never_more_than_direction():
    ev = evidence({"fast": (20_000, 1.0), "slow": (80_000, 1.0)}, seeds=1)
    verdict = v.faster(ev, "fast", "slow", "x")
    assert verdict.status == v.WITHIN_NOISE


def test_speed_reads_censored_times_alone_and_reliability_is_its_own_question():
    # a: 3 seeds converge at 20k, 2 never do; b: every seed converges, later.
    a = curves({"a": (20_000, 1.0)}, seeds=3)
    a_stuck = curves({"a": (20_000, 0.5)}, seeds=2).assign(seed=lambda d: d["seed"] + 3)
    b = curves({"b": (70_000, 1.0)})
    ev = v.Evidence(pd.concat([a, a_stuck, b]))
    s = ev.summary
    assert s.loc["a", "reached"] == 3 and s.loc["a", "steps_mean"] < s.loc["b", "steps_mean"]
    # a censored seed ranks behind every seed that got there: P = (3 x 5 wins) / 25 pairs
    verdict = v.faster(ev, "a", "b", "a faster")
    assert verdict.estimate.startswith("P(a faster) 0.600 ") and verdict.status == v.WITHIN_NOISE
    assert "3/5 seeds reached" in verdict.evidence
    # "as reliably": 3/5 against 5/5, a difference of -0.4 whose interval reaches 0 (a resample of
    # a's seeds can draw only its converged ones): not reproduced; a tie holds
    late = v.reliable(ev, "a", "b", "a as reliably as b")
    assert late.status == v.NOT and late.estimate.startswith("share reached, a minus b: -0.400 [")
    assert v.reliable(ev, "b", "b", "b as reliably as b").status == v.REPRODUCED
    # never reaching against always reaching: the whole interval below 0
    never = pd.concat([curves({"a": (20_000, 0.5)}, seeds=8), curves({"b": (70_000, 1.0)}, seeds=8)])
    assert v.reliable(v.Evidence(never), "a", "b", "x").status == v.CONTRADICTED
    # with no seed of either curve there, neither question can be asked
    nowhere = curves({"a": (20_000, 0.5), "b": (20_000, 0.6)})
    assert v.check(v.Evidence(nowhere), v.reliable, ("a", "b"), "x").status == v.NOT_TESTABLE


def test_unknown_figure_raises():
    with pytest.raises(ValueError, match="fig9"):
        judge("fig9", curves({"a": (1, 1.0)}))


def win_curves(spec, seeds=5, env="smax:2s3z"):
    """spec: label -> list of win rates at evaluation points 0, 10k, 20k, ..."""
    rows = [dict(label=label, seed=seed, env=env, step=10_000 * k, eval_success=w + 0.01 * seed)
            for label, wins in spec.items() for seed in range(seeds) for k, w in enumerate(wins)]
    return pd.DataFrame(rows)


def test_stabler_compares_the_largest_drop_below_an_earlier_peak():
    df = win_curves({"steady": [0, 0.3, 0.6, 0.8, 0.8], "shaky": [0, 0.6, 0.1, 0.7, 0.8]})
    ev = v.Evidence(df, metric=v.WIN_RATE)
    runs = ev.runs.set_index("label")
    assert runs.loc["shaky", "drawdown"].tolist() == pytest.approx([0.5] * 5)
    assert v.stabler(ev, "steady", "shaky", "x").held
    assert v.stabler(ev, "shaky", "steady", "x").status == v.CONTRADICTED


def test_win_rate_claims_are_not_testable_where_the_data_cannot_decide():
    learned = {"oappo": [0, 0.6, 0.9, 0.9], "mappo": [0, 0.1, 0.2, 0.3], "happo": [0, 0.1, 0.6, 0.7]}
    out = {x.claim: x for x in judge("fig4_smax", win_curves(learned))}
    assert out["2s3z: OAPPO (a net per agent) ends above MAPPO (heterogeneous agents)"].held
    assert out["2s3z: OAPPO (a net per agent) converges faster than HAPPO"].held
    assert out["6h_vs_8z: OAPPO (a net per agent) ends above MAPPO"].status == v.NOT_RUN  # no run on that map
    assert out["2s3z: OAPPO (a net per type) ends above MAPPO (heterogeneous agents)"].status == v.NOT_TESTABLE
    nothing = win_curves({k: [0, 0.0, 0.01, 0.0] for k in learned})  # peaks <= 0.05
    assert {x.status for x in judge("fig4_smax", nothing)} == {v.NOT_TESTABLE, v.NOT_RUN}  # maps without runs: not run
    one_seed = {x.claim: x for x in judge("fig4_smax", win_curves(learned, seeds=1))}
    verdict = one_seed["2s3z: OAPPO (a net per agent) ends above HAPPO (heterogeneous agents)"]
    assert verdict.status == v.NOT_TESTABLE and "fewer than 2 seeds" in verdict.reason
    never_half = win_curves({"oappo": [0, 0.2, 0.3, 0.4], "happo": [0, 0.1, 0.3, 0.3], "mappo": [0, 0.1, 0.1, 0.1]})
    out = {x.claim: x for x in judge("fig4_smax", never_half)}
    assert out["2s3z: OAPPO (a net per agent) converges faster than HAPPO"].status == v.NOT_TESTABLE
    assert out["2s3z: OAPPO (a net per agent) ends above HAPPO (heterogeneous agents)"].status != v.NOT_TESTABLE


def test_returns_figures_are_judged_on_the_return_and_absent_curves_have_no_data():
    # App. A: HAPPO plateaus at 1000, MAPPO at 400 (and OAPPO at 900); SEAC has no runs
    df = curves({"happo": (50_000, 1000.0), "mappo": (50_000, 400.0), "oappo": (50_000, 900.0)}, noise=0.1)
    df = df.rename(columns={"frac_opt": "eval_return"}).assign(frac_opt=np.nan)
    verdicts = {x.claim: x for x in judge("figA_mamujoco", df)}
    assert verdicts["full sharing (MAPPO) ends below no reuse (HAPPO)"].held
    assert "final evaluation return, IQM [95% CI]: happo 1000.000" in verdicts["full sharing (MAPPO) ends below no reuse (HAPPO)"].evidence
    assert verdicts["OAPPO (a net per agent) ends above full sharing (MAPPO)"].held
    seac = verdicts["direct reuse (SEAC) ends below no reuse (HAPPO)"]
    assert seac.status == v.NOT_TESTABLE and "seac (0)" in seac.reason and not seac.held
    swapped = df.assign(label=df["label"].replace({"happo": "mappo", "mappo": "happo"}))
    assert not {x.claim: x for x in judge("figA_mamujoco", swapped)}[
        "full sharing (MAPPO) ends below no reuse (HAPPO)"].held
    assert all(x.status == v.NOT_RUN for x in judge("figA_mamujoco", pd.DataFrame()))


def test_grf_claims_are_judged_per_scenario_on_the_score():
    rows = [dict(label=label, seed=seed, env=f"grf:academy_{scenario}", step=10_000 * k, eval_success=w)
            for scenario, spec in {"3_vs_1_with_keeper": {"happo": [0, 0.5, 0.95, 0.97, 0.96, 0.98]},
                                   "counterattack_easy": {"oappo": [0, 0.4, 0.8, 0.8, 0.8, 0.8],
                                                          "mappo": [0, 0.1, 0.2, 0.2, 0.2, 0.2]}}.items()
            for label, wins in spec.items() for seed in range(5) for k, w in enumerate(wins)]
    out = {x.claim: x for x in judge("fig6b", pd.DataFrame(rows))}
    assert out["3_vs_1_with_keeper: own experience alone (HAPPO) scores nearly perfectly"].held
    assert out["counterattack_easy: OAPPO ends above MAPPO"].held
    assert "final score" in out["counterattack_easy: OAPPO ends above MAPPO"].evidence
    # scenarios or algorithms without runs cannot be judged
    assert out["counterattack_easy: OAPPO ends above SEAC"].status == v.NOT_TESTABLE  # no SEAC run there
    assert out["counterattack_hard: OATRPO ends above HAPPO"].status == v.NOT_RUN  # no run of that scenario
    assert out["pass_and_shoot_with_keeper: own experience alone (HAPPO) scores nearly perfectly"].status == v.NOT_RUN


# --- the rule judges only what learned (issue 20) ------------------------------------------

def _fig3b(spec, seeds=5):
    return pd.concat([curves({k: val}, seeds=seeds) if isinstance(val, tuple) else val.assign(label=k)
                      for k, val in spec.items()])


def flat(level, seeds=5, steps=np.arange(0, 100_001, 5_000), lucky=None):
    """A curve that never leaves ``level``; ``lucky``: (seed, step, value) of one outlier evaluation."""
    rows = [dict(seed=s, step=t, frac_opt=level) for s in range(seeds) for t in steps]
    df = pd.DataFrame(rows)
    if lucky is not None:
        seed, step, value = lucky
        df.loc[(df["seed"] == seed) & (df["step"] == step), "frac_opt"] = value
    return df


def test_a_flat_curve_is_not_testable_and_says_which_curve():
    df = _fig3b({"mappo": flat(-0.5), "happo": (90_000, 1.0), "oappo": (50_000, 1.0), "oatrpo": (30_000, 1.0)})
    out = {x.claim: x for x in judge("fig3b", df)}
    stuck = out["MAPPO (shared parameters) stays below the optimum"]
    assert stuck.status == v.NOT_TESTABLE  # below the optimum, but because it learned nothing
    assert "mappo did not learn (initial -0.5, final -0.5: gain +0 +- 0 s.e. over 5 seeds, not above 2 s.e.)" in stuck.reason
    assert out["OAPPO converges faster than HAPPO"].status == v.REPRODUCED  # both learned


def test_one_lucky_evaluation_is_not_learning():
    # every seed flat at -0.5 except one evaluation of one seed at the optimum, mid-run
    lucky = flat(-0.5, lucky=(2, 50_000, 1.0))
    df = _fig3b({"mappo": lucky, "happo": (90_000, 1.0), "oappo": (50_000, 1.0), "oatrpo": (30_000, 1.0)})
    ev = v.Evidence(df)
    assert ev.runs.loc[ev.runs["label"] == "mappo", "peak"].max() == 1.0
    assert not v.learned(ev, "mappo")
    assert judge("fig3b", df)[0].status == v.NOT_TESTABLE
    # one seed that ends high among flat ones: a gain within noise over seeds is not learning
    one_seed = flat(-0.5)
    one_seed.loc[(one_seed["seed"] == 0) & (one_seed["step"] >= 90_000), "frac_opt"] = 1.0
    assert not v.learned(v.Evidence(one_seed.assign(label="x")), "x")


def test_win_rates_below_the_floor_did_not_learn():
    # every seed rises, but only to a 3% win rate: below the 5% floor
    df = win_curves({"a": [0, 0.01, 0.02, 0.02, 0.02, 0.02, 0.02]})
    ev = v.Evidence(df, metric=v.WIN_RATE)
    assert not v.learned(ev, "a")
    # the reason names the test that failed, not the one that passed
    assert v.why_not_learned(ev, "a").endswith(": final IQM 0.04, not above the floor 0.05)")


def test_two_learned_curves_with_p_above_one_half_are_reproduced():
    ev = evidence({"fast": (20_000, 1.0), "slow": (80_000, 1.0)}, noise=0.05)
    assert v.learned(ev, "fast") and v.learned(ev, "slow")
    verdict = v.faster(ev, "fast", "slow", "x")
    assert verdict.status == v.REPRODUCED and verdict.reason.endswith("wholly above 0.5")


def test_the_printed_rule_names_every_status():
    for word in ("Not testable", "did not learn", "reproduced", "contradicted", "within noise",
                 "not reproduced", "as reliably", "Not a test of reuse", "25%"):
        assert word in v.RULE


def test_paired_difference_compares_each_seed_with_its_own_pair():
    """Per seed: the mean of the last fifth of each run (at least 3 evaluations), and a - b; a seed with one run only is
    left out. The pairs differ by exactly 1 while the seeds spread over hundreds, so an
    interval over pairs is the point 1, which an unpaired comparison could not show."""
    steps = np.arange(10) * 100
    rows = []
    for seed, level in enumerate([0.0, 300.0, -200.0, 900.0]):
        for label, shift in (("a", 1.0), ("b", 0.0)):
            if seed == 3 and label == "a":
                continue
            y = np.r_[np.zeros(7), level + shift + np.arange(3)]  # the last 3: level + shift + 1
            rows += [{"label": label, "seed": seed, "step": s, "ret": v} for s, v in zip(steps, y)]
    runs, diff = v.paired_difference(pd.DataFrame(rows), "a", "b", y="ret")
    assert runs.index.tolist() == [0, 1, 2]
    assert runs["b"].tolist() == [1.0, 301.0, -199.0] and runs["difference"].tolist() == [1.0, 1.0, 1.0]
    assert (diff.point, diff.low, diff.high) == (1.0, 1.0, 1.0)


def test_reuse_table_reads_reuse_and_final_values_per_env_and_label():
    """Two envs, two labels: the reuse columns come from M and ``iterations_reusing``, the final
    value from the last fifth of the evaluation points."""
    shared, own = [[0.5, 0.5], [0.5, 0.5]], [[1.0, 0.0], [0.0, 1.0]]
    rows = []
    for env in ("e1", "e2"):
        for label, m, every in (("mappo", shared, 1.0), ("happo", own, 0.0)):
            for seed in (0, 1):
                rows += [{"env": env, "label": label, "seed": seed, "step": s, "reuse_matrix": m,
                          "iterations_reusing": every, "ret": float(s >= 7) * (seed + 1)} for s in range(10)]
    owners = {("e1", "mappo"): [0, 0], ("e2", "mappo"): [0, 1]} | {(e, "happo"): [0, 1] for e in ("e1", "e2")}
    t = tables.reuse_table(pd.DataFrame(rows), "ret", owners)
    assert t.index.tolist() == [("e1", "mappo"), ("e1", "happo"), ("e2", "mappo"), ("e2", "happo")]
    assert t["seeds"].tolist() == [2] * 4 and t["all_iterations"].tolist() == [1.0, 0.0, 1.0, 0.0]
    assert t["mean_peer_share"].tolist() == [0.5, 0.0, 0.5, 0.0]
    assert t["mean_across_nets"].tolist() == [0.0, 0.0, 0.5, 0.0]  # one net on e1: no reuse across nets
    assert t["across_reusing"].tolist() == [0.0, 0.0, 1.0, 0.0]
    assert tables.reuse_table(pd.DataFrame(rows).assign(reuse_matrix=None), "ret", owners).empty  # SEAC-like runs
    assert t["final"].tolist() == [1.5] * 4  # seeds' last fifth (at least 3 evaluations): 1 and 2


def test_sweep_table_chooses_the_best_final_value_and_breaks_ties_by_speed():
    """Family f: a ends at 0.9, b at 0.89 (a tie within 0.02) and reaches 0.5 sooner, c at 0.5;
    family g has one setting. b and the lone setting are chosen."""
    rows = []
    for label, level, reach in (("a", 0.9, 7), ("b", 0.89, 2), ("c", 0.5, 9), ("d", 0.3, 10)):
        for seed in (0, 1):
            rows += [{"label": label, "seed": seed, "step": s * 10, "eval_success": level if s >= reach else 0.0}
                     for s in range(10)]
    t = tables.sweep_table(pd.DataFrame(rows), {"a": "f", "b": "f", "c": "f", "d": "g"}, v.WIN_RATE)
    assert t["chosen"].to_dict() == {"a": False, "b": True, "c": False, "d": True}
    assert t.loc["b", "steps"] == 20 and t.loc["d", "steps"] == 90  # never reached 0.5: counted at its end
    assert t.loc["a", "final"] == pytest.approx(0.9) and t["seeds"].tolist() == [2] * 4


# --- a claim about OAPPO tests reuse only where reuse happened (issue 32) -------------------

SHARED, OWN = np.array([[0.7, 0.3], [0.3, 0.7]]), np.eye(2)


def with_reuse(df, reusing):
    """``df`` with each curve's algorithm (its label) and its reuse matrix M per evaluation:
    ``reusing[label]`` picks the steps at which M gave a peer weight (others: M = I)."""
    df = df.assign(algo=df["label"])
    df["reuse_matrix"] = [SHARED if label in reusing and reusing[label](step) else OWN
                          for label, step in zip(df["label"], df["step"])]
    return df


def test_a_claim_about_oappo_is_no_test_of_reuse_when_its_gate_closed_early():
    # OAPPO reaches the optimum at 50k (evaluation 10 of 21) but gave peers weight only at the
    # first 2 evaluations (0 and 5k): 2 of the 11 up to its threshold, 18% < 25%
    base = _fig3b({"mappo": (90_000, 0.6), "happo": (90_000, 1.0), "oappo": (50_000, 1.0), "oatrpo": (30_000, 1.0)})
    closed = with_reuse(base, {"oappo": lambda s: s <= 5_000, "oatrpo": lambda s: True})
    out = {x.claim: x for x in judge("fig3b", closed)}
    verdict = out["OAPPO converges faster than HAPPO"]
    assert verdict.status == v.NOT_REUSE
    assert verdict.reason.startswith("the gate last opened across networks at 5,000 steps; oappo reused across networks "
                                     "at 18.2% of its evaluated iterations while it learned (mean over seeds), below 25%; "
                                     "by the interval alone reproduced: P(oappo faster) 1.000")  # beside the status
    assert verdict.estimate.startswith("P(oappo faster) 1.000")  # the interval stays as evidence
    assert out["OAPPO ends above MAPPO"].status == v.NOT_REUSE
    # OATRPO reused throughout: its claims are decided by the interval as before
    assert out["OATRPO converges faster than HAPPO"].status == v.REPRODUCED
    # a gate open at every evaluation makes the same data a test of reuse
    opened = with_reuse(base, {"oappo": lambda s: True, "oatrpo": lambda s: True})
    assert {x.claim: x for x in judge("fig3b", opened)}["OAPPO converges faster than HAPPO"].status == v.REPRODUCED


def test_reuse_is_counted_while_the_curve_learns_and_at_least_a_quarter_is_enough():
    base = _fig3b({"mappo": (90_000, 0.6), "happo": (90_000, 1.0), "oappo": (50_000, 1.0), "oatrpo": (30_000, 1.0)})
    # reuse until the threshold (50k), none after: every iteration that learned reused
    learning = v.Evidence(with_reuse(base, {"oappo": lambda s: s <= 50_000}))
    assert learning.summary.loc["oappo", "reusing"] == 1.0
    assert v.reuse_gap(learning, ("oappo", "happo")) is None
    # reuse only after the threshold, at 10 of 21 evaluations of the whole run: no test of reuse
    after = v.Evidence(with_reuse(base, {"oappo": lambda s: s > 50_000}))
    assert after.summary.loc["oappo", "reusing"] == 0.0
    assert after.summary.loc["oappo", "last_reuse_step"] == 100_000
    assert "reused across networks at 0.0% of its evaluated iterations" in v.reuse_gap(after, ("oappo", "happo"))[1]
    # the boundary: 3 of 11 evaluations (27%) is a test, 2 of 11 (18%) is not
    assert v.reuse_gap(v.Evidence(with_reuse(base, {"oappo": lambda s: s <= 10_000})), ("oappo", "happo")) is None
    assert v.reuse_gap(v.Evidence(with_reuse(base, {"oappo": lambda s: s <= 5_000})), ("oappo", "happo"))
    # never reused at all; no reuse matrix on record
    never = v.Evidence(with_reuse(base, {}))
    assert v.reuse_gap(never, ("oappo", "happo"))[1].startswith("no seed ever gave another network's seats weight; "
                                                                "oappo reused across networks at 0.0%")
    unknown = v.Evidence(base.assign(algo=base["label"]))
    assert v.reuse_gap(unknown, ("oappo", "happo")) == (v.NOT_REUSE, "oappo's runs hold no reuse matrix, so whether "
                                                                      "it reused is unknown")


def test_only_claims_that_an_eq9_curve_beats_another_need_reuse_also_between_two_of_its_settings():
    base = _fig3b({"mappo": (90_000, 0.6), "happo": (90_000, 1.0), "oappo": (50_000, 1.0), "oatrpo": (30_000, 1.0)})
    ev = v.Evidence(with_reuse(base, {}))  # nobody reuses
    assert v.reuse_gap(ev, ("happo", "mappo")) is None  # HAPPO does not reuse by Eq. 9
    assert v.reuse_gap(ev, ("oappo",)) is None  # "stuck" / "optimal": one curve
    same = ev.algos | {"oatrpo": "oappo"}  # two OAPPO curves (a sigma sweep, gated against always-on)
    ev.algos = same
    assert v.reuse_gap(ev, ("oatrpo", "oappo"))[0] == v.NOT_REUSE  # a setting that never reused shows nothing of it
    assert v.reuse_gap(v.Evidence(base), ("oappo", "happo")) is None  # no algorithm named: nothing to check


def test_not_testable_comes_before_not_a_test_of_reuse():
    df = with_reuse(_fig3b({"mappo": (90_000, 0.6), "happo": flat(-0.5), "oappo": (50_000, 1.0),
                            "oatrpo": (30_000, 1.0)}), {})
    out = {x.claim: x for x in judge("fig3b", df)}
    assert out["OAPPO converges faster than HAPPO"].status == v.NOT_TESTABLE
    assert out["OAPPO ends above MAPPO"].status == v.NOT_REUSE


def test_a_returns_final_value_is_its_last_fifth_and_its_initial_its_first_tenth():
    # 21 evaluation points: the last fifth is the last 4, the first tenth the first 2
    steps = np.arange(0, 21)
    df = pd.DataFrame(dict(label="a", seed=0, step=steps, eval_return=steps.astype(float)))
    run = v.Evidence(df, metric=v.RETURN).runs.iloc[0]
    assert run["final"] == np.mean([17, 18, 19, 20]) and run["initial"] == np.mean([0, 1])
    # a tenth of 21 is 2 evaluations: the window holds 3 at least
    assert v.Evidence(df.rename(columns={"eval_return": "frac_opt"})).runs.iloc[0]["final"] == np.mean([18, 19, 20])


def test_steadier_is_judged_over_the_seeds_that_learned_and_faster_says_who_never_got_there():
    # one seed of "steady" never leaves 0: it has no drop, and would otherwise rank as the steadiest
    df = win_curves({"steady": [0, 0.3, 0.6, 0.8, 0.8], "shaky": [0, 0.6, 0.1, 0.7, 0.8]})
    df.loc[(df["label"] == "steady") & (df["seed"] == 0), "eval_success"] = 0.0
    ev = v.Evidence(df, metric=v.WIN_RATE)
    verdict = v.stabler(ev, "steady", "shaky", "steady improves more stably")
    assert "over 4 seeds that learned" in verdict.evidence and verdict.held
    df.loc[(df["label"] == "steady") & (df["seed"] > 0), "eval_success"] = 0.0
    lone = v.stabler(v.Evidence(df, metric=v.WIN_RATE), "steady", "shaky", "x")
    assert lone.status == v.NOT_TESTABLE and lone.reason == "fewer than 2 seeds that learned: steady (0 of 5)"
    slow = win_curves({"fast": [0, 0.6, 0.8, 0.8, 0.8], "slow": [0, 0.1, 0.3, 0.4, 0.45]})
    said = v.faster(v.Evidence(slow, metric=v.WIN_RATE), "fast", "slow", "x")
    assert said.reason.endswith("; slow did not reach a 50% win rate in the budget (counted at its end)")
