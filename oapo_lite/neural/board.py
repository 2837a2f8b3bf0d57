"""A run's live diagnostics as TensorBoard scalars, written while it trains
(``train(cfg, out, tensorboard=folder)``, or ``python -m oapo_lite train --tensorboard folder``;
then ``tensorboard --logdir folder``). The optional ``tensorboard`` package writes them.

Per iteration: each learner's approximate KL of its update, clip fraction and entropy (tags
``learner <net>/...``), the critic's explained variance, each seat's peer share (Eq. 9's
weight on other seats' samples), the training return and the env steps per second of the
iteration (``time/steps_per_second``); at every evaluation, the evaluation
return, fraction of the optimum and success rate. The x axis is env steps.
"""
from __future__ import annotations

import math
from pathlib import Path

INSTALL = "pip install tensorboard==2.21.0 (pinned in environment.txt)"


class Board:
    """The writer of one run's scalars; ``agents`` names the seats of the peer shares."""

    def __init__(self, folder: str | Path, agents: list[str]):
        try:
            from torch.utils.tensorboard import SummaryWriter
        except ImportError:
            raise ImportError(f"TensorBoard scalars need the tensorboard package: {INSTALL}") from None
        self.writer, self.agents = SummaryWriter(str(folder)), list(agents)

    def _scalar(self, tag: str, value, step: int) -> None:
        if value is not None and not (isinstance(value, float) and math.isnan(value)):
            self.writer.add_scalar(tag, float(value), step)

    def iteration(self, entry: dict) -> None:
        """One entry of the run's history (``runstate.load_history``)."""
        step = entry["step"]
        for learner in entry.get("learners", []):
            for key in ("approx_kl", "clip_frac", "entropy", "explained_variance"):
                self._scalar(f"learner {learner['net']}/{key}", learner.get(key), step)
        self._scalar("critic/explained_variance", entry.get("explained_variance"), step)
        for agent, share in zip(self.agents, entry.get("peer_shares", [])):
            self._scalar(f"peer share/{agent}", share, step)
        self._scalar("train/return", entry.get("train_return"), step)
        self._scalar("time/steps_per_second", entry.get("steps_per_s"), step)

    def evaluation(self, row: dict) -> None:
        """One results row."""
        for key in ("eval_return", "frac_opt", "eval_success"):
            self._scalar(f"evaluation/{key}", row.get(key), row["step"])

    def close(self) -> None:
        self.writer.close()
