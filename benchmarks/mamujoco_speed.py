"""Env steps per second on Multi-agent MuJoCo: the bare engine, the vector env, the training loop.

    .venv/bin/python benchmarks/mamujoco_speed.py [--envs HalfCheetah-2x3 Ant-2x4] [--steps 20000]
        [--algos oappo happo mappo] [--iterations 40]

Prints wall-clock and CPU-time rates (on a shared machine the CPU-time rate is the one that
carries over to an idle core). "bare": one ParallelEnv stepped with random actions, resets
included; "vector": ``make_vec`` (copies stepped one after another, actions clipped, global
state read every step); "loop": ``train`` with the figure's cpu run of each algorithm, learning
and evaluation included: ``--iterations`` 40 evaluate 3 times, as often as the cpu run does
(every 20 iterations) plus the evaluation before the first iteration, which a 500-iteration run
spreads thinner. Its share of the bare engine is of CPU rates.
"""
from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np

from oapo_lite.envs import mamujoco, registry
from oapo_lite.neural.train import train
from oapo_lite.study.catalogue.figures import get_figure
from oapo_lite.study.catalogue.figures.mujoco import FIGA_ALGOS

from loops import cut_short, warm_up


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


def loop(name: str, algo: str, iterations: int) -> tuple[int, tuple[float, float], dict]:
    """``iterations`` iterations of the figure's cpu run of ``algo`` (seed 0) on ``name``,
    evaluated as that run is, before the first iteration and every ``eval_every``-th: its env
    steps, (wall, CPU) seconds and ``timing``."""
    cfg = cut_short("figA_mamujoco", "cpu", algo, f"mamujoco:{name}", iterations)
    timing = {}
    with tempfile.TemporaryDirectory() as tmp:
        t = timed(lambda: train(cfg, tmp, progress=False, timing=timing))
    return cfg.steps, t, timing


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--envs", nargs="+", default=["HalfCheetah-2x3", "Ant-2x4"])
    parser.add_argument("--steps", type=int, default=20_000, help="env steps of the bare and vector measurements")
    parser.add_argument("--algos", nargs="+", default=["oappo", "happo", "mappo"], choices=FIGA_ALGOS[:3])
    parser.add_argument("--iterations", type=int, default=40, help="iterations of each loop measurement")
    args = parser.parse_args()
    n_envs = get_figure("figA_mamujoco").budget("cpu").config["n_envs"]
    warm_up()
    for name in args.envs:
        print(f"{name}")
        engine = bare(name, args.steps)
        print(f"  bare engine           {rate(args.steps, engine)}")
        print(f"  vector env ({n_envs} copies) {rate(args.steps, vector(name, args.steps, n_envs))}")
        for algo in args.algos:
            steps, t, timing = loop(name, algo, args.iterations)
            print(f"  loop {algo:<7}          {rate(steps, t)}, {engine[1] / args.steps * steps / t[1]:.0%} of the "
                  "bare engine's CPU rate; wall seconds: " + ", ".join(f"{k} {v:.1f}" for k, v in timing.items()))


if __name__ == "__main__":
    main()
