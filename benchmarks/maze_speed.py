"""Agent-steps per second of ``VecMaze.step`` with random actions (agent-steps = env steps * n_agents).

Run: ``.venv/bin/python benchmarks/maze_speed.py``
"""
import time

import numpy as np

from oapo_lite.envs import MAPS, make_vec


def agent_steps_per_second(name: str, n_envs: int, seconds: float = 1.0) -> float:
    vec = make_vec(name, n_envs)
    vec.reset()
    rng = np.random.default_rng(0)
    # pre-drawn actions keep the random generator out of the timing
    actions = rng.integers(0, vec.n_actions, size=(256, n_envs, vec.n_agents))
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        for a in actions:
            vec.step(a)
            steps += 1
    return steps * n_envs * vec.n_agents / (time.perf_counter() - start)


def main() -> None:
    print(f"{'map':<16}{'n_envs':>8}{'agent-steps/s':>16}")
    for name in sorted(MAPS):
        for n_envs in (1, 64, 1024):
            print(f"{name:<16}{n_envs:>8}{agent_steps_per_second(name, n_envs):>16,.0f}")


if __name__ == "__main__":
    main()
