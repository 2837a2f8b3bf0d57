"""Env steps per second of the whole training loop on Black-Red, and where the time goes.

    .venv/bin/python benchmarks/train_speed.py [--steps 48000] [--algos oappo oatrpo happo mappo]

Wall time covers everything ``train`` does (rollouts, learning, evaluation, checkpoints);
the split is the share spent stepping the environment, in the policy forward during
rollouts, in learning (advantages, actor and critic updates) and in evaluation.
"""
from __future__ import annotations

import argparse
import tempfile
import time

from oapo_lite.config import TrainConfig
from oapo_lite.train import train


def measure(algo: str, steps: int) -> dict:
    cfg = TrainConfig(algo=algo, env="black_red", seed=0, steps=steps, eval_every=10)
    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        timing = {}
        train(cfg, out, resume=False, progress=False, timing=timing)
        wall = time.perf_counter() - start
    return {"algo": algo, "steps_per_s": cfg.n_iterations * cfg.n_envs * cfg.rollout_len / wall, "wall": wall,
            **{k: v / wall for k, v in timing.items()}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=48_000)
    parser.add_argument("--algos", nargs="+", default=["oappo", "oatrpo", "happo", "mappo"])
    args = parser.parse_args()
    measure("happo", 3_200)  # warm-up: first-call costs of torch are not the loop's
    print(f"{'algo':<8} {'steps/s':>8} {'wall s':>7} {'env':>6} {'policy':>7} {'learn':>6} {'eval':>6}")
    for algo in args.algos:
        r = measure(algo, args.steps)
        print(f"{r['algo']:<8} {r['steps_per_s']:8.0f} {r['wall']:7.1f} {r['env']:6.1%} {r['policy']:7.1%} "
              f"{r['learn']:6.1%} {r['eval']:6.1%}")


if __name__ == "__main__":
    main()
