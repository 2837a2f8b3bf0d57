"""The maze as a PettingZoo ``ParallelEnv``: a thin dict-shaped view of one ``VecMaze`` copy."""
from __future__ import annotations

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from .core import VecMaze, as_maze
from .vec import VecStep
from .maps import Maze


class MazeParallelEnv(ParallelEnv):
    """One maze episode at a time; agents are named ``f"{type}_{seat}"`` and share the team reward.

    All agents stay in ``agents`` until the episode ends, then ``agents`` becomes ``[]``.
    ``render_mode="rgb_array"`` returns a picture of the map with each agent's path so far.
    """

    metadata = {"name": "oapo_maze_v0", "render_modes": ["rgb_array"], "is_parallelizable": True}

    def __init__(self, maze_name_or_maze: Maze | str, max_steps: int = 50, render_mode: str | None = None):
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.render_mode = render_mode
        self._vec = VecMaze(as_maze(maze_name_or_maze), n_envs=1, max_steps=max_steps)
        self.maze = self._vec.maze
        self.possible_agents = [f"{agent}_{k}" for k, agent in enumerate(self.maze.agents)]
        self.agents: list[str] = []
        obs_space = spaces.Box(0.0, 1.0, (self._vec.obs_dim,), np.float32)
        self.observation_spaces = {a: obs_space for a in self.possible_agents}
        self.action_spaces = {a: spaces.Discrete(self._vec.n_actions) for a in self.possible_agents}
        self.state_space = spaces.Box(0.0, 1.0, (self._vec.state_dim,), np.float32)
        self._state = np.zeros(self._vec.state_dim, dtype=np.float32)
        self._path: list[np.ndarray] = []

    def observation_space(self, agent: str) -> spaces.Box:
        return self.observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Discrete:
        return self.action_spaces[agent]

    def _per_agent(self, obs: np.ndarray) -> dict[str, np.ndarray]:
        return dict(zip(self.possible_agents, obs[0]))

    def reset(self, seed: int | None = None, options: dict | None = None):
        """Start an episode; the maze has no randomness, so ``seed`` only seeds the action spaces."""
        if seed is not None:
            for k, agent in enumerate(self.possible_agents):
                self.action_spaces[agent].seed(seed + k)
        out = self._vec.reset()
        self.agents = list(self.possible_agents)
        self._state = out.state[0]
        self._path = [self._vec.cells[0].copy()]
        return self._per_agent(out.obs), {a: {} for a in self.agents}

    def step(self, actions: dict[str, int]):
        if not self.agents:
            raise RuntimeError("the episode is over (agents is empty); call reset() first")
        if set(actions) != set(self.agents):
            raise ValueError(f"step needs one action per live agent {self.agents}, got actions for {sorted(actions)}")
        joint = np.array([[int(actions[a]) for a in self.possible_agents]])
        out: VecStep = self._vec.step(joint)
        self._state = out.final_state[0]
        # the copy auto-resets inside VecMaze; this view shows the episode's last positions
        final_cells = np.argmax(out.final_state[0, :-1].reshape(self.maze.n_agents, -1), axis=1)
        self._path.append(final_cells)
        reward = float(out.reward[0])
        terminated, truncated = bool(out.terminated[0]), bool(out.truncated[0])
        done = terminated or truncated
        info = {"episode_return": float(out.episode_return[0]), "episode_success": float(out.episode_success[0])} if done else {}
        agents = self.agents
        self.agents = [] if done else agents
        return (self._per_agent(out.final_obs), {a: reward for a in agents}, {a: terminated for a in agents},
                {a: truncated for a in agents}, {a: dict(info) for a in agents})

    def state(self) -> np.ndarray:
        return self._state.copy()

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            return None
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        from .render import draw_maze

        fig = Figure(figsize=(6.5, 4.5), layout="constrained")
        draw_maze(self.maze, routes=np.stack(self._path, 1).tolist(), ax=fig.add_subplot())
        canvas = FigureCanvasAgg(fig)
        canvas.draw()
        return np.asarray(canvas.buffer_rgba())[..., :3].copy()
