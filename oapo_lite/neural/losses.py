"""Objectives of the neural track: GAE, the off-agent surrogates (Eq. 7, Eq. 8), the
sequential factor (rho in Eq. 6-8), the trust-region KL, the critic's loss, and the check
that stops a run whose numbers stop being finite (``Diverged``).

Shapes: a learner sees S sources (agents), each with the same B joint samples (time x env),
so per-source tensors are (S, B) and joint tensors (advantage, factor) are (B,). ``active``
(S, B) bool, or None for all, marks the samples on which the agent acted; the others (an
agent that left a PettingZoo episode early) contribute nothing.
"""
from __future__ import annotations

import numpy as np
import torch


def gae(reward: torch.Tensor, value: torch.Tensor, next_value: torch.Tensor, done: torch.Tensor,
        gamma: float, gae_lambda: float) -> torch.Tensor:
    """Generalised advantage estimation of the joint advantage A(s, a) (Algorithm 1 line 4).

    All (T, N). ``next_value`` is the value of the step's successor: V(s_{t+1}) if the episode
    goes on, V(final state) on truncation, 0 on termination; ``done`` cuts the recursion.
    """
    delta = reward + gamma * next_value - value
    adv = torch.zeros_like(reward)
    running = torch.zeros_like(reward[0])
    for t in reversed(range(reward.shape[0])):
        running = delta[t] + gamma * gae_lambda * torch.where(done[t], 0.0, running)
        adv[t] = running
    return adv


def normalise(x: torch.Tensor) -> torch.Tensor:
    """Batch-normalised advantage (as HARL/MAPPO): zero mean, unit standard deviation."""
    return (x - x.mean()) / (x.std() + 1e-8)


def source_mean(x: torch.Tensor, active: torch.Tensor | None) -> torch.Tensor:
    """Mean over the last axis (a source's samples) of the samples where the agent acted;
    ``active=None`` is the plain mean, bit for bit."""
    if active is None:
        return x.mean(-1)
    return torch.where(active, x, 0.0).sum(-1) / active.sum(-1).clamp_min(1)


def off_agent_objective(logp_new: torch.Tensor, logp_old: torch.Tensor, weights: torch.Tensor,
                        factor: torch.Tensor, adv: torch.Tensor, clip: float | None,
                        active: torch.Tensor | None = None) -> torch.Tensor:
    """Eq. 8 (``clip`` given) or Eq. 7's surrogate (``clip=None``) of one learner i.

    ``logp_new[j]`` = log pi_i_new(a_j | o_j) on source j's samples, ``logp_old[j]`` = log
    pi_j_old(a_j | o_j), the behaviour probability stored at rollout, so the off-agent ratio
    is r_ij = pi_i_new(a_j|o_j) / pi_j_old(a_j|o_j). Returns
    sum_j weights[j] * mean_b min(r_ij rho A, clip(r_ij, 1 +- eps) rho A), to be maximised.
    """
    ratio = torch.exp(logp_new - logp_old)
    scaled = factor * adv
    surrogate = ratio * scaled
    if clip is not None:
        surrogate = torch.min(surrogate, ratio.clamp(1 - clip, 1 + clip) * scaled)
    return (weights * source_mean(surrogate, active)).sum()


def weighted_kl(kl_per_obs: torch.Tensor, weights: torch.Tensor, active: torch.Tensor | None = None) -> torch.Tensor:
    """Eq. 7's constraint: sum_j weights[j] * mean over source j's observations of
    KL(pi_i_old(.|o_j) || pi_i(.|o_j)). ``kl_per_obs`` is (S, B)."""
    return (weights * source_mean(kl_per_obs, active)).sum()


def update_factor(factor: torch.Tensor, logp_new_own: torch.Tensor, logp_old_own: torch.Tensor,
                  active_own: torch.Tensor | None = None) -> torch.Tensor:
    """rho of Eq. 6-8: after a learner is updated, multiply by its own-seat ratio
    pi_new(a|o) / pi_old(a|o) on its own samples (the product over the seats it controls).
    A seat that did not act on a sample sent no action, so its ratio there is 1."""
    log_ratio = logp_new_own - logp_old_own
    if active_own is not None:
        log_ratio = torch.where(active_own, log_ratio, 0.0)
    return factor * torch.exp(log_ratio.sum(0))


def value_loss(value: torch.Tensor, value_old: torch.Tensor, target: torch.Tensor, clip: float,
               delta: float = 10.0) -> torch.Tensor:
    """Clipped Huber value loss (HARL): the worse of the raw and the clipped prediction."""
    clipped = value_old + (value - value_old).clamp(-clip, clip)
    raw_loss = torch.nn.functional.huber_loss(value, target, reduction="none", delta=delta)
    clip_loss = torch.nn.functional.huber_loss(clipped, target, reduction="none", delta=delta)
    return torch.max(raw_loss, clip_loss).mean()


class Diverged(FloatingPointError):
    """A loss, advantage, factor or KL that is NaN or infinite: the run stops (the last
    checkpoint is written only after a whole finite iteration, so it stays the last good one)."""

    def __init__(self, quantity: str, net: int | str, where: str = "", then: str = ""):
        super().__init__(f"{where}{quantity} is not finite (learner {net}){then}")
        self.quantity, self.net = quantity, net  # the net being updated (or who, when none is)


def check_finite(x: torch.Tensor | np.ndarray | float, quantity: str, net: int | str) -> None:
    """Raise ``Diverged`` naming the quantity and the net being updated if ``x`` holds a NaN or an inf."""
    if not torch.isfinite(torch.as_tensor(x)).all():
        raise Diverged(quantity, net)


def update_diagnostics(logp_new: torch.Tensor, logp_old: torch.Tensor, entropy: torch.Tensor,
                       active: torch.Tensor | None, clip: float | None) -> dict:
    """What users of PPO code watch after a learner's update, on its own seats' samples (as
    CleanRL's ppo.py): the approximate KL of the update E[(r - 1) - log r] with r = pi_new /
    pi_old (never negative), the share of samples whose ratio left [1 - clip, 1 + clip] (NaN
    for a trust-region step, which has no clip), and the entropy of the updated policy."""
    log_ratio = (logp_new - logp_old).reshape(-1)
    ratio, active = log_ratio.exp(), None if active is None else active.reshape(-1)
    clip_frac = np.nan if clip is None else source_mean(((ratio - 1).abs() > clip).float(), active).item()
    return {"approx_kl": source_mean((ratio - 1) - log_ratio, active).item(), "clip_frac": clip_frac,
            "entropy": source_mean(entropy.reshape(-1), active).item()}


def explained_variance(predicted: torch.Tensor, target: torch.Tensor) -> float:
    """1 - Var(target - predicted) / Var(target): 1 for a critic that predicts every return, 0
    for one that predicts their mean, below 0 for worse (NaN for constant targets)."""
    var = target.var()
    return float("nan") if var == 0 else (1 - (target - predicted).var() / var).item()
