"""The adaptive reuse rule (oapo_lite/neural/adaptive.py): a hand-computed case, its limiting cases,
the no-new-fixed-point property, bad inputs, and its place in the training loop."""

import numpy as np
import pytest
import torch

from oapo_lite import reuse
from oapo_lite.neural import adaptive
from oapo_lite.neural.config import TrainConfig
from oapo_lite.neural.losses import off_agent_objective
from oapo_lite.neural.nets import Actors
from oapo_lite.neural.ppo_family import LearnerBatch, learner_dists, source_gradients
from oapo_lite.neural.results import learning
from oapo_lite.neural.rollout import collect, make_env
from oapo_lite.neural.runstate import load_checkpoint
from oapo_lite.neural.train import train

torch.set_num_threads(1)

SMALL_BR = dict(env="black_red", n_envs=8, rollout_len=25, steps=600, eval_every=3, eval_episodes=8)


def test_three_agents_by_hand():
    # learner 0: own (1, 0); source 1 (3, 4) has cos 3/5; source 2 (-1, 0) points the other way
    # learner 1: own (0, 2); source 0 (0, -1) has cos -1; source 2 (0, 5) has cos 1
    # learner 2: no gradient of its own, so it agrees with nobody
    g = np.array([
        [[1, 0], [3, 4], [-1, 0]],
        [[0, -1], [0, 2], [0, 5]],
        [[1, 1], [2, 0], [0, 0]],
    ], dtype=float)
    c = adaptive.cosine_agreement(g)
    assert np.allclose(c, [[1, 0.6, -1], [-1, 1, 1], [0, 0, 0]])
    m = reuse.oapo_matrix(np.zeros((3, 3)), sigma=0.1, reuse_lambda=0.7)  # everyone admissible: 0.7 / 0.15 / 0.15
    expected = np.array([
        [1 - 0.15 * 0.6, 0.15 * 0.6, 0.0],  # 0.91, 0.09, 0
        [0.0, 0.85, 0.15],
        [0.0, 0.0, 1.0],
    ])
    assert np.allclose(adaptive.agreement_matrix(m, c), expected)
    # the sign rule keeps Eq. 9's weight of every agreeing source and strikes the others
    sign = np.array([[0.85, 0.15, 0.0], [0.0, 0.85, 0.15], [0.0, 0.0, 1.0]])
    assert np.allclose(adaptive.agreement_matrix(m, c, "gradient_sign"), sign)


def test_the_test_rule_by_hand():
    """Two learners, two folds, one parameter. D_f = g_ii^(f) * g_ij^(other fold)."""
    g = np.zeros((2, 2, 2, 1))
    g[0, 0, :, 0] = [1.0, 3.0]  # learner 0, own, folds 0 and 1
    g[0, 1, :, 0] = [-2.0, -1.0]  # D = (1 * -1, 3 * -2) = (-1, -6): mean -3.5, sd 3.5355, se 2.5
    g[1, 1, :, 0] = [2.0, -2.0]
    g[1, 0, :, 0] = [1.0, 1.0]  # D = (2 * 1, -2 * 1) = (2, -2): mean 0, se 2
    t = adaptive.disagreement_t(g)
    assert np.isclose(t[0, 1], -3.5 / 2.5) and t[1, 0] == 0.0 and np.isinf(t[0, 0]) and t[0, 0] > 0
    m = np.array([[0.7, 0.3], [0.3, 0.7]])
    # -1.4 < -1: learner 0 strikes source 1; learner 1 has no evidence either way and keeps 0
    assert np.allclose(adaptive.agreement_matrix(m, t, "gradient_test"), [[1.0, 0.0], [0.3, 0.7]])
    g[0, 1, :, 0] = [-0.1, -0.1]  # D = (-0.1, -0.3): mean -0.2, se 0.1 -> t = -2
    assert np.isclose(adaptive.disagreement_t(g)[0, 1], -2.0)
    g[0, 1, :, 0] = [0.5, -0.5]  # D = (-0.5, 1.5): mean 0.5 -> kept
    assert adaptive.disagreement_t(g)[0, 1] > 0


def test_the_test_rule_strikes_only_shared_systematic_disagreement():
    """Noise around a zero mean is kept most of the time (a t with 3 degrees of freedom is below
    -1 about 20% of the time; the folds' products share folds, so a little more); a systematic
    disagreement is struck almost always."""
    rng = np.random.default_rng(0)
    m = np.array([[0.7, 0.3], [0.3, 0.7]])
    kept = {}
    for name, mean in (("noise", 0.0), ("against", -1.0)):
        count = 0
        for _ in range(400):
            g = rng.normal(size=(2, 2, 4, 50))
            g[0, 0] += 1.0  # learner 0's own expected gradient: (1, ..., 1)
            g[0, 1] += mean  # the source's: 0 (unrelated) or (-1, ..., -1) (against)
            count += adaptive.agreement_matrix(m, adaptive.disagreement_t(g), "gradient_test")[0, 1] > 0
        kept[name] = count / 400
    assert 0.65 < kept["noise"] < 0.9 and kept["against"] < 0.05


def _random(n, seed):
    rng = np.random.default_rng(seed)
    kl = rng.exponential(0.2, size=(n, n))
    np.fill_diagonal(kl, 0.0)
    return reuse.oapo_matrix(kl, sigma=0.3, reuse_lambda=rng.uniform(0.1, 1.0)), rng.normal(size=(n, n, 7))


RULES = adaptive.ADAPT_RULES
COSINE_RULES = adaptive.COSINE_RULES


def _statistic(g, rule):
    """The statistic ``rule`` reads, from per-source gradients (n, n, P) split into 4 noisy folds."""
    folds = g[:, :, None] + np.random.default_rng(1).normal(size=(*g.shape[:2], 4, g.shape[2]))
    return adaptive.agreement(folds if rule == "gradient_test" else g[:, :, None], rule)


@pytest.mark.parametrize("rule", RULES)
@pytest.mark.parametrize("seed", range(10))
@pytest.mark.parametrize("n", [1, 2, 3, 5])
def test_rows_are_distributions_that_never_reuse_more_than_eq9(n, seed, rule):
    m, g = _random(n, seed)
    out = adaptive.agreement_matrix(m, _statistic(g, rule), rule)
    assert np.allclose(out.sum(1), 1.0) and (out >= 0).all()
    off = ~np.eye(n, dtype=bool)
    assert (out[off] <= m[off] + 1e-12).all()
    assert (np.diag(out) >= np.diag(m) - 1e-12).all()


@pytest.mark.parametrize("rule", COSINE_RULES)
def test_full_agreement_is_eq9_and_full_disagreement_is_happo(rule):
    kl = np.array([[0.0, 0.05, 0.5], [0.05, 0.0, 0.02], [0.3, 0.02, 0.0]])
    m = reuse.oapo_matrix(kl, sigma=0.1, reuse_lambda=0.6)
    assert np.array_equal(adaptive.agreement_matrix(m, np.ones((3, 3)), rule), m)
    disagree = -np.ones((3, 3))
    np.fill_diagonal(disagree, 1.0)
    assert np.array_equal(adaptive.agreement_matrix(m, disagree, rule), np.eye(3))
    assert np.array_equal(adaptive.agreement_matrix(m, np.zeros((3, 3)), rule), np.eye(3))


@pytest.mark.parametrize("rule", COSINE_RULES)
@pytest.mark.parametrize("seed", range(20))
def test_the_mixed_direction_always_climbs_the_learners_own_objective(seed, rule):
    """The module's argument: G_i . g_ii >= M'[i, i] |g_ii|^2, so G_i = 0 forces g_ii = 0."""
    m, g = _random(4, seed)
    out = adaptive.agreement_matrix(m, adaptive.cosine_agreement(g), rule)
    for i in range(4):
        mixed = out[i] @ g[i]
        assert mixed @ g[i, i] >= out[i, i] * (g[i, i] @ g[i, i]) - 1e-9
    # a case where Eq. 9 itself (lambda 0.2) points downhill for learner 0, and the rule does not
    g_bad = np.array([[[1.0, 0.0], [-1.0, 0.1]], [[0.0, 1.0], [0.0, 1.0]]])
    m_bad = reuse.oapo_matrix(np.zeros((2, 2)), 0.1, 0.2)
    c_bad = adaptive.cosine_agreement(g_bad)
    assert (m_bad[0] @ g_bad[0]) @ g_bad[0, 0] < 0  # Eq. 9 with lambda 0.2 goes against the learner
    assert (adaptive.agreement_matrix(m_bad, c_bad, rule)[0] @ g_bad[0]) @ g_bad[0, 0] > 0


@pytest.mark.parametrize("call, words", [
    (lambda: adaptive.cosine_agreement(np.zeros((2, 3, 4))), ["grads", "(2, 3, 4)"]),
    (lambda: adaptive.cosine_agreement(np.full((2, 2, 3), np.nan)), ["finite"]),
    (lambda: adaptive.agreement_matrix(np.eye(2), np.ones((3, 3))), ["agreement", "(3, 3)", "(2, 2)"]),
    (lambda: adaptive.agreement_matrix(np.eye(2), np.full((2, 2), 1.5)), ["[-1, 1]"]),
    (lambda: adaptive.agreement_matrix(np.full((2, 2), 0.7), np.ones((2, 2))), ["sum to 1"]),
    (lambda: adaptive.agreement_matrix(np.ones(3), np.ones(3)), ["square"]),
    (lambda: adaptive.agreement_matrix(np.eye(2), np.ones((2, 2)), "kl"), ["'kl'", "gradient", "gradient_test"]),
    (lambda: adaptive.disagreement_t(np.zeros((2, 2, 1, 3))), ["folds >= 2", "(2, 2, 1, 3)"]),
    (lambda: adaptive.agreement(np.zeros((2, 2, 1, 3)), "gradient_test"), ["(n, n, 4, parameters)", "gradient_test"]),
    (lambda: adaptive.agreement_matrix(np.eye(2), np.full((2, 2), np.nan), "gradient_test"), ["NaN"]),
])
def test_bad_inputs_raise_naming_what_is_wrong(call, words):
    with pytest.raises(ValueError) as err:
        call()
    assert all(w in str(err.value) for w in words)


@pytest.mark.parametrize("bad, words", [
    (dict(reuse_adapt="variance"), ["reuse_adapt", "variance", "gradient"]),
    (dict(reuse_adapt="gradient", algo="happo"), ["reuse_adapt", "happo", "oappo", "oatrpo"]),
    (dict(reuse_adapt="gradient", networks="one"), ["reuse_adapt", "networks='agent'"]),
    (dict(reuse_adapt="gradient_test", n_envs=2, steps=100), ["n_envs", ">= 4", "gradient_test"]),
])
def test_bad_config_raises_naming_the_value_and_the_allowed(bad, words):
    with pytest.raises(ValueError) as err:
        TrainConfig(**bad)
    assert all(w in str(err.value) for w in words)


def test_the_cli_takes_the_rule_and_none():
    from oapo_lite.__main__ import train_parser

    assert train_parser().parse_args(["--reuse-adapt", "gradient_sign"]).reuse_adapt == "gradient_sign"
    assert train_parser().parse_args(["--reuse-adapt", "none"]).reuse_adapt is None
    assert train_parser().parse_args([]).reuse_adapt is None


@pytest.mark.parametrize("clip", [0.2, None])
def test_source_gradients_add_up_to_the_gradient_of_the_weighted_objective(clip):
    """Eq. 8 / Eq. 7 are M-weighted sums over sources, so their gradient must be sum_j M[i, j] g_ij;
    and a source M gives no weight gets zeros."""
    cfg = TrainConfig(**SMALL_BR)
    env = make_env(cfg, cfg.n_envs, seed=0)
    gen = torch.Generator().manual_seed(0)
    actors = Actors(env.n_agents, env.obs_dim, env.n_actions, cfg.hidden, False, gen)
    with torch.no_grad():  # move net 1 away from net 0, so that ratios differ from 1 and clipping acts
        for p in actors.net_params(1):
            p.add_(0.3 * torch.randn(p.shape, generator=gen))
    batch, _ = collect(env, env.reset(), actors, [0, 1], cfg.rollout_len, gen)
    adv = torch.randn(batch.act.shape[1], generator=gen)
    m = np.array([[0.7, 0.3], [0.0, 1.0]])
    g = source_gradients(actors, batch.inputs, batch, m, adv, clip)[:, :, 0]
    assert np.all(g[1, 0] == 0.0)
    # per fold of env copies (8 copies, 4 folds of 2): the whole batch's gradient is their mean
    folds = source_gradients(actors, batch.inputs, batch, m, adv, clip, folds=4)
    assert np.allclose(folds.mean(2), g, atol=1e-6) and not np.allclose(folds[:, :, 0], g)
    src = LearnerBatch.of(0, m[0], [0], batch)
    params = actors.net_params(0)
    d = learner_dists(actors, batch.inputs, src)
    obj = off_agent_objective(actors.head.log_prob(d, src.act), src.logp_old, src.w, torch.ones_like(adv), adv, clip)
    whole = torch.cat([x.reshape(-1) for x in torch.autograd.grad(obj, params)]).double().numpy()
    assert np.allclose(whole, 0.7 * g[0, 0] + 0.3 * g[0, 1], atol=1e-6)
    assert not np.allclose(g[0, 0], g[0, 1])


def test_adaptive_runs_log_eq9_times_agreement_and_default_runs_are_untouched(tmp_path):
    plain = train(TrainConfig(algo="oappo", **SMALL_BR), tmp_path / "plain", resume=False, progress=False)
    assert "agreement" not in plain.columns
    for rule in RULES:
        rows = train(TrainConfig(algo="oappo", reuse_adapt=rule, **SMALL_BR), tmp_path / rule,
                     resume=False, progress=False)
        for _, r in rows.iloc[1:].iterrows():
            k, c, m = (r[col] for col in ("kl_matrix", "agreement", "reuse_matrix"))
            assert np.allclose(m, adaptive.agreement_matrix(reuse.oapo_matrix(k, 0.1, 0.7), c, rule), atol=1e-5)
            assert (np.diag(m) >= 0.7 - 1e-9).all()
    again = train(TrainConfig(algo="oappo", reuse_adapt=rule, **SMALL_BR), tmp_path / "again",
                  resume=False, progress=False)
    assert learning(rows).equals(learning(again))


def test_adaptive_with_nothing_admissible_is_bitwise_happo(tmp_path):
    """sigma = 0 gates every other source out, and the rule never adds reuse Eq. 9 did not allow."""
    train(TrainConfig(algo="happo", **SMALL_BR), tmp_path / "happo", resume=False, progress=False)
    train(TrainConfig(algo="oappo", sigma=0.0, reuse_adapt="gradient", **SMALL_BR), tmp_path / "adapt",
          resume=False, progress=False)
    a, b = (load_checkpoint(tmp_path / name)["actors"] for name in ("happo", "adapt"))
    assert all(torch.equal(a[key], b[key]) for key in a)
