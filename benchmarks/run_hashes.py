"""The check that a change moved no number: every algorithm trained for a few iterations on
every engine (mazes, SMAX, multi-agent MuJoCo, GRF where it is installed), and the SHA-256 of
each run's ``results.csv`` (all but its git revision, what it cost and what it is) and of its checkpoint's
tensors. Run it before and after a change that should not move a number (a refactor) and
compare the two printouts line by line.

    .venv/bin/python benchmarks/run_hashes.py [--envs black_red smax:3m ...]

Prints one line per (algorithm or reading, env): its two hashes.
"""
from __future__ import annotations

import argparse
import csv
import hashlib
import importlib.util
import tempfile
from pathlib import Path

import torch

from oapo_lite.algorithms import ALGOS
from oapo_lite.neural.config import TrainConfig
from oapo_lite.neural.results import COST, STRUCTURE
from oapo_lite.neural.runstate import load_checkpoint
from oapo_lite.neural.train import train
from oapo_lite.study.catalogue import figures

# one short run shape per engine: enough iterations for an evaluation, a checkpoint and, for
# OAPPO, Eq. 9's weights to act; SePS's pre-training ends inside the run
ENVS = {"black_red": dict(n_envs=8, rollout_len=25, max_steps=50),
        "smax:3m": dict(n_envs=4, rollout_len=20, max_steps=60),
        "mamujoco:HalfCheetah-2x3": dict(n_envs=2, rollout_len=25, max_steps=50),
        f"grf:academy_{figures.grf.GRF_SCENARIOS[1]}": dict(n_envs=2, rollout_len=20, max_steps=60)}
ITERATIONS = 4
# readings beyond an algorithm's defaults that take other paths through the update
VARIANTS = {"oappo type": dict(networks="type", kl_reduce="mean"), "oappo one seat": dict(networks="one", update_by="seat"),
            "oappo adaptive": dict(reuse_adapt="gradient_test"), "oappo sample": dict(reuse_mode="sample")}


def tensor_hash(state) -> str:
    """SHA-256 of the sorted SHA-256s of every tensor in a checkpoint's (nested) state: the
    numbers alone, so a refactor that renames or regroups checkpoint keys keeps the hash."""
    hashes = []

    def walk(x):
        if isinstance(x, dict):
            for v in x.values():
                walk(v)
        elif isinstance(x, (list, tuple)):
            for v in x:
                walk(v)
        elif isinstance(x, torch.Tensor):
            hashes.append(hashlib.sha256(x.detach().cpu().contiguous().numpy().tobytes()).hexdigest())
    walk(state)
    return hashlib.sha256("".join(sorted(hashes)).encode()).hexdigest()[:16]


def run_hashes(algo: str, env: str, **reading) -> tuple[str, str]:
    shape = {**ENVS[env], **reading}
    steps = ITERATIONS * shape["n_envs"] * (5 if ALGOS[algo].a2c else shape["rollout_len"])
    cfg = TrainConfig(algo=algo, env=env, seed=0, steps=steps, eval_every=2, eval_episodes=2,
                      checkpoint_every=2, **shape, **(dict(seps_pretrain_steps=steps // 2) if algo == "seps" else {}))
    with tempfile.TemporaryDirectory() as out:
        train(cfg, out, progress=False)
        rows = list(csv.reader((Path(out) / "results.csv").open()))
        # the commit and what the run cost differ by design; what the run is (its seats' networks)
        # was recorded later, and is no number of its learning
        keep = [i for i, name in enumerate(rows[0]) if name != "git_rev" and name not in COST + STRUCTURE]
        results = hashlib.sha256(repr([[r[i] for i in keep] for r in rows]).encode()).hexdigest()[:16]
        return results, tensor_hash(load_checkpoint(out))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", nargs="+", default=list(ENVS))
    args = parser.parse_args()
    torch.set_num_threads(1)
    for env in args.envs:
        if env.startswith("grf:") and importlib.util.find_spec("gfootball") is None:
            print(f"{env}: skipped (gfootball is not installed; make grf)")
            continue
        # the readings on the envs run with 4 copies or more, which the adaptive rule's folds need
        readings = list(VARIANTS.items()) if ENVS[env]["n_envs"] >= 4 else []
        for name, reading in [(a, {}) for a in ALGOS] + readings:
            results, ckpt = run_hashes(name.split()[0], env, **reading)
            print(f"{name:14s} {env:32s} results {results} checkpoint {ckpt}", flush=True)


if __name__ == "__main__":
    main()
