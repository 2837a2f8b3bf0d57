"""GRF speed per CPU-second: the bare engine against the whole training loop, at Fig. 6b's cpu
budget (its config of the scenario, for a few iterations).

    .venv/bin/python benchmarks/grf_speed.py [--algos oappo happo mappo] [--iterations 4]

A GRF run steps its engines in worker processes (``GRFVec``: one per core for the training
copies, as many again for the evaluation copies) while the main process runs the policies and
learns, so a run costs the CPU-seconds of all of them; "per process" means per CPU-second,
what one process busy all along gets done:

- bare: one engine stepped with random actions in this process, resets included: env steps
  per CPU-second;
- vector env: ``GRFVec`` with the config's copies and workers, random actions: env steps per
  CPU-second of this process and the workers together;
- loop: ``train`` for ``--iterations`` iterations (rollouts, learning, the evaluations at
  iteration 0 and every ``eval_every``, checkpoints): training env steps (evaluation steps do
  not count) per CPU-second of the main process and its workers together, without the run's
  start-up (spawning the workers, building the engines), which is measured apart and printed
  ("start"; here it includes every worker importing this script again, as multiprocessing's
  spawn does for a script, which a run under ``python -m oapo_lite`` does not);
- of bare: loop / bare; 100% would be a loop whose every CPU-second steps training copies at
  the bare engine's rate.

"main" and "workers" split the loop's CPU-seconds by process; env / policy / learn / eval are
shares of the main process's wall time in ``train`` (its ``timing``; during env and eval it
waits for the workers). Four iterations evaluate twice where the full run (20) evaluates 6
times, so evaluation weighs more here than in a whole run. Wall-clock rates depend on what else
runs on the machine; CPU-seconds much less. If a loop reaches less than 50% of the bare engine,
the top of a profile of its main process follows.
"""
from __future__ import annotations

import argparse
import gc
import os
import sys
import tempfile
import time

import numpy as np

from oapo_lite.envs import grf
from oapo_lite.neural.config import TrainConfig
from oapo_lite.neural.runstate import RunState
from oapo_lite.neural.train import train
from oapo_lite.study.catalogue import figures

from loops import cut_short, profile, warm_up


def config(scenario: str, algo: str, iterations: int) -> TrainConfig:
    """The cpu budget's settings for ``algo`` on ``scenario``, seed 0, cut to ``iterations``."""
    return cut_short("fig6b", "cpu", algo, f"grf:{scenario}", iterations)


def cpu_of(fn) -> tuple[float, float]:
    """CPU-seconds of ``fn()`` in (this process, its child processes). ``os.times`` counts a
    child once it is reaped; an env reaps its workers when it is closed or collected."""
    gc.collect()
    before = os.times()
    fn()
    gc.collect()
    after = os.times()
    return (after.user + after.system - before.user - before.system,
            after.children_user + after.children_system - before.children_user - before.children_system)


def bare(scenario: str, steps: int = 2000) -> float:
    env = grf._make_engine(scenario, 0)
    actions = np.random.default_rng(0).integers(0, grf.N_ACTIONS, (steps, grf.SCENARIOS[scenario])).tolist()
    env.reset()
    start = time.process_time()
    for a in actions:
        if env.step(a)[2]:
            env.reset()
    return steps / (time.process_time() - start)


def vector(cfg: TrainConfig, steps: int = 200) -> float:
    """Env steps per CPU-second of ``steps`` random steps of the run's training env (its
    building, measured apart, left out)."""
    make = (lambda: grf.GRFVec(cfg.env.removeprefix("grf:"), cfg.n_envs, seed=0, max_steps=cfg.max_steps))
    rng = np.random.default_rng(0)

    def run():
        env = make()
        env.reset()
        for _ in range(steps):
            env.step(rng.integers(0, grf.N_ACTIONS, (env.n_envs, env.n_agents)))
        env.close()

    return steps * cfg.n_envs / (sum(cpu_of(run)) - sum(cpu_of(lambda: make().close())))


def start_up(cfg: TrainConfig) -> tuple[float, float]:
    """CPU-seconds (main, workers) of building a run's state alone: workers, engines, nets."""
    def build():
        state = RunState.start(cfg)
        state.env.close()
        state.eval_env.close()

    return cpu_of(build)


def loop(cfg: TrainConfig) -> dict:
    """The run's training steps per CPU-second, its CPU-seconds (main, workers) after the
    start-up, and its ``timing`` as shares of its wall time."""
    timing = {}
    with tempfile.TemporaryDirectory() as out:
        wall = time.perf_counter()
        cpu = cpu_of(lambda: train(cfg, out, resume=False, progress=False, timing=timing))
        wall = time.perf_counter() - wall
    main, workers = (x - s for x, s in zip(cpu, start_up(cfg)))
    return {"steps_per_cpu_s": cfg.steps / (main + workers), "start": sum(cpu) - main - workers, "main": main,
            "workers": workers,
            **{k: v / wall for k, v in timing.items()}}


def speed(scenario: str, algos: list[str], iterations: int) -> None:
    base = config(scenario, algos[0], iterations)
    engine = bare(scenario)
    print(f"GRF {scenario}, cpu budget: {base.n_envs} copies x {base.rollout_len} steps per iteration, "
          f"{base.eval_episodes} evaluation episodes every {base.eval_every} iterations; {iterations} iterations")
    print(f"bare engine: {engine:6.0f} env steps per CPU-s")
    rate = vector(base)
    print(f"vector env:  {rate:6.0f} env steps per CPU-s ({rate / engine:.0%} of bare)")
    warm_up()
    print(f"{'algo':<7} {'steps/CPU-s':>11} {'of bare':>7} {'start':>6} {'main':>6} {'workers':>7} {'env':>6} "
          f"{'policy':>7} {'learn':>6} {'eval':>6}")
    slow = []
    for algo in algos:
        r = loop(config(scenario, algo, iterations))
        ratio = r["steps_per_cpu_s"] / engine
        print(f"{algo:<7} {r['steps_per_cpu_s']:11.0f} {ratio:7.1%} {r['start']:6.1f} {r['main']:6.1f} "
              f"{r['workers']:7.1f} {r['env']:6.1%} {r['policy']:7.1%} {r['learn']:6.1%} {r['eval']:6.1%}", flush=True)
        slow += [algo] if ratio < 0.5 else []
    for algo in slow:
        print(f"\n{algo}: the loop reaches less than 50% of the bare engine per CPU-second; profile of the main "
              f"process over {iterations} iterations:\n{profile(config(scenario, algo, iterations))}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    scenarios = [env.removeprefix("grf:") for env in figures.get_figure("fig6b").envs("cpu")]
    parser.add_argument("--scenario", default=scenarios[0], choices=scenarios, help="a scenario with runs at the cpu budget")
    parser.add_argument("--algos", nargs="+", default=["oappo", "happo", "mappo"], choices=figures.grf.FIG6B_ALGOS)
    parser.add_argument("--iterations", type=int, default=4)
    args = parser.parse_args()
    if args.iterations < 1:
        parser.error(f"--iterations must be at least 1, got {args.iterations}")
    if not grf.installed():
        sys.exit(grf.INSTALL_HINT)
    speed(args.scenario, args.algos, args.iterations)


if __name__ == "__main__":
    main()
