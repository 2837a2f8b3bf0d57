"""The reuse rule (Eq. 9, Fig. 2, Algorithm 1 lines 5-6) against its defining properties."""
import itertools

import numpy as np
import pytest

from oapo_lite import reuse


def random_kl(n, seed):
    rng = np.random.default_rng(seed)
    kl = rng.exponential(0.2, size=(n, n))
    np.fill_diagonal(kl, 0.0)
    return kl


@pytest.mark.parametrize("n", [1, 2, 3, 4, 7])
@pytest.mark.parametrize("sigma", [0.0, 0.05, 0.2, np.inf])
@pytest.mark.parametrize("lam", [0.0, 0.3, 0.7, 1.0])
def test_oapo_rows_are_distributions(n, sigma, lam):
    m = reuse.oapo_matrix(random_kl(n, n), sigma, lam)
    assert np.allclose(m.sum(1), 1.0)
    assert (m >= 0).all()


def test_eq9_entries_by_hand():
    # Learner 0 may use 1 and 2 (kl <= 0.1), not 3; learner 3 may use nobody.
    kl = np.array(
        [[0.0, 0.05, 0.1, 0.5], [0.05, 0.0, 0.3, 0.3], [0.1, 0.3, 0.0, 0.9], [0.5, 0.3, 0.9, 0.0]]
    )
    m = reuse.oapo_matrix(kl, sigma=0.1, reuse_lambda=0.7)
    expected = np.array(
        [[0.7, 0.15, 0.15, 0.0], [0.3, 0.7, 0.0, 0.0], [0.3, 0.0, 0.7, 0.0], [0.0, 0.0, 0.0, 1.0]]
    )
    assert np.allclose(m, expected)


@pytest.mark.parametrize("seed", range(5))
def test_zeros_exactly_where_gated(seed):
    kl = random_kl(5, seed)
    allowed = np.random.default_rng(seed + 100).random((5, 5)) < 0.6
    m = reuse.oapo_matrix(kl, sigma=0.2, reuse_lambda=0.6, allowed=allowed)
    off = ~np.eye(5, dtype=bool)
    assert (m[off & ((kl > 0.2) | ~allowed)] == 0).all()
    assert (m[off & (kl <= 0.2) & allowed] > 0).all()
    has_peer = ((kl <= 0.2) & allowed & off).any(1)
    assert np.allclose(np.diag(m), np.where(has_peer, 0.6, 1.0))


def test_sigma_zero_gives_identity_and_lone_agent_keeps_all():
    kl = random_kl(4, 0) + 1e-3 * ~np.eye(4, dtype=bool)
    assert np.array_equal(reuse.oapo_matrix(kl, 0.0, 0.4), np.eye(4))
    assert np.array_equal(reuse.oapo_matrix(np.zeros((1, 1)), 0.5, 0.2), np.ones((1, 1)))


def test_infinite_sigma_and_lambda_one_over_n_is_mappo():
    n = 4
    m = reuse.oapo_matrix(random_kl(n, 3), np.inf, 1.0 / n)
    assert np.allclose(m, reuse.mappo_matrix(n))
    assert np.array_equal(reuse.happo_matrix(n), np.eye(n))


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(sigma=-0.1, reuse_lambda=0.5), "sigma"),
        (dict(sigma=float("nan"), reuse_lambda=0.5), "sigma"),
        (dict(sigma=0.1, reuse_lambda=1.5), "lambda"),
        (dict(sigma=0.1, reuse_lambda=-0.01), "lambda"),
        (dict(sigma=0.1, reuse_lambda=0.5, allowed=np.ones((2, 2), bool)), "allowed"),
    ],
)
def test_bad_arguments_raise(kwargs, match):
    with pytest.raises(ValueError, match=match):
        reuse.oapo_matrix(np.zeros((3, 3)), **kwargs)


def test_bad_kl_shape_raises():
    with pytest.raises(ValueError, match="square"):
        reuse.oapo_matrix(np.zeros((2, 3)), 0.1, 0.5)
    with pytest.raises(ValueError, match="non-negative"):
        reuse.oapo_matrix(-np.ones((2, 2)), 0.1, 0.5)


def test_kl_matrix_against_direct_sum():
    rng = np.random.default_rng(1)
    probs = rng.dirichlet(np.ones(5), size=(3, 3, 8))
    k_max, k_mean, k_q90 = (reuse.reduce_kl(reuse.pairwise_kl(probs), s) for s in reuse.KL_REDUCES)
    for i, j in itertools.product(range(3), repeat=2):
        kls = sorted(sum(p * np.log(p / q) for p, q in zip(probs[j, j, b], probs[i, j, b])) for b in range(8))
        assert np.isclose(k_max[i, j], kls[-1])
        assert np.isclose(k_mean[i, j], np.mean(kls))
        # the 90th percentile of 8 values by linear interpolation: position 0.9 * 7 = 6.3
        assert np.isclose(k_q90[i, j], kls[6] + 0.3 * (kls[7] - kls[6]))
    assert np.allclose(np.diag(k_max), 0.0)
    with pytest.raises(ValueError, match="one of \\['max', 'mean', 'q90'\\], got 'median'"):
        reuse.reduce_kl(reuse.pairwise_kl(probs), "median")


def test_reduce_kl_reads_only_the_samples_where_the_source_acted():
    """Inactive samples are left out of every statistic, whatever their KL; a source that
    never acted is at distance 0."""
    rng = np.random.default_rng(3)
    kl = rng.exponential(size=(2, 3, 10))
    active = rng.random((3, 10)) < 0.6
    active[2] = False
    for reduce in reuse.KL_REDUCES:
        K = reuse.reduce_kl(kl, reduce, active)
        noisy = np.where(active[None], kl, 1e6)  # huge KLs where nobody acted change nothing
        assert np.array_equal(K, reuse.reduce_kl(noisy, reduce, active))
        for j in range(2):
            alone = reuse.reduce_kl(kl[:, j:j + 1, active[j]], reduce)[:, 0]
            assert np.array_equal(K[:, j], alone) if reduce == "max" else np.allclose(K[:, j], alone, rtol=1e-12)
        assert (K[:, 2] == 0).all()
        broken = kl.copy()
        broken[1, 0, np.flatnonzero(active[0])[0]] = np.nan  # a diverged learner, where the source acted
        assert np.isnan(reuse.reduce_kl(broken, reduce, active)[1, 0])
        broken[0, 1, np.flatnonzero(~active[1])[0]] = np.nan  # where the source did not act: left out
        assert not np.isnan(reuse.reduce_kl(broken, reduce, active)[0, 1])


def test_categorical_kl_is_exact_without_eps_and_finite_with_it():
    """The one categorical KL behind every K: 0 log 0 = 0; a zero where the source acts is
    inf exactly (tabular policies), and log(1 / eps)-sized when clipped (neural policies)."""
    p = np.array([[0.5, 0.5, 0.0], [1.0, 0.0, 0.0]])
    q = np.array([[0.25, 0.25, 0.5], [0.0, 1.0, 0.0]])
    kl = reuse.categorical_kl(p, q)
    assert kl[0] == pytest.approx(np.log(2.0))  # by hand: 2 * 0.5 * log(0.5 / 0.25)
    assert kl[1] == np.inf
    assert reuse.categorical_kl(p, q, eps=1e-12)[1] == pytest.approx(np.log(1e12))
    assert (reuse.categorical_kl(p, p) == 0.0).all()


def test_sample_mapping_frequencies_match_m():
    m = reuse.oapo_matrix(random_kl(4, 2), 0.3, 0.4)
    rng = np.random.default_rng(0)
    draws = np.array([reuse.sample_mapping(m, rng) for _ in range(20000)])
    freq = np.stack([(draws == j).mean(0) for j in range(4)], 1)
    assert np.abs(freq - m).max() < 0.02
    assert (m[np.arange(4)[None], draws] > 0).all()  # never draws a forbidden source


def test_update_order_is_a_permutation_and_seeded():
    a = reuse.update_order(6, np.random.default_rng(5))
    b = reuse.update_order(6, np.random.default_rng(5))
    assert sorted(a) == list(range(6)) and np.array_equal(a, b)
    with pytest.raises(ValueError, match="positive integer"):
        reuse.update_order(0, np.random.default_rng(0))


def test_scheme_masks():
    agents = ("red", "black", "blue")
    assert np.array_equal(reuse.scheme_mask("NR", agents), np.eye(3, dtype=bool))
    assert reuse.scheme_mask("UR", agents)[0, 1] and not reuse.scheme_mask("UR", agents)[1, 2]
    assert reuse.scheme_mask("RR", agents)[1, 2] and not reuse.scheme_mask("RR", agents)[0, 1]
    assert reuse.scheme_mask("AR", agents).all()
    with pytest.raises(ValueError, match="unknown reuse scheme 'XX'"):
        reuse.scheme_mask("XX", agents)


def test_scheme_mask_names_missing_types_and_mapping_checks_rows():
    with pytest.raises(ValueError, match=r"\['black', 'red'\]"):
        reuse.scheme_mask("UR", ("red_0", "black_1", "blue_2"))
    with pytest.raises(ValueError, match="sum to 1"):
        reuse.sample_mapping(np.array([[0.5, 0.2], [0.0, 1.0]]), np.random.default_rng(0))


def test_matrix_for_dispatches_and_rejects_unknown_kinds():
    kl = random_kl(3, 7)
    assert np.array_equal(reuse.matrix_for("oapo", kl, 0.2, 0.6), reuse.oapo_matrix(kl, 0.2, 0.6))
    assert np.array_equal(reuse.matrix_for("own", kl, 0.2, 0.6), np.eye(3))
    assert np.allclose(reuse.matrix_for("uniform", kl, 0.2, 0.6), 1 / 3)
    with pytest.raises(ValueError, match="unknown reuse rule 'shared'"):
        reuse.matrix_for("shared", kl, 0.2, 0.6)


@pytest.mark.parametrize("n", [1, 2, 3, 5])
def test_peer_share_of_the_three_rules(n):
    assert reuse.peer_share(reuse.happo_matrix(n)) == 0.0
    assert np.isclose(reuse.peer_share(reuse.mappo_matrix(n)), (n - 1) / n)
    close = reuse.oapo_matrix(np.zeros((n, n)), sigma=0.1, reuse_lambda=0.7)  # every peer within sigma
    assert np.isclose(reuse.peer_share(close), 0.0 if n == 1 else 0.3)
    # across networks only: with one network for all seats none, with one per seat all of it
    assert reuse.peer_share(close, [0] * n) == 0.0
    assert reuse.peer_share(close, list(range(n))) == reuse.peer_share(close)


def test_peer_share_across_networks_counts_only_the_other_networks_seats():
    m = np.array([[0.6, 0.3, 0.1], [0.2, 0.8, 0.0], [0.25, 0.25, 0.5]])
    # seats 0 and 1 share a network: row 0 counts 0.1, row 1 0.0, row 2 0.5
    assert np.isclose(reuse.peer_share(m, [0, 0, 1]), (0.1 + 0.0 + 0.5) / 3)


def test_nearest_peer_is_the_smallest_distance_to_another_agent():
    kl = np.array([[0.0, 0.3, 0.05], [2.0, 0.0, 1.0], [1.5, 0.4, 0.0]])
    np.testing.assert_array_equal(reuse.nearest_peer(kl), [0.05, 1.0, 0.4])
    assert np.isnan(reuse.nearest_peer(np.full((2, 2), np.nan))).all()  # K not measured this iteration
    assert reuse.nearest_peer(np.zeros((1, 1))).tolist() == [np.inf]  # a lone agent has no peer
    # the gate: a learner reuses someone exactly when its nearest peer is within sigma
    for sigma in (0.04, 0.05, 0.5, 1.5):
        np.testing.assert_array_equal(1 - np.diag(reuse.oapo_matrix(kl, sigma, 0.7)) > 0, reuse.nearest_peer(kl) <= sigma)
