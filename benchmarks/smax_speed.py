"""SMAX speed: the bare vectorised env against the whole training loop, at Fig. 4's batch size.

    .venv/bin/python benchmarks/smax_speed.py [--map 3m] [--algos oappo happo mappo oatrpo] [--iterations 6]
    .venv/bin/python benchmarks/smax_speed.py --grid   # CPU cost of every map of the cpu budget

Bare env: ``SmaxVec.step`` (one jitted vmapped call plus the host copy) driven by uniformly
random available actions, at Fig. 4's ``n_envs``. Loop: ``train`` with the ``cpu`` budget's
config of the map, for a few iterations (rollouts, learning, evaluation, checkpoints). Both
run after JAX has compiled (the compile time is printed separately). Wall-clock figures
depend on what else runs on the machine; CPU seconds (this process, all threads) do not, and
the ``--grid`` projection of the cpu budget uses them: the loop's share of the bare env is
printed both ways ("of env": wall-clock steps/s, then CPU seconds per step). The env / policy /
learn / eval columns split the loop's wall time. If the loop reaches less than half of the bare
env's throughput, the top of a profile of the loop is printed.
"""
from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np

from oapo_lite.envs.smax import SmaxVec
from oapo_lite.neural.config import TrainConfig
from oapo_lite.neural.train import train
from oapo_lite.study.catalogue import figures

from loops import cut_short, profile


def config(map_name: str, algo: str, iterations: int) -> TrainConfig:
    """The figure's settings for ``algo`` on ``map_name`` (every map has runs at ``paper``)."""
    return cut_short("fig4_smax", "paper", algo, f"smax:{map_name}", iterations)


def clocks() -> tuple[float, float]:
    return time.perf_counter(), time.process_time()


def bare_env(map_name: str, n_envs: int, max_steps: int, steps: int) -> dict:
    tic = time.perf_counter()
    env = SmaxVec(map_name, n_envs, seed=0, max_steps=max_steps)
    compile_s = time.perf_counter() - tic
    rng = np.random.default_rng(0)
    step = env.reset()
    wall, cpu = clocks()
    for _ in range(steps):
        step = env.step((rng.random(step.avail.shape) * step.avail).argmax(-1))
    wall, cpu = (b - a for a, b in zip((wall, cpu), clocks()))
    return {"compile_s": compile_s, "steps_per_s": steps * n_envs / wall, "cpu_per_kstep": 1000 * cpu / (steps * n_envs)}


def loop(cfg: TrainConfig) -> dict:
    with tempfile.TemporaryDirectory() as out:
        wall, cpu = clocks()
        timing = {}
        train(cfg, out, resume=False, progress=False, timing=timing)
        wall, cpu = (b - a for a, b in zip((wall, cpu), clocks()))
    return {"steps_per_s": cfg.steps / wall, "cpu_per_kstep": 1000 * cpu / cfg.steps,
            **{k: v / wall for k, v in timing.items()}}


def speed(map_name: str, algos: list[str], iterations: int) -> None:
    base = config(map_name, algos[0], iterations)
    env = bare_env(map_name, base.n_envs, base.max_steps, steps=4 * base.rollout_len)
    print(f"SMAX {map_name}, {base.n_envs} copies x {base.rollout_len} steps per iteration; "
          f"JAX compile (first env of the process): {env['compile_s']:.1f} s")
    print(f"bare env: {env['steps_per_s']:8.0f} env steps/s, {env['cpu_per_kstep']:.3f} CPU s per 1k steps")
    loop(config(map_name, "happo", 1))  # warm-up: torch's first-call costs are not the loop's
    print(f"{'algo':<8} {'steps/s':>8} {'of env':>7} {'CPU s/1k':>9} {'of env':>7} {'env':>6} {'policy':>7} "
          f"{'learn':>6} {'eval':>6}")
    slow = []
    for algo in algos:
        r = loop(config(map_name, algo, iterations))
        ratio, cpu_ratio = r["steps_per_s"] / env["steps_per_s"], env["cpu_per_kstep"] / r["cpu_per_kstep"]
        print(f"{algo:<8} {r['steps_per_s']:8.0f} {ratio:7.1%} {r['cpu_per_kstep']:9.3f} {cpu_ratio:7.1%} "
              f"{r['env']:6.1%} {r['policy']:7.1%} {r['learn']:6.1%} {r['eval']:6.1%}")
        slow += [algo] if ratio < 0.5 else []
    for algo in slow:
        print(f"\n{algo}: the loop reaches less than 50% of the bare env's throughput; profile of "
              f"{iterations} iterations:\n{profile(config(map_name, algo, iterations))}")


def project_grid(iterations: int) -> None:
    """Project the cpu budget's CPU hours from each map's measured CPU seconds per step (a
    short run evaluates twice, more often than a full one: the projection errs high)."""
    total = 0.0
    print(f"{'map':<24} {'algo':<7} {'CPU s/1k':>9} {'runs':>5} {'steps':>9} {'CPU h':>6}")
    fig = figures.get_figure("fig4_smax")
    for env in fig.envs("cpu"):
        map_name, b = env.removeprefix("smax:"), fig.budget("cpu", env)
        seeds, steps = len(b.seeds), b.steps
        base = config(map_name, "oappo", iterations)
        SmaxVec(map_name, base.n_envs, 0, base.max_steps)  # compile outside the measurement
        for algo in figures.smax.SMAX_ALGOS:
            cpu = loop(config(map_name, algo, iterations))["cpu_per_kstep"]
            hours = cpu * steps / 1000 * seeds / 3600
            total += hours
            print(f"{map_name:<24} {algo:<7} {cpu:9.3f} {seeds:5d} {steps:9,d} {hours:6.2f}", flush=True)
    print(f"cpu budget: {total:.2f} CPU hours (2 cores: {total / 2:.2f} h wall), plus one JAX compile per map and process")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--map", default="3m", choices=figures.smax.FIG4_MAPS)
    parser.add_argument("--algos", nargs="+", default=list(figures.smax.SMAX_ALGOS))
    parser.add_argument("--iterations", type=int, default=6)
    parser.add_argument("--grid", action="store_true", help="project the cpu budget's CPU hours instead")
    args = parser.parse_args()
    if args.grid:
        project_grid(max(2, args.iterations // 2))
    else:
        speed(args.map, args.algos, args.iterations)


if __name__ == "__main__":
    main()
