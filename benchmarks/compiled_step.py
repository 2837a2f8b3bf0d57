"""What a compiled learner would save: one PPO minibatch step of the project's learner (the
actor's forward, Eq. 8's clipped objective with the own-seat entropy, backward, the clipped Adam
step of ``ppo_family.descend``), eager against ``torch.compile``, on one thread, at two shapes:
SMAX 3m MAPPO's minibatch (3 seats x 800 samples, one shared net, no input repeats) and a
Black-Red learner's full batch (2 sources x 1,600 samples over 300 distinct inputs).

    .venv/bin/python benchmarks/compiled_step.py [--steps 200]

Prints the CPU milliseconds per step both ways and the CPU-seconds the first compiled step took,
which a process pays once per graph: compiled with dynamic shapes, since a maze batch's
distinct-input count changes at every iteration (a static compile would recompile each time).
Needs a C++ compiler (inductor's CPU backend).
"""
from __future__ import annotations

import argparse
import time

import torch

from oapo_lite.neural.adam import Adam
from oapo_lite.neural.config import TrainConfig
from oapo_lite.neural.nets import Actors
from oapo_lite.neural.ppo_family import LearnerBatch, descend, ppo_loss
from oapo_lite.neural.rollout import Inputs

# (name, sources R, of them the learner's own seats, samples per source B, distinct inputs U, obs dim, actions)
SHAPES = (("SMAX 3m MAPPO minibatch", 3, 3, 800, 2400, 75, 8), ("Black-Red OAPPO learner", 2, 1, 1600, 300, 72, 5))


def problem(R: int, own: int, B: int, U: int, obs_dim: int, n_actions: int):
    """A learner, its optimiser and the arguments of ``ppo_loss`` on a batch of that shape,
    from a fixed seed."""
    g = torch.Generator().manual_seed(0)
    actors = Actors(1, obs_dim, n_actions, (64, 64), False, g)
    index = torch.randint(0, U, (R, B), generator=g) if U < R * B else torch.randperm(U, generator=g).reshape(R, B)
    inputs = Inputs(torch.randn(U, obs_dim, generator=g), torch.ones(U, n_actions, dtype=torch.bool), index)
    w = torch.full((R,), 1 / R)
    src = LearnerBatch(0, list(range(R)), list(range(own)), w, torch.randint(0, n_actions, (R, B), generator=g),
                  torch.randn(R, B, generator=g) * 0.1 - 1.6, w, None, torch.unique(index, return_inverse=True))
    args = (inputs, src, torch.ones(B), torch.randn(B, generator=g), TrainConfig())
    return actors, Adam(actors.net_params(0), lr=5e-4, eps=1e-5), args


def loss(actors: Actors, *args) -> torch.Tensor:
    return ppo_loss(actors, *args)[0]


def ms_per_step(f, actors: Actors, opt: Adam, args, steps: int) -> tuple[float, float]:
    """(CPU-seconds of the first step, CPU-milliseconds per step after a warm-up)."""
    params = actors.net_params(0)
    tic = time.process_time()
    descend(opt, params, f(actors, *args), 10.0)
    first = time.process_time() - tic
    for _ in range(20):
        descend(opt, params, f(actors, *args), 10.0)
    tic = time.process_time()
    for _ in range(steps):
        descend(opt, params, f(actors, *args), 10.0)
    return first, 1000 * (time.process_time() - tic) / steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=200, help="steps timed per shape and mode")
    args = parser.parse_args()
    torch.set_num_threads(1)  # as train() runs
    print(f"{'shape':<26} {'eager ms':>9} {'compiled ms':>12} {'saved':>6} {'compile CPU-s':>14}")
    for name, *shape in SHAPES:
        _, eager = ms_per_step(loss, *problem(*shape), args.steps)
        torch._dynamo.reset()  # each shape compiles afresh, as in its own process
        first, compiled = ms_per_step(torch.compile(loss, dynamic=True), *problem(*shape), args.steps)
        print(f"{name:<26} {eager:9.3f} {compiled:12.3f} {1 - compiled / eager:6.1%} {first:14.1f}")


if __name__ == "__main__":
    main()
