"""A run's configuration: ``TrainConfig``, checked when it is made, and which algorithms read each field."""
from __future__ import annotations

import dataclasses
import hashlib
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


NETWORKS = ("agent", "type", "one")  # one network per seat, per agent type, for every seat


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
    spec_ok = {EQ9_FIELDS: lambda s: s.reuse_rule == "oapo", TRPO_FIELDS: lambda s: s.trust_region,
               A2C_FIELDS: lambda s: s.a2c, A2C_IGNORES: lambda s: not s.a2c}
    for fields, ok in spec_ok.items():
        if name in fields:
            return sorted(a for a, s in ALGOS.items() if ok(s))
    return sorted(ALGOS)


def _is_int(x) -> bool:
    return isinstance(x, numbers.Integral) and not isinstance(x, (bool, np.bool_))


def _is_real(x) -> bool:
    return isinstance(x, numbers.Real) and not isinstance(x, (bool, np.bool_))


# The seeds every engine takes as they are, so that two seeds never give one engine's randomness:
# SMAX's key is the seed's 32 bits, torch's generators take 64. The streams derived from a seed
# (actions, evaluation episodes, a GRF copy's engine) are SeedSequence hashes of (seed, purpose).
MAX_SEED = 2**32 - 1


def derive_seed(*keys: int) -> int:
    """A seed for one purpose of a run (evaluation episodes, action sampling, ...), from its seed."""
    return int(np.random.SeedSequence(list(keys)).generate_state(1)[0])

# fields renamed since runs were first recorded (old name -> new): the command line names the new one
RENAMED = {"lam": "reuse_lambda"}


def _field(default, meaning: str, allowed: str):
    """A config field with its one line of meaning and its allowed values: the command line's
    ``--help`` and the error for a bad value both read them from here."""
    return dataclasses.field(default=default, metadata={"meaning": meaning, "allowed": allowed})


# torch computes in float32: a larger number overflows there (3.4e38 is float32's largest)
FLOAT32_MAX = float(np.finfo(np.float32).max)
POSITIVE, AT_LEAST_0 = "a number > 0 and below 3.4e38 (float32's largest)", "a number >= 0 and below 3.4e38"
FRACTION = "a number in [0, 1]"
WHOLE, SWITCH = "an integer >= 1", "True or False"


@dataclass
class TrainConfig:
    """Everything that determines a run (with the seed). Defaults follow HARL (PKU-MARL/HARL),
    except the smaller (64, 64) hidden layers and the batch shape (32 copies x 50 steps)."""

    algo: str = _field("oappo", "the algorithm", str(sorted(ALGOS)))
    env: str = _field("black_red", "the environment: a built-in maze, a maze's text or a real engine's scenario",
                      "a built-in map name, a map text or <engine>:<name>")
    env_fn: Callable | None = _field(None, "a PettingZoo ParallelEnv factory; replaces env when given (Python only)",
                                     "None or a callable that returns a PettingZoo ParallelEnv")
    seed: int = _field(0, "the run's seed: networks, actions and environment copies",
                       f"an integer in [0, {MAX_SEED}] (SMAX's JAX key holds 32 bits: seed 2**32 would replay seed 0)")
    steps: int = _field(200_000, "total env steps (joint transitions over all copies)", WHOLE)
    n_envs: int = _field(32, "environment copies stepped together", WHOLE)
    rollout_len: int = _field(50, "steps of every copy per iteration (PPO / TRPO family)", WHOLE)
    gamma: float = _field(0.99, "the discount factor", FRACTION)
    gae_lambda: float = _field(0.95, "GAE's lambda", FRACTION)
    bootstrap_truncation: bool | None = _field(
        None, "add V(final state) to the return where the time limit cut an episode; None: yes, except on the built-in "
              "mazes, whose state holds t / max_steps, so their time limit ends the episode", "None, True or False")
    lr: float = _field(5e-4, "the actors' learning rate (PPO / TRPO family)", POSITIVE)
    critic_lr: float = _field(5e-4, "the critic's learning rate (PPO / TRPO family)", POSITIVE)
    ppo_epochs: int = _field(5, "passes over the batch per iteration (PPO / TRPO family)", WHOLE)
    n_minibatch: int = _field(1, "minibatches per pass", "an integer >= 1 and <= n_envs * rollout_len")
    clip: float = _field(0.2, "PPO's clip of the ratio (Eq. 8's epsilon)", POSITIVE)
    entropy_coef: float = _field(0.01, "the weight of the entropy bonus", AT_LEAST_0)
    max_grad_norm: float = _field(10.0, "gradients are clipped to this norm (PPO / TRPO family)", POSITIVE)
    hidden: tuple[int, ...] = _field((64, 64), "the hidden layers' widths of every actor and the critic",
                                     "a non-empty sequence of positive integers")
    sigma: float = _field(0.1, "Eq. 9's KL threshold: a peer whose K exceeds it is not reused",
                          "a number >= 0 (inf: no KL gate)")
    reuse_lambda: float = _field(0.7, "Eq. 9's lambda: the weight a learner keeps for its own experience", FRACTION)
    kl_reduce: str = _field("max", "Eq. 9's statistic of the per-observation KL", str(list(KL_REDUCES)))
    reuse_mode: str = _field("weights", "weights: train on every source, weighted by M; sample: draw one source per "
                                        "learner from M (Algorithm 1, lines 5-6)", "['sample', 'weights']")
    allowed: object = _field(None, "which seats may reuse which (applied on top of Eq. 9's gate)",
                             f"None, an (n, n) bool mask or a scheme in {list(SCHEMES)}")
    networks: str | None = _field(
        None, "the actors' networks: agent, one per seat; type, one per agent type (Eq. 9 then gates reuse across "
              "types); one, one for every seat; None: the algorithm's own (MAPPO one, the others one per seat)",
        f"None or one of {list(NETWORKS)}")
    reuse_adapt: str | None = _field(
        None, "None: Eq. 9 as written; else Eq. 9's weights scaled online by the agreement of each source's "
              "surrogate gradient with the learner's own (oapo_lite/neural/adaptive.py)",
        f"None or one of {list(adaptive.ADAPT_RULES)}")
    reuse_warmup: int = _field(0, "iterations at the start with M = I (no reuse) before Eq. 9 applies",
                               "an integer >= 0")
    update_by: str = _field(
        "net", "net: each network updated once an iteration on the mean of its seats' rows of M; seat: seat by "
               "seat in a random order with the sequential factor (a shared network moves once per seat)",
        "['net', 'seat']")
    entropy_by_weight: bool = _field(
        False, "weight the entropy bonus as the own seats' surrogate is, so that reuse does not raise it (PPO only)",
        SWITCH)
    kl_threshold: float = _field(0.01, "TRPO's delta: the KL bound of a trust-region step", POSITIVE)
    cg_iters: int = _field(10, "TRPO's conjugate-gradient iterations", WHOLE)
    cg_damping: float = _field(0.1, "TRPO's damping of the Fisher-vector product", AT_LEAST_0)
    line_search_steps: int = _field(10, "TRPO's backtracking steps", WHOLE)
    backtrack: float = _field(0.8, "TRPO's step shrink per backtracking step", "a number in (0, 1)")
    accept_ratio: float = _field(0.5, "TRPO accepts a step whose improvement is this share of the expected one",
                                 AT_LEAST_0)
    eval_every: int = _field(5, "iterations between evaluations", WHOLE)
    eval_episodes: int = _field(32, "evaluation episodes (one per evaluation copy)", WHOLE)
    max_steps: int = _field(50, "an episode's time limit in env steps", WHOLE)
    checkpoint_every: int = _field(25, "iterations between checkpoints", WHOLE)
    # SEAC and SePS train with A2C at their reference code's defaults (ASSUMPTIONS.md); the PPO / TRPO fields
    # above (rollout_len, lr, critic_lr, ppo_epochs, clip, max_grad_norm, ...) do not apply to them
    n_step: int = _field(5, "SEAC / SePS: their n-step returns, and so their rollout length", WHOLE)
    a2c_lr: float = _field(3e-4, "SEAC / SePS: the learning rate", POSITIVE)
    a2c_adam_eps: float = _field(1e-3, "SEAC / SePS: Adam's epsilon", POSITIVE)
    a2c_max_grad_norm: float = _field(0.5, "SEAC / SePS: gradients are clipped to this norm", POSITIVE)
    seac_lambda: float = _field(1.0, "SEAC: the weight of the other agents' importance-weighted terms", AT_LEAST_0)
    seps_clusters: int | None = _field(None, "SePS: its groups; None: the best Davies-Bouldin index over 2..n-1",
                                       "None or an integer >= 1")
    seps_pretrain_steps: int = _field(20_000, "SePS: env steps on one shared network before clustering, part of steps",
                                      "an integer >= n_envs * n_step and < steps")
    # the SMAX settings (at defaults that keep every committed run as it was)
    lr_anneal: bool = _field(False, "every learning rate falls linearly to 0 over the run (JaxMARL's ANNEAL_LR)",
                             SWITCH)
    value_norm: bool = _field(True, "the critic regresses on running-normalised targets (HARL's ValueNorm)", SWITCH)
    feature_norm: bool = _field(
        False, "a LayerNorm on the inputs of every actor and of the critic (HARL's use_feature_normalization; PPO / "
               "TRPO family)", SWITCH)
    normalize: bool = _field(
        False, "running normalisation of observations, states and rewards, as stable-baselines3's VecNormalize "
               "(oapo_lite/neural/normalize.py)", SWITCH)

    def __post_init__(self):
        def need(ok: bool, name: str, allowed: str | None = None):
            """Refuse the field's value unless ``ok``; ``allowed`` defaults to the field's own."""
            if not ok:
                raise ValueError(f"{name} = {getattr(self, name)!r} is invalid; allowed: {allowed or ALLOWED[name]}")

        def real(name: str, ok: Callable[[float], bool], finite: bool = True):
            x = getattr(self, name)
            need(_is_real(x) and not math.isnan(x) and (abs(x) <= FLOAT32_MAX or not finite) and ok(x), name)

        need(isinstance(self.algo, str) and self.algo in ALGOS, "algo")
        need(self.env_fn is None or callable(self.env_fn), "env_fn")
        if self.env_fn is None:
            need(isinstance(self.env, str) and self.env.strip() != "", "env")
            env_registry.check(self.env)  # raises naming the built-in maps or the engine's names
        need(isinstance(self.hidden, (tuple, list)) and len(self.hidden) > 0
             and all(_is_int(h) and h > 0 for h in self.hidden), "hidden")
        self.hidden = tuple(int(h) for h in self.hidden)
        for name in ("steps", "n_envs", "rollout_len", "ppo_epochs", "n_minibatch", "cg_iters", "line_search_steps",
                     "eval_every", "eval_episodes", "max_steps", "checkpoint_every", "n_step", "seps_pretrain_steps"):
            need(_is_int(getattr(self, name)) and getattr(self, name) >= 1, name, WHOLE)
        need(_is_int(self.seed) and 0 <= self.seed <= MAX_SEED, "seed")
        need(_is_int(self.reuse_warmup) and self.reuse_warmup >= 0, "reuse_warmup")
        maze = env_registry.maze_of(self.env) if self.env_fn is None else None
        if maze is not None:
            check_fits(maze, self.max_steps)
        need(self.steps >= self.iteration_steps, "steps",
             f">= n_envs * {self.rollout_field} = {self.iteration_steps} (one iteration)")
        need(self.n_minibatch <= self.n_envs * self.rollout_len, "n_minibatch")
        if not ALGOS[self.algo].a2c and self.iteration_steps < 2:  # one sample has no spread to normalise by
            raise ValueError(f"n_envs = {self.n_envs} and rollout_len = {self.rollout_len} give one sample per "
                             "iteration; allowed: n_envs * rollout_len >= 2 (the advantages are normalised by "
                             "their standard deviation over the iteration's samples)")
        for name in ("gamma", "gae_lambda", "reuse_lambda"):
            real(name, lambda x: 0.0 <= x <= 1.0)
        for name in ("lr", "critic_lr", "clip", "max_grad_norm", "kl_threshold", "a2c_lr", "a2c_adam_eps",
                     "a2c_max_grad_norm"):
            real(name, lambda x: x > 0)
        for name in ("entropy_coef", "cg_damping", "accept_ratio", "seac_lambda"):
            real(name, lambda x: x >= 0)
        real("sigma", lambda x: x >= 0, finite=False)
        real("backtrack", lambda x: 0.0 < x < 1.0)
        need(self.kl_reduce in KL_REDUCES, "kl_reduce")
        need(self.reuse_mode in ("weights", "sample"), "reuse_mode")
        for name in ("lr_anneal", "value_norm", "entropy_by_weight", "feature_norm", "normalize"):
            need(isinstance(getattr(self, name), (bool, np.bool_)), name)
        need(self.bootstrap_truncation is None or isinstance(self.bootstrap_truncation, (bool, np.bool_)),
             "bootstrap_truncation")
        need(self.networks is None or isinstance(self.networks, str) and self.networks in NETWORKS, "networks")
        need(self.update_by in ("net", "seat"), "update_by")
        if self.entropy_by_weight:
            ppo = sorted(a for a, s in ALGOS.items() if not (s.trust_region or s.a2c))
            need(not (ALGOS[self.algo].a2c or ALGOS[self.algo].trust_region) and self.entropy_coef > 0,
                 "entropy_by_weight", f"False with algo {self.algo!r} and entropy_coef {self.entropy_coef!r}; it "
                                      f"weights the entropy bonus of {ppo}, with entropy_coef > 0")
        if self.update_by == "seat":
            sequential = sorted(a for a in ALGOS if ALGOS[a].sequential)
            need(ALGOS[self.algo].sequential, "update_by", f"'net' with algo {self.algo!r}; updating seat by seat "
                                                           f"needs the sequential factor of {sequential}")
        need(self.reuse_adapt is None or isinstance(self.reuse_adapt, str) and self.reuse_adapt in adaptive.ADAPT_RULES,
             "reuse_adapt")
        if self.reuse_adapt is not None:
            # the rule rescales Eq. 9's matrix between separate learners
            need(self.networks_used == "agent" and self.update_by == "net", "reuse_adapt",
                 "None unless every seat has its own network, updated once (networks='agent', update_by='net')")
            need(self.n_envs >= adaptive.folds(self.reuse_adapt), "n_envs",
                 f">= {adaptive.folds(self.reuse_adapt)} with reuse_adapt={self.reuse_adapt!r} (its env-copy folds)")
        if isinstance(self.allowed, str):
            need(self.allowed in SCHEMES, "allowed")
        elif self.allowed is not None:
            try:
                allowed = np.asarray(self.allowed)
            except ValueError:  # ragged rows
                allowed = None
            need(allowed is not None and allowed.ndim == 2 and allowed.shape[0] == allowed.shape[1]
                 and np.isin(allowed, (0, 1)).all(), "allowed")
            self.allowed = allowed.astype(bool)
        need(self.seps_clusters is None or (_is_int(self.seps_clusters) and self.seps_clusters >= 1), "seps_clusters")
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
        return getattr(self, self.rollout_field)

    @property
    def rollout_field(self) -> str:
        """The field that sets ``rollout_steps``: what a message about the rollout's length names."""
        return "n_step" if ALGOS[self.algo].a2c else "rollout_len"

    @property
    def networks_used(self) -> str:
        """The networks reading the run trains (``NETWORKS``): ``networks``, else the algorithm's."""
        return self.networks or ALGOS[self.algo].networks

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

    def changed(self) -> dict:
        """The fields (``flat``) that differ from ``TrainConfig``'s defaults."""
        defaults = TrainConfig().flat()
        return {k: v for k, v in self.flat().items() if str(v) != str(defaults[k])}

    def run_id(self, env_name: str | None = None) -> str:
        """The run's identity: the name of its cached result (and of a command-line run's
        folder): the algorithm, env (``env_name`` if given: a map file's name) and seed, and a
        hash of the fields that differ from the defaults (``changed``). Hashing only those keeps
        every cached run valid when a new field is added with a default that reproduces the old
        behaviour; changing an existing default, on the other hand, must come with a new cache."""
        blob = json.dumps(self.changed(), sort_keys=True, default=str)
        env = env_name or ("map" if "\n" in self.env else self.env)
        env = env.replace(":", "_")  # an engine's env spec ("smax:3m") as a portable file name
        return f"{self.algo}-{env}-s{self.seed}-{hashlib.sha1(blob.encode()).hexdigest()[:10]}"


ALLOWED = {f.name: f.metadata["allowed"] for f in dataclasses.fields(TrainConfig)}
MEANING = {f.name: f.metadata["meaning"] for f in dataclasses.fields(TrainConfig)}
