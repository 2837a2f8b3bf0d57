"""Time of the exact engine on Black-Red (361 joint states, 25 joint actions) and of one tabular iteration.

Run: ``.venv/bin/python benchmarks/exact_speed.py``
"""
import time

import numpy as np

from oapo_lite.envs.maps import load_maze
from oapo_lite.tabular import exact as ex
from oapo_lite.tabular.algorithm1 import TabularConfig, run_tabular


def milliseconds(fn, repeats: int) -> float:
    """Median wall time of ``fn()`` in ms (the median shrugs off other jobs on a shared machine)."""
    fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return 1000 * float(np.median(times))


def main() -> None:
    maze = load_maze("black_red")
    game = ex.from_maze(maze)
    pis = ex.random_policies(game, np.random.default_rng(0))
    print(f"Black-Red: {game.n_states} joint states, {game.joint_actions.shape[0]} joint actions")
    print(f"{'build from_maze':<44}{milliseconds(lambda: ex.from_maze(maze), 5):>9.1f} ms")
    print(f"{'evaluate (V, Q, A, J)':<44}{milliseconds(lambda: ex.evaluate(game, pis), 50):>9.1f} ms")
    print(f"{'state_distribution':<44}{milliseconds(lambda: ex.state_distribution(game, pis), 50):>9.1f} ms")
    print(f"{'lemma1, identity map':<44}"
          f"{milliseconds(lambda: ex.lemma1(game, pis, pis, {(0, 1): 1.0}), 20):>9.1f} ms")
    for estimate in ("exact", "samples"):
        for algo in ("happo", "hatrpo", "oappo", "oatrpo", "mappo"):
            cfg = TabularConfig(algo=algo, iterations=10, estimate=estimate)
            per_iter = milliseconds(lambda: run_tabular(game, cfg), 3) / cfg.iterations
            print(f"{f'tabular {algo} ({estimate}), per iteration':<44}{per_iter:>9.1f} ms")


if __name__ == "__main__":
    main()
