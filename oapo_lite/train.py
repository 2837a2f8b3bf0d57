"""One training loop for OAPPO, OATRPO, HAPPO, HATRPO, MAPPO and IPPO (Algorithm 1), and for
the experience-sharing baselines SEAC and SePS (their A2C learner: ``oapo_lite/a2c.py``).

Each iteration: collect a vectorised rollout, compute the joint advantage with one
centralised critic and GAE, measure the policy distances K and the reuse matrix M (Eq. 9),
then update the learners one after another in a random order, each on the M-weighted
experience of its sources (Eq. 8, or Eq. 7 with a trust-region step), carrying the
sequential factor; finally train the critic. ``train(cfg, out_dir)`` returns the evaluation
rows as a DataFrame and keeps ``results.csv`` and ``checkpoint.pt`` in ``out_dir``.
"""
from __future__ import annotations

import dataclasses
import json
import math
import numbers
import os
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd
import torch

from oapo_lite import adaptive, reuse
from oapo_lite.a2c import Learner as A2CLearner
from oapo_lite.envs import registry as env_registry
from oapo_lite.envs.core import VecMaze
from oapo_lite.envs.oracle import optimal_return
from oapo_lite.envs.pettingzoo_vec import PettingZooVec
from oapo_lite.losses import (Diverged, check_finite, gae, normalise, off_agent_objective, source_mean,
                              update_factor, value_loss, weighted_kl)
from oapo_lite.nets import Actors, Critic, ValueNorm
from oapo_lite.store import DamagedFile, Lock, atomic_write
from oapo_lite.trpo import trpo_step


@dataclass(frozen=True)
class AlgoSpec:
    reuse: str  # "oapo": Eq. 9; "own": M = I; "uniform": M = 1/n
    sequential: bool  # random update order and the factor rho
    trust_region: bool  # Eq. 7 (TRPO step) instead of Eq. 8 (PPO clip)
    shared: bool  # one network for every seat
    a2c: bool = False  # SEAC / SePS: their A2C learner (oapo_lite/a2c.py) replaces the update below


ALGOS = {
    "oappo": AlgoSpec("oapo", True, False, False),
    "oatrpo": AlgoSpec("oapo", True, True, False),
    "happo": AlgoSpec("own", True, False, False),
    "hatrpo": AlgoSpec("own", True, True, False),
    "mappo": AlgoSpec("uniform", False, False, True),
    "ippo": AlgoSpec("own", False, False, False),
    # both may learn from every seat's samples, so all spaces must match (checked like MAPPO's)
    "seac": AlgoSpec("uniform", False, False, False, a2c=True),
    "seps": AlgoSpec("uniform", False, False, False, a2c=True),
}
SCHEMES = ("AR", "NR", "RR", "UR")
START_AFRESH = "start afresh (resume=False; on the command line --no-resume) or use another output folder"


def _is_int(x) -> bool:
    return isinstance(x, numbers.Integral) and not isinstance(x, (bool, np.bool_))


def _is_real(x) -> bool:
    return isinstance(x, numbers.Real) and not isinstance(x, (bool, np.bool_))


@dataclass
class TrainConfig:
    """Everything that determines a run (with the seed). Defaults follow HARL (ANCHORS.md),
    except the smaller (64, 64) hidden layers and the batch shape (32 copies x 50 steps)."""

    algo: str = "oappo"
    env: str = "black_red"  # built-in map name or map text
    env_fn: Callable | None = None  # PettingZoo ParallelEnv factory; replaces ``env`` when given
    seed: int = 0
    steps: int = 200_000  # total env steps (joint transitions over all copies)
    n_envs: int = 32
    rollout_len: int = 50
    gamma: float = 0.99
    gae_lambda: float = 0.95
    # V(final state) on truncation; None: yes, except on the built-in mazes, whose state holds
    # t / max_steps, so the time limit is part of the MDP and its end is terminal
    bootstrap_truncation: bool | None = None
    lr: float = 5e-4
    critic_lr: float = 5e-4
    ppo_epochs: int = 5
    n_minibatch: int = 1
    clip: float = 0.2
    entropy_coef: float = 0.01
    max_grad_norm: float = 10.0
    hidden: tuple[int, ...] = (64, 64)
    sigma: float = 0.1  # Eq. 9's KL threshold
    lam: float = 0.7  # Eq. 9's own-experience probability
    kl_reduce: str = "max"
    reuse_mode: str = "weights"
    allowed: object = None  # None, an (n, n) bool mask, or a scheme name NR / UR / RR / AR
    shared: bool | None = None  # one network for all seats; None: the algorithm's own choice
    # None: Eq. 9 as written; "gradient" / "gradient_sign" / "gradient_test": Eq. 9's weights scaled
    # online by the agreement of each source's surrogate gradient with the learner's own (adaptive.py)
    reuse_adapt: str | None = None
    kl_threshold: float = 0.01  # TRPO delta
    cg_iters: int = 10
    cg_damping: float = 0.1
    line_search_steps: int = 10
    backtrack: float = 0.8
    accept_ratio: float = 0.5
    eval_every: int = 5  # iterations
    eval_episodes: int = 32
    max_steps: int = 50
    checkpoint_every: int = 25  # iterations
    # SEAC and SePS train with A2C at their papers' defaults (ANCHORS.md); the PPO / TRPO fields
    # above (rollout_len, lr, critic_lr, ppo_epochs, clip, max_grad_norm, ...) do not apply to them
    n_step: int = 5  # their n-step returns, and so their rollout length
    a2c_lr: float = 3e-4
    a2c_adam_eps: float = 1e-3
    a2c_max_grad_norm: float = 0.5
    seac_lambda: float = 1.0  # weight of the other agents' importance-weighted terms
    seps_clusters: int | None = None  # None: the best Davies-Bouldin index over 2..n-1
    seps_pretrain_steps: int = 20_000  # env steps on one shared network before clustering; part of ``steps``

    def __post_init__(self):
        def need(ok: bool, name: str, allowed: str):
            if not ok:
                raise ValueError(f"{name} = {getattr(self, name)!r} is invalid; allowed: {allowed}")

        def whole(name: str, low: int = 1):
            need(_is_int(getattr(self, name)) and getattr(self, name) >= low, name, f"an integer >= {low}")

        def real(name: str, ok: Callable[[float], bool], allowed: str, finite: bool = True):
            x = getattr(self, name)
            need(_is_real(x) and not math.isnan(x) and (math.isfinite(x) or not finite) and ok(x), name, allowed)

        need(isinstance(self.algo, str) and self.algo in ALGOS, "algo", str(sorted(ALGOS)))
        need(self.env_fn is None or callable(self.env_fn), "env_fn", "None or a callable that returns a PettingZoo "
                                                                       "ParallelEnv")
        if self.env_fn is None:
            need(isinstance(self.env, str) and self.env.strip() != "", "env",
                 "a built-in map name, a map text or <engine>:<name>")
            env_registry.check(self.env)  # raises naming the built-in maps or the engine's names
        need(isinstance(self.hidden, (tuple, list)) and len(self.hidden) > 0
             and all(_is_int(h) and h > 0 for h in self.hidden), "hidden", "a non-empty sequence of positive integers")
        self.hidden = tuple(int(h) for h in self.hidden)
        for name in ("steps", "n_envs", "rollout_len", "ppo_epochs", "n_minibatch", "cg_iters", "line_search_steps",
                     "eval_every", "eval_episodes", "max_steps", "checkpoint_every", "n_step", "seps_pretrain_steps"):
            whole(name)
        whole("seed", 0)
        need(self.steps >= self.n_envs * self.rollout_steps, "steps",
             f">= n_envs * rollout_len = {self.n_envs * self.rollout_steps} (one iteration)")
        need(self.n_minibatch <= self.n_envs * self.rollout_len, "n_minibatch", "<= n_envs * rollout_len")
        for name in ("gamma", "gae_lambda", "lam"):
            real(name, lambda x: 0.0 <= x <= 1.0, "a number in [0, 1]")
        for name in ("lr", "critic_lr", "clip", "max_grad_norm", "kl_threshold", "a2c_lr", "a2c_adam_eps",
                     "a2c_max_grad_norm"):
            real(name, lambda x: x > 0, "a finite number > 0")
        for name in ("entropy_coef", "cg_damping", "accept_ratio", "seac_lambda"):
            real(name, lambda x: x >= 0, "a finite number >= 0")
        real("sigma", lambda x: x >= 0, "a number >= 0 (inf: no KL gate)", finite=False)
        real("backtrack", lambda x: 0.0 < x < 1.0, "a number in (0, 1)")
        need(self.kl_reduce in ("max", "mean"), "kl_reduce", "['max', 'mean']")
        need(self.reuse_mode in ("weights", "sample"), "reuse_mode", "['sample', 'weights']")
        for name in ("shared", "bootstrap_truncation"):
            need(getattr(self, name) is None or isinstance(getattr(self, name), (bool, np.bool_)), name,
                 "None, True or False")
        need(self.reuse_adapt is None or isinstance(self.reuse_adapt, str) and self.reuse_adapt in adaptive.ADAPT_RULES, "reuse_adapt",
             f"None or one of {list(adaptive.ADAPT_RULES)}")
        if self.reuse_adapt is not None:
            # the rule rescales Eq. 9's matrix between separate learners; others have no Eq. 9 to adapt
            eq9 = sorted(a for a in ALGOS if ALGOS[a].reuse == "oapo")
            need(ALGOS[self.algo].reuse == "oapo", "reuse_adapt",
                 f"None with algo {self.algo!r}; only {eq9} reuse by Eq. 9")
            need(not self.shared, "reuse_adapt", "None with shared=True (one network has one gradient)")
            need(self.n_envs >= adaptive.folds(self.reuse_adapt), "n_envs",
                 f">= {adaptive.folds(self.reuse_adapt)} with reuse_adapt={self.reuse_adapt!r} (its env-copy folds)")
        mask = "None, an (n, n) bool mask or a scheme in " + str(list(SCHEMES))
        if isinstance(self.allowed, str):
            need(self.allowed in SCHEMES, "allowed", mask)
        elif self.allowed is not None:
            try:
                allowed = np.asarray(self.allowed)
            except ValueError:  # ragged rows
                allowed = None
            need(allowed is not None and allowed.ndim == 2 and allowed.shape[0] == allowed.shape[1]
                 and np.isin(allowed, (0, 1)).all(), "allowed", mask)
            self.allowed = allowed.astype(bool)
        need(self.seps_clusters is None or (_is_int(self.seps_clusters) and self.seps_clusters >= 1),
             "seps_clusters", "None or an integer >= 1")
        if ALGOS[self.algo].a2c:
            need(self.shared is None, "shared", f"None with algo {self.algo!r} (SEAC has one network per agent, "
                                                "SePS chooses its groups)")
            need(not self.bootstrap_truncation, "bootstrap_truncation",
                 f"None or False with algo {self.algo!r} (its n-step returns end at a truncation as at a termination, "
                 "the reference code's default)")
        if self.algo == "seps":
            need(self.n_envs * self.n_step <= self.seps_pretrain_steps < self.steps, "seps_pretrain_steps",
                 f">= n_envs * n_step = {self.n_envs * self.n_step} (one iteration) and < steps = {self.steps}")

    @property
    def rollout_steps(self) -> int:
        """Steps of every env copy per iteration: ``n_step`` for SEAC / SePS, else ``rollout_len``."""
        return self.n_step if ALGOS[self.algo].a2c else self.rollout_len

    @property
    def n_iterations(self) -> int:
        return self.steps // (self.n_envs * self.rollout_steps)

    def evaluates(self, iteration: int) -> bool:
        """Whether the run is evaluated after ``iteration`` iterations (0: before the first)."""
        return iteration % self.eval_every == 0 or iteration == self.n_iterations

    @property
    def eval_steps(self) -> list[int]:
        """The env steps of a finished run's evaluation rows."""
        batch = self.n_envs * self.rollout_steps
        return [it * batch for it in range(self.n_iterations + 1) if self.evaluates(it)]

    def flat(self) -> dict:
        """The config as CSV-friendly scalars."""
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        d["hidden"] = "-".join(map(str, self.hidden))
        d["allowed"] = self.allowed if self.allowed is None or isinstance(self.allowed, str) \
            else json.dumps(np.asarray(self.allowed).astype(int).tolist())
        if self.env_fn is not None:
            d["env"] = d["env_fn"] = getattr(self.env_fn, "__name__", type(self.env_fn).__name__)
        elif "\n" in self.env:
            d["env"] = self.env.strip().replace("\n", "/")  # a map text, on one CSV line
        return d


def make_env(cfg: TrainConfig, n_envs: int, seed: int):
    if cfg.env_fn is not None:
        return PettingZooVec(cfg.env_fn, n_envs, seed=seed, max_steps=cfg.max_steps)
    return env_registry.make_vec(cfg.env, n_envs, seed, cfg.max_steps)


def allowed_mask(cfg: TrainConfig, env) -> np.ndarray | None:
    if isinstance(cfg.allowed, str):
        return reuse.scheme_mask(cfg.allowed, env.agents)
    if cfg.allowed is not None and cfg.allowed.shape != (env.n_agents, env.n_agents):
        raise ValueError(f"allowed mask has shape {cfg.allowed.shape}, expected {(env.n_agents,) * 2}")
    return cfg.allowed


def check_reuse_spaces(env, pairs: np.ndarray) -> None:
    """Reusing experience needs equal observation and action spaces (Section 4). ``pairs[i, j]``:
    learner i may train on agent j's experience (not necessarily symmetric)."""
    spaces = getattr(env, "spaces", None)
    for i, j in zip(*np.nonzero(pairs)):
        if spaces is not None and i != j and spaces[i] != spaces[j]:
            raise ValueError(
                f"reuse between agents {env.agents[i]!r} and {env.agents[j]!r} needs equal spaces, got "
                f"{spaces[i]} and {spaces[j]}; forbid the pair with `allowed` or use happo/hatrpo/ippo")


def _seed(*keys: int) -> int:
    return int(np.random.SeedSequence(list(keys)).generate_state(1)[0])


def git_revision() -> str:
    """HEAD of the checkout the code runs from; ``OAPO_GIT_REV`` when set (a Ray worker runs a
    copy of the package shipped by the driver, outside any checkout, and is given the driver's)."""
    if os.environ.get("OAPO_GIT_REV"):
        return os.environ["OAPO_GIT_REV"]
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=Path(__file__).parent, capture_output=True,
                             text=True, timeout=10)
        return out.stdout.strip() if out.returncode == 0 else "unknown"
    except OSError:
        return "unknown"


def _per_agent(x: np.ndarray, seat_axis: int) -> np.ndarray:
    """(T, N, n, ...) or (T, n, N, ...) rollout array -> (n, T * N, ...): sample b = t * N + env."""
    x = np.moveaxis(x, seat_axis, 0)
    return x.reshape(x.shape[0], -1, *x.shape[3:])


@dataclass
class Inputs:
    """The batch's actor inputs with every distinct (observation, mask) stored once; sample b
    of seat j reads row ``index[j, b]``. Maze observations repeat a lot, so forwards get cheap."""

    obs: torch.Tensor  # (U, obs_dim)
    avail: torch.Tensor  # (U, A)
    index: torch.Tensor  # (n, B)

    @classmethod
    def of(cls, obs: np.ndarray, avail: np.ndarray) -> "Inputs":
        n, B = obs.shape[:2]
        obs, avail = obs.reshape(n * B, -1), avail.reshape(n * B, -1)
        raw = np.ascontiguousarray(np.concatenate([obs.view(np.uint8), avail.view(np.uint8)], 1))
        keys = raw.view(np.dtype((np.void, raw.shape[1]))).ravel()
        _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
        return cls(torch.from_numpy(obs[first]), torch.from_numpy(avail[first]),
                   torch.from_numpy(inverse.reshape(n, B)))


@dataclass
class Rollout:
    inputs: Inputs
    act: torch.Tensor  # (n, B) or (n, B, D)
    logp: torch.Tensor  # (n, B) behaviour log-probabilities
    state: torch.Tensor  # (T + 1, N, state_dim)
    final_state: torch.Tensor  # (T, N, state_dim)
    reward: torch.Tensor  # (T, N)
    terminated: torch.Tensor  # (T, N)
    truncated: torch.Tensor  # (T, N)
    # (n, B) bool: the seat acted on the sample; None when every seat always did (the mazes),
    # so the losses take the plain means there
    active: torch.Tensor | None = None
    episode_returns: list = field(default_factory=list)


def sample_actions(actors: Actors, weights, step, gen: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
    """Every seat's action from one batched forward: (actions (n, N, ...), log-probs (n, N))."""
    obs, avail = (torch.from_numpy(x).transpose(0, 1) for x in (step.obs, step.avail))
    d = actors.apply(weights, obs, avail)
    a = actors.head.sample(d, gen)
    return a, actors.head.log_prob(d, a)


def collect(env, step, actors: Actors, owner: list[int], length: int, gen: torch.Generator, clock: dict):
    """Run every seat's actor in one batched forward per step for ``length`` steps."""
    N, n, continuous = env.n_envs, env.n_agents, actors.head.continuous
    obs = np.empty((length, N, n, env.obs_dim), np.float32)
    avail = np.empty((length, N, n, env.n_actions), bool)
    state = np.empty((length + 1, N, env.state_dim), np.float32)
    final_state = np.empty((length, N, env.state_dim), np.float32)
    reward = np.empty((length, N), np.float32)
    term, trunc = np.empty((length, N), bool), np.empty((length, N), bool)
    active = np.empty((length, N, n), bool)
    act = (torch.empty((length, n, N, env.n_actions)) if continuous
           else torch.empty((length, n, N), dtype=torch.long))
    logp = torch.empty((length, n, N))
    returns = []
    with torch.inference_mode():
        weights = actors.stack(owner)
    for t in range(length):
        obs[t], avail[t], state[t], active[t] = step.obs, step.avail, step.state, step.active
        tic = time.perf_counter()
        with torch.inference_mode():
            act[t], logp[t] = sample_actions(actors, weights, step, gen)
        toc = time.perf_counter()
        step = env.step(act[t].transpose(0, 1).numpy())
        clock["policy"] += toc - tic
        clock["env"] += time.perf_counter() - toc
        reward[t], term[t], trunc[t], final_state[t] = step.reward, step.terminated, step.truncated, step.final_state
        returns += step.episode_return[~np.isnan(step.episode_return)].tolist()
    state[length] = step.state
    batch = Rollout(Inputs.of(_per_agent(obs, 2), _per_agent(avail, 2)),
                    *(torch.from_numpy(_per_agent(x.numpy(), 1)) for x in (act, logp)),
                    *(torch.from_numpy(x) for x in (state, final_state, reward, term, trunc)),
                    None if active.all() else torch.from_numpy(_per_agent(active, 2)), returns)
    return batch, step


@dataclass
class Sources:
    """What one learner (net) trains on: the seats ``rows`` — its sources with W > 0 and the
    seats it controls (``own``, positions in ``rows``, for the entropy and the factor)."""

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
    def of(cls, net: int, W: np.ndarray, owner: list[int], batch: Rollout) -> "Sources":
        own = [k for k in range(len(owner)) if owner[k] == net]
        rows = sorted(set(np.flatnonzero(W[net] > 0).tolist()) | set(own))
        w = W[net][rows]
        # Eq. 7 weights the KL by M, which bounds the acting policy's own-seat KL by
        # delta / W[i, i]: nothing when W[i, i] = 0 ("sample" mode drew another source, or
        # lam = 0), and then the policy that acts could move without limit. An own seat with
        # weight 0 therefore enters the trust region with weight 1 (its KL <= delta); where the
        # paper's weight is positive it is kept, so the weights mode is Eq. 7 as written.
        kl_w = np.where(np.isin(rows, own) & (w == 0), 1.0, w)
        return cls(net, rows, [rows.index(k) for k in own], torch.as_tensor(w, dtype=torch.float32),
                   batch.act[rows], batch.logp[rows], torch.as_tensor(kl_w, dtype=torch.float32),
                   None if batch.active is None else batch.active[rows],
                   torch.unique(batch.inputs.index[rows], return_inverse=True))


def learner_dists(actors: Actors, inputs: Inputs, src: Sources, idx=slice(None)) -> torch.Tensor:
    """(R, b, P): the learner's distribution on its sources' samples ``idx``, one forward
    over the distinct inputs they use."""
    if src.distinct is not None and idx == slice(None):
        used, inverse = src.distinct
    else:
        used, inverse = torch.unique(inputs.index[src.rows][:, idx], return_inverse=True)
    return actors(inputs.obs[used].unsqueeze(0), [src.net], inputs.avail[used].unsqueeze(0))[0][inverse]


def _minibatches(size: int, k: int, rng: np.random.Generator) -> list:
    return [slice(None)] if k == 1 else [torch.from_numpy(i) for i in np.array_split(rng.permutation(size), k)]


def ppo_update(actors: Actors, opt: torch.optim.Optimizer, inputs: Inputs, src: Sources, factor: torch.Tensor,
               adv: torch.Tensor, cfg: TrainConfig, rng: np.random.Generator) -> float:
    """OAPPO (Eq. 8): epochs of Adam on the clipped off-agent surrogate plus the entropy of
    the learner's own seats. Returns the last surrogate value."""
    params = actors.net_params(src.net)
    for _ in range(cfg.ppo_epochs):
        for idx in _minibatches(adv.shape[0], cfg.n_minibatch, rng):
            d = learner_dists(actors, inputs, src, idx)
            active = None if src.active is None else src.active[:, idx]
            obj = off_agent_objective(actors.head.log_prob(d, src.act[:, idx]), src.logp_old[:, idx], src.w,
                                      factor[idx], adv[idx], cfg.clip, active)
            own_active = None if active is None else active[src.own].reshape(-1)
            entropy = source_mean(actors.head.entropy(d[src.own]).reshape(-1), own_active)
            loss = -(obj + cfg.entropy_coef * entropy)
            check_finite(loss, "the PPO loss (Eq. 8)", src.net)
            opt.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(params, cfg.max_grad_norm)
            opt.step()
    return obj.item()


def trpo_update(actors: Actors, inputs: Inputs, src: Sources, factor: torch.Tensor, adv: torch.Tensor,
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


def advantages(critic: Critic, value_norm: ValueNorm, batch: Rollout, cfg: TrainConfig, bootstrap: bool):
    """Algorithm 1 line 4: the joint advantage by GAE on de-normalised V(s); a truncated
    episode is continued by V(final state) if ``bootstrap``, else it ends like a terminated
    one. Returns (normalised advantage (B,), returns (B,), the critic's normalised
    predictions (B,) for the clipped value loss)."""
    with torch.no_grad():
        v_norm = critic(batch.state)
        value = value_norm.denormalize(v_norm)
        final_value = value_norm.denormalize(critic(batch.final_state))
    cut = batch.terminated | batch.truncated
    next_value = torch.where(batch.truncated & ~batch.terminated & bootstrap, final_value,
                             torch.where(cut, 0.0, value[1:]))
    adv = gae(batch.reward, value[:-1], next_value, cut, cfg.gamma, cfg.gae_lambda)
    check_finite(adv, "the joint advantage (GAE)", "all: it is joint")
    return normalise(adv.reshape(-1)), (adv + value[:-1]).reshape(-1), v_norm[:-1].reshape(-1)


def policy_distances(actors: Actors, inputs: Inputs, owner: list[int], reduce: str,
                     active: torch.Tensor | None = None) -> np.ndarray:
    """Eq. 9's K[i, j] = KL(pi_j || pi_i) on seat j's observations (those where j acted, if
    ``active`` (n, B) is given): every net on every input in one batched forward, then
    gathered to (learner seat, source seat, sample)."""
    k, (U, _) = actors.n_nets, inputs.obs.shape
    with torch.no_grad():
        d = actors(inputs.obs.expand(k, U, -1), range(k), inputs.avail.expand(k, U, -1))[owner][:, inputs.index]
    if active is None:
        return _finite_distances(actors.head.kl_matrix(d, reduce))
    # where source j did not act, every learner is given j's own distribution: KL exactly 0
    # there, which leaves a max unchanged; a mean is rescaled to the active samples below
    seat, B = torch.arange(active.shape[0]), active.shape[1]
    d = torch.where(active[None, :, :, None], d, d[seat, seat][None])
    K = actors.head.kl_matrix(d, reduce)
    return _finite_distances(K if reduce == "max" else K * (B / active.sum(1).clamp_min(1)).double().numpy())


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
    # sample b is step b // n_envs of env copy b % n_envs (``_per_agent``)
    fold_of = torch.arange(adv.shape[0]) % n_envs % folds
    for i in range(n):
        src = Sources.of(i, M, list(range(n)), batch)
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


def _finite_distances(K: np.ndarray) -> np.ndarray:
    bad = np.argwhere(~np.isfinite(K))
    if len(bad):
        raise Diverged(f"the policy distance KL K[{bad[0][0]}, {bad[0][1]}] (Eq. 9)", bad[0][0])
    return K


def update_actors(actors: Actors, opts: list, batch: Rollout, W: np.ndarray, owner: list[int], order,
                  adv: torch.Tensor, spec: AlgoSpec, cfg: TrainConfig, rng: np.random.Generator):
    """Algorithm 1 lines 7-9: update the learners one after another in ``order``, learner i on
    its sources with weights W[i]; for sequential algorithms the factor rho collects the own-seat
    ratio of every learner already updated. Returns (final factor, surrogates, accepted KLs)."""
    factor = torch.ones(adv.shape[0])
    objectives, trpo_kls = [], []
    for net in order:
        src = Sources.of(net, W, owner, batch)
        if spec.trust_region:
            objective, accepted_kl = trpo_update(actors, batch.inputs, src, factor, adv, cfg)
            trpo_kls.append(accepted_kl)
        else:
            objective = ppo_update(actors, opts[net], batch.inputs, src, factor, adv, cfg, rng)
        objectives.append(objective)
        if spec.sequential:
            with torch.no_grad():
                d_new = learner_dists(actors, batch.inputs, src)[src.own]
                factor = update_factor(factor, actors.head.log_prob(d_new, src.act[src.own]), src.logp_old[src.own],
                                       None if src.active is None else src.active[src.own])
            check_finite(factor, "the sequential factor rho", net)
    return factor, objectives, trpo_kls


def update_critic(critic: Critic, opt: torch.optim.Optimizer, value_norm: ValueNorm, state: torch.Tensor,
                  v_old: torch.Tensor, returns: torch.Tensor, cfg: TrainConfig, rng: np.random.Generator) -> float:
    """The critic, trained after the actors (HARL) on normalised targets. Returns the last loss."""
    value_norm.update(returns)
    target, state = value_norm.normalize(returns), state.reshape(returns.shape[0], -1)
    for _ in range(cfg.ppo_epochs):
        for idx in _minibatches(returns.shape[0], cfg.n_minibatch, rng):
            loss = value_loss(critic(state[idx]), v_old[idx], target[idx], cfg.clip)
            check_finite(loss, "the value loss", "critic")
            opt.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(critic.parameters(), cfg.max_grad_norm)
            opt.step()
    return loss.item()


def evaluate(actors: Actors, owner: list[int], env, gen: torch.Generator, max_steps: int) -> tuple[float, float]:
    """Mean return and success rate of the first episode of every copy, stochastic policies."""
    step = env.reset()
    ret, success = np.full(env.n_envs, np.nan), np.full(env.n_envs, np.nan)
    with torch.inference_mode():
        weights = actors.stack(owner)
        for _ in range(max_steps):
            step = env.step(sample_actions(actors, weights, step, gen)[0].transpose(0, 1).numpy())
            first = np.isnan(ret) & ~np.isnan(step.episode_return)
            ret[first], success[first] = step.episode_return[first], step.episode_success[first]
            if not np.isnan(ret).any():
                break
    return _mean_or_nan(ret), _mean_or_nan(success)


def _mean_or_nan(x) -> float:
    x = np.asarray(x, dtype=float)
    return float(x[~np.isnan(x)].mean()) if (~np.isnan(x)).any() else math.nan


def _write_results(rows: list[dict], out: Path) -> None:
    atomic_write(lambda p: pd.DataFrame(rows).to_csv(p, index=False), out / "results.csv")


def load_checkpoint(out_dir: str | Path) -> dict:
    """The last checkpoint of a run directory (parameters, optimisers, RNG states, metrics);
    ``store.DamagedFile`` naming it if it cannot be read."""
    path = Path(out_dir) / "checkpoint.pt"
    try:
        ck = torch.load(path, weights_only=False)
    except FileNotFoundError:
        raise
    except Exception as err:  # truncated, empty or foreign bytes: torch and pickle raise many kinds
        detail = str(err).split(". ")[0][:120] or "no detail"
        raise DamagedFile(f"checkpoint {path} is damaged and cannot be read ({type(err).__name__}: {detail}); "
                          f"{START_AFRESH}") from None
    if not isinstance(ck, dict) or "config" not in ck:
        raise DamagedFile(f"checkpoint {path} is not an oapo_lite checkpoint; {START_AFRESH}")
    return ck


def _check_resumable(cfg: TrainConfig, ck: dict) -> None:
    """A checkpoint can continue ``cfg`` if it has every current field and only ``steps``
    differs, and grows."""
    now, saved = cfg.flat(), ck["config"]
    missing = [k for k in now if k not in saved]
    if missing:
        raise ValueError(f"checkpoint has no config fields {missing} (written by an older oapo_lite); {START_AFRESH}")
    differ = [k for k in now if k != "steps" and str(now[k]) != str(saved[k])]
    if differ:
        raise ValueError(f"checkpoint was written by a different config (fields {differ}); {START_AFRESH}")
    stale = [f.name for f in dataclasses.fields(ck["step"]) if not hasattr(ck["step"], f.name)]
    if stale:
        raise ValueError(f"checkpoint's environment step has no fields {stale} (written by an older oapo_lite); "
                         f"{START_AFRESH}")
    if ck["iteration"] > cfg.n_iterations:
        raise ValueError(f"checkpoint is at iteration {ck['iteration']} (steps = {saved['steps']}), past steps = "
                         f"{cfg.steps} ({cfg.n_iterations} iterations); resuming needs steps >= {saved['steps']}; "
                         f"or {START_AFRESH}")


def _diverged_at(err: Diverged, iteration: int, cfg: TrainConfig, out: Path, owner: list[int],
                 agents: list[str]) -> Diverged:
    """``err`` told with the iteration, the seats of the learner (a net index) and the checkpoint."""
    learner = err.learner
    if _is_int(learner):
        learner = f"{learner} (seats {[agents[k] for k in range(len(owner)) if owner[k] == learner]})"
    path = out / "checkpoint.pt"
    last = (f"the last good checkpoint {path} (iteration {load_checkpoint(out)['iteration']}) is left as it was"
            if path.exists() else "no checkpoint had been written yet")
    return Diverged(err.quantity, learner, f"iteration {iteration} of {cfg.algo} seed {cfg.seed}: ",
                    f"; the run stopped and {last}")


def train(cfg: TrainConfig, out_dir: str | Path, resume: bool = True, progress: bool = True,
          callback: Callable[[dict], None] | None = None) -> pd.DataFrame:
    """Train ``cfg`` and return one row per evaluation point (also in ``out_dir/results.csv``).

    ``results.csv`` is written with every checkpoint. With ``resume``, continue from
    ``out_dir/checkpoint.pt`` if present (and write ``results.csv`` again from it); the result
    is then identical to an uninterrupted run. ``callback(metrics)`` is called after every iteration.
    ``result.attrs``: ``history`` (per-iteration metrics) and ``timing`` (seconds in env
    stepping, policy forwards during rollouts, learning and evaluation).
    """
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise OSError(f"cannot create the run folder {out} ({err.strerror}); choose another output folder (--out on the command line)") from None
    lock = Lock(out / ".lock")  # two processes on one run: the second waits, then resumes where the first ended
    if not lock.acquire(wait=False):
        print(f"waiting for another process that is training {out}", file=sys.stderr, flush=True)
        lock.acquire()
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # bit-reproducible, and two runs can share two cores
    try:
        return _train(cfg, out, resume, progress, callback)
    finally:
        torch.set_num_threads(threads)
        lock.release()


def _train(cfg, out: Path, resume, progress, callback) -> pd.DataFrame:
    from tqdm import tqdm  # tqdm.auto warns in notebooks without ipywidgets, even when disabled

    spec = ALGOS[cfg.algo]
    shared = spec.shared if cfg.shared is None else cfg.shared
    env = make_env(cfg, cfg.n_envs, seed=cfg.seed)
    eval_env = make_env(cfg, cfg.eval_episodes, seed=_seed(cfg.seed, 2))
    n = env.n_agents
    owner = [0] * n if shared else list(range(n))  # the net of each seat
    n_nets = 1 if shared else n
    allowed = allowed_mask(cfg, env)
    if spec.reuse == "uniform" or shared:
        check_reuse_spaces(env, np.ones((n, n), bool))
    elif spec.reuse == "oapo":
        check_reuse_spaces(env, np.ones((n, n), bool) if allowed is None else allowed)
    optimum = optimal_return(env.maze) if isinstance(env, VecMaze) else math.nan
    bootstrap = not isinstance(env, VecMaze) if cfg.bootstrap_truncation is None else cfg.bootstrap_truncation

    torch.manual_seed(cfg.seed)
    init_gen = torch.Generator().manual_seed(cfg.seed)
    actors = Actors(n_nets, env.obs_dim, env.n_actions, cfg.hidden, getattr(env, "continuous", False), init_gen)
    critic, value_norm = Critic(env.state_dim, cfg.hidden, init_gen), ValueNorm()
    # one optimiser per net: Adam would move a net that got no gradient through its momentum;
    # trust-region algorithms step by hand. foreach: the same per-tensor kernels, looped in C++
    actor_opts = [] if spec.trust_region else [torch.optim.Adam(actors.net_params(k), lr=cfg.lr, eps=1e-5, foreach=True)
                                               for k in range(n_nets)]
    critic_opt = torch.optim.Adam(critic.parameters(), lr=cfg.critic_lr, eps=1e-5, foreach=True)
    learner = A2CLearner(cfg, env, actors, init_gen) if spec.a2c else None  # SEAC / SePS
    owner = owner if learner is None else learner.owner
    act_gen = torch.Generator().manual_seed(_seed(cfg.seed, 1))
    rng = np.random.default_rng(cfg.seed)  # update order, reuse mapping, minibatches
    start, history, rows = 0, [], []
    step = env.reset()
    config_cols, revision = cfg.flat(), git_revision()
    if resume and (out / "checkpoint.pt").exists():
        ck = load_checkpoint(out)
        try:
            _check_resumable(cfg, ck)
            for obj, key in ((actors, "actors"), (critic, "critic"), (value_norm, "value_norm"),
                             (critic_opt, "critic_opt"), *zip(actor_opts, [f"actor_opt{k}" for k in range(n_nets)])):
                obj.load_state_dict(ck[key])
            act_gen.set_state(ck["act_gen"])
            torch.set_rng_state(ck["torch_rng"])
            rng.bit_generator.state = ck["np_rng"]
            env.set_state(ck["env"])
            start, step, history = ck["iteration"], ck["step"], ck["history"]
            if learner is not None:
                learner.load_state_dict(ck["a2c"])
                owner = learner.owner
            # a run extended to more steps has no row where the shorter budget ended off the
            # evaluation grid (evaluating draws no shared randomness, so dropping it changes
            # nothing else), and its rows carry the new config
            rows = [{**r, **config_cols} for r in ck["rows"]
                    if cfg.evaluates(r["iteration"])]
            # a results.csv deleted or damaged after the checkpoint was written comes back from it
            _write_results(rows, out)
        except KeyError as err:
            raise ValueError(f"checkpoint {out / 'checkpoint.pt'} has no entry {err} (written by an older "
                             f"oapo_lite); {START_AFRESH}") from None
    clock = {"env": 0.0, "policy": 0.0, "learn": 0.0, "eval": 0.0}
    batch_size = cfg.n_envs * cfg.rollout_steps

    def evaluation(it: int, metrics: dict) -> None:
        tic = time.perf_counter()
        gen = torch.Generator().manual_seed(_seed(cfg.seed, 3, it))  # independent of history: resumable
        ret, success = evaluate(actors, owner, eval_env, gen, cfg.max_steps)
        rows.append({**config_cols, "git_rev": revision, "iteration": it, "step": it * batch_size,
                     "eval_return": ret, "frac_opt": ret / optimum, "eval_success": success, **metrics})
        clock["eval"] += time.perf_counter() - tic

    if start == 0:
        evaluation(0, {})
    for it in tqdm(range(start, cfg.n_iterations), initial=start, total=cfg.n_iterations,
                   desc=f"{cfg.algo} seed {cfg.seed}", disable=None if progress else True):
        batch, step = collect(env, step, actors, owner, cfg.rollout_steps, act_gen, clock)
        tic = time.perf_counter()
        if learner is not None:
            try:
                metrics, trpo_kls = learner.learn(batch, step, it), []
            except Diverged as err:
                raise _diverged_at(err, it + 1, cfg, out, owner, env.agents) from None
            owner = learner.owner  # SePS regroups once its pre-training ends
            clock["learn"] += time.perf_counter() - tic
        else:
            try:
                adv, returns, v_old = advantages(critic, value_norm, batch, cfg, bootstrap)
                K = policy_distances(actors, batch.inputs, owner, cfg.kl_reduce, batch.active)
                M = reuse.matrix_for(spec.reuse, K, cfg.sigma, cfg.lam, allowed)
                if cfg.reuse_adapt is not None:
                    G = source_gradients(actors, batch.inputs, batch, M, adv,
                                         None if spec.trust_region else cfg.clip, adaptive.folds(cfg.reuse_adapt))
                    C = adaptive.agreement(G, cfg.reuse_adapt)
                    M = adaptive.agreement_matrix(M, C, cfg.reuse_adapt)
                W = M if cfg.reuse_mode == "weights" else np.eye(n)[reuse.sample_mapping(M, rng)]
                W = W.mean(0, keepdims=True) if shared else W  # a shared net learns for every seat
                order = reuse.update_order(n_nets, rng) if spec.sequential else range(n_nets)
                _, objectives, trpo_kls = update_actors(actors, actor_opts, batch, W, owner, order, adv, spec, cfg, rng)
                critic_loss = update_critic(critic, critic_opt, value_norm, batch.state[:-1], v_old, returns, cfg, rng)
            except Diverged as err:
                raise _diverged_at(err, it + 1, cfg, out, owner, env.agents) from None
            clock["learn"] += time.perf_counter() - tic

            accepted = [k for k in trpo_kls if not math.isnan(k)]
            metrics = {
                "train_return": _mean_or_nan(batch.episode_returns),
                "objective": float(np.mean(objectives)), "value_loss": critic_loss,
                "trpo_kl": _mean_or_nan(accepted), "trpo_accepted": len(accepted),
                "kl_matrix": json.dumps(np.round(K, 6).tolist()), "reuse_matrix": json.dumps(np.round(M, 6).tolist()),
            }
            if cfg.reuse_adapt is not None:  # only then: a default run's rows keep their columns
                metrics["agreement"] = json.dumps(np.round(C, 6).tolist())
        history.append({"iteration": it + 1, "step": (it + 1) * batch_size, **metrics, "trpo_kls": trpo_kls})
        if cfg.evaluates(it + 1):
            evaluation(it + 1, metrics)
        if (it + 1) % cfg.checkpoint_every == 0 or it + 1 == cfg.n_iterations:
            ck = {"config": config_cols, "iteration": it + 1, "actors": actors.state_dict(),
                  "critic": critic.state_dict(), "value_norm": value_norm.state_dict(),
                  "critic_opt": critic_opt.state_dict(),
                  **{f"actor_opt{k}": opt.state_dict() for k, opt in enumerate(actor_opts)},
                  "act_gen": act_gen.get_state(), "torch_rng": torch.get_rng_state(),
                  "np_rng": rng.bit_generator.state, "env": env.get_state(), "step": step,
                  "history": history, "rows": rows, **({} if learner is None else {"a2c": learner.state_dict()})}
            # results.csv goes with the checkpoint, so the two always agree (and rewriting the
            # growing CSV at every evaluation cost a tenth of a paper-budget run)
            _write_results(rows, out)
            atomic_write(lambda p: torch.save(ck, p), out / "checkpoint.pt")
        if callback is not None:
            callback(history[-1])

    result = pd.DataFrame(rows)
    result.attrs["timing"] = dict(clock)
    result.attrs["history"] = history
    return result
