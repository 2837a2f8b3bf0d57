"""The exact engine against independent computations, and which statements of the paper hold.

Findings pinned down here (numbers in the test bodies):
(i)  Proposition 1 / Eq. 6 holds with the "- 1" only for the *local* increment
     L^{e_{1:m}} - L^{e_{1:m-1}}; without it, it equals the paper's L^{e_{1:m}}. Either way
     the factor must be the product of the tables *placed in the earlier seats*, on those
     seats' samples.
(ii) Lemma 1 is a valid lower bound on J(pi_e) - J(pi), where pi_e is the joint policy the
     mapping e describes, with the local (decomposition) surrogate and D_KL^max(pi_m, bar pi_{e_m});
     the printed form (D_KL^max(pi_{e_m}, bar pi_{e_m}), cumulative A(s, a_{1:m}), left side
     J(bar pi)) fails on concrete instances.
"""
import itertools

import numpy as np
import pytest

from oapo_lite.envs.maps import load_maze
from oapo_lite.tabular import exact as ex


@pytest.fixture(scope="module")
def maze():
    return load_maze("black_red")


@pytest.fixture(scope="module")
def game(maze):
    return ex.from_maze(maze)


def distances_to_star(maze, k):
    """Shortest number of moves to the star from every cell for seat k (Bellman-Ford on next_cell)."""
    d = np.full(maze.n_cells, np.inf)
    d[maze.star] = 0.0
    for _ in range(maze.n_cells):
        d = np.minimum(d, 1 + d[maze.next_cell[k]].min(1))
    return d


def route_tables(maze, mix=1.0):
    """Each seat's shortest-route table, mixed with the uniform policy: mix * greedy + (1 - mix) / 5."""
    tables = []
    for k in range(maze.n_agents):
        d = distances_to_star(maze, k)
        greedy = np.eye(5)[d[maze.next_cell[k]].argmin(1)]
        tables.append(mix * greedy + (1 - mix) / 5)
    return np.array(tables)


def power_series(game, pis, horizon):
    """V and rho by explicit iteration sum_t gamma^t P_pi^t (dense), truncated at ``horizon``."""
    pi = ex.joint_policy(game, pis)
    p_pi = np.einsum("sa,sat->st", pi, game.P)
    r_pi = (pi * game.R).sum(1)
    V, rho, step, dist = np.zeros(game.n_states), np.zeros(game.n_states), r_pi.copy(), game.rho0.copy()
    for t in range(horizon):
        V += game.gamma ** t * step
        rho += game.gamma ** t * dist
        step, dist = p_pi @ step, dist @ p_pi
    return V, rho


def mixed_random_game(seed, n_agents=2, gamma=0.9):
    rng = np.random.default_rng(seed)
    game = ex.random_game(rng, n_agents=n_agents, n_states=4, n_actions=2, n_obs=3, gamma=gamma)
    return game, rng


# ----------------------------------------------------------------------------- construction

def test_game_validation_names_the_problem():
    game = ex.matrix_game("climbing")
    with pytest.raises(ValueError, match="P has shape"):
        ex.DecPOMDP(P=game.P[:, :4], R=game.R, obs=game.obs, n_obs=1, n_actions=3, rho0=game.rho0, gamma=0.9)
    with pytest.raises(ValueError, match="probability vectors"):
        ex.DecPOMDP(P=game.P * 2, R=game.R, obs=game.obs, n_obs=1, n_actions=3, rho0=game.rho0, gamma=0.9)
    with pytest.raises(ValueError, match="gamma"):
        ex.DecPOMDP(P=game.P, R=game.R, obs=game.obs, n_obs=1, n_actions=3, rho0=game.rho0, gamma=1.0)
    with pytest.raises(ValueError, match="obs values"):
        ex.DecPOMDP(P=game.P, R=game.R, obs=game.obs + 1, n_obs=1, n_actions=3, rho0=game.rho0, gamma=0.9)
    with pytest.raises(ValueError, match="unknown payoff"):
        ex.matrix_game("prisoners")
    with pytest.raises(ValueError, match="rows summing to 1"):
        ex.evaluate(game, np.full((2, 1, 3), 0.5))


def test_climbing_game_has_a_suboptimal_equilibrium():
    payoff = ex.CLIMBING
    assert payoff.max() == payoff[0, 0] == 11
    # (1, 1) pays 7 and no lone deviation improves it: independent learners can stop there
    assert payoff[1, 1] == 7 and payoff[:, 1].max() == 7 and payoff[1, :].max() == 7


def test_maze_state_space_and_terminal(game, maze):
    assert game.n_states == 19 * 19
    assert game.terminal.sum() == 1 and (game.obs[:, game.terminal] == maze.star).all()
    assert game.rho0[(game.obs[0] == maze.starts[0]) & (game.obs[1] == maze.starts[1])].sum() == 1.0


def test_maze_shortest_routes_reach_the_closed_form_optimum(game, maze):
    d = [int(distances_to_star(maze, k)[maze.starts[k]]) for k in range(2)]
    assert d == [12, 12]
    g = game.gamma
    optimum = np.mean([g ** (dk - 1) - 0.01 * sum(g ** t for t in range(dk)) for dk in d])
    assert ex.evaluate(game, route_tables(maze)).J == pytest.approx(optimum, abs=1e-12)


# ----------------------------------------------------------------------------- values

@pytest.mark.parametrize("which", ["matrix", "random", "maze"])
def test_values_and_distribution_match_power_series(which, game):
    rng = np.random.default_rng(3)
    g = {"matrix": ex.matrix_game("penalty", gamma=0.9), "random": ex.random_game(rng, n_agents=3),
         "maze": game}[which]
    pis = ex.random_policies(g, rng)
    V, rho = power_series(g, pis, horizon=4000)
    values = ex.evaluate(g, pis)
    np.testing.assert_allclose(values.V, V, atol=1e-9)
    np.testing.assert_allclose(ex.state_distribution(g, pis), rho, atol=1e-7)
    assert values.J == pytest.approx(g.rho0 @ V, abs=1e-9)
    # Q and A from their definitions: one step, then V
    np.testing.assert_allclose(values.Q, g.R + g.gamma * np.einsum("sat,t->sa", g.P, V), atol=1e-9)
    np.testing.assert_allclose((ex.joint_policy(g, pis) * values.A).sum(1), 0.0, atol=1e-9)
    assert ex.state_distribution(g, pis, normalised=True).sum() == pytest.approx(1.0)
    eta = ex.obs_distribution(g, pis, 0)
    assert eta.sum() == pytest.approx(1 / (1 - g.gamma)) and (eta >= 0).all()
    for o in range(g.n_obs):  # eta is rho summed over the states where agent 0 sees o
        assert eta[o] == pytest.approx(rho[g.obs[0] == o].sum(), abs=1e-6)
    assert ex.obs_distribution(g, pis, 0, normalised=True) == pytest.approx(eta * (1 - g.gamma))


def test_maze_value_matches_monte_carlo_on_the_move_rule(game, maze):
    """Roll the maze out through maze.next_cell and the env's reward, not through game.P."""
    rng = np.random.default_rng(0)
    tables = route_tables(maze, mix=0.6)
    n_runs, n = 4000, maze.n_agents
    seats = np.arange(n)
    cells = np.tile(maze.starts, (n_runs, 1))
    ret = np.zeros(n_runs)
    for t in range(400):
        cum = tables[seats, cells].cumsum(-1)  # (runs, n, actions)
        actions = (cum < rng.random((n_runs, n, 1))).sum(-1)
        nxt = maze.next_cell[seats, cells, actions]
        before = cells == maze.star
        ret += game.gamma ** t * (((nxt == maze.star) & ~before).mean(1) - 0.01 * (~before).mean(1))
        cells = nxt
    assert (cells == maze.star).all()  # nothing left running at the cut
    se = ret.std() / np.sqrt(n_runs)
    assert abs(ret.mean() - ex.evaluate(game, tables).J) < 4 * se


def test_matrix_game_value_matches_monte_carlo():
    rng = np.random.default_rng(1)
    game = ex.matrix_game("climbing")
    pis = ex.random_policies(game, rng)
    a = np.stack([rng.choice(3, size=20000, p=pis[i, 0]) for i in range(2)])
    payoff = ex.CLIMBING[a[0], a[1]]
    assert abs(payoff.mean() - ex.evaluate(game, pis).J) < 4 * payoff.std() / np.sqrt(payoff.size)


def test_kl_max_matches_brute_force():
    rng = np.random.default_rng(2)
    p, q = rng.dirichlet(np.ones(4), size=6), rng.dirichlet(np.ones(4), size=6)
    weights = np.array([0, 1, 0, 2, 0.5, 0])
    per_obs = [sum(p[o, a] * np.log(p[o, a] / q[o, a]) for a in range(4)) for o in range(6)]
    assert ex.kl_max(p, q) == pytest.approx(max(per_obs))
    assert ex.kl_max(p, q, weights) == pytest.approx(max(per_obs[o] for o in (1, 3, 4)))
    assert ex.kl_max(p, p) == 0.0
    with pytest.raises(ValueError, match="one shape"):
        ex.kl_max(p, q[:, :3])


# ----------------------------------------------------------------------------- Eq. 1-4

def test_performance_difference_exact_with_new_distribution_only(game, maze):
    old = ex.random_policies(game, np.random.default_rng(4))
    new = route_tables(maze, mix=0.9)
    gain = ex.evaluate(game, new).J - ex.evaluate(game, old).J
    assert ex.surrogate(game, old, new, dist="new") == pytest.approx(gain, abs=1e-10)
    gap = gain - ex.surrogate(game, old, new, dist="old")
    assert abs(gap) > 0.05, gap  # Eq. 1 as printed (rho_old) is only the surrogate L
    # a one-step game has one state distribution for every policy: there the two agree
    mg = ex.matrix_game("climbing")
    o, n = ex.random_policies(mg, np.random.default_rng(5)), ex.random_policies(mg, np.random.default_rng(6))
    assert ex.surrogate(mg, o, n, "old") == pytest.approx(ex.surrogate(mg, o, n, "new"), abs=1e-12)


@pytest.mark.parametrize("which", ["matrix", "maze"])
def test_permutation_terms_equal_only_under_shared_parameters(which, game):
    rng = np.random.default_rng(7)
    g = ex.matrix_game("climbing") if which == "matrix" else game
    old = ex.random_policies(g, rng)
    shared = np.repeat(ex.random_policies(g, rng)[:1], 2, axis=0)
    terms = ex.permutation_terms(g, old, shared)
    assert np.ptp(list(terms["terms"].values())) < 1e-12
    assert terms["mean"] == pytest.approx(terms["identity"])
    separate = ex.permutation_terms(g, old, ex.random_policies(g, rng))
    assert np.ptp(list(separate["terms"].values())) > 1e-3
    assert abs(separate["mean"] - separate["identity"]) > 1e-4


@pytest.mark.parametrize("which", ["random3", "maze"])
def test_multi_agent_advantage_decomposition_for_every_order(which, game):
    rng = np.random.default_rng(8)
    g = ex.random_game(rng, n_agents=3, n_actions=3) if which == "random3" else game
    pis = ex.random_policies(g, rng)
    A = ex.evaluate(g, pis).A
    for order in itertools.permutations(range(g.n_agents)):
        total = sum(ex.local_advantage(g, pis, order[:m], order[m]) for m in range(g.n_agents))
        np.testing.assert_allclose(total, A, atol=1e-12)
    # the subset advantage of everyone is A, of no one is 0
    np.testing.assert_allclose(ex.multi_agent_advantage(g, pis, range(g.n_agents)), A, atol=1e-12)
    np.testing.assert_allclose(ex.multi_agent_advantage(g, pis, []), 0.0, atol=1e-12)


def test_subset_q_is_a_brute_force_marginal():
    rng = np.random.default_rng(9)
    g = ex.random_game(rng, n_agents=3)
    pis = ex.random_policies(g, rng)
    Q = ex.evaluate(g, pis).Q
    marg = ex.subset_q(g, pis, Q, [2])
    for s in range(g.n_states):
        for a2 in range(2):
            brute = sum(pis[0, g.obs[0, s], a0] * pis[1, g.obs[1, s], a1] * Q[s, 4 * a0 + 2 * a1 + a2]
                        for a0 in range(2) for a1 in range(2))
            assert marg[s, a2] == pytest.approx(brute)  # joint index of (0, 0, a2)


# ----------------------------------------------------------------------------- (i) Proposition 1

@pytest.mark.parametrize("which", ["random3", "maze"])
def test_proposition1_holds_for_the_local_increment_with_minus_one(which, game):
    rng = np.random.default_rng(10)
    g = ex.random_game(rng, n_agents=3) if which == "random3" else game
    old, cand = ex.random_policies(g, rng), ex.random_policies(g, rng)
    order = list(rng.permutation(g.n_agents))
    seat_policies = cand[rng.permutation(g.n_agents)]  # candidates of other learners placed in the seats
    L = ex.sequential_surrogate(g, old, seat_policies, order)
    for m, seat in enumerate(order):
        factor = {k: seat_policies[k] for k in order[:m]}
        with_one = ex.off_agent_estimate(g, old, seat, seat_policies[seat], factor, minus_one=True)
        without = ex.off_agent_estimate(g, old, seat, seat_policies[seat], factor, minus_one=False)
        increment = L[m] - (L[m - 1] if m else 0.0)
        assert with_one == pytest.approx(increment, abs=1e-10)
        assert without == pytest.approx(L[m], abs=1e-10)
        if m:  # as printed (with "- 1" = L^{e_{1:m}}) it is off by L^{e_{1:m-1}}
            assert abs(with_one - L[m]) == pytest.approx(abs(L[m - 1]), abs=1e-10)
            assert abs(L[m - 1]) > 1e-4


def test_proposition1_needs_the_factor_of_the_tables_placed_in_earlier_seats():
    g, rng = mixed_random_game(11)
    old, new = ex.random_policies(g, rng), ex.random_policies(g, rng)
    # seat map e = (1, 0): learner 1's candidate plays seat 0, learner 0's plays seat 1
    seat_policies = new[[1, 0]]
    L = ex.sequential_surrogate(g, old, seat_policies, [0, 1])
    placed = ex.off_agent_estimate(g, old, 1, new[0], {0: new[1]}, minus_one=False)
    own_seat = ex.off_agent_estimate(g, old, 1, new[0], {0: new[0]}, minus_one=False)
    assert placed == pytest.approx(L[1], abs=1e-12)
    assert abs(own_seat - L[1]) > 1e-3  # a learner's own table on seat 0 is not what plays seat 0


# ----------------------------------------------------------------------------- (ii) Lemma 1

def test_lemma1_corrected_form_holds_on_random_instances(game):
    maps = list(itertools.product(range(2), repeat=2))
    for seed in range(60):
        g, rng = mixed_random_game(seed, gamma=[0.5, 0.9][seed % 2])
        old = ex.random_policies(g, rng)
        scale = [0.01, 0.3, 3.0][seed % 3]  # small, medium and large moves
        new = old * np.exp(rng.normal(0, scale, old.shape))
        new /= new.sum(-1, keepdims=True)
        omega = dict(zip(maps, rng.dirichlet(np.ones(4))))
        r = ex.lemma1(g, old, new, omega, order=rng.permutation(2))
        assert r["improvement_mapped"] >= r["bound_corrected"] - 1e-12, (seed, r)
        assert r["surrogate_local"] == pytest.approx(
            sum(p * ex.surrogate(g, old, new[list(e)]) for e, p in omega.items()))
    rng = np.random.default_rng(12)
    for _ in range(3):
        old, new = ex.random_policies(game, rng), ex.random_policies(game, rng)
        r = ex.lemma1(game, old, new, {(0, 1): 0.5, (1, 0): 0.5})
        assert r["improvement_mapped"] >= r["bound_corrected"]


def nearly_equal_agents(seed, noise=0.05):
    """A random game whose two agents hold almost the same table (Condition 1 with a small sigma)."""
    g, rng = mixed_random_game(seed)
    old = ex.random_policies(g, rng)
    old[1] = old[0] * np.exp(rng.normal(0, noise, old[0].shape))
    old /= old.sum(-1, keepdims=True)
    return g, old


def test_lemma1_with_the_learners_own_kl_can_fail():
    """Candidates = old tables, agents swapped: the printed D_KL^max(pi_{e_m}, bar pi_{e_m}) is 0."""
    g, old = nearly_equal_agents(seed=0)
    r = ex.lemma1(g, old, old, {(1, 0): 1.0})
    assert r["kl_written"] == 0.0 and r["kl_seat"] < 3e-3  # the agents are close: sigma = 3e-3 suffices
    written_kl_bound = r["surrogate_local"] - r["C"] * r["kl_written"]
    assert r["improvement_mapped"] == pytest.approx(0.0016020, abs=1e-7)
    assert written_kl_bound == pytest.approx(0.0018585, abs=1e-7)
    assert r["improvement_mapped"] < written_kl_bound  # the counterexample
    assert r["improvement_mapped"] >= r["bound_corrected"]
    fails = 0
    for seed in range(20):
        g, o = nearly_equal_agents(seed)
        r = ex.lemma1(g, o, o, {(1, 0): 1.0})
        fails += r["improvement_mapped"] < r["surrogate_local"]
    assert fails >= 5  # not a fluke: measured 10 of 20


def ascent_step(game, old, delta):
    """Each seat moves along the gradient of its own single-seat surrogate (a typical update)."""
    rho, A = ex.state_distribution(game, old), ex.evaluate(game, old).A
    new = old.copy()
    for k in range(game.n_agents):
        others = [j for j in range(game.n_agents) if j != k]
        w = rho[:, None] * ex.seat_product(game, old, others) * A
        idx = game.obs[k][:, None] * game.n_actions + game.joint_actions[None, :, k]
        grad = np.bincount(idx.ravel(), w.ravel(), game.n_obs * game.n_actions).reshape(old[k].shape)
        new[k] = old[k] * np.exp(delta * grad)
    return new / new.sum(-1, keepdims=True)


def test_lemma1_with_the_cumulative_surrogate_can_fail():
    """Identity mapping (no reuse at all): summing L^{1:m} with A(s, a_{1:m}) = Q^{1:m} - V over m
    counts the first seats' gains several times; the local terms telescope and do not."""
    fails = 0
    for seed in range(30):
        g, rng = mixed_random_game(seed)
        old = ex.random_policies(g, rng)
        r = ex.lemma1(g, old, ascent_step(g, old, 1e-3), {(0, 1): 1.0})
        assert r["kl_written"] == r["kl_seat"]  # identity mapping: the two KL forms coincide
        assert r["improvement"] >= r["bound_corrected"]
        fails += r["improvement"] < r["surrogate_cumulative"] - r["C"] * r["kl_seat"]
    assert fails >= 20  # measured: 27 of 30


def test_lemma1_left_side_must_be_the_mapped_policy():
    """In a one-step game the surrogate is exact, yet J(bar pi) - J(pi) is not bounded by terms about pi_e."""
    g = ex.matrix_game(np.array([[0.0, 1.0], [0.0, 0.0]]))
    old = np.array([[[0.1, 0.9]], [[0.9, 0.1]]])
    r = ex.lemma1(g, old, old, {(1, 0): 1.0})
    assert r["improvement"] == 0.0
    assert r["improvement_mapped"] == pytest.approx(0.8) == r["surrogate_local"]
    assert r["surrogate_cumulative"] == pytest.approx(0.88) and r["kl_written"] == 0.0
    assert r["improvement"] < r["bound_written"]
    assert r["improvement_mapped"] >= r["bound_corrected"]


def test_lemma1_rejects_bad_omega():
    g = ex.matrix_game("climbing")
    p = ex.random_policies(g, np.random.default_rng(0))
    with pytest.raises(ValueError, match="sum to"):
        ex.lemma1(g, p, p, {(0, 1): 0.5})
    with pytest.raises(ValueError, match="one learner"):
        ex.lemma1(g, p, p, {(0, 2): 1.0})


def test_a_settled_policy_keeps_every_probability_above_underflow():
    """A table whose logits differ by more than float64's exp range keeps its unlikely actions at
    float64's smallest normal number, never at 0 (whether exp gives a denormal or 0 there depends
    on the CPU's code path), so the KL between two such tables stays finite and about 0."""
    settled = np.array([[0.0, -800.0, -2000.0], [5.0, 5.0, -900.0]])
    p, q = ex.softmax(settled), ex.softmax(settled - np.array([0.0, 0.0, 50.0]))  # only the unlikely action moves
    assert (p >= np.finfo(float).tiny).all() and (q >= np.finfo(float).tiny).all()
    np.testing.assert_allclose(p.sum(-1), 1.0, rtol=0, atol=1e-15)
    np.testing.assert_allclose(p[1, :2], [0.5, 0.5], rtol=1e-15)
    assert 0.0 <= ex.kl_max(p, q) < 1e-250
    np.testing.assert_allclose(ex.softmax(np.array([[1.0, 2.0, 3.0]])), [np.exp([1, 2, 3]) / np.exp([1, 2, 3]).sum()],
                               rtol=1e-15)
