"""The reuse rule: who learns from whose experience (Fig. 2, Eq. 9, Algorithm 1 lines 5-6).

``M[i, j]`` is the probability that learner ``i`` trains on agent ``j``'s experience.
MAPPO reuses everything uniformly, HAPPO only its own, OAPO gates by policy distance.
"""
from __future__ import annotations

import warnings

import numpy as np

from oapo_lite.renamed import refuse


def _check_n(n: int) -> int:
    if int(n) != n or n < 1:
        raise ValueError(f"number of agents must be a positive integer, got {n!r}")
    return int(n)


def mappo_matrix(n: int) -> np.ndarray:
    """Fig. 2a: parameter sharing, every learner sees every agent's experience, M = 1/n."""
    n = _check_n(n)
    return np.full((n, n), 1.0 / n)


def happo_matrix(n: int) -> np.ndarray:
    """Fig. 2b: no sharing, every learner sees only its own experience, M = I."""
    return np.eye(_check_n(n))


def peer_share(m, owner=None) -> float:
    """How much of the learners' updates comes from other agents' experience: the off-diagonal
    mass of M's rows, averaged over learners (0 for HAPPO, (n - 1) / n for MAPPO, 1 - lambda
    for Eq. 9 with every peer within sigma). With ``owner`` (the network of each seat), only
    the mass on seats of other networks: the reuse Eq. 9's gate decided, since seats that share
    a network are at KL 0 from each other."""
    m = np.asarray(m, dtype=float)
    other = ~np.eye(len(m), dtype=bool) if owner is None else ~np.equal.outer(owner, owner)
    return float(m[other].sum() / len(m))


def nearest_peer(kl) -> np.ndarray:
    """Per learner i, min over the other agents j of K[i, j]: the distance that Eq. 9's gate
    compares with sigma first (i reuses someone iff it is <= sigma, where every pair is allowed);
    inf for a lone agent, NaN where K was not measured."""
    kl = np.asarray(kl, dtype=float)
    return np.where(np.eye(len(kl), dtype=bool), np.inf, kl).min(1)


def oapo_matrix(kl: np.ndarray, sigma: float, reuse_lambda: float, allowed: np.ndarray | None = None) -> np.ndarray:
    """Eq. 9: the reuse distribution of every learner, one row each.

    ``kl[i, j]`` is D_KL^max(pi_j, pi_i), the distance from source j to learner i. Learner
    i keeps ``reuse_lambda`` for itself and spreads ``1 - reuse_lambda`` evenly over the other sources with
    ``kl[i, j] <= sigma`` that ``allowed`` (a fixed boolean mask) permits; if it has no such
    source, it keeps everything (M[i, i] = 1). Rows sum to 1.
    """
    kl = np.asarray(kl, dtype=float)
    if kl.ndim != 2 or kl.shape[0] != kl.shape[1]:
        raise ValueError(f"kl must be a square (n, n) matrix, got shape {kl.shape}")
    if np.isnan(kl).any() or (kl < 0).any():
        raise ValueError("kl must hold non-negative numbers (KL divergences)")
    if not sigma >= 0:
        raise ValueError(f"sigma must be >= 0 (a KL threshold), got {sigma!r}")
    if not 0.0 <= reuse_lambda <= 1.0:
        raise ValueError(f"reuse_lambda must lie in [0, 1], got {reuse_lambda!r}")
    n = kl.shape[0]
    ok = kl <= sigma
    if allowed is not None:
        allowed = np.asarray(allowed, dtype=bool)
        if allowed.shape != kl.shape:
            raise ValueError(f"allowed mask has shape {allowed.shape}, expected {kl.shape}")
        ok &= allowed
    np.fill_diagonal(ok, False)
    others = ok.sum(1, keepdims=True)  # gamma_i - 1 in the paper's notation
    m = np.where(ok, (1.0 - reuse_lambda) / np.maximum(others, 1), 0.0)
    m[np.arange(n), np.arange(n)] = np.where(others[:, 0] > 0, reuse_lambda, 1.0)
    return m


REUSE_RULES = ("oapo", "own", "uniform")  # ``AlgoSpec.reuse_rule``


def matrix_for(reuse_rule: str, kl: np.ndarray, sigma: float, reuse_lambda: float, allowed: np.ndarray | None = None) -> np.ndarray:
    """The reuse matrix of a reuse rule (Fig. 2): "oapo" Eq. 9 from ``kl``, "own" HAPPO's
    identity, "uniform" MAPPO's 1/n (the last two ignore ``kl``, ``sigma``, ``reuse_lambda``, ``allowed``)."""
    if reuse_rule == "oapo":
        return oapo_matrix(kl, sigma, reuse_lambda, allowed)
    if reuse_rule == "own":
        return happo_matrix(len(kl))
    if reuse_rule == "uniform":
        return mappo_matrix(len(kl))
    raise ValueError(f"unknown reuse rule {reuse_rule!r}; choose from {list(REUSE_RULES)}")


def categorical_kl(p: np.ndarray, q: np.ndarray, eps: float = 0.0) -> np.ndarray:
    """KL(p || q) of categorical distributions along the last axis (actions), with 0 log 0 = 0:
    the one KL of discrete policies behind Eq. 9's K, tabular and neural. With ``eps`` > 0 the
    probabilities are clipped at ``eps`` before the log, so a neural policy whose probability
    rounded to 0 gives a large finite KL rather than inf; with 0 the KL is exact (inf where
    q = 0 < p)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        log_p, log_q = (np.log(np.clip(x, eps, None) if eps else x) for x in (p, q))
        return np.where(p == 0, 0.0, p * (log_p - log_q)).sum(-1)  # a NaN stays NaN (a diverged net)


# Eq. 9's D_KL^max is a statistic of the per-observation KL over a source's batch. "max" is
# the paper's; it is an extreme value that grows with the batch (the gate-statistic study). "mean" is the
# expected KL, the paper's own relaxation of the max in Section 5.1; "q90" its 90th percentile.
KL_REDUCES = ("max", "mean", "q90")


@refuse({"reduce": "kl_reduce"})
def reduce_kl(kl: np.ndarray, kl_reduce: str, active: np.ndarray | None = None) -> np.ndarray:
    """Eq. 9's K from per-observation KLs: ``kl[i, j]`` (i, j, batch) are KL(pi_j || pi_i) on
    source j's observations, reduced over the observations where j acted (``active[j]``, all
    if None) by the gate statistic ``kl_reduce`` in ``KL_REDUCES``; a source that never acted is at
    distance 0 from every learner (nothing to disagree on)."""
    if kl_reduce not in KL_REDUCES:
        raise ValueError(f"kl_reduce (the gate statistic) must be one of {list(KL_REDUCES)}, got {kl_reduce!r}")
    if active is None:
        if kl_reduce == "q90":
            return np.quantile(kl, 0.9, axis=-1)
        return kl.max(-1) if kl_reduce == "max" else kl.mean(-1)
    on = np.broadcast_to(np.asarray(active, dtype=bool)[None], kl.shape)
    if kl_reduce == "max":  # KL >= 0, so the zeros of inactive samples never win
        return np.where(on, kl, 0.0).max(-1)
    if kl_reduce == "mean":
        return np.where(on, kl, 0.0).sum(-1) / np.maximum(on.sum(-1), 1)
    with warnings.catch_warnings():  # an all-NaN row (a source that never acted) warns
        warnings.simplefilter("ignore", RuntimeWarning)
        q = np.nanquantile(np.where(on, kl, np.nan), 0.9, axis=-1)
    # a NaN where the source acted (a diverged net) stays NaN, as in the other statistics
    return np.where((np.isnan(kl) & on).any(-1), np.nan, np.where(on.any(-1), q, 0.0))


def pairwise_kl(probs: np.ndarray, eps: float = 1e-12) -> np.ndarray:
    """Per observation, KL(pi_j(.|o_j) || pi_i(.|o_j)) of categorical policies, what Eq. 9's
    D_KL^max(pi_j, pi_i) is estimated from (``reduce_kl``): ``probs[i, j]`` (batch, actions) is
    learner i's action distribution on agent j's observations, so ``probs[j, j]`` is the
    source's own policy there. Returns (i, j, batch)."""
    probs = np.asarray(probs, dtype=float)
    if probs.ndim != 4 or probs.shape[0] != probs.shape[1]:
        raise ValueError(f"probs must have shape (n, n, batch, actions), got {probs.shape}")
    n = probs.shape[0]
    own = probs[np.arange(n), np.arange(n)]  # (n_sources, batch, actions)
    return np.maximum(categorical_kl(own[None], probs, eps), 0.0)


def sample_mapping(m: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Algorithm 1 line 5: draw e, one source per learner, e[i] ~ M[i, :]."""
    m = np.asarray(m, dtype=float)
    if m.ndim != 2 or (m < 0).any() or not np.allclose(m.sum(1), 1.0):
        raise ValueError("M must be a matrix of non-negative rows that sum to 1")
    u = rng.random(m.shape[0])
    e = (np.cumsum(m, 1) < u[:, None]).sum(1)
    return np.minimum(e, m.shape[1] - 1)


def update_order(n: int, rng: np.random.Generator) -> np.ndarray:
    """Algorithm 1 line 6: a random order in which the learners are updated."""
    return rng.permutation(_check_n(n))


SCHEMES = ("NR", "UR", "RR", "AR")  # Fig. 5b's reuse schemes, in the paper's order


def scheme_mask(scheme: str, agents: tuple[str, ...]) -> np.ndarray:
    """Allowed-pair masks of Fig. 5b on Black-Blue-Red, by agent type.

    NR: no reuse; UR: red and black share (unreasonable); RR: black and blue share
    (reasonable); AR: everyone shares. The diagonal is always allowed.
    """
    pairs = {"NR": set(), "UR": {("red", "black")}, "RR": {("black", "blue")}}
    if scheme == "AR":
        return np.ones((len(agents), len(agents)), dtype=bool)
    if scheme not in pairs:
        raise ValueError(f"unknown reuse scheme {scheme!r}; choose from {list(SCHEMES)}")
    missing = {t for pair in pairs[scheme] for t in pair} - set(agents)
    if missing:
        raise ValueError(f"scheme {scheme!r} pairs agent types {sorted(missing)}, "
                         f"but the agents are {list(agents)}")
    mask = np.eye(len(agents), dtype=bool)
    for i, a in enumerate(agents):
        for j, b in enumerate(agents):
            mask[i, j] |= (a, b) in pairs[scheme] or (b, a) in pairs[scheme]
    return mask


def allowed_mask(allowed, agents: tuple[str, ...]) -> np.ndarray | None:
    """A config's ``allowed`` (None, a scheme name or an (n, n) bool mask) for these agents."""
    if isinstance(allowed, str):
        return scheme_mask(allowed, agents)
    if allowed is not None and allowed.shape != (len(agents),) * 2:
        raise ValueError(f"allowed mask has shape {allowed.shape}, expected {(len(agents),) * 2}")
    return allowed


def check_spaces(agents, spaces, pairs: np.ndarray) -> None:
    """Reusing experience needs equal observation and action spaces (Section 4). ``pairs[i, j]``:
    learner i may train on agent j's experience (not necessarily symmetric); ``spaces`` per seat,
    or None where every seat's are equal by construction (``envs.vec.seat_spaces``)."""
    for i, j in zip(*np.nonzero(pairs)):
        if spaces is not None and i != j and spaces[i] != spaces[j]:
            raise ValueError(
                f"reuse between agents {agents[i]!r} and {agents[j]!r} needs equal spaces, got "
                f"{spaces[i]} and {spaces[j]}; forbid the pair with `allowed` or use happo/hatrpo/ippo")
