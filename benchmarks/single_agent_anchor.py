"""The single-agent anchor for the multi-agent MuJoCo runs: stable-baselines3's PPO at its
defaults, with VecNormalize, on the same robot (gymnasium's HalfCheetah-v5, the env under
MaMuJoCo's HalfCheetah 2x3; or ``--env Ant-v5``, under Ant 4x2) for the same env steps. Nothing of it enters the package: stable-baselines3 is
not a dependency, so install it beside the environment for this script alone::

    .venv/bin/pip install --target /tmp/sb3 --no-deps stable-baselines3
    PYTHONPATH=/tmp/sb3 .venv/bin/python benchmarks/single_agent_anchor.py --seeds 0 1 2

Every ``--eval-every`` env steps the policy is evaluated on ``--episodes`` episodes, stochastic
as the project's evaluations are, with the training run's observation statistics frozen. The
rows (seed, step, mean return) go to ``figures/data/anchor_<robot>_sb3.csv`` with the
settings, versions and git revision in a JSON beside it; a seed already there is not run
again. It prints each seed's final return (the mean over the last fifth of its evaluation
points) and their interquartile mean, the number App. A's HAPPO is held against.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from oapo_lite.neural.runstate import git_revision  # noqa: E402
from oapo_lite.store import atomic_write, write_frame  # noqa: E402
from oapo_lite.study.judge.statistics import bootstrap_interval, iqm  # noqa: E402

ROBOTS = ("HalfCheetah-v5", "Ant-v5")


def out_path(env: str) -> Path:
    """The anchor's rows for gymnasium env ``env``: figures/data/anchor_<robot>_sb3.csv."""
    return ROOT / "figures" / "data" / f"anchor_{env.split('-')[0].lower()}_sb3.csv"


def run_seed(env: str, seed: int, steps: int, eval_every: int, episodes: int) -> pd.DataFrame:
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.vec_env import VecNormalize

    train_env = VecNormalize(make_vec_env(env, n_envs=1, seed=seed))
    eval_env = VecNormalize(make_vec_env(env, n_envs=1, seed=seed + 10_000), training=False, norm_reward=False)
    rows = []

    def evaluate(step: int) -> None:
        eval_env.obs_rms = train_env.obs_rms  # the training statistics, frozen for the evaluation
        returns, _ = evaluate_policy(model, eval_env, n_eval_episodes=episodes, deterministic=False)
        rows.append({"seed": seed, "step": step, "eval_return": float(np.mean(returns))})
        print(f"seed {seed} step {step:,}: {rows[-1]['eval_return']:.0f}", flush=True)

    class Every(BaseCallback):
        def _on_step(self) -> bool:
            if self.num_timesteps % eval_every == 0:
                evaluate(self.num_timesteps)
            return True

    model = PPO("MlpPolicy", train_env, seed=seed, verbose=0, device="cpu")
    evaluate(0)
    model.learn(total_timesteps=steps, callback=Every())
    return pd.DataFrame(rows)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--env", default=ROBOTS[0], choices=ROBOTS)
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument("--steps", type=int, default=1_000_000)
    parser.add_argument("--eval-every", type=int, default=40_000)
    parser.add_argument("--episodes", type=int, default=10)
    args = parser.parse_args(argv)
    import stable_baselines3
    import torch

    out = out_path(args.env)
    done = pd.read_csv(out) if out.exists() else pd.DataFrame(columns=["seed", "step", "eval_return"])
    for seed in args.seeds:
        if seed in set(done["seed"]):
            continue
        done = pd.concat([done, run_seed(args.env, seed, args.steps, args.eval_every, args.episodes)], ignore_index=True)
        write_frame(done, out)
        record = json.dumps({"env": args.env, "algorithm": "stable-baselines3 PPO, MlpPolicy, defaults, VecNormalize",
                             "steps": args.steps, "eval_every": args.eval_every, "episodes": args.episodes,
                             "stable_baselines3": stable_baselines3.__version__, "torch": torch.__version__,
                             "git_rev": git_revision()}, indent=1)
        atomic_write(lambda tmp: Path(tmp).write_text(record), out.with_suffix(".json"))
    finals = {s: run["eval_return"].iloc[-max(1, round(0.2 * len(run))):].mean()
              for s, run in done.sort_values("step").groupby("seed")}
    print("final return per seed (mean of the last fifth of the evaluations):",
          {s: round(v) for s, v in finals.items()})
    print(f"IQM over {len(finals)} seeds: {bootstrap_interval(iqm, list(finals.values())).fmt('.0f')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
