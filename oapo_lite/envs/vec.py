"""What every engine gives the training loop: a vector of ``n_envs`` copies of one game, with
auto-reset (``VecEnv``), the record ``VecStep`` that its ``reset`` and ``step`` return, and the
checks every engine's constructor shares (``check_copies``). The arrays of a step may be
overwritten by the next step: the loop copies what it keeps.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, Sequence, runtime_checkable

import numpy as np

# the numpy kinds a checkpoint may hold (``runstate.DATA``): booleans, integers, floats, complex
# numbers and fixed-width strings; not objects
DATA_KINDS = "biufcUS"


@dataclass
class VecStep:
    """What one ``reset`` or ``step`` of N copies returns (leading axis: copy)."""

    obs: np.ndarray  # (N, n_agents, obs_dim) float32, after auto-reset
    state: np.ndarray  # (N, state_dim) float32, after auto-reset
    avail: np.ndarray  # (N, n_agents, n_actions) bool: the legal actions of every seat
    reward: np.ndarray  # (N,) float32 team reward of this step
    terminated: np.ndarray  # (N,) bool: the episode ended (the game's own end)
    truncated: np.ndarray  # (N,) bool: the time limit ended it first
    final_obs: np.ndarray  # like obs, before auto-reset (equals obs where nothing ended)
    final_state: np.ndarray  # like state, before auto-reset: bootstrap on truncation from here
    episode_return: np.ndarray  # (N,) float32 undiscounted return of the episode that ended, NaN elsewhere
    episode_success: np.ndarray  # (N,) float32 1.0 / 0.0 for an ended episode (won, scored), NaN elsewhere
    active: np.ndarray  # (N, n_agents) bool: the seat acts on ``obs`` (a unit that died does not)

    @classmethod
    def at_reset(cls, obs: np.ndarray, state: np.ndarray, avail: np.ndarray, active: np.ndarray) -> "VecStep":
        """The step a reset returns: no reward, nothing ended."""
        n_envs = obs.shape[0]
        no, nan = np.zeros(n_envs, dtype=bool), np.full(n_envs, np.nan, dtype=np.float32)
        return cls(obs, state, avail, np.zeros(n_envs, dtype=np.float32), no, no.copy(), obs.copy(), state.copy(),
                   nan, nan.copy(), active)


@runtime_checkable
class VecEnv(Protocol):
    """An engine as the loop sees it."""

    n_envs: int
    agents: Sequence[str]  # seat names
    agent_types: Sequence[str]  # the agent type of each seat: seats of one type may share a network (TrainConfig.networks)
    n_agents: int
    n_actions: int  # per seat; the size of a Box action
    obs_dim: int
    state_dim: int  # the centralised critic's input
    continuous: bool  # Box actions: a Gaussian policy
    time_in_state: bool  # the state carries the time left: the time limit is part of the game, no bootstrap there

    @property
    def optimum(self) -> float:
        """The best team return where an oracle knows it; NaN otherwise."""

    def reset(self) -> VecStep: ...

    def step(self, actions: np.ndarray) -> VecStep:
        """``actions`` (n_envs, n_agents[, n_actions])."""

    def get_state(self) -> object:
        """Everything random or running, for checkpoints: data only (numbers, strings, bytes,
        containers, numpy arrays of ``DATA_KINDS``), no objects."""

    def set_state(self, state: object) -> None: ...


@runtime_checkable
class StepsSomeCopies(Protocol):
    """Optional: an env whose copies each cost an engine's CPU (GRF) may step some copies alone,
    with zeros and no ended episode in the others' rows; the evaluation then stops the copies
    whose first episode has ended."""

    def step_only(self, actions: np.ndarray, which: np.ndarray) -> VecStep:
        """A step of the copies where ``which`` (n_envs,) is true."""


@runtime_checkable
class HasWorkers(Protocol):
    """Optional: an env that steps its copies in other processes (GRF) names them, so that a
    run's CPU time counts theirs (``neural.cost``)."""

    def worker_pids(self) -> list[int]: ...


@runtime_checkable
class HasSeatSpaces(Protocol):
    """Optional: an env whose seats may differ in their spaces (a PettingZoo env) names them, so
    that reuse between two seats can be refused where they differ (``reuse.check_spaces``)."""

    spaces: tuple  # per seat: (observation space, action space)


def seat_spaces(env) -> tuple | None:
    """Every seat's (observation, action) spaces where they may differ; None where the engine
    builds every seat alike."""
    return env.spaces if isinstance(env, HasSeatSpaces) else None


def check_copies(n_envs, max_steps, own_limit: bool = False) -> tuple[int, int | None]:
    """``n_envs`` and ``max_steps`` as integers, or a ValueError naming the bad one: the checks
    every engine's constructor makes first. ``own_limit``: the engine may end episodes itself,
    so ``max_steps`` may be None (a PettingZoo env)."""
    for name, value in (("n_envs", n_envs), ("max_steps", max_steps)):
        if not (value is None and name == "max_steps" and own_limit) and not (
                isinstance(value, (int, float, np.integer)) and int(value) == value and value >= 1):
            raise ValueError(f"{name} must be a positive integer, got {value!r}")
    return int(n_envs), None if max_steps is None else int(max_steps)
