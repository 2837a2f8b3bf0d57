"""A verdict as a record: the claim, the status (one enum), the interval estimates the status
read, each curve's level, the mechanism readings it used, its robustness to dropping one seed,
and, where the data could not decide, why. Every sentence, table and count about a verdict is
rendered from these fields (``report.words``); nothing reads a fact back out of a sentence."""
from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

from oapo_lite.study.catalogue.metrics import Metric
from oapo_lite.study.catalogue.tests import Claim
from oapo_lite.study.judge.evidence import NotLearned, Reuse
from oapo_lite.study.judge.statistics import Interval


class Status(str, Enum):
    """What a verdict says (``judge.verdicts.RULE`` decides it)."""

    REPRODUCED = "reproduced"
    WITHIN_NOISE = "within noise"
    NOT = "not reproduced"
    CONTRADICTED = "contradicted"
    NOT_REUSE = "not a test of reuse"
    SHARING = "a test of sharing"
    NO_SELECTION = "not a test of selection"
    NOT_TESTABLE = "not testable at this budget"
    NOT_RUN = "not run"

    def __str__(self) -> str:
        return self.value


# what each status means, in one line (the README's list; the rule in full is ``judge.verdicts.RULE``)
MEANINGS = {
    Status.REPRODUCED: "the whole 95% interval is on the paper's side",
    Status.WITHIN_NOISE: "the point estimate is on the paper's side, the interval is not",
    Status.NOT: "the point estimate is not on the paper's side",
    Status.CONTRADICTED: "the whole 95% interval is on the other side",
    Status.NOT_REUSE: "OAPPO / OATRPO hardly reused other networks' experience while it learned, so the claim says "
                      "nothing about reuse (the interval's reading is given beside it)",
    Status.SHARING: "the OAPPO reading shares networks between seats and hardly reused across them, so the claim tests "
                    "parameter sharing (the interval's reading is given beside it)",
    Status.NO_SELECTION: "the gate did not choose among peers: it had one peer (a switch), or on every seed it shut for "
                         "good early or never shut, so its runs tested reuse switched off or always on (the interval's "
                         "reading is given beside it)",
    Status.NOT_TESTABLE: "a curve did not learn at this budget or has fewer than 2 seeds",
    Status.NOT_RUN: "the env has no run on disk at this budget (not trained yet, or only at `paper`, a cluster's job)",
}
# the statuses an interval gives, and those of them where the whole interval is on one side
INTERVAL = (Status.REPRODUCED, Status.WITHIN_NOISE, Status.NOT, Status.CONTRADICTED)
DECIDED = (Status.REPRODUCED, Status.CONTRADICTED)
# the statuses that say what the runs tested instead of reading the interval
MECHANISM = (Status.NOT_REUSE, Status.SHARING, Status.NO_SELECTION)


@dataclass(frozen=True)
class Estimate:
    """One interval estimate a verdict reads: ``kind`` "improvement" (P(a better than b) on
    ``run_stat``), "paired" (the IQM over seeds of a - b, seed by seed), "reached_share" (the share
    of a's seeds that reached the threshold minus b's) or "level" (a's IQM); read against
    ``against`` on the claimed ``side``, which gives ``status``. ``seeds``: the runs per curve it
    read (the pairs, for "paired"); ``higher_on``: for "paired", the seeds on which a was better."""

    kind: str
    curves: tuple
    run_stat: str
    interval: Interval
    against: float
    side: str
    status: Status
    seeds: int
    higher_on: int | None = None


@dataclass(frozen=True)
class Level:
    """A curve's runs at this budget: the IQM of ``stat`` over its seeds with its interval, the
    mean, and how many of its seeds reached the threshold."""

    curve: object
    stat: str
    interval: Interval
    mean: float
    seeds: int
    reached: int


@dataclass(frozen=True)
class Robustness:
    """The seeds a verdict read and, for each seed whose removal gives its interval another
    status, that status (empty: no single seed carries the verdict)."""

    seeds: tuple
    flips: tuple[tuple[object, Status], ...]

    @property
    def one_seed(self) -> bool:
        return bool(self.flips)


@dataclass(frozen=True)
class Gap:
    """Why the data cannot decide a claim: ``kind`` "seeds" (a curve has fewer than 2 seeds on disk;
    ``counts``: (curve, seeds)), "learned" (a curve did not learn: ``not_learned``), "learned seeds"
    (a claim about steadiness, fewer than 2 seeds that learned; ``counts``: (curve, learned, seeds)),
    "reached" (a claim about speed or reliability, and no seed of its curves reached the threshold)
    or "not run" (no run of the env on disk at this budget)."""

    kind: str
    curves: tuple = ()
    counts: tuple = ()
    not_learned: tuple[NotLearned, ...] = ()


@dataclass(frozen=True)
class Verdict:
    """A claim judged (``judge.verdicts.check``). ``status`` is the verdict; ``interval_status``
    what the interval alone read (the same unless the mechanism check gave ``MECHANISM``'s
    status); ``estimates`` the intervals read, in the test's order (a selection claim: the gated
    curve against no reuse, against always-on, then always-on against no reuse, which the first
    two do not read); ``reuse`` the mechanism readings of the curves that reuse by Eq. 9;
    ``never_reached`` the curves that never reached the threshold (counted at the budget's end);
    ``by_speed`` where "better" found the final values tied and read speed; ``empty`` the curves
    with evaluations that hold no value, and how many."""

    claim: Claim
    figure: str
    section: str
    metric: Metric
    threshold: float
    status: Status
    interval_status: Status | None = None
    estimates: tuple[Estimate, ...] = ()
    levels: tuple[Level, ...] = ()
    reuse: tuple[Reuse, ...] = ()
    robustness: Robustness | None = None
    gap: Gap | None = None
    never_reached: tuple = ()
    by_speed: bool = False
    empty: tuple[tuple[object, int], ...] = ()

    @property
    def held(self) -> bool:
        return self.status == Status.REPRODUCED

    @property
    def one_seed(self) -> bool:
        """Dropping one seed gives the interval another status."""
        return self.robustness is not None and self.robustness.one_seed

    def reuse_of(self, curve) -> Reuse | None:
        return next((r for r in self.reuse if r.curve == curve), None)
