"""Env steps per second on Multi-agent MuJoCo: the bare engine, the vector env, the training loop.

    .venv/bin/python benchmarks/mamujoco_speed.py [--envs HalfCheetah-2x3 Ant-2x4] [--steps 20000]

Prints wall-clock and CPU-time rates (on a shared machine the CPU-time rate is the one that
carries over to an idle core). "bare": one ParallelEnv stepped with random actions, resets
included; "vector": ``make_vec`` (copies stepped one after another, actions clipped, global
state read every step); "loop": ``train`` (OAPPO) with the figure's cpu batch shape, learning included.
"""
from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np

from oapo_lite.envs import mamujoco, registry
from oapo_lite.grid import get_figure
from oapo_lite.config import TrainConfig
from oapo_lite.train import train


def rate(n: int, t: tuple[float, float]) -> str:
    return f"{n / t[0]:7.0f} /s wall, {n / t[1]:7.0f} /s CPU"


def timed(fn) -> tuple[float, float]:
    wall, cpu = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - wall, time.process_time() - cpu


def bare(name: str, steps: int) -> None:
    env = mamujoco.env_fn(name, 1000)()
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    acts = [{a: rng.uniform(-1, 1, env.action_space(a).shape).astype(np.float32) for a in env.possible_agents}
            for _ in range(100)]

    def run():
        for t in range(steps):
            env.step(acts[t % 100])
            if not env.agents:
                env.reset()
    return timed(run)


def vector(name: str, steps: int, n_envs: int) -> tuple[float, float]:
    vec = registry.make_vec(f"mamujoco:{name}", n_envs, seed=0, max_steps=1000)
    vec.reset()
    a = np.random.default_rng(0).uniform(-1, 1, (n_envs, vec.n_agents, vec.n_actions)).astype(np.float32)
    return timed(lambda: [vec.step(a) for _ in range(steps // n_envs)])


def loop(name: str, steps: int) -> tuple[tuple[float, float], dict]:
    """The figure's cpu configuration, evaluated on one episode at the start and the end only
    (their time counts, their steps do not: a conservative rate)."""
    b = get_figure("figA_mamujoco").budget("cpu")
    cfg = TrainConfig(algo="oappo", env=f"mamujoco:{name}", steps=steps, eval_every=10_000, eval_episodes=1,
                      **{**b.config, "checkpoint_every": 10_000})
    timing = {}
    with tempfile.TemporaryDirectory() as tmp:
        t = timed(lambda: train(cfg, tmp, progress=False, timing=timing))
    return t, timing


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--envs", nargs="+", default=["HalfCheetah-2x3", "Ant-2x4"])
    parser.add_argument("--steps", type=int, default=20_000, help="env steps per measurement")
    args = parser.parse_args()
    n_envs = get_figure("figA_mamujoco").budget("cpu").config["n_envs"]
    for name in args.envs:
        print(f"{name}")
        print(f"  bare engine           {rate(args.steps, bare(name, args.steps))}")
        print(f"  vector env ({n_envs} copies) {rate(args.steps, vector(name, args.steps, n_envs))}")
        t, timing = loop(name, args.steps)
        print(f"  training loop         {rate(args.steps, t)}  (wall seconds: "
              + ", ".join(f"{k} {v:.1f}" for k, v in timing.items()) + ")")


if __name__ == "__main__":
    main()
