"""Adaptive reuse (issue 12, the paper's Section 7 future work): Eq. 9's weights scaled online by
gradient agreement.

Eq. 9 decides reuse from policy distance alone. On Black-Red that signal misses the trap:
with lambda < 1/2 both learners follow the other's samples more than their own, their policies
are pulled together, K stays below sigma, and the pair settles on one shared policy (MAPPO's
level). There the two agents *agree in policy* but *disagree in what should change*: the
gradient of learner i's objective on source j's samples points against the gradient on its own.

The rules: let g_ij be the gradient, in learner i's parameters at the start of the iteration,
of its update objective (Eq. 8's clipped term, Eq. 7's for OATRPO) on source j's samples alone,
and c_ij = cos(g_ii, g_ij). Then, from Eq. 9's matrix M,

    M'[i, j] = M[i, j] * a(c_ij)        (j != i)
    M'[i, i] = 1 - sum_{j != i} M'[i, j]

with a(c) = max(0, c) (``"gradient"``) or a(c) = 1 if c > 0 else 0 (``"gradient_sign"``), so
sigma, lambda and the allowed mask cap the reuse and the agreement decides how much of the cap
is used. c = 1 everywhere gives Eq. 9 under both; c <= 0 everywhere gives HAPPO's identity;
the sign rule is Eq. 9 with the disagreeing sources struck out.
Why it cannot trap where HAPPO does not: with exact gradients, learner i's objective moves
along G_i = sum_j M'[i, j] g_ij. If G_i = 0 then M'[i, i] |g_ii|^2 = -sum_{j != i} M'[i, j]
g_ii . g_ij <= 0, since every kept source has g_ii . g_ij > 0; M'[i, i] >= M[i, i] > 0 whenever
Eq. 9 keeps anything for the learner (lambda > 0), so g_ii = 0. A stationary point of the mixed
objective is then one of the learner's own (HAPPO's): reuse adds no fixed point of its own.
The argument holds for exact gradients at the start of an iteration. One batch's cosines are
noisy, and after convergence (own gradient near 0, off-agent ratios far from 1) noise alone can
let a source in, so sigma stays on as the variance guard (ASSUMPTIONS.md, measured there).
"""
from __future__ import annotations

import numpy as np

ADAPT_RULES = ("gradient", "gradient_sign")


def cosine_agreement(grads: np.ndarray, eps: float = 1e-12) -> np.ndarray:
    """c[i, j] = cos(g_ii, g_ij) from ``grads`` (n, n, P): learner i's gradient on source j's samples.

    A zero vector agrees with nothing (c = 0): a learner with no signal of its own, or a source
    that gives none, is not reused. The diagonal is 1 where g_ii != 0.
    """
    g = np.asarray(grads, dtype=float)
    if g.ndim != 3 or g.shape[0] != g.shape[1]:
        raise ValueError(f"grads must have shape (n, n, parameters), got {g.shape}")
    if not np.isfinite(g).all():
        raise ValueError("grads must be finite")
    own = g[np.arange(len(g)), np.arange(len(g))]  # (n, P)
    dot = np.einsum("ip,ijp->ij", own, g)
    norm = np.linalg.norm(own, axis=1)[:, None] * np.linalg.norm(g, axis=2)
    return np.where(norm > eps, dot / np.maximum(norm, eps), 0.0)


def agreement_matrix(m: np.ndarray, agreement: np.ndarray, rule: str = "gradient") -> np.ndarray:
    """M'[i, j] = M[i, j] * a(c[i, j]) off the diagonal; the rest stays with the learner.

    ``m`` is a reuse matrix (rows are distributions, e.g. Eq. 9's), ``agreement`` c in [-1, 1],
    ``rule`` one of ``ADAPT_RULES``: a(c) = max(0, c) ("gradient") or 1{c > 0} ("gradient_sign").
    """
    if rule not in ADAPT_RULES:
        raise ValueError(f"unknown adaptive reuse rule {rule!r}; choose from {list(ADAPT_RULES)}")
    m, c = np.asarray(m, dtype=float), np.asarray(agreement, dtype=float)
    if m.ndim != 2 or m.shape[0] != m.shape[1]:
        raise ValueError(f"M must be a square (n, n) matrix, got shape {m.shape}")
    if (m < 0).any() or not np.allclose(m.sum(1), 1.0):
        raise ValueError("M must hold non-negative rows that sum to 1")
    if c.shape != m.shape:
        raise ValueError(f"agreement has shape {c.shape}, expected {m.shape}")
    if np.isnan(c).any() or (np.abs(c) > 1 + 1e-9).any():
        raise ValueError("agreement must hold cosines in [-1, 1]")
    n = len(m)
    out = m * (np.clip(c, 0.0, 1.0) if rule == "gradient" else (c > 0).astype(float))
    out[np.arange(n), np.arange(n)] = 0.0
    out[np.arange(n), np.arange(n)] = 1.0 - out.sum(1)
    return out
