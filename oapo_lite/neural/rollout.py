"""Rollouts: every seat's policy acting in a vector of env copies, for training (``collect``) and
for evaluation (``episode_scores``), and the batch they produce (``Rollout``)."""
from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, field

import numpy as np
import torch

from oapo_lite.envs import registry as env_registry
from oapo_lite.envs.pettingzoo_vec import PettingZooVec
from oapo_lite.envs.vec import StepsSomeCopies, VecEnv
from oapo_lite.neural.config import TrainConfig
from oapo_lite.neural.nets import Actors


def make_env(cfg: TrainConfig, n_envs: int, seed: int) -> VecEnv:
    if cfg.env_fn is not None:
        return PettingZooVec(cfg.env_fn, n_envs, seed=seed, max_steps=cfg.max_steps)
    return env_registry.make_vec(cfg.env, n_envs, seed, cfg.max_steps)


def _per_seat(x: np.ndarray) -> np.ndarray:
    """(T, n, N, ...) rollout buffer -> (n, T * N, ...): the batch's one layout, seat-major, in
    which sample b of a seat is step t = b // N of env copy b % N."""
    return x.swapaxes(0, 1).reshape(x.shape[1], -1, *x.shape[3:])


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
        first, inverse = distinct_rows(obs, avail)
        return cls(torch.from_numpy(obs[first]), torch.from_numpy(avail[first]),
                   torch.from_numpy(inverse.reshape(n, B)))


@dataclass
class States:
    """The batch's states with every distinct one stored once, for the critic: state s_t of env
    copy e is row ``index[t, e]`` of ``rows``. The mazes' states repeat (every copy starts
    alike, and a policy that has learned walks one path), and V(s) and its gradient then cost
    what the distinct states cost."""

    rows: torch.Tensor  # (U, state_dim)
    index: torch.Tensor  # (T + 1, N)

    @classmethod
    def of(cls, state: torch.Tensor) -> "States":
        flat = state.reshape(-1, state.shape[-1]).numpy()
        first, inverse = distinct_rows(flat)
        return cls(torch.from_numpy(flat[first]), torch.from_numpy(inverse).reshape(state.shape[:-1]))


def distinct_rows(*columns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct rows of 2-D arrays with equal row counts, read side by side as bytes:
    (index of each one's first occurrence, the position of every row among them), in the
    order of their bytes: np.unique's (return_index, return_inverse) over the rows' bytes.

    np.unique compares whole rows, and two equal rows to their last byte; here each row's exact
    hash is uniqued instead, every row checked to equal the first row of its hash (else np.unique
    decides), and only the distinct rows are sorted by their bytes. The batch's rows are never
    copied whole: a fresh megabyte costs more in page faults than all the rest."""
    raw = [np.ascontiguousarray(c).view(np.uint8) for c in columns]
    _, first, inverse = np.unique(_row_hash(raw), return_index=True, return_inverse=True)
    if not all(_rows_equal(r, first[inverse]) for r in raw):  # two different rows with one hash
        _, first, inverse = np.unique(_keys(np.concatenate(raw, 1)), return_index=True, return_inverse=True)
        return first, inverse
    order = np.argsort(_keys(np.concatenate([r[first] for r in raw], 1)))
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return first[order], rank[inverse]


def _keys(raw: np.ndarray) -> np.ndarray:
    """Every row of a 2-D uint8 array as one value that compares by its bytes."""
    return np.ascontiguousarray(raw).view(np.dtype((np.void, raw.shape[1]))).ravel()


def _row_hash(raw: list[np.ndarray], chunk: int = 512) -> np.ndarray:
    """A 64-bit hash of every row of 2-D uint8 arrays (the columns' bytes, side by side): the
    row's 32-bit words (bytes where a width is no multiple of 4) times fixed random odd numbers,
    summed modulo 2**64. Integer arithmetic, so equal rows get equal hashes on any CPU, whatever
    kernel sums them (a floating-point product rounded one row differently by its place in the
    batch under MKL's AVX2 kernels); different rows may share one, and ``distinct_rows`` checks.
    A slice of rows at a time: a whole batch widened to 64 bits would be a fresh megabyte again."""
    rng = np.random.default_rng(0)
    h = np.zeros(len(raw[0]), np.uint64)
    for r in raw:
        words = r.view(np.uint32) if r.shape[1] % 4 == 0 else r
        odd = rng.integers(0, 2**64, words.shape[1], np.uint64, endpoint=False) | np.uint64(1)
        for i in range(0, len(h), chunk):
            h[i:i + chunk] += words[i:i + chunk].astype(np.uint64) @ odd
    return h


def _rows_equal(raw: np.ndarray, rows: np.ndarray, chunk: int = 512) -> bool:
    """``raw[rows] == raw``, a slice of rows at a time (a gathered copy of the whole batch
    would be a fresh megabyte again)."""
    return all(np.array_equal(raw[rows[i:i + chunk]], raw[i:i + chunk]) for i in range(0, len(raw), chunk))


@dataclass
class Rollout:
    """One iteration's samples of every seat in one layout: per-seat fields are (n, B) with
    B = T * N, and sample b of any seat is step b // N of env copy b % N; per-step fields are
    (T, N) or (T + 1, N)."""

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
    # (N, n, obs_dim): the observations after the rollout, where SEAC's returns bootstrap and
    # SePS's recorded transitions end
    next_obs: torch.Tensor | None = None
    episode_returns: list = field(default_factory=list)
    seconds: dict = field(default_factory=dict)  # spent in the policy forwards and in env stepping

    @functools.cached_property
    def states(self) -> States:
        """``state`` de-duplicated, found when a critic first asks (SEAC and SePS value observations)."""
        return States.of(self.state)


def sample_actions(actors: Actors, weights, step, gen: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
    """Every seat's action from one batched forward: (actions (n, N, ...), log-probs (n, N))."""
    obs, avail = (torch.from_numpy(x).transpose(0, 1) for x in (step.obs, step.avail))
    d = actors.apply(weights, obs, avail)
    a = actors.head.sample(d, gen)
    return a, actors.head.log_prob(d, a)


def collect(env: VecEnv, step, actors: Actors, owner: list[int], length: int, gen: torch.Generator):
    """Run every seat's actor in one batched forward per step for ``length`` steps. Returns the
    batch and the envs' last step (where the next rollout starts)."""
    N, n, continuous = env.n_envs, env.n_agents, actors.head.continuous
    # every per-seat buffer is (step, seat, env copy): the envs give (copy, seat), the actors act seat-major
    obs = np.empty((length, n, N, env.obs_dim), np.float32)
    avail = np.empty((length, n, N, env.n_actions), bool)
    state = np.empty((length + 1, N, env.state_dim), np.float32)
    final_state = np.empty((length, N, env.state_dim), np.float32)
    reward = np.empty((length, N), np.float32)
    term, trunc = np.empty((length, N), bool), np.empty((length, N), bool)
    active = np.empty((length, n, N), bool)
    # numpy buffers: a step's writes into torch tensors cost several times more
    act = np.empty((length, n, N, env.n_actions), np.float32) if continuous else np.empty((length, n, N), np.int64)
    logp = np.empty((length, n, N), np.float32)
    returns, seconds = [], {"policy": 0.0, "env": 0.0}
    with torch.inference_mode():
        weights = actors.stack(owner)
        for t in range(length):
            obs[t], avail[t], active[t] = (x.swapaxes(0, 1) for x in (step.obs, step.avail, step.active))
            state[t] = step.state
            tic = time.perf_counter()
            act[t], logp[t] = (x.numpy() for x in sample_actions(actors, weights, step, gen))
            toc = time.perf_counter()
            step = env.step(act[t].swapaxes(0, 1))
            seconds["policy"] += toc - tic
            seconds["env"] += time.perf_counter() - toc
            reward[t], term[t], trunc[t], final_state[t] = step.reward, step.terminated, step.truncated, step.final_state
            returns += step.episode_return[~np.isnan(step.episode_return)].tolist()
    state[length] = step.state
    batch = Rollout(Inputs.of(_per_seat(obs), _per_seat(avail)),
                    *(torch.from_numpy(_per_seat(x)) for x in (act, logp)),
                    *(torch.from_numpy(x) for x in (state, final_state, reward, term, trunc)),
                    active=None if active.all() else torch.from_numpy(_per_seat(active)),
                    next_obs=torch.from_numpy(step.obs.copy()), episode_returns=returns, seconds=seconds)
    return batch, step


def episode_scores(actors: Actors, owner: list[int], env: VecEnv, gen: torch.Generator, max_steps: int) -> tuple[float, float]:
    """Mean return and success rate of the first episode of every copy, stochastic policies."""
    step = env.reset()
    ret, success = np.full(env.n_envs, np.nan), np.full(env.n_envs, np.nan)
    # an env that steps copies one by one (GRF) can leave those whose first episode ended
    some = isinstance(env, StepsSomeCopies)
    with torch.inference_mode():
        weights = actors.stack(owner)
        # SMAX ends an episode that reaches its time limit on the step after the max_steps-th;
        # one step fewer left those copies out, so a time-out was never counted as a loss
        for _ in range(max_steps + 1):
            # every copy's action is drawn, so the generator's draws do not depend on who still plays
            actions = sample_actions(actors, weights, step, gen)[0].transpose(0, 1).numpy()
            step = env.step_only(actions, np.isnan(ret)) if some else env.step(actions)
            first = np.isnan(ret) & ~np.isnan(step.episode_return)
            ret[first], success[first] = step.episode_return[first], step.episode_success[first]
            if not np.isnan(ret).any():
                break
    return mean_or_nan(ret), mean_or_nan(success)


def mean_or_nan(x) -> float:
    x = np.asarray(x, dtype=float)
    return float(x[~np.isnan(x)].mean()) if (~np.isnan(x)).any() else math.nan

