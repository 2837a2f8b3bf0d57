"""The maze game, vectorised: N copies of one maze stepped at once with numpy.

The rules are ``maps``' (the move rule and the reward): every seat starts on its start cell and
moves through ``maze.next_cell``; an episode terminates when every agent is on the star and is
truncated after ``max_steps`` steps. Ended copies reset at once (auto-reset); nothing is random.
"""
from __future__ import annotations

import functools

import numpy as np

from .maps import ACTIONS, N_ACTIONS, STEP_COST, Maze, load_maze
from .oracle import optimal_return
from .vec import VecStep, check_copies


def as_maze(maze: Maze | str) -> Maze:
    """A ``Maze`` as given, or one loaded from a built-in name or a map text."""
    return maze if isinstance(maze, Maze) else load_maze(maze)


class VecMaze:
    """``n_envs`` copies of ``maze`` with auto-reset; see the module docstring for the rules.

    Observation of a seat: ``maze.obs_table[cell]`` (no agent id). Global state: one-hot
    cell of every seat, seat after seat, then the elapsed fraction ``t / max_steps``.

    ``step`` writes into buffers allocated once (fresh megabyte-sized arrays every step make
    glibc map and unmap pages each time, several times slower at 1,024 copies). With
    ``copy=True`` (as gymnasium's vector envs) it returns copies; with ``copy=False`` the
    arrays it returns are those buffers, overwritten by the next ``step``, and ``final_obs`` /
    ``final_state`` are ``obs`` / ``state`` themselves when no copy ended: for a caller that
    copies what it keeps, like the training loop.
    """

    def __init__(self, maze: Maze, n_envs: int, max_steps: int = 50, copy: bool = True):
        if not isinstance(maze, Maze):
            raise TypeError(f"VecMaze needs a Maze, got {type(maze).__name__}; use make_vec for a map name or text")
        self.maze = maze
        self.n_envs, self.max_steps = check_copies(n_envs, max_steps)
        self.agents = self.agent_types = self.maze.agents  # a maze names its seats by their type
        self.n_agents = self.maze.n_agents
        self.n_actions = N_ACTIONS
        self.continuous = False
        # the state holds t / max_steps, so the time limit is part of the game and its end terminal
        self.time_in_state = True
        self.obs_dim = self.maze.obs_table.shape[1]
        self.state_dim = self.n_agents * self.maze.n_cells + 1
        self._seat = np.arange(self.n_agents)
        self._offsets = self._seat * self.maze.n_cells  # of each seat's one-hot block in the state
        self._starts = np.array(self.maze.starts)
        self._start_obs = self.maze.obs_table[self._starts]
        self._start_state = self._state(self._starts[None], np.zeros(1, dtype=np.int64))[0]
        self.copy = bool(copy)
        N = self.n_envs
        self._obs, self._final_obs = (np.empty((N, self.n_agents, self.obs_dim), np.float32) for _ in range(2))
        self._state_buf, self._final_state = np.empty((N, self.state_dim), np.float32), np.zeros((N, self.state_dim), np.float32)
        self._avail_buf, self._active_buf = self._avail(), self._active()
        self._hot = np.zeros(0, np.int64)
        self._ones = np.ones(self.n_agents, np.uint8)  # flat positions of the ones in _final_state
        self._row_offsets = np.arange(N)[:, None] * self.state_dim + self._offsets
        # next_cell[seat, cell, action] flattened: one np.take instead of a 3-array fancy index
        self._next_flat, self._seat_base = self.maze.next_cell.ravel(), self._seat * self.maze.n_cells * N_ACTIONS
        self._reset_all()

    @functools.cached_property
    def optimum(self) -> float:
        """The best team return (the search oracle's), which evaluations are measured against."""
        return optimal_return(self.maze)

    def _reset_all(self) -> None:
        self.cells = np.tile(self._starts, (self.n_envs, 1))
        self.t = np.zeros(self.n_envs, dtype=np.int64)
        # float64 so long runs of small step costs add up without drift
        self.returns = np.zeros(self.n_envs, dtype=np.float64)

    def _state(self, cells: np.ndarray, t: np.ndarray) -> np.ndarray:
        state = np.zeros((len(cells), self.state_dim), dtype=np.float32)
        state[np.arange(len(cells))[:, None], self._offsets + cells] = 1.0
        state[:, -1] = t / self.max_steps
        return state

    def _count(self, mask: np.ndarray) -> np.ndarray:
        """Seats per copy where ``mask`` (N, n_agents) holds, as a matrix product: numpy's
        reductions along a length-2 or -3 axis are several times slower."""
        return mask.view(np.uint8) @ self._ones

    def _write_final_state(self) -> np.ndarray:
        """``_state(cells, t)`` into its buffer, clearing only the previous step's ones."""
        flat = self._final_state.reshape(-1)
        flat[self._hot] = 0.0
        self._hot = (self._row_offsets + self.cells).ravel()
        flat[self._hot] = 1.0
        self._final_state[:, -1] = self.t / self.max_steps
        return self._final_state

    def reset(self) -> VecStep:
        """Put every copy on its start cells at t = 0."""
        self._reset_all()
        obs = np.broadcast_to(self._start_obs, (self.n_envs, *self._start_obs.shape)).copy()
        state = np.broadcast_to(self._start_state, (self.n_envs, self.state_dim)).copy()
        return VecStep.at_reset(obs, state, self._avail(), self._active())

    def _avail(self) -> np.ndarray:
        return np.ones((self.n_envs, self.n_agents, N_ACTIONS), dtype=bool)

    def _active(self) -> np.ndarray:
        return np.ones((self.n_envs, self.n_agents), dtype=bool)

    def _check_actions(self, actions) -> np.ndarray:
        a = np.asarray(actions)
        if a.shape != (self.n_envs, self.n_agents):
            raise ValueError(f"actions must have shape (n_envs, n_agents) = {(self.n_envs, self.n_agents)}, got {a.shape}")
        if a.dtype.kind not in "iu":
            raise TypeError(f"actions must be integers, got dtype {a.dtype}")
        if a.min() < 0 or a.max() >= N_ACTIONS:
            bad = (a < 0) | (a >= N_ACTIONS)
            raise ValueError(f"actions must lie in 0..{N_ACTIONS - 1} {ACTIONS}, got {np.unique(a[bad]).tolist()}")
        return a

    def step(self, actions) -> VecStep:
        """Move every seat of every copy by ``actions[env, seat]``, then auto-reset ended copies."""
        a = self._check_actions(actions)
        star = self.maze.star
        active = self.cells != star
        self.cells = np.take(self._next_flat, self._seat_base + self.cells * N_ACTIONS + a)
        on_star = self.cells == star
        reward = (self._count(active & on_star) - STEP_COST * self._count(active)) / self.n_agents
        self.t += 1
        self.returns += reward
        terminated = self._count(on_star) == self.n_agents
        truncated = (self.t >= self.max_steps) & ~terminated
        done = terminated | truncated

        # mode="clip" (the cells are valid): with the default "raise" numpy buffers the output
        final_obs = np.take(self.maze.obs_table, self.cells, axis=0, out=self._final_obs, mode="clip")
        final_state = self._write_final_state()
        episode_return = np.where(done, self.returns, np.nan).astype(np.float32)
        episode_success = np.where(done, terminated, np.nan).astype(np.float32)

        obs, state = final_obs, final_state
        if done.any():
            self.cells[done] = self._starts
            self.t[done] = 0
            self.returns[done] = 0.0
            obs, state = self._obs, self._state_buf
            np.copyto(obs, final_obs)
            np.copyto(state, final_state)
            obs[done] = self._start_obs
            state[done] = self._start_state
        avail, acting = self._avail_buf, self._active_buf
        if self.copy:
            obs, state, final_obs, final_state, avail, acting = (
                x.copy() for x in (obs, state, final_obs, final_state, avail, acting))
        return VecStep(obs=obs, state=state, avail=avail, reward=reward.astype(np.float32), terminated=terminated,
                       truncated=truncated, final_obs=final_obs, final_state=final_state,
                       episode_return=episode_return, episode_success=episode_success, active=acting)

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


def make_vec(name_or_text: str | Maze, n_envs: int, max_steps: int = 50, copy: bool = True) -> VecMaze:
    """A ``VecMaze`` of a built-in map name, a map text or a ``Maze``."""
    return VecMaze(as_maze(name_or_text), n_envs, max_steps, copy)
