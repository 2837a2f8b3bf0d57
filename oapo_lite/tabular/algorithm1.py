"""Algorithm 1 with softmax tables: OAPPO, OATRPO, HAPPO, HATRPO and MAPPO on an exact game.

Each iteration: take a batch from the current joint policy (every (state, joint action)
pair weighted by its exact discounted probability, or sampled episodes), build the reuse
matrix M (Eq. 9) from D_KL^max between the agents' tables on each source's visited
observations, draw the update order (and in "sample" mode one source per learner), and
update the learners one after another. Learner i maximises the M-weighted sum over
sources j of the off-agent surrogate on j's samples,

    sum_j M[i, j] E_{(s, a) ~ batch}[ratio_ij * factor * A(s, a)],
    ratio_ij = pi_i^new(a_j | o_j) / pi_j^old(a_j | o_j),

PPO-clipped (Eq. 8) or under a KL trust region (Eq. 7). The factor is HAPPO's: the product
of the already-updated learners' own-seat ratios. HAPPO / HATRPO are the identity M;
MAPPO is one shared table trained on every seat with M = 1/n and no factor.

Every iteration also records the true improvement J(pi_{k+1}) - J(pi_k) and Lemma 1's
lower bound in its valid form (see oapo_lite.tabular.exact.lemma1 and tests/tabular/test_exact.py).
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from oapo_lite import reuse
from oapo_lite.algorithms import ALGOS
from oapo_lite.renamed import refuse
from oapo_lite.tabular.exact import DecPOMDP, evaluate, joint_policy, kl_max, lemma1, log_softmax, softmax, state_distribution

# the algorithms of the tabular track: the PPO / TRPO family of the algorithm table (``ALGOS``,
# which says each one's reuse matrix and update) but IPPO
TABLE_ALGOS = ("oappo", "oatrpo", "happo", "hatrpo", "mappo")


@refuse({"epochs": "ppo_epochs", "reuse": "reuse_mode"})
@dataclass(frozen=True)
class TabularConfig:
    algo: str = "oappo"
    iterations: int = 30
    lr: float = 5.0  # PPO: gradient-ascent step on the logits (advantages are normalised)
    ppo_epochs: int = 10  # PPO: ascent steps per learner per iteration
    clip: float = 0.2  # PPO: clip epsilon of Eq. 8
    kl_threshold: float = 0.01  # TRPO: delta of Eq. 7
    backtrack: float = 0.5  # TRPO: line-search shrink factor (up to 10 tries)
    sigma: float = 0.1  # Eq. 9: KL gate for reuse
    reuse_lambda: float = 0.7  # Eq. 9's lambda: weight a learner keeps on its own experience
    reuse_mode: str = "weights"  # "weights": M as weights; "sample": one source per learner (Alg. 1 line 5)
    estimate: str = "exact"  # "exact" expectations or "samples"
    n_episodes: int = 64  # samples: episodes per iteration
    horizon: int = 400  # samples: episodes are cut here
    init_scale: float = 0.1  # std of the initial logits (distinct agents: Eq. 9's KL is positive)
    seed: int = 0

    def __post_init__(self):
        for name, value, allowed in (("algo", self.algo, TABLE_ALGOS), ("reuse_mode", self.reuse_mode, ("weights", "sample")),
                                     ("estimate", self.estimate, ("exact", "samples"))):
            if value not in allowed:
                raise ValueError(f"{name} must be one of {list(allowed)}, got {value!r}")
        for name in ("iterations", "ppo_epochs", "n_episodes", "horizon"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        for name in ("lr", "clip", "kl_threshold"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if not 0 < self.backtrack < 1:
            raise ValueError(f"backtrack must lie in (0, 1), got {self.backtrack}")
        if not self.sigma >= 0:
            raise ValueError(f"sigma must be >= 0 (a KL threshold), got {self.sigma!r}")
        if not 0 <= self.reuse_lambda <= 1:
            raise ValueError(f"reuse_lambda must lie in [0, 1], got {self.reuse_lambda!r}")


@dataclass(frozen=True)
class Record:
    """One iteration of Algorithm 1 (pi_k -> pi_{k+1})."""

    iteration: int
    J: float  # J(pi_k)
    improvement: float  # J(pi_{k+1}) - J(pi_k)
    bound: float  # Lemma 1, valid form, for the evaluated pi_{k+1} (identity seat map: HATRPO's bound)
    bound_written: float  # Lemma 1 as printed, omega(e) = prod_m M[m, e_m]
    M: np.ndarray  # reuse matrix, row = learner
    mapping: np.ndarray | None  # "sample" mode: the source drawn for each learner
    order: np.ndarray  # update order of the learners
    kl: np.ndarray  # kl[i, j] = D_KL^max(pi_j, pi_i) on j's visited observations
    step_kl: np.ndarray  # per learner: KL(old || new) on its sources' observations, M-weighted
    policies: np.ndarray  # pi_k, (n_agents, n_obs, n_actions)


@dataclass(frozen=True)
class Batch:
    """Samples of the old joint policy: state, joint-action index, weight (sums to ~1), advantage."""

    state: np.ndarray
    action: np.ndarray
    weight: np.ndarray
    adv: np.ndarray


# ----------------------------------------------------------------------------- batches

def exact_batch(game: DecPOMDP, pis: np.ndarray) -> Batch:
    """Every non-terminal (s, a) weighted by (1 - gamma) rho_pi(s) pi(a|s), with the exact A_pi."""
    weight = state_distribution(game, pis, normalised=True)[:, None] * joint_policy(game, pis)
    state, action = np.nonzero((weight > 0) & ~game.terminal[:, None])
    return Batch(state, action, weight[state, action], evaluate(game, pis).A[state, action])


def sample_batch(game: DecPOMDP, pis: np.ndarray, n_episodes: int, horizon: int,
                 rng: np.random.Generator) -> Batch:
    """Episodes of the old joint policy, cut at ``horizon``.

    A step at time t weighs (1 - gamma) gamma^t / n_episodes, so weighted averages estimate
    expectations under the normalised rho_pi. The advantage is r + gamma V(s') - V(s) with V
    the every-visit Monte-Carlo return average of this batch (a tabular critic).
    """
    pi = joint_policy(game, pis)
    draw = reuse.sample_mapping  # one categorical draw per row
    state = draw(np.broadcast_to(game.rho0, (n_episodes, game.n_states)), rng)
    steps = []
    alive = ~game.terminal[state]
    for _ in range(horizon):
        if not alive.any():
            break
        action = draw(pi[state], rng)
        nxt = draw(game.P[state, action], rng)
        steps.append((state, action, game.R[state, action], nxt, alive))
        state, alive = nxt, alive & ~game.terminal[nxt]
    s, a, r, s1, live = (np.stack(x) for x in zip(*steps))  # (T, n_episodes)
    goes_on = np.concatenate([live[1:], np.zeros((1, n_episodes), dtype=bool)])
    ret = np.zeros_like(r)
    follow = np.zeros(n_episodes)
    for t in reversed(range(len(r))):
        follow = r[t] + game.gamma * goes_on[t] * follow
        ret[t] = follow
    visits = np.bincount(s[live], minlength=game.n_states)
    value = np.bincount(s[live], ret[live], game.n_states) / np.maximum(visits, 1)
    adv = r + game.gamma * value[s1] * ~game.terminal[s1] - value[s]
    t_index = np.broadcast_to(np.arange(len(r))[:, None], r.shape)
    weight = (1 - game.gamma) * game.gamma ** t_index / n_episodes
    return Batch(s[live], a[live], weight[live], adv[live])


def visited(game: DecPOMDP, batch: Batch) -> np.ndarray:
    """(n_agents, n_obs) eta: batch weight of each seat's observations (the sources' experience)."""
    return np.stack([np.bincount(game.obs[j][batch.state], batch.weight, game.n_obs) for j in range(game.n_agents)])


# ----------------------------------------------------------------------------- learner updates

@dataclass(frozen=True)
class Objective:
    """A learner's off-agent surrogate on its sources' samples, flattened over sources.

    ``idx`` indexes the learner's flattened table (observation, action) of each sample,
    ``behaviour`` is the source's old probability of that action, ``coef`` the M weight
    times sample weight times sequential factor times advantage.
    """

    idx: np.ndarray
    behaviour: np.ndarray
    coef: np.ndarray
    kl_weight: np.ndarray  # (n_obs,) where the trust region is measured

    def ratio(self, logits: np.ndarray) -> np.ndarray:
        return softmax(logits).ravel()[self.idx] / self.behaviour

    def grad(self, logits: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """d/dlogits of sum(weights * ratio): softmax chain rule on d/dlog pi."""
        p = softmax(logits)
        g = np.bincount(self.idx, weights * self.ratio(logits), p.size).reshape(p.shape)
        return g - p * g.sum(-1, keepdims=True)

    def kl(self, old_logits: np.ndarray, logits: np.ndarray) -> float:
        log_p = log_softmax(old_logits)
        return float(self.kl_weight @ (np.exp(log_p) * (log_p - log_softmax(logits))).sum(-1))


def learner_objective(game: DecPOMDP, batch: Batch, old: np.ndarray, row: np.ndarray, factor: np.ndarray,
                      adv: np.ndarray, eta: np.ndarray) -> Objective:
    """Eq. 7/8's objective for one learner: its M row ``row`` over the sources' samples, the
    sources' old tables ``old`` as behaviour, and the trust-region weights row @ eta (normalised)."""
    sources = np.flatnonzero(row)
    obs = game.obs[sources][:, batch.state]  # (n_sources, B)
    act = game.joint_actions[batch.action][:, sources].T
    coef = row[sources, None] * (batch.weight * factor * adv)[None]
    kl_weight = row @ (eta / eta.sum(1, keepdims=True))
    return Objective(idx=(obs * game.n_actions + act).ravel(), behaviour=old[sources[:, None], obs, act].ravel(),
                     coef=coef.ravel(), kl_weight=kl_weight)


def ppo_update(obj: Objective, logits: np.ndarray, cfg: TabularConfig) -> np.ndarray:
    """Eq. 8: a few exact gradient-ascent steps on sum coef * min(r, clip(r, 1 +- eps))."""
    for _ in range(cfg.ppo_epochs):
        r = obj.ratio(logits)
        clipped = ((obj.coef > 0) & (r > 1 + cfg.clip)) | ((obj.coef < 0) & (r < 1 - cfg.clip))
        logits = logits + cfg.lr * obj.grad(logits, obj.coef * ~clipped)
    return logits


def trpo_update(obj: Objective, logits: np.ndarray, cfg: TabularConfig) -> np.ndarray:
    """Eq. 7: natural-gradient step on sum coef * r under E_o[KL(old || new)] <= delta, line search.

    For a softmax table the Fisher of the weighted KL is w(o) (diag p - p p^T) per
    observation, and G / (w p) solves it exactly (G = gradient w.r.t. log pi), so no
    conjugate gradient is needed.
    """
    p = softmax(logits)
    g = np.bincount(obj.idx, obj.coef * obj.ratio(logits), p.size).reshape(p.shape)
    w = obj.kl_weight[:, None]
    direction = np.divide(g, w * p, out=np.zeros_like(g), where=w > 0)
    quad = float(obj.kl_weight @ ((p * direction ** 2).sum(-1) - (p * direction).sum(-1) ** 2))
    if quad <= 0:
        return logits
    step = np.sqrt(2 * cfg.kl_threshold / quad) * direction
    base = obj.coef @ obj.ratio(logits)
    for k in range(10):
        trial = logits + cfg.backtrack ** k * step
        if obj.kl(logits, trial) <= cfg.kl_threshold and obj.coef @ obj.ratio(trial) > base:
            return trial
    return logits


# ----------------------------------------------------------------------------- Algorithm 1

def kl_between_agents(tables: np.ndarray, eta: np.ndarray) -> np.ndarray:
    """Eq. 9's K[i, j] = D_KL^max(pi_j, pi_i) over the observations source j visited."""
    n = len(tables)
    return np.array([[kl_max(tables[j], tables[i], eta[j]) for j in range(n)] for i in range(n)])


def seat_map_distribution(m: np.ndarray) -> dict:
    """omega(e) = prod_m M[m, e_m]: row m of M read as Eq. 9's p(e_m), the learner playing seat m."""
    n = len(m)
    omega = {e: float(np.prod(m[np.arange(n), list(e)])) for e in itertools.product(range(n), repeat=n)}
    return {e: p for e, p in omega.items() if p > 0}


def run_tabular(game: DecPOMDP, cfg: TabularConfig) -> list[Record]:
    """Algorithm 1 on ``game`` with softmax tables; one Record per iteration."""
    n = game.n_agents
    shared = ALGOS[cfg.algo].networks == "one"
    streams = np.random.SeedSequence(cfg.seed).spawn(4)
    rng_init, rng_order, rng_map, rng_samples = (np.random.default_rng(s) for s in streams)
    logits = rng_init.normal(0.0, cfg.init_scale, (1 if shared else n, game.n_obs, game.n_actions))
    owner = np.zeros(n, dtype=np.int64) if shared else np.arange(n)
    update = trpo_update if ALGOS[cfg.algo].trust_region else ppo_update
    records = []
    for k in range(cfg.iterations):
        old = softmax(logits)[owner]
        batch = (exact_batch(game, old) if cfg.estimate == "exact"
                 else sample_batch(game, old, cfg.n_episodes, cfg.horizon, rng_samples))
        eta = visited(game, batch)
        mean = batch.weight @ batch.adv / batch.weight.sum()
        std = np.sqrt(batch.weight @ (batch.adv - mean) ** 2 / batch.weight.sum())
        adv = (batch.adv - mean) / (std + 1e-8)
        kl = kl_between_agents(old, eta)
        m = reuse.matrix_for(ALGOS[cfg.algo].reuse_rule, kl, cfg.sigma, cfg.reuse_lambda)
        mapping = reuse.sample_mapping(m, rng_map) if cfg.reuse_mode == "sample" else None
        rows = np.eye(n)[mapping] if mapping is not None else m
        order = np.zeros(1, dtype=np.int64) if shared else reuse.update_order(n, rng_order)
        factor = np.ones(len(batch.state))
        new_logits = logits.copy()
        step_kl = np.zeros(len(logits))
        for i in order:
            obj = learner_objective(game, batch, old, rows[i], factor, adv, eta)
            new_logits[i] = update(obj, logits[i], cfg)
            step_kl[i] = obj.kl(logits[i], new_logits[i])
            # HAPPO's sequential factor: learner i now plays its own seat with the new table
            own = (game.obs[i][batch.state], game.joint_actions[batch.action, i])
            factor = factor * softmax(new_logits[i])[own] / old[i][own]
        new = softmax(new_logits)[owner]
        valid = lemma1(game, old, new, {tuple(range(n)): 1.0})
        written = lemma1(game, old, new, seat_map_distribution(m))
        records.append(Record(iteration=k, J=evaluate(game, old).J, improvement=valid["improvement"],
                              bound=valid["bound_corrected"], bound_written=written["bound_written"], M=m,
                              mapping=mapping, order=order, kl=kl, step_kl=step_kl, policies=old))
        logits = new_logits
    return records
