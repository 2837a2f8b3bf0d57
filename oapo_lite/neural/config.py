"""A run's configuration: ``TrainConfig``, checked when it is made, and which algorithms read each field."""
from __future__ import annotations

import dataclasses
import json
import math
import numbers
from dataclasses import dataclass
from typing import Callable

import numpy as np

from oapo_lite.algorithms import ALGOS
from oapo_lite.envs import registry as env_registry
from oapo_lite.envs.oracle import check_fits
from oapo_lite.neural import adaptive
from oapo_lite.reuse import KL_REDUCES, SCHEMES


NETWORKS = ("agent", "type", "one")  # one network per seat, per kind of seat, for every seat


# The fields only some algorithms read; every other field applies to every run. A run refuses a
# value other than the default in a field its algorithm does not read (it could not honour it).
EQ9_FIELDS = ("sigma", "reuse_lambda", "kl_reduce", "reuse_mode", "allowed", "reuse_adapt", "reuse_warmup")
TRPO_FIELDS = ("kl_threshold", "cg_iters", "cg_damping", "line_search_steps", "backtrack", "accept_ratio")
A2C_FIELDS = ("n_step", "a2c_lr", "a2c_adam_eps", "a2c_max_grad_norm")
ONLY = {"seac_lambda": ("seac",), "seps_clusters": ("seps",), "seps_pretrain_steps": ("seps",)}
# the PPO / TRPO fields SEAC and SePS ignore: the grids pass a map's common settings to every
# curve, so a config accepts them and only the command line refuses them when given
A2C_IGNORES = ("rollout_len", "lr", "critic_lr", "ppo_epochs", "n_minibatch", "clip", "max_grad_norm", "gae_lambda",
               "value_norm", "update_by", "entropy_by_weight")


def readers(name: str) -> list[str]:
    """The algorithms that read field ``name`` (all of them for a field every run reads)."""
    if name in ONLY:
        return list(ONLY[name])
    spec_ok = {EQ9_FIELDS: lambda s: s.reuse == "oapo", TRPO_FIELDS: lambda s: s.trust_region,
               A2C_FIELDS: lambda s: s.a2c, A2C_IGNORES: lambda s: not s.a2c}
    for fields, ok in spec_ok.items():
        if name in fields:
            return sorted(a for a, s in ALGOS.items() if ok(s))
    return sorted(ALGOS)


def _is_int(x) -> bool:
    return isinstance(x, numbers.Integral) and not isinstance(x, (bool, np.bool_))


def _is_real(x) -> bool:
    return isinstance(x, numbers.Real) and not isinstance(x, (bool, np.bool_))


# fields renamed since runs were first recorded (old name -> new): the command line names the new one
RENAMED = {"lam": "reuse_lambda"}


@dataclass
class TrainConfig:
    """Everything that determines a run (with the seed). Defaults follow HARL (PKU-MARL/HARL),
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
    reuse_lambda: float = 0.7  # Eq. 9's lambda: the probability a learner keeps for its own experience
    kl_reduce: str = "max"  # Eq. 9's statistic of the per-observation KL (reuse.KL_REDUCES)
    reuse_mode: str = "weights"
    allowed: object = None  # None, an (n, n) bool mask, or a scheme name NR / UR / RR / AR
    # the actors' networks, issue 31's readings of the paper: "agent" one per seat, "type" one per
    # kind of seat (the env's agent_types; Eq. 9 then gates reuse across kinds), "one" one for every
    # seat; None: the algorithm's own (MAPPO one, the others one per seat)
    networks: str | None = None
    # None: Eq. 9 as written; "gradient" / "gradient_sign" / "gradient_test": Eq. 9's weights scaled
    # online by the agreement of each source's surrogate gradient with the learner's own (adaptive.py)
    reuse_adapt: str | None = None
    # iterations at the start with M = I (no reuse) before Eq. 9 applies: the control for "is the
    # reuse of the first iterations, while untrained nets look alike, harmful?" (issue 31)
    reuse_warmup: int = 0
    # "net": each network is updated once an iteration, on the mean of its seats' rows of M;
    # "seat": seat by seat in a random order, each update on its own seat's row of M with the
    # sequential factor, so a network shared by several seats moves once per seat (HARL's HAPPO
    # with a shared actor); where every network has one seat the two are the same
    update_by: str = "net"
    # the entropy bonus weighted as the own seats' surrogate is (W[i, i] for a net of one seat;
    # for several, the sum of their weights; 0 where "sample" mode drew another source), so that
    # reuse does not raise the bonus against the learner's own experience. PPO only (TRPO has no bonus)
    entropy_by_weight: bool = False
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
    # SEAC and SePS train with A2C at their reference code's defaults (ASSUMPTIONS.md); the PPO / TRPO fields
    # above (rollout_len, lr, critic_lr, ppo_epochs, clip, max_grad_norm, ...) do not apply to them
    n_step: int = 5  # their n-step returns, and so their rollout length
    a2c_lr: float = 3e-4
    a2c_adam_eps: float = 1e-3
    a2c_max_grad_norm: float = 0.5
    seac_lambda: float = 1.0  # weight of the other agents' importance-weighted terms
    seps_clusters: int | None = None  # None: the best Davies-Bouldin index over 2..n-1
    seps_pretrain_steps: int = 20_000  # env steps on one shared network before clustering; part of ``steps``
    # Issue 22's SMAX settings (at defaults that keep every committed run as it was)
    # lr, critic_lr (and a2c_lr) fall linearly over the run: iteration it (0-based) of N uses
    # lr * (1 - it / N), as JaxMARL's ANNEAL_LR; after the last iteration the rate is 0
    lr_anneal: bool = False
    value_norm: bool = True  # the critic regresses on running-normalised targets (HARL's ValueNorm)
    # a LayerNorm on the inputs of every actor and of the critic (HARL's use_feature_normalization,
    # on in its tuned MaMuJoCo settings); the PPO / TRPO family only
    feature_norm: bool = False

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
        whole("reuse_warmup", 0)
        maze = env_registry.maze_of(self.env) if self.env_fn is None else None
        if maze is not None:
            check_fits(maze, self.max_steps)
        need(self.steps >= self.iteration_steps, "steps", f">= n_envs * rollout_len = {self.iteration_steps} (one iteration)")
        need(self.n_minibatch <= self.n_envs * self.rollout_len, "n_minibatch", "<= n_envs * rollout_len")
        for name in ("gamma", "gae_lambda", "reuse_lambda"):
            real(name, lambda x: 0.0 <= x <= 1.0, "a number in [0, 1]")
        for name in ("lr", "critic_lr", "clip", "max_grad_norm", "kl_threshold", "a2c_lr", "a2c_adam_eps",
                     "a2c_max_grad_norm"):
            real(name, lambda x: x > 0, "a finite number > 0")
        for name in ("entropy_coef", "cg_damping", "accept_ratio", "seac_lambda"):
            real(name, lambda x: x >= 0, "a finite number >= 0")
        real("sigma", lambda x: x >= 0, "a number >= 0 (inf: no KL gate)", finite=False)
        real("backtrack", lambda x: 0.0 < x < 1.0, "a number in (0, 1)")
        need(self.kl_reduce in KL_REDUCES, "kl_reduce", str(list(KL_REDUCES)))
        need(self.reuse_mode in ("weights", "sample"), "reuse_mode", "['sample', 'weights']")
        for name in ("lr_anneal", "value_norm", "entropy_by_weight", "feature_norm"):
            need(isinstance(getattr(self, name), (bool, np.bool_)), name, "True or False")
        need(self.bootstrap_truncation is None or isinstance(self.bootstrap_truncation, (bool, np.bool_)),
             "bootstrap_truncation", "None, True or False")
        need(self.networks is None or isinstance(self.networks, str) and self.networks in NETWORKS, "networks",
             f"None or one of {list(NETWORKS)}")
        need(self.update_by in ("net", "seat"), "update_by", "['net', 'seat']")
        if self.entropy_by_weight:
            ppo = sorted(a for a, s in ALGOS.items() if not (s.trust_region or s.a2c))
            need(not (ALGOS[self.algo].a2c or ALGOS[self.algo].trust_region) and self.entropy_coef > 0,
                 "entropy_by_weight", f"False with algo {self.algo!r} and entropy_coef {self.entropy_coef!r}; it "
                                      f"weights the entropy bonus of {ppo}, with entropy_coef > 0")
        if self.update_by == "seat":
            sequential = sorted(a for a in ALGOS if ALGOS[a].sequential)
            need(ALGOS[self.algo].sequential, "update_by", f"'net' with algo {self.algo!r}; updating seat by seat "
                                                           f"needs the sequential factor of {sequential}")
        need(self.reuse_adapt is None or isinstance(self.reuse_adapt, str) and self.reuse_adapt in adaptive.ADAPT_RULES, "reuse_adapt",
             f"None or one of {list(adaptive.ADAPT_RULES)}")
        if self.reuse_adapt is not None:
            # the rule rescales Eq. 9's matrix between separate learners
            need(self.network_kind == "agent" and self.update_by == "net", "reuse_adapt",
                 "None unless every seat has its own network, updated once (networks='agent', update_by='net')")
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
            need(not self.feature_norm, "feature_norm", f"False with algo {self.algo!r} (its A2C networks have none)")
            need(self.networks is None, "networks", f"None with algo {self.algo!r} (SEAC has one network per agent, "
                                                    "SePS chooses its groups)")
            need(not self.bootstrap_truncation, "bootstrap_truncation",
                 f"None or False with algo {self.algo!r} (its n-step returns end at a truncation as at a termination, "
                 "the reference code's default)")
        if self.algo == "seps":
            need(self.n_envs * self.n_step <= self.seps_pretrain_steps < self.steps, "seps_pretrain_steps",
                 f">= n_envs * n_step = {self.n_envs * self.n_step} (one iteration) and < steps = {self.steps}")
        defaults = {f.name: f.default for f in dataclasses.fields(self)}
        for name in (*EQ9_FIELDS, *TRPO_FIELDS, *A2C_FIELDS, *ONLY):
            value, default = getattr(self, name), defaults[name]
            same = value is default or (value is not None and not isinstance(value, np.ndarray) and value == default)
            need(same or self.algo in readers(name), name,
                 f"{default!r} with algo {self.algo!r}; only {readers(name)} read it")

    @property
    def rollout_steps(self) -> int:
        """Steps of every env copy per iteration: ``n_step`` for SEAC / SePS, else ``rollout_len``."""
        return self.n_step if ALGOS[self.algo].a2c else self.rollout_len

    @property
    def network_kind(self) -> str:
        """Whose seats share a network (``NETWORKS``): ``networks``, else the algorithm's choice."""
        return self.networks or ("one" if ALGOS[self.algo].shared else "agent")

    @property
    def iteration_steps(self) -> int:
        """Env steps of one iteration: every copy's rollout."""
        return self.n_envs * self.rollout_steps

    @property
    def n_iterations(self) -> int:
        return self.steps // self.iteration_steps

    def lr_scale(self, iteration: int) -> float:
        """The factor on every learning rate in iteration ``iteration`` (0-based): 1 without
        ``lr_anneal``, else 1 - iteration / n_iterations (0 once the run is over)."""
        return 1.0 - min(iteration, self.n_iterations) / self.n_iterations if self.lr_anneal else 1.0

    def evaluates(self, iteration: int) -> bool:
        """Whether the run is evaluated after ``iteration`` iterations (0: before the first)."""
        return iteration % self.eval_every == 0 or iteration == self.n_iterations

    @property
    def eval_steps(self) -> list[int]:
        """The env steps of a finished run's evaluation rows."""
        return [it * self.iteration_steps for it in range(self.n_iterations + 1) if self.evaluates(it)]

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

