"""Closed-form quantities of a small Dec-POMDP: the exact engine behind every tabular check.

A game is a finite Dec-POMDP whose observations are a deterministic function of the
state: agent i sees ``obs[i, s]``. A joint policy is one softmax table per seat,
``pis[i]`` of shape (n_obs, n_actions), rows summing to 1; all seats share observation
and action spaces, so any agent's table can be placed in any seat (off-agent reuse).

Everything is computed by linear algebra on the joint state space (float64): values by
solving (I - gamma P_pi) V = r_pi, discounted state distributions by the transposed
system. Terminal states are absorbing, zero-reward states; the policy there matters to
nobody, so KL divergences that bound returns skip them.

Conventions for Section 4.2 (Algorithm 1, Lemma 1, Proposition 1): *seats* are the
places in the joint action (seat m acts on its own observation o_m); a *seat map* ``e``
places learner ``e[m]``'s candidate table in seat m, as in the paper's
tilde pi = bar pi_{e_1} x ... x bar pi_{e_m}.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from oapo_lite.envs.maps import STEP_COST, Maze, reachable
from oapo_lite.reuse import categorical_kl

MAX_DENSE_ENTRIES = 50_000_000  # S * A_joint * S floats held in P (400 MB)


@dataclass(frozen=True)
class DecPOMDP:
    """A finite Dec-POMDP with deterministic observations (Section 3).

    ``P[s, a, s']`` transition probabilities over joint actions ``a`` (enumerated as
    ``itertools.product(range(n_actions), repeat=n_agents)``, see ``joint_actions``),
    ``R[s, a]`` the team reward, ``obs[i, s]`` agent i's observation index in state s,
    ``rho0`` the start distribution.
    """

    P: np.ndarray
    R: np.ndarray
    obs: np.ndarray
    n_obs: int
    n_actions: int
    rho0: np.ndarray
    gamma: float
    n_agents: int = field(init=False)
    n_states: int = field(init=False)
    joint_actions: np.ndarray = field(init=False, repr=False)
    terminal: np.ndarray = field(init=False, repr=False)
    flat_P: sp.csr_array = field(init=False, repr=False)  # P as a sparse (S * A_joint, S) matrix

    def __post_init__(self):
        obs = np.asarray(self.obs)
        if obs.ndim != 2 or not np.issubdtype(obs.dtype, np.integer):
            raise ValueError(f"obs must be an integer (n_agents, n_states) array, got {obs.dtype} {obs.shape}")
        n, s = obs.shape
        if obs.min() < 0 or obs.max() >= self.n_obs:
            raise ValueError(f"obs values must lie in [0, n_obs={self.n_obs}), got range [{obs.min()}, {obs.max()}]")
        joint = np.array(list(itertools.product(range(self.n_actions), repeat=n)), dtype=np.int64)
        a = len(joint)
        P, R, rho0 = (np.asarray(x, dtype=float) for x in (self.P, self.R, self.rho0))
        for name, x, shape in (("P", P, (s, a, s)), ("R", R, (s, a)), ("rho0", rho0, (s,))):
            if x.shape != shape:
                raise ValueError(
                    f"{name} has shape {x.shape}; with {n} agents, {self.n_actions} actions and {s} states "
                    f"it must be {shape}"
                )
        if (P < 0).any() or not np.allclose(P.sum(-1), 1.0):
            raise ValueError("P[s, a, :] must be probability vectors (non-negative, summing to 1)")
        if (rho0 < 0).any() or not np.isclose(rho0.sum(), 1.0):
            raise ValueError(f"rho0 must be a probability vector, it sums to {rho0.sum()}")
        if not 0.0 <= self.gamma < 1.0:
            raise ValueError(f"gamma must lie in [0, 1) for an infinite-horizon discounted game, got {self.gamma}")
        idx = np.arange(s)
        terminal = np.isclose(P[idx, :, idx], 1.0).all(1) & (R == 0).all(1)
        for name, value in (("P", P), ("R", R), ("rho0", rho0), ("obs", obs), ("n_agents", n),
                            ("n_states", s), ("joint_actions", joint), ("terminal", terminal),
                            ("flat_P", sp.csr_array(P.reshape(s * a, s)))):
            object.__setattr__(self, name, value)


@dataclass(frozen=True)
class Values:
    """V (S,), Q (S, A_joint), the joint advantage A = Q - V and J = rho0 @ V."""

    V: np.ndarray
    Q: np.ndarray
    A: np.ndarray
    J: float


# ----------------------------------------------------------------------------- games

CLIMBING = np.array([[11.0, -30.0, 0.0], [-30.0, 7.0, 6.0], [0.0, 0.0, 5.0]])
"""Claus & Boutilier's climbing game: the optimum (0, 0) pays 11, but (1, 1) paying 7 is
an equilibrium independent learners settle in (a lone deviation to 0 meets -30)."""

PENALTY = np.array([[-10.0, 0.0, 10.0], [0.0, 2.0, 0.0], [10.0, 0.0, -10.0]])
"""The penalty game: two optima (0, 2) and (2, 0) that need *different* actions, so one
shared table that mixes them is punished; (1, 1) is a safe suboptimal equilibrium."""

PAYOFFS = {"climbing": CLIMBING, "penalty": PENALTY}


def matrix_game(payoff: np.ndarray | str, gamma: float = 0.99) -> DecPOMDP:
    """A one-step cooperative game: play once in state 0, then sit in the terminal state 1.

    ``payoff`` has shape (n_actions,) * n_agents (or is a name from ``PAYOFFS``). Every
    agent sees observation 0, so its policy is a single row.
    """
    if isinstance(payoff, str):
        if payoff not in PAYOFFS:
            raise ValueError(f"unknown payoff {payoff!r}; named payoffs are {sorted(PAYOFFS)}")
        payoff = PAYOFFS[payoff]
    payoff = np.asarray(payoff, dtype=float)
    if payoff.ndim < 1 or len(set(payoff.shape)) != 1:
        raise ValueError(f"payoff must have shape (n_actions,) * n_agents, got {payoff.shape}")
    n_agents, n_actions = payoff.ndim, payoff.shape[0]
    a = payoff.size
    P = np.zeros((2, a, 2))
    P[:, :, 1] = 1.0
    R = np.stack([payoff.ravel(), np.zeros(a)])
    return DecPOMDP(P=P, R=R, obs=np.zeros((n_agents, 2), dtype=np.int64), n_obs=1,
                    n_actions=n_actions, rho0=np.array([1.0, 0.0]), gamma=gamma)


def from_maze(maze: Maze, gamma: float = 0.99) -> DecPOMDP:
    """The maze of Section 6.1 as an exact Dec-POMDP on its joint state space.

    A state is the tuple of agent cells, each over the cells its seat can reach from its
    start (stepping through ``maze.next_cell``, the one move rule). The reward is the
    environment's: (1/n) sum_k [1{k reaches the star this step} - STEP_COST * 1{k is not on the
    star at the step's start}]; the state with everyone on the star is absorbing with
    zero reward. Unlike the environment there is *no time limit*: the game is infinite
    horizon and discounted, so J is the value of an endless episode. Seat k observes its
    cell index, a one-to-one function of the environment's observation ``obs_table[cell]``.
    """
    n = maze.n_agents
    cells = [np.flatnonzero(reachable(maze.next_cell[k], maze.starts[k])) for k in range(n)]
    state_cells = np.stack([g.ravel() for g in np.meshgrid(*cells, indexing="ij")], 1)  # (S, n)
    s_count = len(state_cells)
    joint = np.array(list(itertools.product(range(maze.next_cell.shape[2]), repeat=n)))
    if s_count * len(joint) * s_count > MAX_DENSE_ENTRIES:
        raise ValueError(
            f"maze {maze.name!r} has {s_count} joint states and {len(joint)} joint actions; the dense "
            f"transition tensor would hold {s_count ** 2 * len(joint):,} entries (limit {MAX_DENSE_ENTRIES:,})"
        )
    position = np.full((n, maze.n_cells), -1)
    for k in range(n):
        position[k, cells[k]] = np.arange(len(cells[k]))
    seats = np.arange(n)
    after = maze.next_cell[seats, state_cells[:, None, :], joint[None, :, :]]  # (S, A, n)
    nxt = np.ravel_multi_index(tuple(position[seats, after].transpose(2, 0, 1)), [len(c) for c in cells])
    before_on = state_cells[:, None, :] == maze.star
    R = ((after == maze.star) & ~before_on).mean(-1) - STEP_COST * (~before_on).mean(-1)
    P = np.zeros((s_count, len(joint), s_count))
    np.put_along_axis(P, nxt[..., None], 1.0, axis=2)
    start = np.ravel_multi_index([position[k, maze.starts[k]] for k in range(n)], [len(c) for c in cells])
    rho0 = np.zeros(s_count)
    rho0[start] = 1.0
    return DecPOMDP(P=P, R=np.broadcast_to(R, P.shape[:2]).copy(), obs=state_cells.T.copy(),
                    n_obs=maze.n_cells, n_actions=maze.next_cell.shape[2], rho0=rho0, gamma=gamma)


def random_game(rng: np.random.Generator, n_agents: int = 2, n_states: int = 4, n_actions: int = 2,
                n_obs: int = 3, gamma: float = 0.9) -> DecPOMDP:
    """A random Dec-POMDP (Dirichlet transitions, uniform rewards in [-1, 1]) for property tests."""
    a = n_actions ** n_agents
    return DecPOMDP(P=rng.dirichlet(np.ones(n_states), size=(n_states, a)),
                    R=rng.uniform(-1, 1, (n_states, a)),
                    obs=rng.integers(0, n_obs, (n_agents, n_states)), n_obs=n_obs,
                    n_actions=n_actions, rho0=rng.dirichlet(np.ones(n_states)), gamma=gamma)


def random_policies(game: DecPOMDP, rng: np.random.Generator, scale: float = 1.0) -> np.ndarray:
    """Softmax tables with N(0, scale^2) logits, one per seat: (n_agents, n_obs, n_actions)."""
    return softmax(rng.normal(0.0, scale, (game.n_agents, game.n_obs, game.n_actions)))


# ----------------------------------------------------------------------------- policies

def log_softmax(logits: np.ndarray) -> np.ndarray:
    shifted = logits - logits.max(-1, keepdims=True)
    return shifted - np.log(np.exp(shifted).sum(-1, keepdims=True))


# A policy that has all but settled on one action gives the others e^-700 and less; below
# float64's smallest normal number exp rounds to a denormal or to 0 by the CPU's code path, and a
# 0 makes every KL against that table infinite (Lemma 1's bound -inf on one machine, finite on
# another). So no probability is stored below it.
TINY = np.finfo(float).tiny


def softmax(logits: np.ndarray) -> np.ndarray:
    """Policy tables from logits, along the last axis; no entry below float64's smallest normal number."""
    return np.maximum(np.exp(log_softmax(logits)), TINY)


def _tables(game: DecPOMDP, pis) -> np.ndarray:
    tables = np.asarray(pis, dtype=float)
    shape = (game.n_agents, game.n_obs, game.n_actions)
    if tables.shape != shape:
        raise ValueError(f"a joint policy is one (n_obs, n_actions) table per seat, shape {shape}; got {tables.shape}")
    if (tables < 0).any() or not np.allclose(tables.sum(-1), 1.0):
        raise ValueError("policy tables must hold probabilities with rows summing to 1")
    return tables


def seat_product(game: DecPOMDP, pis, seats) -> np.ndarray:
    """(S, A_joint): prod over ``seats`` k of pis[k](a_k | o_k(s)); 1 for no seats."""
    tables = _tables(game, pis)
    seats = np.asarray(seats, dtype=np.int64).reshape(-1)
    picked = tables[seats[:, None, None], game.obs[seats][:, :, None], game.joint_actions[:, seats].T[:, None, :]]
    return picked.prod(0)


def joint_policy(game: DecPOMDP, pis) -> np.ndarray:
    """pi(a | s) = prod_i pi_i(a_i | o_i) (Section 3), shape (S, A_joint)."""
    return seat_product(game, pis, np.arange(game.n_agents))


def _bellman(game: DecPOMDP, pi: np.ndarray) -> sp.csc_array:
    """I - gamma P_pi as a sparse matrix (transitions are sparse in the mazes)."""
    s, a = pi.shape
    spread = sp.csr_array((pi.ravel(), (np.repeat(np.arange(s), a), np.arange(s * a))), shape=(s, s * a))
    return (sp.eye_array(s) - game.gamma * (spread @ game.flat_P)).tocsc()


def evaluate(game: DecPOMDP, pis) -> Values:
    """V_pi, Q_pi, A_pi = Q_pi - V_pi and J(pi) = E_{s0 ~ rho0} V_pi(s0) (Section 3), in closed form."""
    pi = joint_policy(game, pis)
    V = np.atleast_1d(spsolve(_bellman(game, pi), (pi * game.R).sum(1)))
    Q = game.R + game.gamma * (game.flat_P @ V).reshape(pi.shape)
    return Values(V=V, Q=Q, A=Q - V[:, None], J=float(game.rho0 @ V))


def state_distribution(game: DecPOMDP, pis, normalised: bool = False) -> np.ndarray:
    """rho_pi = sum_t gamma^t rho_pi^t (Section 3), unnormalised: it sums to 1 / (1 - gamma).

    ``normalised=True`` multiplies by (1 - gamma), giving a probability vector.
    """
    rho = np.atleast_1d(spsolve(_bellman(game, joint_policy(game, pis)).T.tocsc(), game.rho0))
    return rho * (1.0 - game.gamma) if normalised else rho


def obs_distribution(game: DecPOMDP, pis, i: int, normalised: bool = False) -> np.ndarray:
    """eta_{pi_i}(o) = sum_t gamma^t P(o_i^t = o) (Section 3): rho_pi pushed through agent i's observations."""
    return np.bincount(game.obs[i], weights=state_distribution(game, pis, normalised), minlength=game.n_obs)


def seat_observations(game: DecPOMDP, i: int) -> np.ndarray:
    """(n_obs,) bool: the observations seat i can have in a non-terminal state."""
    return np.bincount(game.obs[i][~game.terminal], minlength=game.n_obs) > 0


def kl_max(p: np.ndarray, q: np.ndarray, weights: np.ndarray | None = None) -> float:
    """D_KL^max(p, q) = max_o KL(p(.|o) || q(.|o)) (Lemma 1, Eq. 9), over observations with weight > 0."""
    p, q = np.asarray(p, dtype=float), np.asarray(q, dtype=float)
    if p.shape != q.shape or p.ndim != 2:
        raise ValueError(f"p and q must be (n_obs, n_actions) tables of one shape, got {p.shape} and {q.shape}")
    kl = categorical_kl(p, q)
    if weights is not None:
        keep = np.asarray(weights) > 0
        if keep.shape != kl.shape:
            raise ValueError(f"weights must have one entry per observation ({kl.shape}), got {keep.shape}")
        kl = kl[keep]
    return float(kl.max()) if kl.size else 0.0


# ----------------------------------------------------------------------------- advantages

def subset_q(game: DecPOMDP, pis, values: np.ndarray, agents) -> np.ndarray:
    """Marginalise (S, A_joint) values over the agents *not* in ``agents`` under ``pis``.

    With Q this is the multi-agent Q^{i_{1:m}}(s, a_{i_{1:m}}) (Appendix B); with A it is
    the multi-agent advantage A^{i_{1:m}} = Q^{i_{1:m}} - V. The result stays (S, A_joint),
    constant along the marginalised agents' actions.
    """
    others = np.setdiff1d(np.arange(game.n_agents), np.asarray(agents, dtype=np.int64))
    weighted = values * seat_product(game, pis, others)
    grid = weighted.reshape((game.n_states,) + (game.n_actions,) * game.n_agents)
    marginal = grid.sum(axis=tuple(1 + others), keepdims=True)
    return np.broadcast_to(marginal, grid.shape).reshape(values.shape)


def multi_agent_advantage(game: DecPOMDP, pis, agents) -> np.ndarray:
    """A_pi(s, a_{i_{1:m}}) = Q^{i_{1:m}}(s, a_{i_{1:m}}) - V(s) (Section 4.2), shape (S, A_joint)."""
    return subset_q(game, pis, evaluate(game, pis).A, agents)


def local_advantage(game: DecPOMDP, pis, earlier, agent: int) -> np.ndarray:
    """A^{i_m}(s, a_{i_{1:m-1}}, a_{i_m}) = Q^{i_{1:m}} - Q^{i_{1:m-1}}: one term of the
    multi-agent advantage decomposition (Appendix B); summed along any order it gives A."""
    earlier = list(earlier)
    A = evaluate(game, pis).A
    return subset_q(game, pis, A, earlier + [agent]) - subset_q(game, pis, A, earlier)


# ----------------------------------------------------------------------------- surrogates

def surrogate(game: DecPOMDP, old, new, dist: str = "old") -> float:
    """Eq. 1's correction term sum_s rho(s) sum_a new(a|s) A_old(s, a).

    ``dist="new"`` weights by rho_new: then it equals J(new) - J(old) exactly (the
    performance-difference identity). ``dist="old"`` weights by rho_old, as the paper
    writes Eq. 1: that is the surrogate L_old(new), only a first-order approximation.
    """
    if dist not in ("old", "new"):
        raise ValueError(f"dist must be 'old' or 'new', got {dist!r}")
    rho = state_distribution(game, new if dist == "new" else old)
    return float(rho @ (joint_policy(game, new) * evaluate(game, old).A).sum(1))


def permutation_terms(game: DecPOMDP, old, new) -> dict:
    """Eq. 2-4: E_zeta for every permutation zeta of the candidate tables over the seats.

    Returns ``terms`` {zeta: E_zeta} (seat i plays new[zeta[i]], states from rho_old),
    ``mean`` (Eq. 3's average), ``identity`` (Eq. 4, zeta = identity: HAPPO's term) and
    ``improvement`` = J(new) - J(old) for comparison.
    """
    new = _tables(game, new)
    terms = {z: surrogate(game, old, new[list(z)], "old") for z in itertools.permutations(range(game.n_agents))}
    return {"terms": terms, "mean": float(np.mean(list(terms.values()))),
            "identity": terms[tuple(range(game.n_agents))],
            "improvement": evaluate(game, new).J - evaluate(game, old).J}


def _placed(game: DecPOMDP, old, seat_policies, seats) -> np.ndarray:
    tables = _tables(game, old).copy()
    seats = list(seats)
    tables[seats] = _tables(game, seat_policies)[seats]
    return tables


def sequential_surrogate(game: DecPOMDP, old, seat_policies, order) -> np.ndarray:
    """Section 4.2's L^{e_{1:m}}_pi(tilde pi^{m-1}, bar pi_{e_m}) for m = 1..n, as an (n,) array.

    Seats enter in ``order``; the first m seats play ``seat_policies`` (the candidates
    placed there), s ~ rho_old, and the integrand is the multi-agent advantage
    A_pi(s, a_{1:m}) = Q^{1:m} - V of those seats (the rest marginalised under ``old``).
    ``np.diff`` of the result, prefixed by 0, gives the local-advantage (decomposition)
    terms, whose sum is L_old(tilde pi^n).
    """
    order = _check_order(game, order)
    rho = state_distribution(game, old)
    A = evaluate(game, old).A
    out = []
    for m in range(1, game.n_agents + 1):
        seats = order[:m]
        # seats outside the subset keep their old tables; the subset advantage is constant
        # along their actions, so their probabilities just sum to one
        pi_m = joint_policy(game, _placed(game, old, seat_policies, seats))
        out.append(rho @ (pi_m * subset_q(game, old, A, seats)).sum(1))
    return np.array(out)


def _check_order(game: DecPOMDP, order) -> list[int]:
    order = [int(k) for k in order]
    if sorted(order) != list(range(game.n_agents)):
        raise ValueError(f"order must be a permutation of the seats 0..{game.n_agents - 1}, got {order}")
    return order


def off_agent_estimate(game: DecPOMDP, old, seat: int, candidate, factor_policies: dict,
                       minus_one: bool = True) -> float:
    """Eq. 6's right-hand side, computed exactly as an importance-weighted expectation:

        E_{s ~ rho_old, a ~ pi_old}[(candidate(a_m|o_m) / pi_m(a_m|o_m) - 1)
                                     * prod_{k in factor_policies} f_k(a_k|o_k) / pi_k(a_k|o_k)
                                     * A_old(s, a)]

    with m = ``seat`` and ``factor_policies`` {seat k: table f_k} for the earlier seats.
    ``minus_one=False`` drops the "- 1" (then it equals L^{e_{1:m}}; with it, the local
    increment L^{e_{1:m}} - L^{e_{1:m-1}}; see tests/tabular/test_exact.py).
    """
    if seat in factor_policies:
        raise ValueError(f"seat {seat} is the one being estimated; factor_policies may hold only earlier seats")
    tables = _tables(game, old)
    cand = tables.copy()
    cand[seat] = np.asarray(candidate, dtype=float)
    factor_tables = tables.copy()
    for k, table in factor_policies.items():
        factor_tables[k] = np.asarray(table, dtype=float)
    earlier = list(factor_policies)
    ratio = seat_product(game, cand, [seat]) / seat_product(game, tables, [seat])
    factor = seat_product(game, factor_tables, earlier) / seat_product(game, tables, earlier)
    weight = joint_policy(game, tables) * (ratio - float(minus_one)) * factor
    return float(state_distribution(game, tables) @ (weight * evaluate(game, tables).A).sum(1))


# ----------------------------------------------------------------------------- Lemma 1

def lemma1(game: DecPOMDP, old, new, omega, order=None) -> dict:
    """Both sides of Lemma 1 for a distribution ``omega`` {seat map e: probability}.

    Seat map e places learner e[m]'s candidate new[e[m]] in seat m, giving the joint
    policy pi_e. C = 4 gamma eps / (1 - gamma)^2 with eps = max_{s,a} |A_old(s, a)|.
    Returned (all expectations over e ~ omega):

    - ``improvement``: J(new) - J(old), the paper's left side (new in its own seats);
    - ``improvement_mapped``: E J(pi_e) - J(old), the policy the right side describes;
    - ``surrogate_cumulative``: sum_m L^{e_{1:m}} with A_pi(s, a_{1:m}) = Q^{1:m} - V (as written);
    - ``surrogate_local``: sum_m of the local (decomposition) terms = L_old(pi_e);
    - ``kl_written``: sum_m D_KL^max(pi_{e_m}, bar pi_{e_m}), learner e_m's own move on its own seat;
    - ``kl_seat``: sum_m D_KL^max(pi_m, bar pi_{e_m}), seat m's old table vs the candidate placed there;
    - ``bound_written`` = surrogate_cumulative - C kl_written (Lemma 1 as printed);
    - ``bound_corrected`` = surrogate_local - C kl_seat, a lower bound on improvement_mapped
      (TRPO's bound for pi_e; KL of a product is the sum of the seats' KLs).
    """
    old, new = _tables(game, old), _tables(game, new)
    order = _check_order(game, range(game.n_agents) if order is None else order)
    items = list(omega.items())
    probs = np.array([p for _, p in items], dtype=float)
    if (probs < 0).any() or not np.isclose(probs.sum(), 1.0):
        raise ValueError(f"omega must be a distribution over seat maps; its probabilities sum to {probs.sum()}")
    values = evaluate(game, old)
    eps = float(np.abs(values.A).max())
    C = 4 * game.gamma * eps / (1 - game.gamma) ** 2
    seat_obs = [seat_observations(game, m) for m in range(game.n_agents)]
    rows = []
    for e, _ in items:
        e = np.asarray(e, dtype=np.int64)
        if e.shape != (game.n_agents,) or e.min() < 0 or e.max() >= game.n_agents:
            raise ValueError(f"a seat map gives one learner in 0..{game.n_agents - 1} per seat, got {e.tolist()}")
        cumulative = sequential_surrogate(game, old, new[e], order)
        rows.append([
            evaluate(game, new[e]).J - values.J,
            cumulative.sum(),
            cumulative[-1],
            sum(kl_max(old[k], new[k], seat_obs[k]) for k in e),
            sum(kl_max(old[m], new[k], seat_obs[m]) for m, k in enumerate(e)),
        ])
    mapped, cum, local, kl_written, kl_seat = probs @ np.array(rows)
    return {"improvement": evaluate(game, new).J - values.J, "improvement_mapped": mapped,
            "surrogate_cumulative": cum, "surrogate_local": local, "kl_written": kl_written,
            "kl_seat": kl_seat, "eps": eps, "C": C,
            "bound_written": cum - C * kl_written, "bound_corrected": local - C * kl_seat}
