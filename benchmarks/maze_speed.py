"""Agent-steps per second of ``VecMaze.step`` with random actions (agent-steps = env steps * n_agents).

Run: ``.venv/bin/python benchmarks/maze_speed.py``

``copy=False`` is how the training loop steps the mazes (the arrays of a step live in buffers
the next step overwrites); ``copy=True`` returns fresh arrays, as gymnasium's vector envs do.
Rates are per second of wall time and per second of this process's CPU time (on a shared
machine the second is the steadier one).
"""
import time

import numpy as np

from oapo_lite.envs import MAPS, make_vec


def agent_steps_per_second(name: str, n_envs: int, copy: bool, seconds: float = 1.0) -> tuple[float, float]:
    vec = make_vec(name, n_envs, copy=copy)
    vec.reset()
    rng = np.random.default_rng(0)
    # pre-drawn actions keep the random generator out of the timing
    actions = rng.integers(0, vec.n_actions, size=(256, n_envs, vec.n_agents))
    steps, start, cpu = 0, time.perf_counter(), time.process_time()
    while time.perf_counter() - start < seconds:
        for a in actions:
            vec.step(a)
            steps += 1
    agent_steps = steps * n_envs * vec.n_agents
    return agent_steps / (time.perf_counter() - start), agent_steps / (time.process_time() - cpu)


def main() -> None:
    print(f"{'map':<16}{'n_envs':>8}{'copy':>7}{'agent-steps/s':>16}{'per CPU s':>14}")
    for name in sorted(MAPS):
        for n_envs in (1, 64, 1024):
            for copy in (False, True):
                wall, cpu = agent_steps_per_second(name, n_envs, copy)
                print(f"{name:<16}{n_envs:>8}{str(copy):>7}{wall:>16,.0f}{cpu:>14,.0f}")


if __name__ == "__main__":
    main()
