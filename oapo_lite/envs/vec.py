"""What every engine gives the training loop: a vector of ``n_envs`` copies of one game, with
auto-reset, and the record ``VecStep`` that its ``reset`` and ``step`` return.

A vector env has ``n_envs``, ``agents`` (seat names), ``agent_types`` (the kind of each seat:
seats of one kind may share a network, ``TrainConfig.networks``), ``n_agents``, ``n_actions`` (per seat;
the size of a Box action), ``obs_dim``, ``state_dim`` (the centralised critic's input),
``continuous`` (Box actions: a Gaussian policy), ``time_in_state`` (its state carries the time
left, so hitting the time limit is part of the game: no bootstrap there) and ``optimum`` (the
best team return, when an oracle knows it; NaN otherwise); ``reset()`` and ``step(actions)``
(actions ``(n_envs, n_agents[, n_actions])``) return a ``VecStep``; ``get_state()`` /
``set_state(state)`` save and restore everything random or running, for checkpoints. The
arrays of a step may be overwritten by the next step: the loop copies what it keeps. An env
whose copies each cost an engine's CPU may also offer ``step_only(actions, which)``: a step of
the copies where ``which`` (n_envs,) is true alone, zeros and no ended episode in the others'
rows; the evaluation then stops the copies whose first episode has ended.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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
