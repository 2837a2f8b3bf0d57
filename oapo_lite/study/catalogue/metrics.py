"""What a curve measures: its column of the runs' rows, the level that counts as converged, the
floor a run must end above to count as having learned anything, and the window of evaluations
its final value averages. A figure names one (``grid.Figure.metric``); the judge reads it."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

THRESHOLD = 0.95  # of the optimum: a maze run has converged
FINAL_MIN = 3  # evaluations in a final window at least: one evaluation is too noisy a final value


@dataclass(frozen=True)
class Metric:
    """A curve's measure; ``reach`` and ``final`` are how a sentence names reaching the threshold
    (formatted with it) and the final value."""

    column: str
    threshold: float
    floor: float
    reach: str
    final: str
    tail: float = 0.1  # the share of a run's last evaluation points its final value averages (``FINAL_MIN`` at least)

    @property
    def window(self) -> str:
        """The final window in words, as every table and figure names it."""
        share = {0.1: "tenth", 0.2: "fifth"}.get(self.tail, f"{self.tail:.0%}")
        return f"the last {share} of the evaluations, at least {FINAL_MIN}"


FRAC_OPT = Metric("frac_opt", THRESHOLD, -np.inf, "{:.0%} of the optimum", "final fraction of the optimum")
WIN_RATE = Metric("eval_success", 0.5, 0.05, "a win rate of {:.0%}", "final win rate")
# a return is noisier than a win rate over 64 battles: its final value is the last fifth
RETURN = Metric("eval_return", np.inf, -np.inf, "return {:g}", "final evaluation return", tail=0.2)
# GRF's score: the share of evaluation episodes with a goal; "nearly perfect" is 90%
SCORE = Metric("eval_success", 0.9, 0.05, "a {:.0%} score", "final score (share of episodes with a goal)")
