"""Networks of the neural track: per-agent actors evaluated in one batched forward, the
centralised critic V(s), and the running value normaliser.

Every actor owns its parameter tensors (so each has its own Adam state and an agent
without gradients never moves); a forward stacks the requested actors' weights and runs
them side by side with ``torch.baddbmm``. MAPPO is the case of one actor used by every seat.
"""
from __future__ import annotations

import math

import numpy as np
import torch
from torch import nn

from oapo_lite import reuse
from oapo_lite.neural.config import NETWORKS

UNAVAILABLE_LOGIT = -1e10  # as in HARL: masked actions keep a finite logit, so 0 * logit stays 0


def owners(networks: str, agent_types) -> list[int]:
    """The owner map, the network of every seat, under a networks reading
    (``TrainConfig.networks``): "agent" one each, "one" the same for all, "type" one per agent
    type in ``agent_types``, numbered as the types first appear."""
    if networks == "agent":
        return list(range(len(agent_types)))
    if networks == "one":
        return [0] * len(agent_types)
    if networks == "type":
        types = list(dict.fromkeys(agent_types))
        return [types.index(t) for t in agent_types]
    raise ValueError(f"unknown networks reading {networks!r}; choose from {list(NETWORKS)}")


def _orthogonal(shape: tuple[int, int], gain: float, gen: torch.Generator) -> torch.Tensor:
    return nn.init.orthogonal_(torch.empty(shape), gain=gain, generator=gen)


class Categorical:
    """Discrete actions. Distribution parameters: masked log-probabilities (..., A)."""

    continuous = False

    @staticmethod
    def params(out: torch.Tensor, avail: torch.Tensor, log_std: torch.Tensor) -> torch.Tensor:
        return torch.log_softmax(out.masked_fill(~avail, UNAVAILABLE_LOGIT), -1)

    @staticmethod
    def sample(d: torch.Tensor, gen: torch.Generator) -> torch.Tensor:
        # Gumbel-max: one uniform draw per action, and masked actions can never win
        u = torch.rand(d.shape, generator=gen)
        return (d - torch.log(-torch.log(u))).argmax(-1)

    @staticmethod
    def log_prob(d: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        return d.gather(-1, a.unsqueeze(-1)).squeeze(-1)

    @staticmethod
    def entropy(d: torch.Tensor) -> torch.Tensor:
        return -(d.exp() * d).sum(-1)

    @staticmethod
    def kl(d_old: torch.Tensor, d_new: torch.Tensor) -> torch.Tensor:
        """Closed-form KL(old || new) per observation."""
        return (d_old.exp() * (d_old - d_new)).sum(-1)

    @staticmethod
    def pairwise_kl(d: torch.Tensor) -> np.ndarray:
        """Per observation, KL(pi_j || pi_i) (i, j, batch) from ``d[i, j]`` = learner i's
        log-probs on agent j's observations: what Eq. 9's K reduces (``reuse.reduce_kl``)."""
        return reuse.pairwise_kl(d.detach().exp().double().numpy())


class Gaussian:
    """Continuous actions, diagonal Gaussian. Distribution parameters: mean ‖ log_std (..., 2D)."""

    continuous = True

    @staticmethod
    def params(out: torch.Tensor, avail: torch.Tensor, log_std: torch.Tensor) -> torch.Tensor:
        return torch.cat([out, log_std.unsqueeze(1).expand_as(out)], -1)

    @staticmethod
    def sample(d: torch.Tensor, gen: torch.Generator) -> torch.Tensor:
        mean, log_std = d.chunk(2, -1)
        return mean + log_std.exp() * torch.randn(mean.shape, generator=gen)

    @staticmethod
    def log_prob(d: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        """Summed over action dimensions: the policy ratio is the product over dimensions."""
        mean, log_std = d.chunk(2, -1)
        z = (a - mean) * torch.exp(-log_std)
        return (-0.5 * z.pow(2) - log_std - 0.5 * math.log(2 * math.pi)).sum(-1)

    @staticmethod
    def entropy(d: torch.Tensor) -> torch.Tensor:
        return (d.chunk(2, -1)[1] + 0.5 * math.log(2 * math.pi * math.e)).sum(-1)

    @staticmethod
    def kl(d_old: torch.Tensor, d_new: torch.Tensor) -> torch.Tensor:
        """Closed-form KL(old || new) per observation, summed over dimensions."""
        m0, s0 = d_old.chunk(2, -1)
        m1, s1 = d_new.chunk(2, -1)
        return (s1 - s0 + (torch.exp(2 * s0) + (m0 - m1).pow(2)) / (2 * torch.exp(2 * s1)) - 0.5).sum(-1)

    @classmethod
    def pairwise_kl(cls, d: torch.Tensor) -> np.ndarray:
        """Per observation, KL(pi_j(.|o_j) || pi_i(.|o_j)) (i, j, batch), for Gaussians."""
        n, d = d.shape[0], d.detach()
        own = d[torch.arange(n), torch.arange(n)]  # (sources, batch, 2D)
        return cls.kl(own.unsqueeze(0), d).clamp_min(0.0).double().numpy()


class Actors(nn.Module):
    """``n_nets`` MLP policies with separate parameters, run together in one batched forward.

    ``forward(obs, nets, avail)``: obs (k, M, obs_dim) and ``nets`` (k,) net indices; row r
    of the batch goes through net ``nets[r]``. Returns distribution parameters (k, M, P).
    With ``feature_norm`` every net first normalises its input with its own LayerNorm (HARL's
    ``use_feature_normalization``).
    """

    def __init__(self, n_nets: int, obs_dim: int, n_actions: int, hidden: tuple[int, ...],
                 continuous: bool, gen: torch.Generator, feature_norm: bool = False):
        super().__init__()
        # LayerNorm's scale and shift per net (no random draws: a run without it is unchanged)
        self.norms = nn.ModuleList(nn.ParameterList([nn.Parameter(torch.ones(obs_dim)), nn.Parameter(torch.zeros(obs_dim))])
                                   for _ in range(n_nets if feature_norm else 0))
        self.head = Gaussian if continuous else Categorical
        sizes = (obs_dim, *hidden, n_actions)
        gains = [math.sqrt(2)] * len(hidden) + [0.01]  # HARL: ReLU gain, small output gain
        self.weights = nn.ModuleList()
        for _ in range(n_nets):
            layers = nn.ParameterList()
            for (fan_in, fan_out), gain in zip(zip(sizes[:-1], sizes[1:]), gains):
                layers.append(nn.Parameter(_orthogonal((fan_in, fan_out), gain, gen)))
                layers.append(nn.Parameter(torch.zeros(fan_out)))
            layers.append(nn.Parameter(torch.zeros(n_actions)))  # log_std, used by Gaussian only
            self.weights.append(layers)

    @property
    def n_nets(self) -> int:
        return len(self.weights)

    def net_params(self, k: int) -> list[nn.Parameter]:
        """The trainable tensors of net k (the log_std only for continuous actions)."""
        params = list(self.weights[k])
        norm = list(self.norms[k]) if len(self.norms) else []
        return norm + (params if self.head.continuous else params[:-1])

    def stack(self, nets) -> tuple:
        """The weights of ``nets``, stacked for a batched forward: ([w0, b0, w1, b1, ...], log_std,
        the LayerNorms' (scale, shift) or None), every bias, scale and shift (k, 1, size), as
        ``baddbmm`` adds it (shaped once: a rollout applies one stack at every step)."""
        per_net = [list(self.weights[int(k)]) for k in nets]  # indexing a ParameterList is slow
        layers = [_stack(layer) for layer in zip(*(w[:-1] for w in per_net))]
        norm = None
        if len(self.norms):
            norm = tuple(_stack(part).unsqueeze(1) for part in zip(*(list(self.norms[int(k)]) for k in nets)))
        return ([x if k % 2 == 0 else x.unsqueeze(1) for k, x in enumerate(layers)], _stack([w[-1] for w in per_net]),
                norm)

    def apply(self, stacked: tuple, obs: torch.Tensor, avail: torch.Tensor | None) -> torch.Tensor:
        """Forward with weights from ``stack`` (a rollout stacks once and applies every step)."""
        layers, log_std, norm = stacked
        x = obs
        if norm is not None:
            x = torch.nn.functional.layer_norm(x, x.shape[-1:]) * norm[0] + norm[1]
        for k in range(0, len(layers), 2):
            x = torch.baddbmm(layers[k + 1], x, layers[k])
            if k < len(layers) - 2:
                x = torch.relu(x)
        return self.head.params(x, avail, log_std)

    def forward(self, obs: torch.Tensor, nets, avail: torch.Tensor | None) -> torch.Tensor:
        return self.apply(self.stack(nets), obs, avail)


def _stack(tensors) -> torch.Tensor:
    """``torch.stack``, a view where there is one tensor: a learner's forward stacks its own net
    alone, and a stack would copy it (and split the gradient again in the backward pass)."""
    return tensors[0].unsqueeze(0) if len(tensors) == 1 else torch.stack(tensors)


class Critic(nn.Module):
    """The centralised critic V(s) (Algorithm 1 line 4), predicting normalised values."""

    def __init__(self, state_dim: int, hidden: tuple[int, ...], gen: torch.Generator, feature_norm: bool = False):
        super().__init__()
        sizes = (state_dim, *hidden, 1)
        layers: list[nn.Module] = [nn.LayerNorm(state_dim)] if feature_norm else []  # HARL's feature normalisation
        for k, (fan_in, fan_out) in enumerate(zip(sizes[:-1], sizes[1:])):
            last = k == len(sizes) - 2
            lin = nn.Linear(fan_in, fan_out)
            with torch.no_grad():
                lin.weight.copy_(_orthogonal((fan_out, fan_in), 1.0 if last else math.sqrt(2), gen))
                lin.bias.zero_()
            layers += [lin] if last else [lin, nn.ReLU()]
        self.net = nn.Sequential(*layers)

    def forward(self, state: torch.Tensor) -> torch.Tensor:
        return self.net(state).squeeze(-1)


class ValueNorm(nn.Module):
    """Running mean / variance of the value targets (HARL's ValueNorm: debiased EMA,
    beta 0.99999, variance floored at 1e-2), so the critic regresses on unit-scale targets."""

    def __init__(self, beta: float = 0.99999, var_floor: float = 1e-2, enabled: bool = True):
        super().__init__()
        self.beta, self.var_floor, self.enabled = beta, var_floor, enabled  # disabled: the identity
        self.register_buffer("mean", torch.zeros((), dtype=torch.float64))
        self.register_buffer("mean_sq", torch.zeros((), dtype=torch.float64))
        self.register_buffer("debias", torch.zeros((), dtype=torch.float64))

    def update(self, x: torch.Tensor) -> None:
        if not self.enabled:
            return
        x = x.double()
        self.mean.mul_(self.beta).add_((1 - self.beta) * x.mean())
        self.mean_sq.mul_(self.beta).add_((1 - self.beta) * x.pow(2).mean())
        self.debias.mul_(self.beta).add_(1 - self.beta)

    def _stats(self) -> tuple[torch.Tensor, torch.Tensor]:
        debias = self.debias.clamp_min(1e-5)
        mean = self.mean / debias
        var = (self.mean_sq / debias - mean.pow(2)).clamp_min(self.var_floor)
        return mean, var.sqrt()

    def normalize(self, x: torch.Tensor) -> torch.Tensor:
        if not self.enabled:
            return x
        mean, std = self._stats()
        return ((x - mean) / std).to(x.dtype)

    def denormalize(self, x: torch.Tensor) -> torch.Tensor:
        if not self.enabled:
            return x
        mean, std = self._stats()
        return (x * std + mean).to(x.dtype)
