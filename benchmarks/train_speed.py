"""Env steps per second of the whole training loop on Black-Red, and where the time goes; with
``--paper``, the CPU-seconds of one paper-budget OAPPO run on Black-Red (issue 23's measure).

    .venv/bin/python benchmarks/train_speed.py [--steps 48000] [--algos oappo oatrpo happo mappo]
    .venv/bin/python benchmarks/train_speed.py --paper [--repeat 3]

Wall time covers everything ``train`` does (rollouts, learning, evaluation, checkpoints);
the split is the share spent stepping the environment, in the policy forward during
rollouts, in learning (advantages, actor and critic updates) and in evaluation.

``--paper`` trains Fig. 3b's OAPPO seed 0 at the paper budget (240k steps, an evaluation of 32
episodes every 2 iterations) ``--repeat`` times and prints this process's CPU time per run
(``train`` uses one torch thread), which a machine shared with other jobs disturbs less than
wall time: the median and the range.
"""
from __future__ import annotations

import argparse
import statistics
import tempfile
import time

from oapo_lite.neural.config import TrainConfig
from oapo_lite.neural.train import train
from oapo_lite.study.catalogue.figures import runs_of

from loops import warm_up


def measure(algo: str, steps: int) -> dict:
    cfg = TrainConfig(algo=algo, env="black_red", seed=0, steps=steps, eval_every=10)
    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        timing = {}
        train(cfg, out, resume=False, progress=False, timing=timing)
        wall = time.perf_counter() - start
    return {"algo": algo, "steps_per_s": cfg.n_iterations * cfg.n_envs * cfg.rollout_len / wall, "wall": wall,
            **{k: v / wall for k, v in timing.items()}}


def paper_run_cpu_seconds() -> float:
    """CPU-seconds of Fig. 3b's paper-budget OAPPO run, seed 0."""
    cfg = next(r.cfg for r in runs_of("fig3b", "paper") if r.cfg.algo == "oappo" and r.cfg.seed == 0)
    with tempfile.TemporaryDirectory() as out:
        start = time.process_time()
        train(cfg, out, resume=False, progress=False)
        return time.process_time() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=48_000)
    parser.add_argument("--algos", nargs="+", default=["oappo", "oatrpo", "happo", "mappo"])
    parser.add_argument("--paper", action="store_true", help="CPU-seconds of a paper-budget OAPPO Black-Red run")
    parser.add_argument("--repeat", type=int, default=3, help="runs measured with --paper")
    args = parser.parse_args()
    warm_up()
    if args.paper:
        seconds = [paper_run_cpu_seconds() for _ in range(args.repeat)]
        print(f"paper-budget OAPPO Black-Red run (240k steps): {statistics.median(seconds):.2f} CPU-s "
              f"(median of {len(seconds)}; {min(seconds):.2f}-{max(seconds):.2f})")
        return
    print(f"{'algo':<8} {'steps/s':>8} {'wall s':>7} {'env':>6} {'policy':>7} {'learn':>6} {'eval':>6}")
    for algo in args.algos:
        r = measure(algo, args.steps)
        print(f"{r['algo']:<8} {r['steps_per_s']:8.0f} {r['wall']:7.1f} {r['env']:6.1%} {r['policy']:7.1%} "
              f"{r['learn']:6.1%} {r['eval']:6.1%}")


if __name__ == "__main__":
    main()
