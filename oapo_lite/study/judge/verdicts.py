"""Did a paper claim reproduce? Decided from the runs by ``RULE``, the one place it is written,
into a ``records.Verdict``: ``check`` judges one claim on one ``Evidence``, ``judge`` every claim
of a figure on its runs, ``at_budget`` a figure's claims at a budget from the run cache, and
``glance`` every claim of the paper at its better-powered budget. Each test of
``catalogue.tests.TESTS`` names its estimator here (``ESTIMATORS``); no test is special-cased."""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import pandas as pd

from oapo_lite.cli import boolean, names
from oapo_lite.neural import results
from oapo_lite.study.catalogue import grid
from oapo_lite.study.catalogue.figures import GRID, get_figure, required_runs
from oapo_lite.study.catalogue.grid import Figure
from oapo_lite.study.catalogue.tests import FINAL_TIE, Claim
from oapo_lite.study.judge.evidence import EQ9_ALGOS, LEARN_SE, LEARNED, REUSE_PART, Evidence, not_learned
from oapo_lite.study.judge.records import Estimate, Gap, Level, Robustness, Status, Verdict
from oapo_lite.study.judge.statistics import Interval, bootstrap_interval, iqm, probability_of_improvement
from oapo_lite.study.runs import experiments

RULE = f"""How a verdict is decided (oapo_lite.study.judge.verdicts), in this order:
1. Not testable at this budget: a curve has fewer than 2 seeds, or did not learn (its final
   level is not above its initial level by more than {LEARN_SE:g} standard errors of the gain over
   seeds, or ends at or below the metric's floor: a 5% win rate or score), or, for a claim about
   speed or reliability, no seed of any of its curves reached the threshold.
2. What the runs tested. A run "reused while it learned" at the share of its evaluated
   iterations, up to its first evaluation at {LEARNED:.0%} of its way from its initial to its final
   value (all of them if it gained nothing), in which Eq. 9 gave the seats of other networks a
   positive weight (seats that share a network always weigh each other, at KL 0: that is
   parameter sharing, not a gate's decision); the same reading for a win rate, a return and a
   fraction of the optimum. A claim that a curve reusing by Eq. 9 (OAPPO, OATRPO) beats another is
   not a test of reuse where that curve reused while it learned at fewer than {REUSE_PART:.0%} of
   those iterations (mean over seeds), or a test of sharing where its seats share networks. A
   claim that a gated curve selects (ends above, or is faster than, both no reuse and always-on
   reuse) is not a test of selection where the gate had one peer to choose (two networks: a
   switch, not a choice) or, on every seed, last let another network in within the first
   {REUSE_PART:.0%} of the run's steps (shut for good early) or never shut (every across-network
   K within sigma at every evaluated iteration: always-on reuse). Either way the interval's
   reading (step 3) is given beside it.
3. Otherwise the 95% bootstrap interval decides: reproduced when the whole interval is on the
   claimed side (of 0.5 for P(a better than b); of 0 for a paired difference, the IQM over
   seeds of a minus b, seed by seed, or for the share of seeds that reached the threshold minus
   the other curve's, a tie included; of the threshold for a curve's final IQM), contradicted
   when it is wholly on the other side, within noise when just the point estimate is on the
   claimed side, not reproduced otherwise. A selection claim needs both its intervals (against
   no reuse and against always-on) on the claimed side, and is contradicted when either is wholly
   on the other. "Faster" reads the steps to the threshold alone: a seed that never got there
   counts at the budget's end, behind every seed that did.
4. Robustness: with 3 seeds or more, the interval of step 3 is read again without each seed in
   turn; a verdict whose status changes when one seed is dropped rests on that seed, and says so."""


def _side(i: Interval, against: float, side: str) -> Status:
    """The interval rule for an estimate claimed ``side`` ("above", "below", "at least") of
    ``against``; NaN bounds (one seed) never decide."""
    if side == "at least":
        return (Status.REPRODUCED if i.low >= against else Status.CONTRADICTED if i.high < against
                else Status.WITHIN_NOISE if i.point >= against else Status.NOT)
    sign = 1.0 if side == "above" else -1.0
    low, high = sorted((sign * (i.low - against), sign * (i.high - against)))
    if low > 0:
        return Status.REPRODUCED
    if high < 0:
        return Status.CONTRADICTED
    return Status.WITHIN_NOISE if sign * (i.point - against) > 0 else Status.NOT


def _estimate(kind: str, curves: tuple, run_stat: str, i: Interval, against: float, side: str, seeds: int,
              higher_on: int | None = None) -> Estimate:
    return Estimate(kind, curves, run_stat, i, against, side, _side(i, against, side), seeds, higher_on)


def _level(ev: Evidence, label, stat: str) -> Level:
    s = ev.summary.loc[label]
    return Level(label, stat, ev.level(label, stat), float(s["steps_mean" if stat == "steps" else "final_mean"]),
                 int(s["seeds"]), int(s["reached"]))


def _improvement(ev: Evidence, a, b, stat: str, against=0.5, side="above") -> Estimate:
    return _estimate("improvement", (a, b), stat, ev.improvement(a, b, stat), against, side,
                     min(len(ev.run_values(a, stat)), len(ev.run_values(b, stat))))


def _paired(ev: Evidence, a, b, stat: str, against=0.0, side="above") -> Estimate:
    pairs = ev.pairs(a, b, stat)
    return _estimate("paired", (a, b), stat, ev.paired(a, b, stat), against, side, len(pairs),
                     int((pairs["difference"] > 0).sum()))


@dataclass(frozen=True)
class Reading:
    """What step 3 reads: the status of the interval(s), the estimates and the curves' levels."""

    status: Status
    estimates: tuple[Estimate, ...]
    levels: tuple[Level, ...]
    by_speed: bool = False


def improvement(ev: Evidence, claim: Claim) -> Reading:
    """P(a better than b) on the test's per-run statistic (``faster``: steps, ``higher``: final)."""
    (a, b), t = claim.curves, claim.kind
    e = _improvement(ev, a, b, t.run_stat, t.against, t.side)
    return Reading(e.status, (e,), (_level(ev, a, t.run_stat), _level(ev, b, t.run_stat)))


def improvement_of_learned(ev: Evidence, claim: Claim) -> Reading | Gap:
    """P(a steadier than b): a smaller largest drop below an earlier peak, over the seeds that
    learned (ended above their start and the metric's floor: a seed that never moved has no drop
    and would count as the steadiest)."""
    (a, b), t = claim.curves, claim.kind
    runs = ev.runs[(ev.runs["final"] > ev.runs["initial"]) & (ev.runs["final"] > ev.metric.floor)]
    drops = {x: runs.loc[runs["label"] == x, "drawdown"].to_numpy(float) for x in (a, b)}
    few = [(x, len(d), int(ev.summary.loc[x, "seeds"])) for x, d in drops.items() if len(d) < 2]
    if few:
        return Gap("learned seeds", tuple(x for x, _, _ in few), tuple(few))
    i = bootstrap_interval(probability_of_improvement, -drops[a], -drops[b])
    e = _estimate("improvement", (a, b), t.run_stat, i, t.against, t.side, min(map(len, drops.values())))
    levels = tuple(Level(x, "drawdown", bootstrap_interval(iqm, d), float(np.mean(d)), len(d), len(d))
                   for x, d in drops.items())
    return Reading(e.status, (e,), levels)


def _share_difference(x, y, axis: int = -1):
    return np.mean(x, axis=axis) - np.mean(y, axis=axis)


def reached_share(ev: Evidence, claim: Claim) -> Reading:
    """The share of a's seeds that reached the threshold minus b's, read against 0 (a tie holds)."""
    (a, b), t = claim.curves, claim.kind
    i = bootstrap_interval(_share_difference, ev.run_values(a, "reached"), ev.run_values(b, "reached"))
    e = _estimate("reached_share", (a, b), "reached", i, t.against, t.side,
                  min(len(ev.run_values(a, "reached")), len(ev.run_values(b, "reached"))))
    return Reading(e.status, (e,), (_level(ev, a, "steps"), _level(ev, b, "steps")))


def final_else_speed(ev: Evidence, claim: Claim) -> Reading:
    """Higher at the end or, where both final IQMs are within ``FINAL_TIE`` of each other, faster
    to the threshold."""
    a, b = claim.curves
    if abs(ev.level(a, "final").point - ev.level(b, "final").point) > FINAL_TIE:
        e = _improvement(ev, a, b, "final")
        return Reading(e.status, (e,), (_level(ev, a, "final"), _level(ev, b, "final")))
    e = _improvement(ev, a, b, "steps")
    return Reading(e.status, (e,), (_level(ev, a, "final"), _level(ev, b, "final"), _level(ev, a, "steps"),
                                    _level(ev, b, "steps")), by_speed=True)


def paired(ev: Evidence, claim: Claim) -> Reading:
    """a's final value minus b's seed by seed (``Evidence.paired``), read against 0."""
    (a, b), t = claim.curves, claim.kind
    e = _paired(ev, a, b, t.run_stat, t.against, t.side)
    return Reading(e.status, (e,), (_level(ev, a, "final"), _level(ev, b, "final")))


def selection(ev: Evidence, claim: Claim) -> Reading:
    """The gated curve a against no reuse and against always-on reuse, each on the test's
    statistic (final: paired differences; steps: P(faster)), with always-on against no reuse
    beside them (what reuse itself did). Both must be on the claimed side."""
    (a, never, always), t = claim.curves, claim.kind
    compare = _paired if t.run_stat == "final" else _improvement
    pairs = tuple(compare(ev, x, y, t.run_stat, t.against, t.side) for x, y in ((a, never), (a, always), (always, never)))
    first, second = pairs[0].status, pairs[1].status
    status = (Status.CONTRADICTED if Status.CONTRADICTED in (first, second) else
              Status.REPRODUCED if first == second == Status.REPRODUCED else
              Status.WITHIN_NOISE if {first, second} <= {Status.REPRODUCED, Status.WITHIN_NOISE} else Status.NOT)
    return Reading(status, pairs, tuple(_level(ev, x, t.run_stat) for x in claim.curves))


def level(ev: Evidence, claim: Claim) -> Reading:
    """A curve's final IQM against the threshold (``stuck``: below, ``optimal``: at or above)."""
    (a,), t = claim.curves, claim.kind
    e = _estimate("level", (a,), "final", ev.level(a, "final"), ev.threshold, t.side,
                  int(ev.summary.loc[a, "seeds"]))
    return Reading(e.status, (e,), (_level(ev, a, "final"),))


ESTIMATORS = {"improvement": improvement, "improvement_of_learned": improvement_of_learned,
              "reached_share": reached_share, "final_else_speed": final_else_speed, "paired": paired,
              "selection": selection, "level": level}


def _gap(ev: Evidence, claim: Claim) -> Gap | None:
    """Step 1: why the data cannot decide ``claim``, or None."""
    s = ev.summary
    few = tuple((x, int(s.loc[x, "seeds"]) if x in s.index else 0) for x in claim.curves
                if x not in s.index or s.loc[x, "seeds"] < 2)
    if few:
        return Gap("seeds", tuple(x for x, _ in few), few)
    idle = tuple(w for x in claim.curves if (w := not_learned(ev, x)) is not None)
    if idle:
        return Gap("learned", tuple(w.curve for w in idle), not_learned=idle)
    if claim.kind.reach and not s.loc[list(claim.curves), "reached"].any():
        return Gap("reached", tuple(claim.curves))
    return None


def _mechanism(ev: Evidence, claim: Claim) -> tuple[Status | None, tuple]:
    """Step 2: the status that says what the runs tested instead (None: they tested the claim),
    and the mechanism readings used."""
    kind, a = claim.kind.mechanism, claim.curves[0]
    if ev.algos.get(a) not in EQ9_ALGOS or kind is None:
        return None, ()
    r = ev.reuse(a)
    if kind == "reuse":
        if np.isnan(r.while_learning) or r.while_learning < REUSE_PART:
            return (Status.SHARING if r.sharing else Status.NOT_REUSE), (r,)
        return None, (r,)
    readings = (r, ev.reuse(claim.curves[2]))
    no_choice = r.peers <= 1 or r.shut_early == r.seeds or r.never_shut == r.seeds
    return (Status.NO_SELECTION if no_choice else None), readings


def check(ev: Evidence | None, claim: Claim, figure: Figure | None = None) -> Verdict:
    """``claim`` judged on ``ev`` by ``RULE`` (``ev`` None: no run of it on disk)."""
    meta = dict(claim=claim, figure=figure.id if figure else "", section=figure.section if figure else "",
                metric=ev.metric if ev is not None else (figure.metric if figure else None),
                threshold=ev.threshold if ev is not None else np.nan)
    if ev is None:
        return Verdict(status=Status.NOT_RUN, gap=Gap("not run"), **meta)
    gap = _gap(ev, claim)
    reading = gap or ESTIMATORS[claim.kind.statistic](ev, claim)
    if isinstance(reading, Gap):
        return Verdict(status=Status.NOT_TESTABLE, gap=reading, **meta)
    instead, reuse = _mechanism(ev, claim)
    seeds = tuple(ev.seeds(*claim.curves))
    flips = []
    for seed in seeds if len(seeds) > 2 else ():  # without one of two seeds no interval is left to read
        other = ESTIMATORS[claim.kind.statistic](ev.without(seed), claim)
        status = other.status if isinstance(other, Reading) else Status.NOT_TESTABLE
        if status != reading.status:
            flips.append((seed, status))
    gaps = ev.runs.groupby("label")["gaps"].sum()
    reached = ev.summary["reached"]
    return Verdict(status=instead or reading.status, interval_status=reading.status, estimates=reading.estimates,
                   levels=reading.levels, reuse=reuse, robustness=Robustness(seeds, tuple(flips)),
                   never_reached=tuple(x for x in claim.curves if claim.test == "faster" and not reached[x]),
                   by_speed=reading.by_speed, empty=tuple((x, int(gaps[x])) for x in claim.curves if gaps[x]), **meta)


def judge(figure, df: pd.DataFrame) -> list[Verdict]:
    """Every claim of ``figure`` (a ``grid.Figure`` or its id) checked against that figure's runs
    ``df``, measured by its metric: a claim about one env on that env's runs alone. Every value of
    ``df`` in a column a run writes is checked as the run files are when read (``results.check_values``):
    a frame changed in memory is refused, not judged."""
    fig = get_figure(figure)
    if not fig.claims:
        raise ValueError(f"no claims recorded for figure {fig.id!r}; choose from {sorted(f.id for f in GRID if f.claims)}")
    if not isinstance(df, pd.DataFrame):
        raise TypeError(f"the runs must be a pandas DataFrame (e.g. experiments.load_figure's), got {type(df).__name__}")
    try:
        results.check_values(df, [c for c in ("env", "label", "seed") if c in df])
        experiments.check_levels(df)
    except results.BadRows as err:
        raise ValueError(f"the runs of {fig.id} given to judge are not what runs write: {err}") from None
    evidence = {}

    def of(env):
        if env not in evidence:
            part = df if env is None or not len(df) else df[df["env"] == env]
            evidence[env] = Evidence(part, fig.metric) if len(part) else None
        return evidence[env]

    return [check(of(c.env), c, fig) for c in fig.claims]


def on_disk(figure: str, budget: str) -> bool:
    """``figure`` has runs at ``budget``, and every one has finished and been written."""
    runs = get_figure(figure).runs(budget)
    return bool(runs) and all(experiments.on_disk(r.cfg, budget) for r in runs)


def at_budget(fig: Figure, budget: str, required: bool) -> tuple[list[Verdict], dict] | None:
    """The claims' verdicts of ``fig`` at ``budget``, and per env (None for a figure judged whole)
    the fewest seeds of a curve on disk; None where its runs are not all on disk and the budget is
    not ``required`` (a ``required`` budget then raises, naming what is missing)."""
    required = boolean(required, "at_budget's required")
    if not fig.runs(budget):
        if required:
            required_runs(fig, budget)  # raises, naming the budgets it has runs at
        return None
    if fig.runs_at is None and not on_disk(fig.id, budget):  # an engine figure is judged on the runs it has
        if not required:
            return None
        missing = experiments.missing_runs(fig.id, budget)
        raise FileNotFoundError(
            f"{len(missing)} run(s) of {fig.id} at budget {budget!r} are not on disk in "
            f"{experiments.run_path(missing[0].cfg, budget).parent} (first: "
            f"{', '.join(r.cfg.run_id() for r in missing[:3])}); train them with "
            f"`python -m oapo_lite reproduce --budget {budget} --figures {fig.id}`")
    return _judged(fig.id, budget, experiments.versions(fig.id, budget))


@functools.lru_cache(maxsize=256)
def _judged(figure: str, budget: str, versions: tuple) -> tuple[list[Verdict], dict]:
    """``at_budget``'s work, once per version of the figure's run files (``versions``: the key)."""
    fig = get_figure(figure)
    df = experiments.read_figure(fig.id, budget, skip_missing=True)[0]
    per_env = any(c.env for c in fig.claims)
    seeds = (df.groupby(["env" if per_env else "figure", "label"])["seed"].nunique().groupby(level=0).min().to_dict()
             if len(df) else {})
    return judge(fig, df), {(k if per_env else None): n for k, n in seeds.items()}


@dataclass(frozen=True)
class Judged:
    """A claim at a glance: its verdict at the better-powered budget that has its runs (``lead``,
    at ``budget``, with the fewest seeds of a curve on disk there), and, where that is the
    20-seed budget, the first budget's verdict beside it (``first``)."""

    figure: Figure
    lead: Verdict
    budget: str
    seeds_on_disk: int | None
    first: Verdict | None


def glance(budgets: tuple[str, str] = ("cpu", "paper20")) -> list[Judged]:
    """Every claim of the paper's experiments judged at ``budgets[1]`` where its runs are all there
    (20 seeds on the mazes), else at ``budgets[0]``, which must have them (it raises naming what is
    missing). Nothing is trained."""
    budgets = names(budgets, "budgets")
    if len(budgets) != 2:
        raise ValueError(f"budgets must be two budget names, got {budgets!r}")
    for b in budgets:
        grid.get_budget(b)
    out = []
    for fig in (f for f in GRID if f.claims):
        (first, seeds), second = at_budget(fig, budgets[0], required=True), at_budget(fig, budgets[1], required=False)
        for k, v in enumerate(first):
            w = None if second is None else second[0][k]
            lead, budget, on = (w, budgets[1], second[1]) if w is not None else (v, budgets[0], seeds)
            out.append(Judged(fig, lead, budget, on.get(v.claim.env), None if w is None else v))
    return out
