"""The claims, as data: a ``Test`` is one kind of claim (a row of ``TESTS``: what it compares, by
which statistic, read against which value, and which check of the mechanism applies before the
interval is read), and a ``Claim`` is one sentence of the paper tied to a test and the curves it
compares. The judge (``judge.verdicts``) computes each row; nothing here computes."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Test:
    """One kind of claim.

    ``curves``: how many curves it names (the first is the one claimed better, or the gated one
    of a selection claim: gated, no reuse, always-on); ``statistic``: how the judge estimates it
    (a key of ``judge.verdicts.ESTIMATORS``); ``run_stat``: the per-run number it reads;
    ``side`` of ``against`` (a number, or "threshold": the metric's) the claim puts the estimate
    on; ``reach``: untestable unless some seed reached the metric's threshold; ``mechanism``:
    the check that applies before the interval is read (``judge.verdicts.RULE``, step 2):
    "reuse" (a curve reusing by Eq. 9 is claimed better: did it reuse across networks while it
    learned?), "selection" (did the gate have peers to choose between, and did it stay open?) or
    None; ``word``: how a sentence names the comparison."""

    name: str
    curves: int
    statistic: str
    run_stat: str
    side: str  # "above", "below" or "at least" (a tie holds)
    against: float | str
    reach: bool
    mechanism: str | None
    word: str


TESTS = {t.name: t for t in (
    Test("faster", 2, "improvement", "steps", "above", 0.5, True, "reuse", "faster"),
    Test("higher", 2, "improvement", "final", "above", 0.5, False, "reuse", "higher"),
    Test("stabler", 2, "improvement_of_learned", "drawdown", "above", 0.5, False, "reuse", "steadier"),
    Test("reliable", 2, "reached_share", "reached", "at least", 0.0, True, "reuse", "as reliably"),
    # higher at the end or, where both final IQMs are within FINAL_TIE, faster to the threshold
    Test("better", 2, "final_else_speed", "final", "above", 0.5, False, "reuse", "better"),
    Test("paired_higher", 2, "paired", "final", "above", 0.0, False, "reuse", "higher"),
    # the gated curve above no reuse and above always-on reuse, seed by seed
    Test("selects", 3, "selection", "final", "above", 0.0, False, "selection", "above both ends"),
    # ... and reaches the metric's threshold before both (P(faster) over each end)
    Test("selects_faster", 3, "selection", "steps", "above", 0.5, True, "selection", "faster than both ends"),
    Test("stuck", 1, "level", "final", "below", "threshold", False, None, "below"),
    Test("optimal", 1, "level", "final", "at least", "threshold", False, None, "at or above"),
)}
FINAL_TIE = 0.02  # final fractions closer than this count as a tie, decided by speed ("better")


@dataclass(frozen=True)
class Claim:
    """One claim: its words, its test (a key of ``TESTS``), the curves it compares (labels, in the
    test's order), for a figure judged env by env the env it is judged on (its ``env`` column's
    value), and whether it is one of the paper's headline claims (the README lists those first)."""

    text: str
    test: str
    curves: tuple
    env: str | None = None
    headline: bool = False

    def __post_init__(self):
        if self.test not in TESTS:
            raise ValueError(f"claim {self.text!r}: unknown test {self.test!r}; choose from {sorted(TESTS)}")
        if len(self.curves) != TESTS[self.test].curves:
            raise ValueError(f"claim {self.text!r}: test {self.test!r} compares {TESTS[self.test].curves} curve(s), "
                             f"got {list(self.curves)}")

    @property
    def kind(self) -> Test:
        return TESTS[self.test]
