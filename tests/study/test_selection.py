"""Eq. 9's selection ablation: its sigma, fixed by a rule that reads K alone, and its runs' shape."""
import dataclasses

import numpy as np
import pandas as pd
import pytest

from oapo_lite.study.catalogue import figures
from oapo_lite.study.studies import selection


@pytest.mark.parametrize("env, reading", list(figures.SELECTION_SIGMA))
def test_the_committed_sigma_is_what_the_rule_gives_from_the_committed_runs(env, reading):
    assert figures.SELECTION_SIGMA[env, reading] == selection.gate_sigma(env, reading)


@pytest.mark.parametrize("env, sigmas", [(figures.smax.DOSE_SMAX, figures.smax.DOSE_SIGMA),
                                          (figures.mujoco.ANT, figures.mujoco.ANT_DOSE_SIGMA)])
def test_the_dose_sigmas_are_the_rules_quantiles_of_the_committed_runs(env, sigmas):
    assert list(sigmas) == list(figures.readings.DOSE_QUANTILES)
    assert sigmas == {q: selection.gate_sigma(env, "agent", q) for q in sigmas}


def test_the_dose_response_shares_the_ablations_runs_at_its_ends():
    dose = {r.label: r.cfg for r in figures.runs_of("fig_dose_smax", "cpu") if r.cfg.seed == 10}
    ablation = {r.label: r.cfg for r in figures.runs_of("fig_selection_smax", "cpu")
                if r.cfg.seed == 10 and r.cfg.env == figures.smax.DOSE_SMAX}
    median = figures.readings.dose_label(figures.smax.DOSE_SIGMA[0.5])
    assert (dose["happo"], dose["oappo always"], dose[median]) == \
        (ablation["happo"], ablation["oappo always"], ablation["oappo gated"])
    gated = [c for label, c in dose.items() if label.startswith("oappo sigma=")]
    assert sorted(c.sigma for c in gated) == sorted(figures.smax.DOSE_SIGMA.values())
    assert all(dataclasses.replace(c, sigma=np.inf) == dose["oappo always"] for c in gated)


def test_the_ablation_pairs_its_curves_on_seeds_that_chose_no_setting():
    chose = {run.cfg.seed for figure in ("fig_sweep_2s3z", "fig4_smax", "fig_early_reuse", "figA_mamujoco")
             for run in figures.runs_of(figure, "cpu")}
    runs = figures.runs_of("fig_selection_smax", "cpu")
    assert {r.cfg.seed for r in runs} == set(figures.readings.SELECTION_SEEDS) and not chose & set(figures.readings.SELECTION_SEEDS)
    by = {(r.cfg.env, r.label): r.cfg for r in runs if r.cfg.seed == 10}
    for env in figures.smax.SELECTION_SMAX:
        happo, always, gated = by[env, "happo"], by[env, "oappo always"], by[env, "oappo gated"]
        # the same settings but the reuse rule: the same networks, so the same initial weights per seed
        assert always.sigma == np.inf and gated.sigma == figures.SELECTION_SIGMA[env, "agent"]
        for other in (always, gated):
            assert (other.lr, other.entropy_coef, other.clip, other.networks_used, other.steps) == \
                (happo.lr, happo.entropy_coef, happo.clip, happo.networks_used, happo.steps)
    own, kind = by["smax:2s3z", "oappo type own type"], by["smax:2s3z", "oappo type gated"]
    assert own.reuse_lambda == 1.0 and kind.reuse_lambda == 0.7 and own.networks_used == kind.networks_used == "type"
    # HalfCheetah: the normalised learner fig_mamujoco_normalize chose, at App. A's settings
    cheetah = {r.label: r.cfg for r in figures.runs_of("fig_selection_mamujoco", "cpu") if r.cfg.seed == 10}
    app_a = next(r.cfg for r in figures.runs_of("figA_mamujoco", "cpu") if r.label == "happo")
    assert all(c.normalize and c.ppo_epochs == app_a.ppo_epochs and c.n_envs == app_a.n_envs for c in cheetah.values())
    assert cheetah["oappo always"].sigma == np.inf and {r.cfg.seed for r in figures.runs_of(
        "fig_selection_mamujoco", "cpu")} == set(figures.readings.SELECTION_SEEDS)


def test_gate_use_counts_the_across_network_pairs_open_and_shut():
    k = [[0.0, 0.01, 0.2], [0.03, 0.0, 0.05], [0.5, 0.02, 0.0]]
    df = pd.DataFrame({"env": ["black_blue_red"] * 2, "label": ["x"] * 2, "kl_matrix": [np.nan, np.array(k)],
                       "owner": [np.arange(3)] * 2, "sigma": [0.04] * 2, "across_share": [np.nan, 0.2]})
    use = selection.gate_use(df, {})
    # 6 ordered pairs of the 3 seats: 0.01, 0.2, 0.03, 0.05, 0.5, 0.02; within 0.04: three
    assert use.loc[0, ["pair-iterations", "open", "shut", "across_share"]].tolist() == [6, 0.5, 0.5, 0.2]


def test_the_sampled_curves_are_the_weighted_ones_drawing_one_source():
    for figure in ("fig_selection_smax", "fig_selection_mamujoco"):
        by = {(r.cfg.env, r.label): r.cfg for r in figures.runs_of(figure, "cpu") if r.cfg.seed == 10}
        envs = {env for env, _ in by}
        for sampled, weighted in figures.readings.SAMPLED.items():
            assert {env for env, label in by if label == sampled} == set(figures.readings.COST_ENVS) & envs
            for env in set(figures.readings.COST_ENVS) & envs:
                assert by[env, weighted].reuse_mode == "weights"
                assert by[env, sampled] == dataclasses.replace(by[env, weighted], reuse_mode="sample")


def test_estimators_pairs_the_seeds_counts_reuse_and_prices_each_curve_from_its_records():
    reuse, alone = np.array([[0.7, 0.3], [0.3, 0.7]]), np.eye(2)
    rows = []
    # final win rates (the last 3 evaluations' mean) per seed: weights 0.2, 0.3, 0.4; sampled 0.3, 0.3, 0.6
    for seed, (w, s) in enumerate([(0.2, 0.3), (0.3, 0.3), (0.4, 0.6)]):
        for label, final, cpu, m in (("oappo gated", w, 3.0 + seed, reuse), ("oappo gated sampled", s, 1.0, alone),
                                     ("happo", 0.0, 2.0, alone)):
            rows += [{"env": "smax:2s3z", "label": label, "seed": seed, "step": 1000 * k, "eval_success": final,
                      "cpu_s": cpu * k, "reuse_matrix": m, "owner": np.arange(2)} for k in range(1, 4)]
    out = selection.estimators(pd.DataFrame(rows), "fig_selection_smax").iloc[0]
    assert (out["sampled"], out["weights"], out["pairs"], out["sampled higher"]) == \
        ("oappo gated sampled", "oappo gated", 3, 2)
    assert out["sampled minus weights"] == pytest.approx((0.1 + 0.0 + 0.2) / 3)  # the IQM of three: their mean
    assert out["low"] <= out["sampled minus weights"] <= out["high"]
    # every evaluation of the weights curve gave the peer weight, none of the sampled one's
    assert (out["reused weights"], out["reused sampled"]) == (1.0, 0.0)
    # CPU seconds per 1,000 steps: the median over seeds of the last row's cpu_s / step
    assert out[["CPU-s happo", "CPU-s weights", "CPU-s sampled"]].tolist() == pytest.approx([2.0, 4.0, 1.0])


def test_cpu_to_level_reads_the_runs_own_records_where_the_curves_iqm_first_gets_there():
    rows = [{"label": "a", "seed": seed, "step": k, "eval_success": min(1.0, k * rate), "cpu_s": 10.0 * k * (seed + 1)}
            for seed, rate in enumerate((0.5, 0.25, 0.2)) for k in range(5)]
    cpu = selection.cpu_to_level(pd.DataFrame(rows), figures.smax.SPEED_WIN_RATE, 0.5)
    # win rates per step: k=1 (0.5, 0.25, 0.2): IQM of three is their mean, 0.317; k=2 (1, 0.5, 0.4): 0.633
    assert cpu["a"] == pytest.approx(np.median([20.0, 40.0, 60.0]))
    assert np.isnan(selection.cpu_to_level(pd.DataFrame(rows), figures.smax.SPEED_WIN_RATE, 2.0)["a"])
