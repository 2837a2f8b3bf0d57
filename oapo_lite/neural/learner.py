"""What the training loop drives, whatever the algorithm: one protocol, two families, and the
seam to observe them.

- ``ppo_family.PPOFamilyLearner``: OAPPO, OATRPO, HAPPO, HATRPO, MAPPO and IPPO (Algorithm 1
  lines 4-9 with Eq. 8's clip or Eq. 7's trust region, then the centralised critic);
- ``a2c_family.A2CFamilyLearner``: SEAC and SePS (advantage actor-critic, a critic per network).

A learner reports each iteration as an ``Update`` (SB3's logger, JaxMARL's typed record): what
the results rows keep, what the history keeps, and what a caller asked for beyond them
(``wanted``), which an ``Observer`` passed to ``train`` receives. The loop builds a learner
right after the actors, from the same generator and with the owner map (``nets.owners``: the
network of every seat), so that a run is reproducible from its seed
(``runstate.RunState.start``); a checkpoint keeps its ``state_dict`` under the key ``"learner"``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import torch

from oapo_lite.neural.rollout import Rollout

# what a caller may ask a learner to report beyond what it always does; the PPO / TRPO family
# computes them only when asked (the A2C family has neither)
WANTS = {
    "kl": "Eq. 9's K, where the algorithm does not reuse (the loop asks at evaluated iterations: "
          "the results rows' kl_matrix)",
    "pairwise_kl": "the per-observation KL(pi_j || pi_i) that K reduces, (n, n, B), with the batch's "
                   "active mask (n, B) or None",
}


@dataclass
class Update:
    """One iteration's update as its learner reports it. ``metrics``: the values the results row
    keeps at an evaluation and the history at every iteration; ``detail``: what the history alone
    keeps (each learner's diagnostics, every accepted trust-region step); ``observed``: what
    ``wanted`` asked for (``WANTS``), kept nowhere."""

    metrics: dict
    detail: dict = field(default_factory=dict)
    observed: dict = field(default_factory=dict)


class Observer(Protocol):
    """Called by the loop after every iteration's update; ``wants`` is what it asks the learner
    to report at every iteration (``WANTS``)."""

    wants: frozenset[str]

    def __call__(self, iteration: int, update: Update) -> None: ...


@runtime_checkable
class Learner(Protocol):
    owner: list[int]  # the network of every seat, which the rollouts and evaluations act with

    def learn(self, batch: Rollout, it: int, wanted: frozenset[str] = frozenset()) -> Update:
        """Iteration ``it``'s update (0-based) on ``batch``, reporting what ``wanted`` asks."""

    def optimisers(self) -> list[tuple[torch.optim.Optimizer, float]]:
        """Every optimiser with its learning rate before annealing."""

    def state_dict(self) -> dict:
        """Everything the learner carries between iterations (networks beyond the actors,
        optimisers, generators)."""

    def load_state_dict(self, state: dict) -> None:
        """Continue from ``state_dict()``'s output."""
