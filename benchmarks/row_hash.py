"""Row hashing on one real batch of Fig. 4's SMAX 3m config and of Black-Red: the exact integer
hash of ``rollout._row_hash`` against the float32 random projection it replaced (issue 30: a
BLAS kernel may round two equal rows differently by their place in the batch, so that hash was
not exact), and ``Inputs.of`` (hash, check, sort) on the same rows.

    .venv/bin/python benchmarks/row_hash.py [--repeats 200]

Prints milliseconds per call (median of ``repeats``) on the loop's one thread.
"""
from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from oapo_lite.neural.nets import Actors
from oapo_lite.neural.rollout import Inputs, _row_hash, collect, make_env

from loops import cut_short


def float_projection(columns: tuple[np.ndarray, ...]) -> np.ndarray:
    """The hash before issue 30: two float32 random projections of each row's numbers."""
    rng = np.random.default_rng(0)
    h = sum(torch.from_numpy(np.asarray(c, np.float32)) @ torch.from_numpy(rng.standard_normal((c.shape[1], 2), np.float32))
            for c in columns)
    return h.numpy().view(np.uint64).ravel()


def batch_rows(figure: str, algo: str, env_name: str) -> tuple[np.ndarray, np.ndarray]:
    """The (samples, obs_dim) observations and (samples, actions) masks of one rollout of seat
    policies at initialisation, as ``Inputs.of`` receives them."""
    cfg = cut_short(figure, "cpu", algo, env_name, 1)
    env = make_env(cfg, cfg.n_envs, seed=0)
    gen = torch.Generator().manual_seed(0)
    actors = Actors(env.n_agents, env.obs_dim, env.n_actions, cfg.hidden, False, gen)
    batch, _ = collect(env, env.reset(), actors, list(range(env.n_agents)), cfg.rollout_len, gen)
    index = batch.inputs.index.reshape(-1)
    return batch.inputs.obs[index].numpy(), batch.inputs.avail[index].numpy()


def median_ms(f, *args, repeats: int) -> float:
    f(*args)
    times = []
    for _ in range(repeats):
        tic = time.perf_counter()
        f(*args)
        times.append(time.perf_counter() - tic)
    return 1000 * float(np.median(times))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=200)
    args = parser.parse_args()
    torch.set_num_threads(1)
    for name, (figure, algo, env_name) in {"SMAX 3m": ("fig4_smax", "mappo", "smax:3m"),
                                           "Black-Red": ("fig3b", "oappo", "black_red")}.items():
        obs, avail = batch_rows(figure, algo, env_name)
        columns, raw = (obs, avail), [obs.view(np.uint8), avail.view(np.uint8)]
        distinct = len(np.unique(_row_hash(raw)))
        print(f"{name}: {obs.shape[0]:,} rows of {obs.shape[1]} float32 + {avail.shape[1]} bools, {distinct:,} distinct")
        for label, f, a in (("float32 projection (before)", float_projection, (columns,)),
                            ("exact integer hash (now)", _row_hash, (raw,)),
                            ("Inputs.of, whole", Inputs.of, (obs[None], avail[None]))):
            print(f"  {label:<28} {median_ms(f, *a, repeats=args.repeats):7.3f} ms")


if __name__ == "__main__":
    main()
