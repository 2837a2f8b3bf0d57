"""The PPO / TRPO family's update of one iteration (Algorithm 1 lines 4-9, then the critic):
the joint advantage, the policy distances K and Eq. 9's reuse weights, the learners updated one
after another on their sources' samples (Eq. 8, or Eq. 7's trust-region step) with the
sequential factor, and the centralised critic. ``PPOFamilyLearner`` holds what only this family
needs (critic, value normaliser, optimisers, the update-order generator): the family's side of
``learner.Learner``."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from oapo_lite import reuse
from oapo_lite.algorithms import ALGOS, AlgoSpec
from oapo_lite.envs.vec import seat_spaces
from oapo_lite.neural import adaptive
from oapo_lite.neural.adam import Adam
from oapo_lite.neural.config import TrainConfig
from oapo_lite.neural.learner import Update
from oapo_lite.neural.losses import (Diverged, check_finite, explained_variance, gae, normalise, off_agent_objective,
                                     source_mean, update_diagnostics, update_factor, value_loss, weighted_kl)
from oapo_lite.neural.nets import Actors, Critic, ValueNorm
from oapo_lite.neural.rollout import Inputs, Rollout, States, mean_or_nan
from oapo_lite.neural.trpo import trpo_step
from oapo_lite.renamed import refuse


@dataclass
class LearnerBatch:
    """What one update of a net trains on: the seats ``rows`` — its sources with W > 0 and the
    seats it learns for (``own``, positions in ``rows``, for the entropy and the factor)."""

    net: int
    rows: list[int]
    own: list[int]
    w: torch.Tensor  # (R,) reuse weights W[net, rows]
    act: torch.Tensor  # (R, B)
    logp_old: torch.Tensor  # (R, B) behaviour log-probs pi_j_old(a_j | o_j)
    kl_w: torch.Tensor  # (R,) trust-region weights (Eq. 7's W[net, rows], own seats never 0)
    active: torch.Tensor | None = None  # (R, B) the source acted on the sample; None: always
    # the distinct input rows of all the sources' samples, and each sample's position among
    # them (R, B): every full-batch forward of the learner needs them, so they are found once
    distinct: tuple[torch.Tensor, torch.Tensor] | None = None

    @classmethod
    def of(cls, net: int, weights: np.ndarray, own: list[int], batch: Rollout) -> "LearnerBatch":
        """Net ``net`` learning for the seats ``own`` from every seat's samples, weighted by
        ``weights`` (n,)."""
        rows = sorted(set(np.flatnonzero(weights > 0).tolist()) | set(own))
        w = weights[rows]
        # Eq. 7 weights the KL by M, which bounds the acting policy's own-seat KL by
        # delta / W[i, i]: nothing when W[i, i] = 0 ("sample" mode drew another source, or
        # reuse_lambda = 0), and then the policy that acts could move without limit. An own seat with
        # weight 0 therefore enters the trust region with weight 1 (its KL <= delta); where the
        # paper's weight is positive it is kept, so the weights mode is Eq. 7 as written.
        kl_w = np.where(np.isin(rows, own) & (w == 0), 1.0, w)
        return cls(net, rows, [rows.index(int(k)) for k in own], torch.as_tensor(w, dtype=torch.float32),
                   batch.act[rows], batch.logp[rows], torch.as_tensor(kl_w, dtype=torch.float32),
                   None if batch.active is None else batch.active[rows],
                   torch.unique(batch.inputs.index[rows], return_inverse=True))


def learner_dists(actors: Actors, inputs: Inputs, src: LearnerBatch, idx=slice(None)) -> torch.Tensor:
    """(R, b, P): the learner's distribution on its sources' samples ``idx``, one forward
    over the distinct inputs they use."""
    if src.distinct is not None and idx == slice(None):
        used, inverse = src.distinct
    else:
        used, inverse = torch.unique(inputs.index[src.rows][:, idx], return_inverse=True)
    return actors(inputs.obs[used].unsqueeze(0), [src.net], inputs.avail[used].unsqueeze(0))[0][inverse]


def _minibatches(size: int, k: int, rng: np.random.Generator) -> list:
    return [slice(None)] if k == 1 else [torch.from_numpy(i) for i in np.array_split(rng.permutation(size), k)]


def descend(opt: torch.optim.Optimizer, params: list[torch.Tensor], loss: torch.Tensor, max_norm: float) -> None:
    """One step of ``opt`` down the gradient of ``loss``, its norm clipped to ``max_norm`` as
    torch.nn.utils.clip_grad_norm_ clips it, bit for bit, but without grouping the tensors by
    device and dtype at every call, which on these small nets costs as much as the clip."""
    for p in params:  # opt.zero_grad(), without its profiler hook
        p.grad = None
    loss.backward()
    grads = [p.grad for p in params]
    norm = torch.linalg.vector_norm(torch.stack(torch._foreach_norm(grads)))
    torch._foreach_mul_(grads, (max_norm / (norm + 1e-6)).clamp(max=1.0))
    opt.step()


def ppo_loss(actors: Actors, inputs: Inputs, src: LearnerBatch, factor: torch.Tensor, adv: torch.Tensor,
             cfg: TrainConfig, idx=slice(None)) -> tuple[torch.Tensor, torch.Tensor]:
    """Eq. 8's loss of one learner on its sources' samples ``idx``: minus the clipped off-agent
    surrogate and the entropy bonus of its own seats. Returns (loss, surrogate)."""
    d = learner_dists(actors, inputs, src, idx)
    active = None if src.active is None else src.active[:, idx]
    obj = off_agent_objective(actors.head.log_prob(d, src.act[:, idx]), src.logp_old[:, idx], src.w,
                              factor[idx], adv[idx], cfg.clip, active)
    own_active = None if active is None else active[src.own].reshape(-1)
    entropy = source_mean(actors.head.entropy(d[src.own]).reshape(-1), own_active)
    if cfg.entropy_by_weight:  # weighted as the own seats' surrogate terms are
        entropy = entropy * src.w[src.own].sum()
    return -(obj + cfg.entropy_coef * entropy), obj


def ppo_update(actors: Actors, opt: torch.optim.Optimizer, inputs: Inputs, src: LearnerBatch, factor: torch.Tensor,
               adv: torch.Tensor, cfg: TrainConfig, rng: np.random.Generator) -> float:
    """OAPPO (Eq. 8): epochs of Adam on ``ppo_loss``. Returns the last surrogate value."""
    params = actors.net_params(src.net)
    for _ in range(cfg.ppo_epochs):
        for idx in _minibatches(adv.shape[0], cfg.n_minibatch, rng):
            loss, obj = ppo_loss(actors, inputs, src, factor, adv, cfg, idx)
            check_finite(loss, "the PPO loss (Eq. 8)", src.net)
            descend(opt, params, loss, cfg.max_grad_norm)
    return obj.item()


def trpo_update(actors: Actors, inputs: Inputs, src: LearnerBatch, factor: torch.Tensor, adv: torch.Tensor,
                cfg: TrainConfig) -> tuple[float, float]:
    """OATRPO (Eq. 7): one trust-region step on the unclipped off-agent surrogate under the
    weighted KL(pi_old || pi) on the sources' observations (weights ``src.kl_w``).
    Returns (surrogate, KL or NaN)."""
    head = actors.head
    with torch.no_grad():
        d_old = learner_dists(actors, inputs, src)
        check_finite(off_agent_objective(head.log_prob(d_old, src.act), src.logp_old, src.w, factor, adv, None,
                                         src.active), "the TRPO surrogate (Eq. 7)", src.net)

    def objective() -> torch.Tensor:
        d = learner_dists(actors, inputs, src)
        return off_agent_objective(head.log_prob(d, src.act), src.logp_old, src.w, factor, adv, None, src.active)

    def kl() -> torch.Tensor:
        return weighted_kl(head.kl(d_old, learner_dists(actors, inputs, src)), src.kl_w, src.active)

    accepted = trpo_step(actors.net_params(src.net), objective, kl, cfg.kl_threshold, cfg.cg_iters, cfg.cg_damping,
                         cfg.line_search_steps, cfg.backtrack, cfg.accept_ratio)
    with torch.no_grad():
        return objective().item(), accepted


def critic_values(critic: Critic, rows: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """V(rows[index]). Where most samples repeat a state (the mazes: every copy starts alike, and
    a policy that has learned walks one path), from one forward of the distinct states, which
    V's gradient then costs too; else the samples' rows as they come (the engines' batches,
    where a state seldom repeats), so that the gradient sums them in their own order."""
    used, inverse = torch.unique(index, return_inverse=True)
    return critic(rows[used])[inverse] if 2 * len(used) <= len(index) else critic(rows[index])


def advantages(critic: Critic, value_norm: ValueNorm, batch: Rollout, cfg: TrainConfig, bootstrap: bool):
    """Algorithm 1 line 4: the joint advantage by GAE on de-normalised V(s); a truncated
    episode is continued by V(final state) if ``bootstrap``, else it ends like a terminated
    one. Returns (normalised advantage (B,), returns (B,), the critic's normalised
    predictions (B,) for the clipped value loss)."""
    cut = batch.terminated | batch.truncated
    with torch.no_grad():
        v_norm = critic_values(critic, batch.states.rows, batch.states.index.reshape(-1)).reshape(batch.states.index.shape)
        value = value_norm.denormalize(v_norm)
        next_value = torch.where(cut, 0.0, value[1:])
        if bootstrap:  # only then is V(final state) read: a critic forward the mazes do without
            final_value = value_norm.denormalize(critic(batch.final_state))
            next_value = torch.where(batch.truncated & ~batch.terminated, final_value, next_value)
    adv = gae(batch.reward, value[:-1], next_value, cut, cfg.gamma, cfg.gae_lambda)
    check_finite(adv, "the joint advantage (GAE)", "all: it is joint")
    return normalise(adv.reshape(-1)), (adv + value[:-1]).reshape(-1), v_norm[:-1].reshape(-1)


def pairwise_distances(actors: Actors, inputs: Inputs, owner: list[int]) -> np.ndarray:
    """(learner seat i, source seat j, sample): KL(pi_j || pi_i) on each of seat j's
    observations, what Eq. 9's K reduces; every net on every input in one batched forward."""
    k, (U, _) = actors.n_nets, inputs.obs.shape
    with torch.no_grad():
        d = actors(inputs.obs.expand(k, U, -1), range(k), inputs.avail.expand(k, U, -1))[owner][:, inputs.index]
    return actors.head.pairwise_kl(d)


@refuse({"reduce": "kl_reduce"})
def policy_distances(actors: Actors, inputs: Inputs, owner: list[int], kl_reduce: str,
                     active: torch.Tensor | None = None) -> np.ndarray:
    """Eq. 9's K[i, j] = KL(pi_j || pi_i) on seat j's observations (those where j acted, if
    ``active`` (n, B) is given), reduced by the statistic ``kl_reduce`` (``reuse.KL_REDUCES``)."""
    return reduced_distances(pairwise_distances(actors, inputs, owner), kl_reduce,
                             None if active is None else active.numpy())


@refuse({"reduce": "kl_reduce"})
def reduced_distances(kl: np.ndarray, kl_reduce: str, active: np.ndarray | None) -> np.ndarray:
    """Eq. 9's K from the per-observation KLs (``pairwise_distances``) by the statistic ``kl_reduce``;
    a K that is not finite raises, naming the pair."""
    K = reuse.reduce_kl(kl, kl_reduce, active)
    bad = np.argwhere(~np.isfinite(K))
    if len(bad):
        raise Diverged(f"the policy distance KL K[{bad[0][0]}, {bad[0][1]}] (Eq. 9)", bad[0][0])
    return K


def source_gradients(actors: Actors, inputs: Inputs, batch: Rollout, M: np.ndarray, adv: torch.Tensor,
                     clip: float | None, folds: int = 1) -> np.ndarray:
    """(n, n, folds, P): row i, column j is the gradient, in learner i's parameters as they are
    now, of its update objective (Eq. 8 with ``clip``, Eq. 7's surrogate with ``clip=None``) on
    source j's samples alone, with the factor rho = 1 (nobody has moved yet); with ``folds`` > 1,
    once per fold of env copies (copy e in fold e % folds), each the mean over its fold. Sources
    that M[i] gives no weight get zeros (the adaptive rule only rescales what Eq. 9 allows).
    Separate nets only."""
    n, n_envs = M.shape[0], batch.reward.shape[1]
    if not 1 <= folds <= n_envs:
        raise ValueError(f"folds = {folds!r} must lie in [1, n_envs = {n_envs}]")
    size = sum(p.numel() for p in actors.net_params(0))
    grads = np.zeros((n, n, folds, size))
    ones = torch.ones(1)
    # sample b is step b // n_envs of env copy b % n_envs (``Rollout``)
    fold_of = torch.arange(adv.shape[0]) % n_envs % folds
    for i in range(n):
        src = LearnerBatch.of(i, M[i], [i], batch)
        params = actors.net_params(i)
        logp = actors.head.log_prob(learner_dists(actors, inputs, src), src.act)
        for r, j in enumerate(src.rows):
            for f in range(folds):
                active = None if src.active is None else src.active[r:r + 1]
                if folds > 1:  # one fold alone; with one fold the plain mean, bit for bit
                    active = (fold_of == f)[None] if active is None else active & (fold_of == f)[None]
                obj = off_agent_objective(logp[r:r + 1], src.logp_old[r:r + 1], ones, torch.ones_like(adv), adv,
                                          clip, active)
                last = r + 1 == len(src.rows) and f + 1 == folds
                g = torch.autograd.grad(obj, params, retain_graph=not last)
                grads[i, j, f] = torch.cat([x.reshape(-1) for x in g]).double().numpy()
    check_finite(grads, "a source gradient of the adaptive reuse rule", "all")
    return grads


def update_units(W: np.ndarray, owner: list[int], by: str) -> list[tuple[int, np.ndarray, list[int]]]:
    """The updates of one iteration as (net, weights over the seats, the seats it learns for):
    by "net", each network once on the mean of its seats' rows of ``W`` (n, n); by "seat", each
    seat's network on that seat's row alone (a shared network then moves once per seat)."""
    if by == "seat":
        return [(net, W[k], [k]) for k, net in enumerate(owner)]
    owner = np.asarray(owner)
    return [(k, W[owner == k].mean(0), np.flatnonzero(owner == k).tolist()) for k in range(owner.max() + 1)]


def update_actors(actors: Actors, opts: list, batch: Rollout, units: list, order, adv: torch.Tensor,
                  spec: AlgoSpec, cfg: TrainConfig, rng: np.random.Generator):
    """Algorithm 1 lines 7-9: the updates ``units`` (``update_units``) one after another in
    ``order``, each on its sources with its weights (Eq. 8, or Eq. 7's step); for sequential
    algorithms the factor rho collects the own-seat ratio of every update already made.
    Returns (final factor, surrogates, accepted KLs)."""
    factor = torch.ones(adv.shape[0])
    objectives, trpo_kls, learners = [], [], []
    for u in order:
        src = LearnerBatch.of(*units[u], batch)
        if spec.trust_region:
            objective, accepted_kl = trpo_update(actors, batch.inputs, src, factor, adv, cfg)
            trpo_kls.append(accepted_kl)
        else:
            objective = ppo_update(actors, opts[src.net], batch.inputs, src, factor, adv, cfg, rng)
        objectives.append(objective)
        with torch.no_grad():
            d_new = learner_dists(actors, batch.inputs, src)[src.own]
            logp_new = actors.head.log_prob(d_new, src.act[src.own])
            active = None if src.active is None else src.active[src.own]
            learners.append({"net": src.net, "seats": [src.rows[k] for k in src.own],
                             **update_diagnostics(logp_new, src.logp_old[src.own], actors.head.entropy(d_new), active,
                                                  None if spec.trust_region else cfg.clip)})
            if spec.sequential:
                factor = update_factor(factor, logp_new, src.logp_old[src.own], active)
        if spec.sequential:
            check_finite(factor, "the sequential factor rho", src.net)
    return factor, objectives, trpo_kls, learners


def update_critic(critic: Critic, opt: torch.optim.Optimizer, value_norm: ValueNorm, states: States,
                  v_old: torch.Tensor, returns: torch.Tensor, cfg: TrainConfig, rng: np.random.Generator) -> float:
    """The critic, trained after the actors (HARL) on normalised targets, on the states of
    the batch's samples (``states`` less the last step's). Returns the last loss."""
    value_norm.update(returns)
    target, index = value_norm.normalize(returns), states.index[:-1].reshape(-1)
    for _ in range(cfg.ppo_epochs):
        for idx in _minibatches(returns.shape[0], cfg.n_minibatch, rng):
            loss = value_loss(critic_values(critic, states.rows, index[idx]), v_old[idx], target[idx], cfg.clip)
            check_finite(loss, "the value loss", "critic")
            descend(opt, list(critic.parameters()), loss, cfg.max_grad_norm)
    return loss.item()


class PPOFamilyLearner:
    """``learner.Learner`` for OAPPO, OATRPO, HAPPO, HATRPO, MAPPO and IPPO: ``learn`` is one
    iteration's update (Algorithm 1 lines 4-9, then the critic); ``owner[k]`` is the net of seat k.
    The critic's initialisation follows the actors' in the generator."""

    def __init__(self, cfg: TrainConfig, env, actors: Actors, gen: torch.Generator, owner: list[int]):
        self.cfg, self.spec, self.actors, self.owner = cfg, ALGOS[cfg.algo], actors, owner
        n = env.n_agents
        self.allowed = reuse.allowed_mask(cfg.allowed, env.agents)
        same_net = np.equal.outer(self.owner, self.owner)  # seats of one network need equal spaces too
        pairs = {"uniform": np.ones((n, n), bool),
                 "oapo": same_net | (np.ones((n, n), bool) if self.allowed is None else self.allowed)}
        reuse.check_spaces(env.agents, seat_spaces(env), pairs.get(self.spec.reuse_rule, same_net))
        # the mazes' state holds t / max_steps: their time limit is part of the game, its end terminal
        self.bootstrap = not env.time_in_state if cfg.bootstrap_truncation is None else cfg.bootstrap_truncation
        self.critic = Critic(env.state_dim, cfg.hidden, gen, cfg.feature_norm)
        self.value_norm = ValueNorm(enabled=cfg.value_norm)
        # one optimiser per net: Adam would move a net that got no gradient through its momentum;
        # trust-region algorithms step by hand
        self.actor_opts = [] if self.spec.trust_region else [
            Adam(actors.net_params(k), lr=cfg.lr, eps=1e-5) for k in range(actors.n_nets)]
        self.critic_opt = Adam(self.critic.parameters(), lr=cfg.critic_lr, eps=1e-5)
        self.rng = np.random.default_rng(cfg.seed)  # update order, reuse mapping, minibatches

    def learn(self, batch: Rollout, it: int, wanted: frozenset[str] = frozenset()) -> Update:
        """Iteration ``it``'s update on ``batch`` (``learner.Learner``); ``wanted``: "kl", "pairwise_kl"
        (``learner.WANTS``)."""
        cfg, spec, actors, n = self.cfg, self.spec, self.actors, len(self.owner)
        # Algorithm 1 line 4: the joint advantage (the loop's rollout was line 3)
        adv, returns, v_old = advantages(self.critic, self.value_norm, batch, cfg, self.bootstrap)
        # K feeds Eq. 9 only for OAPO; for the others it is computed when asked for
        active = None if batch.active is None else batch.active.numpy()
        kl = (pairwise_distances(actors, batch.inputs, self.owner)
              if spec.reuse_rule == "oapo" or wanted & {"kl", "pairwise_kl"} else None)
        K = (reduced_distances(kl, cfg.kl_reduce, active)
             if spec.reuse_rule == "oapo" or "kl" in wanted else np.full((n, n), np.nan))
        # line 5: omega, the distribution of reuse sequences, as the matrix M of Eq. 9
        M = (np.eye(n) if it < cfg.reuse_warmup  # the control: no reuse while untrained nets look alike
             else reuse.matrix_for(spec.reuse_rule, K, cfg.sigma, cfg.reuse_lambda, self.allowed))
        if cfg.reuse_adapt is not None:
            G = source_gradients(actors, batch.inputs, batch, M, adv, None if spec.trust_region else cfg.clip,
                                 adaptive.folds(cfg.reuse_adapt))
            C = adaptive.agreement(G, cfg.reuse_adapt)
            M = adaptive.agreement_matrix(M, C, cfg.reuse_adapt)
        W = M if cfg.reuse_mode == "weights" else np.eye(n)[reuse.sample_mapping(M, self.rng)]
        units = update_units(W, self.owner, cfg.update_by)
        # line 6: the update sequence; lines 7-9: every learner in turn (Eq. 8, or Eq. 7's step)
        order = reuse.update_order(len(units), self.rng) if spec.sequential else range(len(units))
        _, objectives, trpo_kls, learners = update_actors(actors, self.actor_opts, batch, units, order, adv, spec, cfg,
                                                          self.rng)
        explained = explained_variance(self.value_norm.denormalize(v_old), returns)  # the critic before its update
        critic_loss = update_critic(self.critic, self.critic_opt, self.value_norm, batch.states, v_old, returns, cfg,
                                    self.rng)
        accepted = [k for k in trpo_kls if not math.isnan(k)]
        metrics = {
            "train_return": mean_or_nan(batch.episode_returns),
            "objective": float(np.mean(objectives)), "value_loss": critic_loss,
            "trpo_kl": mean_or_nan(accepted), "trpo_accepted": len(accepted),
            "kl_matrix": K, "reuse_matrix": M,
            # reuse made visible at every iteration (the matrices reach the results rows at evaluations only)
            "peer_share": reuse.peer_share(M), "kl_nearest": reuse.nearest_peer(K),
            # the weight on seats of other networks: the reuse Eq. 9's gate decided (seats that share a
            # network always weigh each other, at KL 0)
            "across_share": reuse.peer_share(M, self.owner),
        }
        if cfg.reuse_adapt is not None:  # only then: a default run's rows keep their columns
            metrics["agreement"] = C
        # the live diagnostics (history only: the results rows keep their columns)
        detail = {"trpo_kls": trpo_kls, "learners": learners, "explained_variance": explained,
                  "peer_shares": (1 - np.diag(M)).tolist()}
        return Update(metrics, detail, {"pairwise_kl": (kl, active)} if "pairwise_kl" in wanted else {})

    def optimisers(self) -> list[tuple[torch.optim.Optimizer, float]]:
        """Every optimiser with its learning rate before annealing."""
        return [(o, self.cfg.lr) for o in self.actor_opts] + [(self.critic_opt, self.cfg.critic_lr)]

    def state_dict(self) -> dict:
        return {"critic": self.critic.state_dict(), "value_norm": self.value_norm.state_dict(),
                "critic_opt": self.critic_opt.state_dict(), "np_rng": self.rng.bit_generator.state,
                **{f"actor_opt{k}": opt.state_dict() for k, opt in enumerate(self.actor_opts)}}

    def load_state_dict(self, state: dict) -> None:
        for obj, key in ((self.critic, "critic"), (self.value_norm, "value_norm"), (self.critic_opt, "critic_opt"),
                         *((opt, f"actor_opt{k}") for k, opt in enumerate(self.actor_opts))):
            obj.load_state_dict(state[key])
        self.rng.bit_generator.state = state["np_rng"]
