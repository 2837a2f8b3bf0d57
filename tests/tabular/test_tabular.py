"""Tabular Algorithm 1 (OAPPO, OATRPO, HAPPO, HATRPO, MAPPO) on exact games."""
import numpy as np
import pytest

from oapo_lite.envs.maps import load_maze
from oapo_lite.tabular import exact as ex
from oapo_lite.tabular.algorithm1 import TabularConfig, exact_batch, run_tabular, sample_batch, visited


@pytest.fixture(scope="module")
def maze_game():
    return ex.from_maze(load_maze("black_red"))


def returns(records):
    """J(pi_0), ..., J(pi_K) from a run's records."""
    return np.array([r.J for r in records] + [records[-1].J + records[-1].improvement])


def optimum(gamma=0.99, d=(12, 12)):
    """Separate-policy optimum on Black-Red: mean_k(gamma^(d_k - 1) - 0.01 sum_{t < d_k} gamma^t)."""
    return float(np.mean([gamma ** (dk - 1) - 0.01 * sum(gamma ** t for t in range(dk)) for dk in d]))


@pytest.mark.parametrize("payoff", ["climbing", "penalty"])
@pytest.mark.parametrize("algo", ["happo", "hatrpo"])
def test_sequential_updates_improve_a_matrix_game_monotonically(payoff, algo):
    records = run_tabular(ex.matrix_game(payoff), TabularConfig(algo=algo, iterations=12))
    J = returns(records)
    assert (np.diff(J) >= -1e-12).all(), np.diff(J)
    assert J[-1] > J[0] + 0.1


@pytest.mark.parametrize("algo", ["oappo", "oatrpo", "mappo", "happo"])
def test_lemma1_valid_bound_holds_every_iteration(algo, maze_game):
    for game, iters in ((ex.matrix_game("penalty"), 10), (maze_game, 4)):
        for r in run_tabular(game, TabularConfig(algo=algo, iterations=iters)):
            assert r.improvement >= r.bound - 1e-12, (algo, r.iteration, r.improvement, r.bound)


@pytest.mark.parametrize("pair", [("oappo", "happo"), ("oatrpo", "hatrpo")])
def test_off_agent_with_sigma_zero_is_the_heterogeneous_trajectory(pair, maze_game):
    """sigma = 0 gates out every other agent (their tables differ from the seeded start),
    so M = I and the run must be HAPPO's / HATRPO's, bit for bit."""
    off, het = (run_tabular(maze_game, TabularConfig(algo=a, sigma=0.0, iterations=6, seed=3)) for a in pair)
    for a, b in zip(off, het):
        np.testing.assert_array_equal(a.M, np.eye(2))
        np.testing.assert_array_equal(a.policies, b.policies)
        np.testing.assert_array_equal(a.order, b.order)
        assert a.J == b.J
    # with reuse switched on the trajectory really differs (the test above can fail)
    reusing = run_tabular(maze_game, TabularConfig(algo=pair[0], sigma=10.0, iterations=6, seed=3))
    assert not np.array_equal(reusing[-1].policies, het[-1].policies)
    assert reusing[0].M[0, 1] == pytest.approx(0.3)


def test_shared_table_stays_below_the_separate_optimum_on_black_red(maze_game):
    best = optimum()
    happo = returns(run_tabular(maze_game, TabularConfig(algo="happo", iterations=30)))
    mappo = returns(run_tabular(maze_game, TabularConfig(algo="mappo", iterations=30)))
    assert happo[-1] > best - 0.01 and happo[-1] <= best + 1e-12  # approaches J* = 0.7817
    assert mappo.max() < best - 0.3  # one table cannot send red left and black right from one start


def test_same_seed_same_records_other_seed_other_records(maze_game):
    cfg = TabularConfig(algo="oappo", iterations=4, reuse_mode="sample", seed=5)
    a, b = run_tabular(maze_game, cfg), run_tabular(maze_game, cfg)
    for x, y in zip(a, b):
        for field in ("J", "improvement", "bound", "bound_written"):
            assert getattr(x, field) == getattr(y, field)
        for field in ("M", "mapping", "order", "kl", "step_kl", "policies"):
            np.testing.assert_array_equal(getattr(x, field), getattr(y, field))
    c = run_tabular(maze_game, TabularConfig(algo="oappo", iterations=4, reuse_mode="sample", seed=6))
    assert not np.array_equal(a[-1].policies, c[-1].policies)


def test_sample_mode_draws_one_source_per_learner_from_m(maze_game):
    records = run_tabular(maze_game, TabularConfig(algo="oappo", iterations=5, reuse_mode="sample", sigma=10.0))
    for r in records:
        assert r.mapping.shape == (2,)
        assert (r.M[np.arange(2), r.mapping] > 0).all()
    assert any((r.mapping != np.arange(2)).any() for r in records)  # some learner reused another's data


def test_trust_region_steps_respect_the_kl_threshold(maze_game):
    for algo in ("oatrpo", "hatrpo"):
        for r in run_tabular(maze_game, TabularConfig(algo=algo, iterations=5, kl_threshold=0.02)):
            assert (r.step_kl <= 0.02 + 1e-12).all() and (r.step_kl > 0).any()


def test_exact_reuse_matrix_follows_eq9_kl(maze_game):
    r = run_tabular(maze_game, TabularConfig(algo="oappo", iterations=1, sigma=10.0, reuse_lambda=0.6))[0]
    np.testing.assert_allclose(r.M, [[0.6, 0.4], [0.4, 0.6]])
    assert (np.diag(r.kl) == 0).all() and (r.kl[~np.eye(2, dtype=bool)] > 0).all()
    gated = run_tabular(maze_game, TabularConfig(algo="oappo", iterations=1, sigma=r.kl.max() / 2, reuse_lambda=0.6))[0]
    assert gated.M[r.kl > r.kl.max() / 2].sum() == 0


def test_sampled_batch_estimates_the_exact_batch(maze_game):
    """Weighted samples estimate the exact (1 - gamma) rho_pi expectations: observation
    distributions, and the policy gradient sum w A d log pi that every update follows."""
    pis = ex.random_policies(maze_game, np.random.default_rng(0), scale=0.5)
    pis[:, :, 4] *= 0.1  # few nops: episodes end within the horizon
    pis /= pis.sum(-1, keepdims=True)
    exact = exact_batch(maze_game, pis)
    sampled = sample_batch(maze_game, pis, n_episodes=200, horizon=1000, rng=np.random.default_rng(1))
    assert sampled.weight.sum() == pytest.approx(exact.weight.sum(), abs=0.01)
    total_variation = 0.5 * np.abs(visited(maze_game, sampled) - visited(maze_game, exact)).sum(1)
    assert (total_variation < 0.06).all(), total_variation

    def gradient(batch):
        idx = maze_game.obs[0][batch.state] * 5 + maze_game.joint_actions[batch.action, 0]
        return np.bincount(idx, batch.weight * batch.adv, maze_game.n_obs * 5)

    assert np.corrcoef(gradient(exact), gradient(sampled))[0, 1] > 0.7  # measured 0.81-0.93 over seeds


def test_sampled_mode_tracks_exact_mode():
    game = ex.matrix_game("climbing")
    for algo in ("happo", "mappo", "oappo"):
        exact = returns(run_tabular(game, TabularConfig(algo=algo, iterations=10)))
        sampled = returns(run_tabular(game, TabularConfig(algo=algo, iterations=10, estimate="samples",
                                                          n_episodes=2000)))
        assert np.abs(exact - sampled).max() < 0.05 * np.ptp(exact), algo


def test_sampled_mode_tracks_exact_mode_on_black_red(maze_game):
    exact = returns(run_tabular(maze_game, TabularConfig(algo="hatrpo", iterations=12)))
    sampled = returns(run_tabular(maze_game, TabularConfig(algo="hatrpo", iterations=12, estimate="samples")))
    assert sampled[-1] > sampled[0] + 1.0
    assert abs(sampled[-1] - exact[-1]) < 0.15


def test_config_rejects_bad_values():
    with pytest.raises(ValueError, match="algo must be one of"):
        TabularConfig(algo="ippo")
    with pytest.raises(ValueError, match="reuse_mode must be one of"):
        TabularConfig(reuse_mode="all")
    with pytest.raises(ValueError, match="iterations must be >= 1"):
        TabularConfig(iterations=0)
    with pytest.raises(ValueError, match="clip must be > 0"):
        TabularConfig(clip=0.0)


def test_a_renamed_keyword_is_refused_naming_its_new_name():
    """The two tracks share one name per concept (the neural track's, its run files' columns)."""
    from oapo_lite.algorithms import AlgoSpec
    from oapo_lite.reuse import reduce_kl

    for call, old, new in ((lambda: TabularConfig(epochs=3), "epochs", "ppo_epochs"),
                           (lambda: TabularConfig(reuse="sample"), "reuse", "reuse_mode"),
                           (lambda: AlgoSpec(reuse="own", sequential=True, trust_region=False, networks="agent"),
                            "reuse", "reuse_rule"),
                           (lambda: AlgoSpec("own", True, False, shared=False), "shared", "networks"),
                           (lambda: reduce_kl(np.zeros((2, 2, 3)), reduce="max"), "reduce", "kl_reduce")):
        with pytest.raises(TypeError, match=f"keyword {old}= was renamed {new}=$"):
            call()
    assert TabularConfig(ppo_epochs=3, reuse_mode="sample").ppo_epochs == 3  # the new names work


@pytest.mark.parametrize("kwargs, match", [(dict(sigma=-1.0), "sigma"), (dict(reuse_lambda=3.0), "lambda")])
def test_bad_sigma_lambda_raise(kwargs, match):
    with pytest.raises(ValueError, match=match):
        TabularConfig(algo="oappo", **kwargs)
