"""The maze game, vectorised: N copies of one maze stepped at once with numpy.

Rules: every seat starts on its start cell and moves through ``maze.next_cell``. The team
reward of a step is ``(1/n) * sum_k [1{k reaches the star now} - STEP_COST * 1{k was not on
the star before the step}]``; an agent on the star stays there and pays nothing. An episode
terminates when every agent is on the star and is truncated after ``max_steps`` steps. Ended
copies reset at once (auto-reset); nothing is random.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .maps import ACTIONS, N_ACTIONS, Maze, load_maze

STEP_COST = 0.01


@dataclass
class VecStep:
    """What one ``reset`` or ``step`` of N copies returns (leading axis: copy)."""

    obs: np.ndarray  # (N, n_agents, obs_dim) float32, after auto-reset
    state: np.ndarray  # (N, state_dim) float32, after auto-reset
    avail: np.ndarray  # (N, n_agents, N_ACTIONS) bool; every move is always legal
    reward: np.ndarray  # (N,) float32 team reward of this step
    terminated: np.ndarray  # (N,) bool: every agent reached the star
    truncated: np.ndarray  # (N,) bool: max_steps reached first
    final_obs: np.ndarray  # like obs, before auto-reset (equals obs where nothing ended)
    final_state: np.ndarray  # like state, before auto-reset: bootstrap on truncation from here
    episode_return: np.ndarray  # (N,) float32 undiscounted return of the episode that ended, NaN elsewhere
    episode_success: np.ndarray  # (N,) float32 1.0 / 0.0 for an ended episode, NaN elsewhere
    active: np.ndarray  # (N, n_agents) bool: the seat acts on ``obs`` (on the maze always)


def as_maze(maze: Maze | str) -> Maze:
    """A ``Maze`` as given, or one loaded from a built-in name or a map text."""
    return maze if isinstance(maze, Maze) else load_maze(maze)


class VecMaze:
    """``n_envs`` copies of ``maze`` with auto-reset; see the module docstring for the rules.

    Observation of a seat: ``maze.obs_table[cell]`` (no agent id). Global state: one-hot
    cell of every seat, seat after seat, then the elapsed fraction ``t / max_steps``.
    """

    def __init__(self, maze: Maze, n_envs: int, max_steps: int = 50):
        if not isinstance(maze, Maze):
            raise TypeError(f"VecMaze needs a Maze, got {type(maze).__name__}; use make_vec for a map name or text")
        if int(n_envs) != n_envs or n_envs < 1:
            raise ValueError(f"n_envs must be a positive integer, got {n_envs!r}")
        if int(max_steps) != max_steps or max_steps < 1:
            raise ValueError(f"max_steps must be a positive integer, got {max_steps!r}")
        self.maze = maze
        self.n_envs, self.max_steps = int(n_envs), int(max_steps)
        self.agents = self.maze.agents
        self.n_agents = self.maze.n_agents
        self.n_actions = N_ACTIONS
        self.obs_dim = self.maze.obs_table.shape[1]
        self.state_dim = self.n_agents * self.maze.n_cells + 1
        self._seat = np.arange(self.n_agents)
        self._starts = np.array(self.maze.starts)
        self._start_obs = self.maze.obs_table[self._starts]
        self._start_state = self._state(self._starts[None], np.zeros(1, dtype=np.int64))[0]
        self._reset_all()

    def _reset_all(self) -> None:
        self.cells = np.tile(self._starts, (self.n_envs, 1))
        self.t = np.zeros(self.n_envs, dtype=np.int64)
        # float64 so long runs of small step costs add up without drift
        self.returns = np.zeros(self.n_envs, dtype=np.float64)

    def _state(self, cells: np.ndarray, t: np.ndarray) -> np.ndarray:
        state = np.zeros((len(cells), self.state_dim), dtype=np.float32)
        state[np.arange(len(cells))[:, None], self._seat * self.maze.n_cells + cells] = 1.0
        state[:, -1] = t / self.max_steps
        return state

    def reset(self) -> VecStep:
        """Put every copy on its start cells at t = 0."""
        self._reset_all()
        obs = np.broadcast_to(self._start_obs, (self.n_envs, *self._start_obs.shape)).copy()
        state = np.broadcast_to(self._start_state, (self.n_envs, self.state_dim)).copy()
        no = np.zeros(self.n_envs, dtype=bool)
        nan = np.full(self.n_envs, np.nan, dtype=np.float32)
        return VecStep(obs, state, self._avail(), np.zeros(self.n_envs, dtype=np.float32), no, no.copy(),
                       obs.copy(), state.copy(), nan, nan.copy(), self._active())

    def _avail(self) -> np.ndarray:
        return np.ones((self.n_envs, self.n_agents, N_ACTIONS), dtype=bool)

    def _active(self) -> np.ndarray:
        return np.ones((self.n_envs, self.n_agents), dtype=bool)

    def _check_actions(self, actions) -> np.ndarray:
        a = np.asarray(actions)
        if a.shape != (self.n_envs, self.n_agents):
            raise ValueError(f"actions must have shape (n_envs, n_agents) = {(self.n_envs, self.n_agents)}, got {a.shape}")
        if not np.issubdtype(a.dtype, np.integer):
            raise TypeError(f"actions must be integers, got dtype {a.dtype}")
        bad = (a < 0) | (a >= N_ACTIONS)
        if bad.any():
            raise ValueError(f"actions must lie in 0..{N_ACTIONS - 1} {ACTIONS}, got {np.unique(a[bad]).tolist()}")
        return a

    def step(self, actions) -> VecStep:
        """Move every seat of every copy by ``actions[env, seat]``, then auto-reset ended copies."""
        a = self._check_actions(actions)
        star = self.maze.star
        active = self.cells != star
        self.cells = self.maze.next_cell[self._seat, self.cells, a]
        arrived = active & (self.cells == star)
        reward = (arrived.sum(1) - STEP_COST * active.sum(1)) / self.n_agents
        self.t += 1
        self.returns += reward
        terminated = (self.cells == star).all(1)
        truncated = (self.t >= self.max_steps) & ~terminated
        done = terminated | truncated

        final_obs = self.maze.obs_table[self.cells]
        final_state = self._state(self.cells, self.t)
        episode_return = np.where(done, self.returns, np.nan).astype(np.float32)
        episode_success = np.where(done, terminated, np.nan).astype(np.float32)

        self.cells[done] = self._starts
        self.t[done] = 0
        self.returns[done] = 0.0
        obs, state = final_obs.copy(), final_state.copy()
        obs[done] = self._start_obs
        state[done] = self._start_state
        return VecStep(obs, state, self._avail(), reward.astype(np.float32), terminated, truncated,
                       final_obs, final_state, episode_return, episode_success, self._active())

    def get_state(self) -> dict[str, np.ndarray]:
        """Everything the dynamics carry between steps, as copies (for checkpoints)."""
        return {"cells": self.cells.copy(), "t": self.t.copy(), "returns": self.returns.copy()}

    def set_state(self, d: dict[str, np.ndarray]) -> None:
        """Restore what ``get_state`` returned; the continuation is then bit-identical."""
        if set(d) != {"cells", "t", "returns"}:
            raise ValueError(f"state dict must have keys ['cells', 'returns', 't'], got {sorted(d)}")
        cells, t, returns = (np.array(d[k]) for k in ("cells", "t", "returns"))
        for key, value, shape in (("cells", cells, (self.n_envs, self.n_agents)),
                                  ("t", t, (self.n_envs,)), ("returns", returns, (self.n_envs,))):
            if value.shape != shape:
                raise ValueError(f"state[{key!r}] must have shape {shape}, got {value.shape}")
        if not np.issubdtype(cells.dtype, np.integer) or (cells < 0).any() or (cells >= self.maze.n_cells).any():
            raise ValueError(f"state['cells'] must hold integer cells in 0..{self.maze.n_cells - 1}")
        if not self.maze.passable[self._seat, cells].all():
            raise ValueError("state['cells'] puts a seat on a cell its agent type may not stand on")
        if (t < 0).any() or (t >= self.max_steps).any():
            raise ValueError(f"state['t'] must lie in 0..{self.max_steps - 1}, got {np.unique(t).tolist()}")
        self.cells, self.t, self.returns = cells.astype(np.int64), t.astype(np.int64), returns.astype(np.float64)


def make_vec(name_or_text: str | Maze, n_envs: int, max_steps: int = 50) -> VecMaze:
    """A ``VecMaze`` of a built-in map name, a map text or a ``Maze``."""
    return VecMaze(as_maze(name_or_text), n_envs, max_steps)
