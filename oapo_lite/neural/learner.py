"""What the training loop drives, whatever the algorithm: one protocol, two families.

- ``ppo_family.PPOFamilyLearner``: OAPPO, OATRPO, HAPPO, HATRPO, MAPPO and IPPO (Algorithm 1
  lines 4-9 with Eq. 8's clip or Eq. 7's trust region, then the centralised critic);
- ``a2c_family.A2CFamilyLearner``: SEAC and SePS (advantage actor-critic, a critic per network).

The loop builds a learner right after the actors, from the same generator, so that a run is
reproducible from its seed (``runstate.RunState.start``); a checkpoint keeps its ``state_dict``
under the one key ``"learner"``.
"""
from __future__ import annotations

from typing import Protocol, runtime_checkable

import torch

from oapo_lite.envs.vec import VecStep
from oapo_lite.neural.rollout import Rollout


@runtime_checkable
class Learner(Protocol):
    owner: list[int]  # the network of every seat, which the rollouts and evaluations act with

    def learn(self, batch: Rollout, step: VecStep, it: int) -> tuple[dict, dict]:
        """Iteration ``it``'s update on ``batch``; ``step`` is the envs' step after the rollout (SePS
        records its observations). Returns (metrics for the results rows, per-iteration detail
        for the history)."""

    def optimisers(self) -> list[tuple[torch.optim.Optimizer, float]]:
        """Every optimiser with its learning rate before annealing."""

    def state_dict(self) -> dict:
        """Everything the learner carries between iterations (networks beyond the actors,
        optimisers, generators)."""

    def load_state_dict(self, state: dict) -> None:
        """Continue from ``state_dict()``'s output."""

