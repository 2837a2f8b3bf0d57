"""The A2C family: SEAC (Christianos et al., NeurIPS 2020) and the A2C that SePS trains with
(``A2CFamilyLearner``, the family's side of ``learner.Learner``), and the shape of its runs
beside a PPO-family run (``beside_ppo``).

Both are advantage actor-critic with n-step returns and a critic V(o) per network (not the
centralised V(s) of the PPO family); each network has one Adam over its actor and its critic,
and its gradient norm is clipped, as in the SEAC reference code.

SEAC's loss for learner i (the paper's Eq. 4 for the policy, Eq. 5 for the value), on its own
samples and on every other agent k's samples with the importance weight
w_ik = pi_i(a_k | o_k) / pi_k(a_k | o_k) (detached, not clipped)::

    policy = -mean[log pi_i(a_i|o_i) (R_i - V_i(o_i))] + lambda sum_k -mean[w_ik log pi_i(a_k|o_k) (R_k - V_i(o_k))]
    value  =  mean[(R_i - V_i(o_i))^2]               + lambda sum_k  mean[w_ik (R_k - V_i(o_k))^2]
    loss   = policy + 0.5 value - 0.01 entropy(own samples)

R_k is agent k's n-step return, bootstrapped by its own network's critic (the reference code
reads it from agent k's storage). lambda = 0 is independent A2C. A network that several seats
share (SePS) pools its seats' samples in the own-data means: parameter-sharing A2C.
"""
from __future__ import annotations

import logging

import numpy as np
import torch
from torch import nn

from oapo_lite import reuse
from oapo_lite.envs.vec import seat_spaces
from oapo_lite.neural import seps
from oapo_lite.neural.adam import Adam
from oapo_lite.neural.config import TrainConfig, derive_seed
from oapo_lite.neural.learner import Update
from oapo_lite.neural.losses import check_finite, explained_variance, source_mean, update_diagnostics
from oapo_lite.neural.nets import Actors, Critic
from oapo_lite.neural.rollout import Rollout

log = logging.getLogger(__name__)

VALUE_COEF = 0.5
# SEAC / SePS (5-step rollouts) run 16 env copies beside a PPO-family run: 80 env steps an
# update, 20 updates per PPO iteration of 32 x 50 steps
A2C_ENVS = 16


def beside_ppo(kw: dict) -> dict:
    """The settings ``kw`` of a PPO-family run (``steps``, ``eval_every``, its batch shape)
    turned into a SEAC / SePS run's: ``A2C_ENVS`` copies, and evaluations and checkpoints spaced
    as many A2C updates apart as fit one PPO iteration, so every curve of a figure is evaluated
    at the same env steps; SePS pre-trains for the first tenth of the steps (at least one update)."""
    batch = kw.get("n_envs", TrainConfig.n_envs) * kw.get("rollout_len", TrainConfig.rollout_len)
    ratio = max(1, batch // (A2C_ENVS * TrainConfig.n_step))
    out = dict(kw, n_envs=A2C_ENVS, eval_every=kw.get("eval_every", TrainConfig.eval_every) * ratio,
               checkpoint_every=kw.get("checkpoint_every", TrainConfig.checkpoint_every) * ratio)
    if kw["algo"] == "seps":
        out["seps_pretrain_steps"] = max(kw["steps"] // 10, A2C_ENVS * TrainConfig.n_step)
    return out


def nstep_returns(reward: torch.Tensor, done: torch.Tensor, last_value: torch.Tensor, gamma: float) -> torch.Tensor:
    """n-step returns over a rollout of n steps: R_t = r_t + gamma (1 - done_t) R_{t+1}, with
    R_n = V(o_n) (the A2C target; ``use_gae=False`` in the reference code). ``reward``, ``done``
    (T, ...) broadcast against ``last_value`` (...): e.g. (T, N) and (N,). A truncated episode ends like a terminated one (the reference
    code's default: no ``use_proper_time_limits``)."""
    returns = torch.empty(reward.shape[0], *last_value.shape)
    running = last_value
    for t in reversed(range(reward.shape[0])):
        running = reward[t] + gamma * torch.where(done[t], 0.0, running)
        returns[t] = running
    return returns


def _pooled_mean(x: torch.Tensor, active: torch.Tensor | None) -> torch.Tensor:
    """Mean over every entry of (S, B) ``x`` where ``active`` (all if None)."""
    return source_mean(x.reshape(-1), None if active is None else active.reshape(-1))


def seac_loss(logp: torch.Tensor, logp_behaviour: torch.Tensor, value: torch.Tensor, returns: torch.Tensor,
              entropy: torch.Tensor, own: torch.Tensor, seac_lambda: float, entropy_coef: float,
              active: torch.Tensor | None = None) -> tuple[torch.Tensor, dict]:
    """One learner's SEAC loss (module docstring; Eq. 4 + 0.5 Eq. 5 - entropy).

    Row k of the (n, B) inputs is seat k's samples seen by the learner: ``logp`` = log
    pi_i(a_k | o_k), ``logp_behaviour`` = log pi_k(a_k | o_k) stored at rollout, ``value`` =
    V_i(o_k), ``returns`` = R_k, ``entropy`` of pi_i(. | o_k). ``own`` (n,) bool marks the
    learner's seats. Returns (loss, parts: policy, value, entropy and the weights (n, B))."""
    adv = returns - value
    w = torch.exp(logp - logp_behaviour).detach()
    w = torch.where(own[:, None], 1.0, w)
    policy_terms, value_terms = -w * logp * adv.detach(), w * adv.pow(2)
    act = (lambda rows: None if active is None else active[rows])
    others = ~own
    policy = _pooled_mean(policy_terms[own], act(own)) + seac_lambda * source_mean(policy_terms[others], act(others)).sum()
    value_l = _pooled_mean(value_terms[own], act(own)) + seac_lambda * source_mean(value_terms[others], act(others)).sum()
    ent = _pooled_mean(entropy[own], act(own))
    loss = policy + VALUE_COEF * value_l - entropy_coef * ent
    return loss, {"policy": policy, "value": value_l, "entropy": ent, "weights": w}


class A2C:
    """The A2C learner of SEAC and SePS: critics V(o) beside ``actors`` (one per network), one
    Adam per network over actor and critic, and ``step(batch, owner)``.

    ``seac_lambda`` is SEAC's lambda (0: each network learns from its own seats only)."""

    def __init__(self, actors: Actors, obs_dim: int, hidden: tuple[int, ...], seac_lambda: float, gamma: float,
                 lr: float, eps: float, max_grad_norm: float, entropy_coef: float, gen: torch.Generator):
        self.actors, self.seac_lambda, self.gamma = actors, seac_lambda, gamma
        self.max_grad_norm, self.entropy_coef = max_grad_norm, entropy_coef
        self.critics = nn.ModuleList(Critic(obs_dim, hidden, gen) for _ in range(actors.n_nets))
        self.opts = [Adam(self.params(k), lr=lr, eps=eps) for k in range(actors.n_nets)]

    def params(self, net: int) -> list[nn.Parameter]:
        return self.actors.net_params(net) + list(self.critics[net].parameters())

    def critic_values(self, obs: torch.Tensor, nets) -> torch.Tensor:
        """(len(nets), M): V_c(obs) for every net c in ``nets``; ``obs`` (M, obs_dim)."""
        return torch.stack([self.critics[c](obs) for c in nets])

    def returns(self, batch: Rollout, owner: list[int]) -> torch.Tensor:
        """(n, B): each seat's n-step returns bootstrapped by its own network's critic on the
        observations after the rollout (``batch.next_obs``)."""
        with torch.no_grad():
            last = torch.stack([self.critics[c](batch.next_obs[:, k]) for k, c in enumerate(owner)])
        done = (batch.terminated | batch.truncated)[:, None]  # (T, 1, N): every seat's episode ends together
        R = nstep_returns(batch.reward[:, None], done, last, self.gamma)  # (T, n, N)
        return R.transpose(0, 1).reshape(len(owner), -1)

    def step(self, batch: Rollout, owner: list[int]) -> tuple[dict, list]:
        """One A2C step of every network that controls a seat, on ``batch``: (metrics,
        ``diagnostics``)."""
        inputs, head = batch.inputs, self.actors.head
        returns = self.returns(batch, owner)
        check_finite(returns, "the n-step returns", "all: they share the team reward")
        nets = sorted(set(owner))
        # every used net on every distinct input in one batched forward, gathered per seat
        k, U = len(nets), inputs.obs.shape[0]
        d = self.actors(inputs.obs.expand(k, U, -1), nets, inputs.avail.expand(k, U, -1))[:, inputs.index]
        v = self.critic_values(inputs.obs, nets)[:, inputs.index]
        total, parts = 0.0, []
        for row, net in enumerate(nets):
            own = torch.tensor([c == net for c in owner])
            loss, p = seac_loss(head.log_prob(d[row], batch.act), batch.logp, v[row], returns,
                                head.entropy(d[row]), own, self.seac_lambda, self.entropy_coef, batch.active)
            check_finite(loss, "the SEAC / A2C loss", net)
            total, parts = total + loss, parts + [p]
        for opt in self.opts:
            opt.zero_grad()
        total.backward()  # the nets share no parameters: each gets the gradient of its own loss
        for net in nets:
            torch.nn.utils.clip_grad_norm_(self.params(net), self.max_grad_norm)
            self.opts[net].step()
        others = [p["weights"][[c != net for c in owner]] for p, net in zip(parts, nets)]
        others = torch.cat([w.reshape(-1) for w in others])
        mean = (lambda key: float(sum(p[key].detach() for p in parts) / k))
        metrics = {"policy_loss": mean("policy"), "value_loss": mean("value"), "entropy": mean("entropy"),
                   "seac_weight": float(others.mean()) if self.seac_lambda > 0 and others.numel() else float("nan")}
        return metrics, self.diagnostics(batch, returns, v.detach(), nets, owner)

    def diagnostics(self, batch, returns: torch.Tensor, v: torch.Tensor, nets: list[int], owner: list[int]) -> list:
        """Per network, on its own seats' samples: the update's approximate KL and the updated
        policy's entropy (``losses.update_diagnostics``; A2C has no clip), and the explained
        variance of its critic before the step."""
        inputs, head, k, U = batch.inputs, self.actors.head, len(nets), batch.inputs.obs.shape[0]
        with torch.no_grad():
            d = self.actors(inputs.obs.expand(k, U, -1), nets, inputs.avail.expand(k, U, -1))[:, inputs.index]
        learners = []
        for row, net in enumerate(nets):
            own = [s for s, c in enumerate(owner) if c == net]
            active = None if batch.active is None else batch.active[own]
            learners.append({"net": net, "seats": own, **update_diagnostics(
                head.log_prob(d[row][own], batch.act[own]), batch.logp[own], head.entropy(d[row][own]), active, None),
                "explained_variance": explained_variance(v[row][own].reshape(-1), returns[own].reshape(-1))})
        return learners

    def copy_net(self, src: int, dst: int) -> None:
        """Network ``dst`` becomes a copy of ``src``: actor, critic and Adam state."""
        with torch.no_grad():
            for a, b in zip(self.params(dst), self.params(src)):
                a.copy_(b)
        self.opts[dst].load_state_dict(self.opts[src].state_dict())

    def state_dict(self) -> dict:
        return {"critics": self.critics.state_dict(), "opts": [o.state_dict() for o in self.opts]}

    def load_state_dict(self, state: dict) -> None:
        self.critics.load_state_dict(state["critics"])
        for opt, s in zip(self.opts, state["opts"]):
            opt.load_state_dict(s)


class A2CFamilyLearner:
    """``learner.Learner`` for ``seac`` and ``seps``: the A2C step of every iteration and, for
    SePS, the pre-training phase on one shared network followed by the switch to one network per
    cluster. ``owner`` (seat -> network) is what the rollouts and evaluations act with."""

    def __init__(self, cfg, env, actors: Actors, gen: torch.Generator, owner: list[int]):
        n, self.seps, self.agents = env.n_agents, cfg.algo == "seps", list(env.agents)
        if self.seps and cfg.seps_clusters is not None and not 1 <= cfg.seps_clusters <= n:
            raise ValueError(f"seps_clusters = {cfg.seps_clusters} is invalid for {n} agents; allowed: None or 1..{n}")
        # SEAC learns from every seat, SePS may group any
        reuse.check_spaces(env.agents, seat_spaces(env), np.ones((n, n), bool))
        # the draws of the PPO family's critic, which SEAC / SePS do not have: their networks keep
        # the initialisation their committed runs were trained with
        Critic(env.state_dim, cfg.hidden, gen)
        self.cfg, self.n_actions = cfg, env.n_actions
        self.a2c = A2C(actors, env.obs_dim, cfg.hidden, cfg.seac_lambda if cfg.algo == "seac" else 0.0, cfg.gamma,
                       cfg.a2c_lr, cfg.a2c_adam_eps, cfg.a2c_max_grad_norm, cfg.entropy_coef, gen)
        self.owner = [0] * n if self.seps else owner  # SePS pre-trains every seat on network 0
        self.pretrain_iters = cfg.seps_pretrain_steps // (cfg.n_envs * cfg.n_step) if self.seps else 0
        self.buffer = seps.Buffer() if self.seps else None
        self.embeddings, self.db_scores = None, {}

    @property
    def groups(self) -> str:
        return seps.group_names(self.owner, self.agents)

    def learn(self, batch: Rollout, it: int, wanted: frozenset[str] = frozenset()) -> Update:
        """Iteration ``it``'s update on ``batch`` (``learner.Learner``; this family has nothing
        ``wanted`` may ask for): the results rows' metrics, each network's live diagnostics."""
        if self.buffer is not None:
            self._record(batch)
        metrics, learners = self.a2c.step(batch, self.owner)
        if self.buffer is not None and it + 1 == self.pretrain_iters:
            self._regroup()
        returns = batch.episode_returns
        metrics = {"train_return": sum(returns) / len(returns) if returns else float("nan"), **metrics}
        return Update({**metrics, "seps_groups": self.groups} if self.seps else metrics, {"learners": learners})

    def optimisers(self) -> list[tuple[torch.optim.Optimizer, float]]:
        """Every optimiser with its learning rate before annealing."""
        return [(opt, self.cfg.a2c_lr) for opt in self.a2c.opts]

    def _record(self, batch: Rollout) -> None:
        """Store (o, a, o', r, id); o' of the last step is the observation after the rollout
        (after an auto-reset where the episode ended, as in the reference code)."""
        obs = batch.inputs.obs[batch.inputs.index]  # (n, B, d)
        nxt = torch.cat([obs[:, batch.next_obs.shape[0]:], batch.next_obs.transpose(0, 1)], 1)
        act = batch.act.float() if self.a2c.actors.head.continuous \
            else torch.nn.functional.one_hot(batch.act, self.n_actions).float()
        self.buffer.record(obs, act, nxt, batch.reward.reshape(-1), batch.active)

    def _regroup(self) -> None:
        """End of pre-training: embed the agents, cluster them, and give every cluster a copy of
        the pre-trained network (actor, critic, Adam state)."""
        agent, obs, act, nxt, reward = self.buffer.arrays()
        key = derive_seed(self.cfg.seed, 4)
        self.embeddings = seps.agent_embeddings(agent, obs, act, nxt, reward, len(self.owner), int(key))
        labels, self.db_scores = seps.choose_groups(self.embeddings, self.cfg.seps_clusters,
                                                    np.random.default_rng(key))
        for net in range(1, labels.max() + 1):
            self.a2c.copy_net(0, net)
        self.owner, self.buffer = labels.tolist(), None
        log.info("SePS groups after pre-training: %s (Davies-Bouldin by k: %s)", self.groups,
                 {k: round(v, 4) for k, v in self.db_scores.items()})

    def state_dict(self) -> dict:
        return {"a2c": self.a2c.state_dict(), "owner": self.owner,
                "buffer": None if self.buffer is None else self.buffer.parts, "embeddings": self.embeddings,
                "db_scores": self.db_scores}

    def load_state_dict(self, state: dict) -> None:
        self.a2c.load_state_dict(state["a2c"])
        self.owner = state["owner"]
        self.buffer = None if state["buffer"] is None else seps.Buffer(state["buffer"])
        self.embeddings, self.db_scores = state["embeddings"], state["db_scores"]
