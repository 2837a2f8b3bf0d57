"""A verdict in words: every phrase here is rendered from a ``judge.records.Verdict``'s fields,
so a table, a notebook and the conclusion say the same thing about the same record, and no
code reads a fact back out of a sentence."""
from __future__ import annotations

import numpy as np

from oapo_lite.study.catalogue.tests import FINAL_TIE
from oapo_lite.study.judge.evidence import REUSE_PART, NotLearned, Reuse
from oapo_lite.study.judge.records import DECIDED, MECHANISM, Estimate, Gap, Level, Status, Verdict

STAT_WORDS = {"steps": "faster", "final": "higher", "drawdown": "steadier", "reached": "reached"}


def steps(n: float) -> str:
    """An env-step count in words: 240k, 1M, 1.5M."""
    return f"{n / 1e6:g}M" if n >= 1e6 else f"{n / 1e3:g}k"


def short(i) -> str:
    """An interval in few digits, for a sentence: two decimals, or none for numbers of 10 and more."""
    spec = ".0f" if max(abs(i.point), abs(i.low), abs(i.high)) >= 10 else ".2f"
    return i.fmt(spec)


def estimate(e: Estimate) -> str:
    """An interval estimate with its name: "P(oappo faster) 0.740 [0.360, 1.000]"."""
    i = e.interval.fmt()
    if e.kind == "improvement":
        return f"P({e.curves[0]} {STAT_WORDS[e.run_stat]}) {i}"
    if e.kind == "level":
        return f"IQM final {i}"
    if e.kind == "reached_share":
        return f"share reached, {e.curves[0]} minus {e.curves[1]}: {i}"
    what = "fewer steps to the threshold" if e.run_stat == "steps" else "final value"
    return (f"{e.curves[0]} minus {e.curves[1]}, {what}, IQM over {e.seeds} paired seeds: {i}; "
            f"{e.curves[0]} higher on {e.higher_on} of {e.seeds}")


def _against(e: Estimate) -> str:
    return f"{e.against:g}"


def where(e: Estimate) -> str:
    """Where ``e``'s interval lies, as its status reads it: "wholly above 0.5", ..."""
    side = {"above": f"above {_against(e)}", "below": f"below {_against(e)}",
            "at least": f"at or above {_against(e)}"}[e.side]
    return {Status.REPRODUCED: f"wholly {side}", Status.CONTRADICTED: f"wholly on the other side of {_against(e)}",
            Status.WITHIN_NOISE: f"point estimate {side}, interval across {_against(e)}",
            Status.NOT: f"point estimate not {side}"}[e.status]


def reading(e: Estimate) -> str:
    """``e`` and where it lies: "P(oappo faster) 0.740 [0.360, 1.000]: point estimate above 0.5, ..."."""
    return f"{estimate(e)}: {where(e)}"


def lead_estimate(v: Verdict) -> str:
    """The estimates a verdict's interval status read, in words (empty: none)."""
    read = v.estimates[:2] if v.claim.kind.statistic == "selection" else v.estimates
    return "; ".join(estimate(e) for e in read)


def _interval(v: Verdict) -> str:
    if v.claim.kind.statistic == "selection":  # against the ends, in the claim's order
        return "; ".join(f"against {end}: {reading(e)}" for end, e in zip(SELECTION_ENDS, v.estimates))
    return "; ".join(reading(e) for e in v.estimates)


SELECTION_ENDS = ("no reuse", "always-on reuse")  # a selection claim's second and third curves


def not_learned(w: NotLearned) -> str:
    failures = {"gain": f"gain {w.gain:+.3g} +- {w.gain_se:.2g} s.e. over {w.seeds} seeds, not above 2 s.e.",
                "floor": f"final IQM {w.final_iqm:.3g}, not above the floor {w.floor:g}"}
    return (f"{w.curve} did not learn (initial {w.initial:.3g}, final {w.final_mean:.3g}: "
            f"{'; '.join(failures[f] for f in w.failures)})")


def gap(g: Gap, v: Verdict) -> str:
    """Why the data could not decide."""
    if g.kind == "not run":
        return "no run of this env on disk at this budget"
    if g.kind == "seeds":
        return "fewer than 2 seeds on disk: " + ", ".join(f"{x} ({n})" for x, n in g.counts)
    if g.kind == "learned seeds":
        return "fewer than 2 seeds that learned: " + ", ".join(f"{x} ({n} of {of})" for x, n, of in g.counts)
    if g.kind == "learned":
        return "; ".join(not_learned(w) for w in g.not_learned)
    return f"no seed of {' or '.join(map(str, g.curves))} reached {v.metric.reach.format(v.threshold)}"


def reuse(r: Reuse) -> str:
    """How a curve reused the seats of other networks."""
    last = ("no seed ever gave another network's seats weight" if np.isnan(r.last_open)
            else f"the gate last opened across networks at {r.last_open:,.0f} steps")
    return (f"{last}; {r.curve} reused across networks at {r.while_learning:.1%} of its evaluated iterations while "
            f"it learned ({r.overall:.1%} of all of them), mean over {r.seeds} "
            f"seed{'s' * (r.seeds != 1)}")


def mechanism(v: Verdict) -> str:
    """Why the runs tested something other than the claim (``records.MECHANISM``)."""
    r = v.reuse[0]
    if v.status == Status.NO_SELECTION:
        why, tested = [], "reuse switched off"
        if r.peers <= 1:
            why.append(f"with {r.networks} networks the gate of {r.curve} has one peer to choose: it is a switch, "
                       "not a choice")
        if r.shut_early == r.seeds:
            why.append(f"on all {r.seeds} seeds its gate last let another network in within the first "
                       f"{REUSE_PART:.0%} of the run (at {r.last_open:,.0f} steps at the latest)")
        if r.never_shut == r.seeds:
            why.append(f"on all {r.seeds} seeds every across-network K was within sigma at every evaluated iteration: "
                       "its gate never shut")
            tested = "always-on reuse"
        return "; ".join(why) + f": its runs tested {tested}; {shown(v)}"
    text = f"{reuse(r)}, below {REUSE_PART:.0%}"
    if v.status == Status.SHARING:
        text += ": its seats share networks, so the claim tests parameter sharing"
    return text


def shown(v: Verdict) -> str:
    """What a selection claim's runs show where the gate did not select: what always-on reuse did
    against no reuse, and what the gate did against always-on, from the third and second estimates."""
    gated, always = v.estimates[1], v.estimates[2]
    better = "ended higher" if gated.run_stat == "final" else "was faster"
    measure = "the final value" if always.run_stat == "final" else "the speed"
    side = lambda e: ("below" if e.interval.high < e.against else "above" if e.interval.low > e.against  # noqa: E731
                      else "across")
    reused = {"below": f"reuse lowered {measure}", "above": f"reuse raised {measure}",
              "across": f"the interval is across {always.against:g}: no effect of reuse on {measure} shown"}[side(always)]
    return (f"what they show: always-on reuse against no reuse, {reading(always)} ({reused}); the "
            f"gated curve against always-on, {reading(gated)}"
            + (f" (the gated curve {better}: the gate helped by switching reuse off)" if side(gated) == "above" else
               " (switching reuse off did not help measurably)"))


def robustness(v: Verdict) -> str:
    """"" where no single seed carries the verdict; else which seeds do."""
    if not v.one_seed:
        return ""
    flips = v.robustness.flips
    by: dict[str, list] = {}  # the status each seed's removal gives, and the seeds that give it
    for seed, status in flips:
        by.setdefault(str(status), []).append(str(seed))

    def without(seeds: list) -> str:
        if len(seeds) == 1:
            return f"without seed {seeds[0]}"
        return f"without any one of seeds {', '.join(seeds[:-1])} or {seeds[-1]}"

    return "rests on one seed: " + "; ".join(f"{without(seeds)} the interval reads {status}"
                                             for status, seeds in by.items())


def reason(v: Verdict) -> str:
    """One line: why ``v`` has its status (and, beside a status of ``MECHANISM``, what the interval
    alone read), with what it left out and whether one seed carries it."""
    if v.status in (Status.NOT_RUN, Status.NOT_TESTABLE):
        return gap(v.gap, v)
    if v.status in MECHANISM:
        text = f"{mechanism(v)}; by the interval alone {v.interval_status}: {_interval(v)}"
    else:
        text = _interval(v)
        if v.by_speed:
            text = f"final values tied within {FINAL_TIE:g}, so speed decides: {text}"
    if v.never_reached:
        text += (f"; {' and '.join(map(str, v.never_reached))} did not reach "
                 f"{v.metric.reach.format(v.threshold)} in the budget (counted at its end)")
    if v.empty:
        text += "; " + " and ".join(f"{n} of {x}'s" for x, n in v.empty) + \
            " evaluations hold no value (no evaluation episode ended) and are left out"
    if v.one_seed:
        text += f"; {robustness(v)}"
    return text


def level(lv: Level, v: Verdict) -> str:
    if lv.stat == "steps":
        return f"{lv.curve} {lv.interval.fmt(',.0f')} (mean {lv.mean:,.0f}; {lv.reached}/{lv.seeds} seeds reached)"
    return f"{lv.curve} {lv.interval.fmt()} (mean {lv.mean:.3f})"


def evidence(v: Verdict) -> str:
    """The curves' levels a verdict read, as a sentence."""
    parts = {}
    for lv in v.levels:
        parts.setdefault(lv.stat, []).append(level(lv, v))
    name = {"steps": f"steps to {v.metric.reach.format(v.threshold)}" if v.metric else "steps",
            "final": v.metric.final if v.metric else "final value", "drawdown": "largest drop below an earlier peak"}
    return "; ".join(f"{name[s]}, IQM [95% CI] over seeds: {' vs '.join(p)}" for s, p in parts.items()) + \
        ("." if parts else "")


def seeds(v: Verdict) -> str:
    """How many seeds a verdict holds on, and whether one seed carries it."""
    if v.robustness is None:
        return "-"
    paired = next((e for e in v.estimates if e.kind == "paired"), None)
    text = f"{len(v.robustness.seeds)} seeds" + (f", higher on {paired.higher_on} of {paired.seeds}" if paired else "")
    return text + ("; " + robustness(v) if v.one_seed else "")


def sentence(v: Verdict) -> str:
    """The verdict as a notebook states it: claim, status, why, and the curves' levels."""
    if v.status in (Status.NOT_TESTABLE, Status.NOT_RUN):
        return f"{v.claim.text}: {v.status}: {reason(v)}"
    return f"{v.claim.text}: {v.status} ({reason(v)}). {evidence(v)}"


def by_status(vs: list[Verdict]) -> list[str]:
    """A figure's verdicts grouped by status (in ``Status``'s order), each with its claim and reason."""
    return [f"{v.status}: {v.claim.text} ({reason(v)})." for status in Status for v in vs if v.status == status]


def decided(v: Verdict) -> bool:
    """Whether an interval decided ``v``: its whole interval on one side (``records.DECIDED``)."""
    return v.status in DECIDED
