"""The SMAX anchor: our MAPPO beside JaxMARL's MAPPO on the same scenarios and machine (issue 22).

JaxMARL's code is not vendored here (nothing of it goes into this repository); this file is the
recipe for running it side by side, and runs OUR side of the comparison itself.

Our side (this script)::

    .venv/bin/python benchmarks/smax_anchor.py --map 3m --seeds 0 1            # 300k steps
    .venv/bin/python benchmarks/smax_anchor.py --map 2s3z --seeds 0 1 2        # 500k steps
    .venv/bin/python benchmarks/smax_anchor.py --map 3m --settings defaults    # TrainConfig's (HARL's) defaults

trains MAPPO with ``figures.smax.SMAX_TUNED`` (Fig. 4's settings; or TrainConfig's defaults) at Fig. 4's batch shape
into a temporary folder and prints, per seed, the evaluation win rate (64 battles, stochastic
policy) at every evaluation and the CPU seconds per 1,000 env steps (this process, all threads,
JAX compile included).

JaxMARL's side (by hand; its 300k-step 3m run costs about 100 CPU-seconds here):

1. ``git clone https://github.com/FLAIROx/JaxMARL`` and check out a revision whose
   ``baselines/MAPPO/config/mappo_homogenous_rnn_smax.yaml`` reads (as at commit ea4733c7):
   LR 0.002, ANNEAL_LR True, NUM_STEPS 128, FC_DIM_SIZE 128, GRU_HIDDEN_DIM 128,
   UPDATE_EPOCHS 4, NUM_MINIBATCHES 4, GAMMA 0.99, GAE_LAMBDA 0.95, CLIP_EPS 0.2,
   SCALE_CLIP_EPS False, ENT_COEF 0.0, VF_COEF 0.5, MAX_GRAD_NORM 0.25, OBS_WITH_AGENT_ID True,
   ENV_NAME HeuristicEnemySMAX, ENV_KWARGS {see_enemy_actions: True, walls_cause_death: True,
   attack_mode: closest} (max_steps stays SMAX's default, 100).
2. Use this repository's environment (``jaxmarl==0.2.0``, its jax, flax and optax are in
   ``environment.txt``); do not ``pip install`` JaxMARL's requirements over it. JaxMARL's script
   also imports ``distrax``, ``hydra``, ``omegaconf`` and ``wandb``: install ``hydra-core`` (it
   brings ``omegaconf``), and in a local copy of ``baselines/MAPPO/mappo_rnn_smax.py`` (outside
   this repository) replace two things only:

   - ``distrax.Categorical(logits=...)``: a categorical with ``sample`` (``jax.random.categorical``),
     ``log_prob`` (``jax.nn.log_softmax`` gathered at the action) and ``entropy``; or install
     ``distrax`` if a version matching the installed jax exists;
   - the ``wandb`` calls: ``wandb.init`` removed, and the logging callback appends
     (env_step, win_rate, returns) to a CSV. Its win rate is the share of won episodes among the
     training episodes that ended in that update (``returned_won_episode`` where
     ``returned_episode``), the number to read at 295k-300k (3m) and 500k (2s3z) steps.

3. Run on the same 2 cores, one process at a time, with the settings of step 1 and
   ``NUM_ENVS=64 TOTAL_TIMESTEPS=3e5 MAP_NAME=3m`` (and ``TOTAL_TIMESTEPS=5e5 MAP_NAME=2s3z``),
   ``SEED`` 0, 1, ..., e.g. ``python mappo_rnn_smax.py NUM_ENVS=64 TOTAL_TIMESTEPS=3e5 MAP_NAME=3m
   SEED=0`` (hydra overrides), with ``XLA_FLAGS=--xla_force_host_platform_device_count=1`` and
   ``JAX_PLATFORMS=cpu``. Time it with ``/usr/bin/time -v`` (user + system seconds / env steps
   x 1,000 gives its CPU-s per 1,000 steps).

What it measured on 2 cores is ``figures/data/anchor_smax_jaxmarl.csv`` (win rate at the steps,
seeds, CPU-s per 1,000 env steps; the JSON beside it says how). The two win rates differ in
kind: JaxMARL's is over its training episodes, ours over 64 evaluation battles; both policies
act stochastically.
"""
from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time

from oapo_lite.neural.config import TrainConfig
from oapo_lite.neural.train import train
from oapo_lite.study.catalogue import figures

STEPS = {"3m": 300_000, "2s3z": 500_000}


def config(map_name: str, seed: int, settings: str = "tuned", algo: str = "mappo") -> TrainConfig:
    """MAPPO (or ``algo``) on ``map_name`` at Fig. 4's batch shape, evaluated every ~32k steps
    on 64 battles, with ``figures.smax.SMAX_TUNED`` or TrainConfig's defaults."""
    kw = dict(figures.smax.SMAX_BATCH)
    if settings == "tuned":
        kw.update(figures.smax.SMAX_TUNED)
    every = max(1, round(32_000 / (kw["n_envs"] * kw["rollout_len"])))
    return TrainConfig(algo=algo, env=f"smax:{map_name}", seed=seed, steps=STEPS.get(map_name, 1_000_000),
                       eval_every=every, eval_episodes=64, **kw)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--map", default="3m", choices=figures.smax.FIG4_MAPS)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--algo", default="mappo")
    ap.add_argument("--settings", default="tuned", choices=["tuned", "defaults"])
    ap.add_argument("--steps", type=int, default=None, help="env steps (default: 300k on 3m, 500k on 2s3z)")
    args = ap.parse_args()
    for seed in args.seeds:
        cfg = config(args.map, seed, args.settings, args.algo)
        if args.steps:
            cfg = dataclasses.replace(cfg, steps=args.steps)
        with tempfile.TemporaryDirectory() as out:
            cpu = time.process_time()
            rows = train(cfg, out, resume=False, progress=False)
            cpu = time.process_time() - cpu
        curve = "  ".join(f"{s // 1000}k {w:.2f}" for s, w in zip(rows["step"], rows["eval_success"]))
        print(f"{args.algo} {args.map} seed {seed} ({args.settings}): final win rate "
              f"{rows['eval_success'].iloc[-1]:.3f} at {rows['step'].iloc[-1]} steps; "
              f"{1000 * cpu / rows['step'].iloc[-1]:.3f} CPU-s per 1,000 steps\n  {curve}", flush=True)


if __name__ == "__main__":
    main()
