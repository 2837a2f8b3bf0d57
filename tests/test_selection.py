"""Eq. 9's selection ablation: its sigma, fixed by a rule that reads K alone, and its runs' shape."""
import numpy as np
import pandas as pd
import pytest

from oapo_lite.study import grid, selection


@pytest.mark.parametrize("env, reading", list(grid.SELECTION_SIGMA))
def test_the_committed_sigma_is_what_the_rule_gives_from_the_committed_runs(env, reading):
    assert grid.SELECTION_SIGMA[env, reading] == selection.gate_sigma(env, reading)


def test_the_ablation_pairs_its_curves_on_seeds_that_chose_no_setting():
    chose = {run.cfg.seed for figure in ("fig_sweep_2s3z", "fig4_smax", "fig_early_reuse", "figA_mamujoco")
             for run in grid.runs_of(figure, "cpu")}
    runs = grid.runs_of("fig_selection_smax", "cpu")
    assert {r.cfg.seed for r in runs} == set(grid.SELECTION_SEEDS) and not chose & set(grid.SELECTION_SEEDS)
    by = {(r.cfg.env, r.label): r.cfg for r in runs if r.cfg.seed == 10}
    for env in grid.SELECTION_SMAX:
        happo, always, gated = by[env, "happo"], by[env, "oappo always"], by[env, "oappo gated"]
        # the same settings but the reuse rule: the same networks, so the same initial weights per seed
        assert always.sigma == np.inf and gated.sigma == grid.SELECTION_SIGMA[env, "agent"]
        for other in (always, gated):
            assert (other.lr, other.entropy_coef, other.clip, other.network_kind, other.steps) == \
                (happo.lr, happo.entropy_coef, happo.clip, happo.network_kind, happo.steps)
    own, kind = by["smax:2s3z", "oappo type own kind"], by["smax:2s3z", "oappo type gated"]
    assert own.reuse_lambda == 1.0 and kind.reuse_lambda == 0.7 and own.network_kind == kind.network_kind == "type"
    # HalfCheetah: the normalised learner fig_mamujoco_normalize chose, at App. A's settings
    cheetah = {r.label: r.cfg for r in grid.runs_of("fig_selection_mamujoco", "cpu") if r.cfg.seed == 10}
    app_a = next(r.cfg for r in grid.runs_of("figA_mamujoco", "cpu") if r.label == "happo")
    assert all(c.normalize and c.ppo_epochs == app_a.ppo_epochs and c.n_envs == app_a.n_envs for c in cheetah.values())
    assert cheetah["oappo always"].sigma == np.inf and {r.cfg.seed for r in grid.runs_of(
        "fig_selection_mamujoco", "cpu")} == set(grid.SELECTION_SEEDS)


def test_gate_use_counts_the_across_network_pairs_open_and_shut():
    k = [[0.0, 0.01, 0.2], [0.03, 0.0, 0.05], [0.5, 0.02, 0.0]]
    df = pd.DataFrame({"env": ["black_blue_red"] * 2, "label": ["x"] * 2, "kl_matrix": [np.nan, np.array(k)],
                       "networks": ["agent"] * 2, "max_steps": [50] * 2, "sigma": [0.04] * 2,
                       "across_share": [np.nan, 0.2]})
    use = selection.gate_use(df, {})
    # 6 ordered pairs of the 3 seats: 0.01, 0.2, 0.03, 0.05, 0.5, 0.02; within 0.04: three
    assert use.loc[0, ["pair-iterations", "open", "shut", "across_share"]].tolist() == [6, 0.5, 0.5, 0.2]
