"""GRF speed: the bare engine, the vectorised env (worker processes) and the training loop.

    .venv/bin/python benchmarks/grf_speed.py [scenario] [seconds]

Prints env steps/s (joint transitions) of: one engine stepped in this process with random
actions; ``GRFVec`` with 8 copies in 1 and in 2 worker processes; a short OAPPO run of the
cpu budget's shape (8 copies x 200 steps per iteration), env steps over its wall time and
the share of that time spent in env stepping, policy forwards and learning.
"""
import sys
import tempfile
import time

import numpy as np

from oapo_lite.envs import grf
from oapo_lite.config import TrainConfig
from oapo_lite.train import train


def bare(name: str, seconds: float) -> float:
    env = grf._make_engine(name, 0)
    rng = np.random.default_rng(0)
    env.reset()
    n, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        _, _, done, _ = env.step(rng.integers(0, grf.N_ACTIONS, grf.SCENARIOS[name]).tolist())
        n += 1
        if done:
            env.reset()
    return n / (time.perf_counter() - start)


def vec(name: str, seconds: float, workers: int, n_envs: int = 8) -> float:
    env = grf.GRFVec(name, n_envs, seed=0, max_steps=400, workers=workers)
    rng = np.random.default_rng(0)
    env.reset()
    n, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        env.step(rng.integers(0, grf.N_ACTIONS, (n_envs, env.n_agents)))
        n += n_envs
    rate = n / (time.perf_counter() - start)
    env.close()
    return rate


def loop(name: str, iterations: int = 3) -> tuple[float, dict]:
    cfg = TrainConfig(algo="oappo", env=f"grf:{name}", n_envs=8, rollout_len=200, steps=1600 * iterations,
                      max_steps=400, hidden=(64, 64), ppo_epochs=15, n_minibatch=2, eval_every=1000,
                      eval_episodes=2)
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        timing = {}
        train(cfg, tmp, progress=False, timing=timing)
        wall = time.perf_counter() - start
    return cfg.steps / (wall - timing["eval"]), {k: v / (wall - timing["eval"]) for k, v in timing.items() if k != "eval"}


if __name__ == "__main__":
    name = sys.argv[1] if len(sys.argv) > 1 else "academy_3_vs_1_with_keeper"
    seconds = float(sys.argv[2]) if len(sys.argv) > 2 else 20.0
    print(f"{name}:")
    print(f"  bare engine, 1 process:        {bare(name, seconds):7.0f} env steps/s")
    for w in (1, 2):
        print(f"  GRFVec, 8 copies, {w} worker(s): {vec(name, seconds, w):7.0f} env steps/s")
    rate, share = loop(name)
    print(f"  training loop (OAPPO, 8 x 200): {rate:7.0f} env steps/s; time share "
          + ", ".join(f"{k} {v:.0%}" for k, v in share.items()))
