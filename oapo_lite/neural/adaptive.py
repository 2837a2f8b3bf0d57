"""Adaptive reuse (the paper's Section 7 future work): Eq. 9's weights scaled online by
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

``"gradient_test"`` strikes a source only on *evidence* of disagreement. One batch's cosine is
noise while the KL gate is open (centred at 0: ASSUMPTIONS.md), so the two rules above strike
about half of the early reuse that makes Eq. 9 faster than HAPPO. Instead,
the batch's env copies are split into ``TEST_FOLDS`` folds; D_f = g_ii^(f) . mean_{h != f}
g_ij^(h) estimates g_ii . g_ij without the noise the two share, and the source is struck when
mean_f D_f < -TEST_Z * sd_f(D_f) / sqrt(TEST_FOLDS) (a one-sided t-test at z = 1); a(t) = 1
otherwise. No evidence either way keeps Eq. 9.
Why it cannot trap where HAPPO does not: with exact gradients, learner i's objective moves
along G_i = sum_j M'[i, j] g_ij. If G_i = 0 then M'[i, i] |g_ii|^2 = -sum_{j != i} M'[i, j]
g_ii . g_ij <= 0, since every kept source has g_ii . g_ij > 0; M'[i, i] >= M[i, i] > 0 whenever
Eq. 9 keeps anything for the learner (lambda > 0), so g_ii = 0. A stationary point of the mixed
objective is then one of the learner's own (HAPPO's): reuse adds no fixed point of its own.
(The test rule keeps a source whose disagreement is not yet significant, so it has this
property only in the limit of large batches, where every true disagreement is significant.)
The argument holds for exact gradients at the start of an iteration. One batch's cosines are
noisy, and after convergence (own gradient near 0, off-agent ratios far from 1) noise alone can
let a source in, so sigma stays on as the variance guard (ASSUMPTIONS.md, measured there).
"""
from __future__ import annotations

import numpy as np

ADAPT_RULES = ("gradient", "gradient_sign", "gradient_test")
COSINE_RULES = ("gradient", "gradient_sign")  # read c = cos(g_ii, g_ij) of the whole batch
TEST_FOLDS = 4  # env-copy folds of the test rule (needs n_envs >= 4)
TEST_Z = 1.0  # strike when the mean cross-fold product is more than z standard errors below 0


def folds(rule: str) -> int:
    """How many env-copy folds ``rule`` needs the source gradients split into."""
    if rule not in ADAPT_RULES:
        raise ValueError(f"unknown adaptive reuse rule {rule!r}; choose from {list(ADAPT_RULES)}")
    return TEST_FOLDS if rule == "gradient_test" else 1


def agreement(grads: np.ndarray, rule: str) -> np.ndarray:
    """The statistic ``rule`` reads from ``grads`` (n, n, folds, P): cosines of the whole-batch
    gradients for the cosine rules, t-statistics across folds for the test rule."""
    g = np.asarray(grads, dtype=float)
    if g.ndim != 4 or g.shape[2] != folds(rule):
        raise ValueError(f"grads must have shape (n, n, {folds(rule)}, parameters) for rule {rule!r}, got {g.shape}")
    return cosine_agreement(g[:, :, 0]) if rule in COSINE_RULES else disagreement_t(g)


def disagreement_t(grads: np.ndarray) -> np.ndarray:
    """t[i, j] = mean_f D_f / (sd_f D_f / sqrt(k)) with D_f = g_ii^(f) . mean_{h != f} g_ij^(h),
    from per-fold gradients ``grads`` (n, n, k, P), k >= 2. Each D_f pairs independent folds, so
    its mean estimates g_ii . g_ij free of the batch noise the two gradients share. No spread:
    t = 0 at a zero mean (no evidence), +-inf otherwise. The diagonal is +inf (always kept)."""
    g = np.asarray(grads, dtype=float)
    if g.ndim != 4 or g.shape[0] != g.shape[1] or g.shape[2] < 2:
        raise ValueError(f"grads must have shape (n, n, folds >= 2, parameters), got {g.shape}")
    if not np.isfinite(g).all():
        raise ValueError("grads must be finite")
    n, k = g.shape[0], g.shape[2]
    own = g[np.arange(n), np.arange(n)]  # (n, k, P)
    others = (g.sum(2, keepdims=True) - g) / (k - 1)  # (n, n, k, P): mean over the other folds
    d = np.einsum("ifp,ijfp->ijf", own, others)
    mean, se = d.mean(2), d.std(2, ddof=1) / np.sqrt(k)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(se > 0, mean / np.where(se > 0, se, 1.0), np.sign(mean) * np.inf)
    t = np.where((se == 0) & (mean == 0), 0.0, t)
    t[np.arange(n), np.arange(n)] = np.inf
    return t


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

    ``m`` is a reuse matrix (rows are distributions, e.g. Eq. 9's); ``rule`` one of
    ``ADAPT_RULES``: a(c) = max(0, c) ("gradient") or 1{c > 0} ("gradient_sign") of cosines c in
    [-1, 1], or 1{t >= -TEST_Z} ("gradient_test") of the t-statistics of ``disagreement_t``.
    """
    folds(rule)  # names the rules if ``rule`` is not one
    m, c = np.asarray(m, dtype=float), np.asarray(agreement, dtype=float)
    if m.ndim != 2 or m.shape[0] != m.shape[1]:
        raise ValueError(f"M must be a square (n, n) matrix, got shape {m.shape}")
    if (m < 0).any() or not np.allclose(m.sum(1), 1.0):
        raise ValueError("M must hold non-negative rows that sum to 1")
    if c.shape != m.shape:
        raise ValueError(f"agreement has shape {c.shape}, expected {m.shape}")
    if np.isnan(c).any():
        raise ValueError("agreement must not hold NaN")
    if rule in COSINE_RULES and (np.abs(c) > 1 + 1e-9).any():
        raise ValueError(f"agreement must hold cosines in [-1, 1] for rule {rule!r}")
    n = len(m)
    a = {"gradient": np.clip(c, 0.0, 1.0), "gradient_sign": c > 0, "gradient_test": c >= -TEST_Z}[rule]
    out = m * a.astype(float)
    out[np.arange(n), np.arange(n)] = 0.0
    out[np.arange(n), np.arange(n)] = 1.0 - out.sum(1)
    return out
