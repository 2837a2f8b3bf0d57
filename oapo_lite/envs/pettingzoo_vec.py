"""Any PettingZoo ``ParallelEnv`` behind the ``VecEnv`` interface (``envs.vec``).

The generic path: ``n_envs`` copies stepped one after another (environments we do not own
cannot be vectorised for them). Agents come in ``possible_agents`` order; the team reward
of a step is the mean of the agents' rewards; observations of agents whose spaces are
smaller are zero-padded, and so are discrete action sets (padded actions are unavailable).
Agents that have left ``env.agents`` before the episode ends are marked inactive
(``VecStep.active``): they get no action, and training ignores their samples.
"""
from __future__ import annotations

import copy
import math
from typing import Callable

import numpy as np
from gymnasium import spaces

from .vec import VecStep, check_copies


def _flat_obs(obs) -> tuple[np.ndarray, np.ndarray | None]:
    """(flat observation, action mask or None) of one agent's raw observation."""
    mask = None
    if isinstance(obs, dict) and "observation" in obs:
        mask = obs.get("action_mask")
        obs = obs["observation"]
    return np.asarray(obs, dtype=np.float32).ravel(), mask


def _obs_size(space: spaces.Space) -> int:
    if isinstance(space, spaces.Dict) and "observation" in space.spaces:
        space = space["observation"]
    return int(np.prod(space.shape))


class PettingZooVec:
    """``n_envs`` copies of ``env_fn()`` with auto-reset, presenting ``VecMaze``'s interface.

    ``reset()`` seeds copy k with ``seed + k`` (so every evaluation that resets starts from
    the same episodes); auto-resets after an episode continue the copy's own randomness.
    The global state is ``env.state()`` when the environment implements it, otherwise the
    concatenated observations. Action masks come
    from an ``action_mask`` key of a dict observation or of the info dict; Box action spaces
    give continuous actions (``continuous = True``), clipped to their bounds when stepping.
    ``max_steps`` (optional) truncates episodes that the environment itself lets run on.
    ``episode_success`` is read from an ``episode_success`` info entry (NaN without one).
    """

    def __init__(self, env_fn: Callable[[], object], n_envs: int, seed: int = 0, max_steps: int | None = None):
        self.n_envs, self.max_steps = check_copies(n_envs, max_steps, own_limit=True)
        self.envs = [env_fn() for _ in range(self.n_envs)]
        self.seed = int(seed)
        first = self.envs[0]
        self.agents = tuple(first.possible_agents)
        # every seat its own type unless the env says otherwise (``agent_types``: one name per seat)
        self.agent_types = tuple(getattr(first, "agent_types", self.agents))
        if len(self.agent_types) != len(self.agents):
            raise ValueError(f"the env's agent_types {list(self.agent_types)} must name one type per agent "
                             f"of {list(self.agents)}")
        self.n_agents = len(self.agents)
        self.time_in_state, self.optimum = False, math.nan  # no clock in the state; no oracle
        self.spaces = tuple((first.observation_space(a), first.action_space(a)) for a in self.agents)
        acts = [act for _, act in self.spaces]
        kinds = {type(a) for a in acts}
        if kinds == {spaces.Discrete}:
            self.continuous = False
            self.n_actions = max(int(a.n) for a in acts)
        elif kinds == {spaces.Box} and len({a.shape for a in acts}) == 1:
            self.continuous = True
            self.n_actions = int(np.prod(acts[0].shape))
        else:
            raise ValueError(
                "PettingZooVec needs all-Discrete action spaces, or Box spaces of one shape; got "
                + ", ".join(f"{a}: {s}" for a, s in zip(self.agents, acts))
            )
        self.obs_dim = max(_obs_size(o) for o, _ in self.spaces)
        state = self._try_state(first)
        self._has_state = state is not None
        # an env may implement state() without declaring state_space (MaMuJoCo does)
        self.state_dim = (int(np.prod(getattr(first, "state_space", state).shape)) if self._has_state
                          else sum(_obs_size(o) for o, _ in self.spaces))
        self._t = np.zeros(self.n_envs, dtype=np.int64)
        self._returns = np.zeros(self.n_envs, dtype=np.float64)

    @staticmethod
    def _try_state(env) -> np.ndarray | None:
        try:
            return np.asarray(env.state(), dtype=np.float32).ravel()
        except (NotImplementedError, AttributeError):
            return None

    def _view(self, env, obs: dict, infos: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(obs (n, obs_dim), avail (n, A), state, active (n,)) of one copy; agents without an
        observation read as zeros, and agents no longer in ``env.agents`` are inactive."""
        o = np.zeros((self.n_agents, self.obs_dim), dtype=np.float32)
        avail = np.ones((self.n_agents, self.n_actions), dtype=bool)
        for k, agent in enumerate(self.agents):
            if not self.continuous:
                avail[k, self.spaces[k][1].n:] = False
            if agent not in obs:
                continue
            flat, mask = _flat_obs(obs[agent])
            o[k, : flat.size] = flat  # the rest stays zero: padding up to the largest space
            mask = mask if mask is not None else infos.get(agent, {}).get("action_mask")
            if mask is not None and not self.continuous:
                avail[k, : len(mask)] = np.asarray(mask, dtype=bool)
        state = self._try_state(env) if self._has_state else self._concat_obs(obs)
        return o, avail, state, np.array([a in env.agents for a in self.agents])

    def _concat_obs(self, obs: dict) -> np.ndarray:
        """The global state of an environment without ``state()``: every agent's raw observation."""
        return np.concatenate([_flat_obs(obs[a])[0] if a in obs else np.zeros(_obs_size(s), np.float32)
                               for a, (s, _) in zip(self.agents, self.spaces)])

    def _reset_copy(self, k: int, seed: int | None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        obs, infos = self.envs[k].reset(seed=seed)
        self._t[k], self._returns[k] = 0, 0.0
        return self._view(self.envs[k], obs, infos)

    def reset(self) -> VecStep:
        views = [self._reset_copy(k, self.seed + k) for k in range(self.n_envs)]
        obs, avail, state, active = (np.stack(v) for v in zip(*views))
        return VecStep.at_reset(obs, state, avail, active)

    def _env_action(self, k: int, a):
        space = self.spaces[k][1]
        return np.clip(a, space.low, space.high).astype(space.dtype) if self.continuous else int(a)

    def step(self, actions) -> VecStep:
        """``actions`` (N, n) ints, or (N, n, D) floats for Box spaces."""
        N = self.n_envs
        out = {key: [] for key in ("obs", "avail", "state", "active", "final_obs", "final_state")}
        reward = np.zeros(N, np.float32)
        terminated, truncated = np.zeros(N, bool), np.zeros(N, bool)
        ep_return, ep_success = np.full(N, np.nan, np.float32), np.full(N, np.nan, np.float32)
        for e, env in enumerate(self.envs):
            live = list(env.agents)
            obs, rew, term, trunc, infos = env.step(
                {a: self._env_action(k, actions[e][k]) for k, a in enumerate(self.agents) if a in live})
            team = sum(float(rew[a]) for a in live) / len(live) if live else 0.0
            reward[e] = team
            self._t[e] += 1
            self._returns[e] += team
            terminated[e] = bool(live) and all(term.get(a, False) for a in live)
            truncated[e] = not terminated[e] and (
                not env.agents or all(term.get(a, False) or trunc.get(a, False) for a in live)
                or (self.max_steps is not None and self._t[e] >= self.max_steps))
            final = self._view(env, obs, infos)
            if terminated[e] or truncated[e]:
                ep_return[e] = self._returns[e]
                ep_success[e] = next((i["episode_success"] for i in infos.values() if "episode_success" in i), np.nan)
                now = self._reset_copy(e, None)
            else:
                now = final
            for key, value in zip(("obs", "avail", "state", "active"), now):
                out[key].append(value)
            out["final_obs"].append(final[0])
            out["final_state"].append(final[2])
        o = {key: np.stack(v) for key, v in out.items()}
        return VecStep(obs=o["obs"], state=o["state"], avail=o["avail"], reward=reward, terminated=terminated,
                       truncated=truncated, final_obs=o["final_obs"], final_state=o["final_state"],
                       episode_return=ep_return, episode_success=ep_success, active=o["active"])

    def get_state(self) -> dict:
        """Deep copies of the environment copies and the episode counters (for checkpoints)."""
        return copy.deepcopy({"envs": self.envs, "t": self._t, "returns": self._returns})

    def set_state(self, d: dict) -> None:
        d = copy.deepcopy(d)
        self.envs, self._t, self._returns = d["envs"], d["t"], d["returns"]
