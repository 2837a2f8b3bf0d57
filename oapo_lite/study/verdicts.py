"""Did a paper claim reproduce? Computed from tidy run data, never typed by hand.

Input: one row per (run, evaluation point) with columns ``label`` (the curve: an
algorithm, a sigma, a scheme...), ``seed``, ``step`` (env steps) and ``frac_opt`` (return
as a fraction of the oracle optimum), or another measure where there is no oracle (a
``Metric``: SMAX's win rate, MaMuJoCo's return). A run is one (label, seed).

Two numbers summarise a run: the env steps it took to first reach ``threshold`` of the
optimum (censored at its last step if it never did), and its final fraction of the optimum
(mean over the last ``tail`` share of its evaluation points, at least ``FINAL_MIN`` of them: a
tenth, a fifth for returns; ``Metric.window`` names it).

Interval estimates (IQM, probability of improvement, stratified bootstrap) come from
``statistics``. The decision rule, with what "a curve learned" means, is ``RULE``, the one place
it is written (printed where the verdicts are introduced); ``check`` applies it to one claim.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from oapo_lite.algorithms import ALGOS
from oapo_lite.envs import registry as env_registry
from oapo_lite.neural.nets import owners
from oapo_lite.reuse import peer_share
from oapo_lite.study.statistics import Interval, bootstrap_interval, iqm, probability_of_improvement

THRESHOLD = 0.95
FINAL_TIE = 0.02  # final fractions closer than this count as a tie, decided by speed
# The statuses of a verdict: the one vocabulary of every table, summary and notebook (``STATUSES``)
REPRODUCED, WITHIN_NOISE, NOT = "reproduced", "within noise", "not reproduced"
CONTRADICTED, NOT_TESTABLE, NOT_RUN = "contradicted", "not testable at this budget", "not run"
NOT_REUSE = "not a test of reuse"
NO_RUN = "no run of this env on disk at this budget"  # the reason of ``NOT_RUN``
INTERVAL_ALONE = "by the interval alone"  # what the interval read, beside a status that says what the runs tested
SHARING = "a test of sharing"  # a reading whose seats share networks, where reuse across them hardly operated
# what each status means, in one line (the README's list; the rule in full is ``RULE``)
STATUSES = {
    REPRODUCED: "the whole 95% interval is on the paper's side",
    WITHIN_NOISE: "the point estimate is on the paper's side, the interval is not",
    NOT: "the point estimate is not on the paper's side",
    CONTRADICTED: "the whole 95% interval is on the other side",
    NOT_REUSE: "OAPPO / OATRPO hardly reused other networks' experience while it learned, so the claim says nothing "
               "about reuse (the interval's reading is given beside it)",
    SHARING: "the OAPPO reading shares networks between seats and hardly reused across them, so the claim tests "
             "parameter sharing (the interval's reading is given beside it)",
    NOT_TESTABLE: "a curve did not learn at this budget or has fewer than 2 seeds",
    NOT_RUN: "the env has no run on disk at this budget (not trained yet, or only at `paper`, a cluster's job)",
}
# a curve reusing by Eq. 9 tests reuse when some peer weight was given at this share of its
# evaluated iterations while it learned: the gate operates (the gate-statistic study's rule too)
REUSE_PART = 0.25
EQ9_ALGOS = tuple(a for a, spec in ALGOS.items() if spec.reuse_rule == "oapo")
INITIAL = 0.1  # a run's initial level: its first tenth of evaluation points (the untrained policy at step 0)
LEARN_SE = 2.0  # a curve learned when its gain exceeds this many standard errors over seeds
# per-run numbers a verdict reads; "steps" and "drawdown" are better when lower
RUN_STATS = {"steps": "steps_to_threshold", "final": "final", "drawdown": "drawdown", "reached": "reached"}


@dataclass(frozen=True)
class Metric:
    """What a curve measures: its column, the level that counts as converged, the level a run
    must end above to count as having learned anything, and how evidence names reaching
    the threshold (formatted with it) and the final value."""

    column: str
    threshold: float
    floor: float
    reach: str
    final: str
    tail: float = 0.1  # the share of a run's last evaluation points its final value averages (``FINAL_MIN`` at least)

    @property
    def window(self) -> str:
        """The final window in words, as every table and figure names it."""
        return f"the last {_share(self.tail)} of the evaluations, at least {FINAL_MIN}"


FINAL_MIN = 3  # evaluations in a final window at least: one evaluation is too noisy a final value


def _share(tail: float) -> str:
    return {0.1: "tenth", 0.2: "fifth"}.get(tail, f"{tail:.0%}")


FRAC_OPT = Metric("frac_opt", THRESHOLD, -np.inf, "{:.0%} of the optimum", "final fraction of the optimum")
WIN_RATE = Metric("eval_success", 0.5, 0.05, "a {:.0%} win rate", "final win rate")
# a return is noisier than a win rate over 64 battles: its final value is the last fifth
RETURN = Metric("eval_return", np.inf, -np.inf, "return {:g}", "final evaluation return", tail=0.2)
# GRF's score: the share of evaluation episodes with a goal; "nearly perfect" is 90%
SCORE = Metric("eval_success", 0.9, 0.05, "a {:.0%} score", "final score (share of episodes with a goal)")


def per_run(df: pd.DataFrame, threshold: float = THRESHOLD, tail: float = 0.1, y: str = "frac_opt") -> pd.DataFrame:
    """One row per run: steps to threshold (censored), whether it got there, final value of
    ``y`` over the last ``tail`` of its evaluation points (column ``final``: a fraction of the
    optimum, a win rate or a return, as ``y`` is), its initial value (its first ``INITIAL``), its
    peak, its largest drop below an earlier peak, and its ``gaps``: evaluations whose ``y`` is
    empty (an engine's evaluation in which no episode ended), which every number leaves out and
    ``check`` names beside its verdict."""
    if not isinstance(df, pd.DataFrame):
        raise TypeError(f"the runs must be a pandas DataFrame (e.g. experiments.load_figure's), got {type(df).__name__}")
    if not (isinstance(threshold, (int, float)) and not np.isnan(threshold)):
        raise ValueError(f"threshold = {threshold!r} is invalid; allowed: a number (inf: never reached)")
    if not (isinstance(tail, (int, float)) and 0 < tail <= 1):
        raise ValueError(f"tail = {tail!r} is invalid; allowed: a share of the evaluation points in (0, 1]")
    rows = []
    if df.empty:
        df = pd.DataFrame(columns=["label", "seed", "step", y])
    lacking = [c for c in ("label", "seed", "step", y) if c not in df]
    if lacking:
        raise ValueError(f"the runs lack the columns {lacking}; they need label, seed, step and {y!r} "
                         "(e.g. experiments.load_figure's rows)")
    if len(df) and not pd.api.types.is_numeric_dtype(df[y]):
        raise ValueError(f"the runs' {y!r} column holds text (e.g. {df[y].iloc[0]!r}); allowed: numbers")
    twice = df[df.duplicated(["label", "seed", "step"])]
    if len(twice):
        first = twice.iloc[0]
        raise ValueError(f"curve {first['label']!r} has two rows for seed {first['seed']} at step {first['step']}; "
                         "a run has one row per evaluation (two runs with one seed under one label?)")
    for (label, seed), run in df.sort_values("step", kind="stable").groupby(["label", "seed"], sort=False):
        hit = run.loc[run[y] >= threshold, "step"]
        k, k0 = max(FINAL_MIN, int(round(tail * len(run)))), max(1, int(round(INITIAL * len(run))))
        held = run[y].dropna()  # the windows hold k and k0 evaluations with a value
        steps, shares = peer_shares(run, _owner(run))
        learning = steps <= (hit.iloc[0] if len(hit) else np.inf)
        rows.append({
            "label": label,
            "seed": seed,
            "steps_to_threshold": float(hit.iloc[0]) if len(hit) else float(run["step"].max()),
            "reached": bool(len(hit)),
            "initial": float(held.iloc[:k0].mean()),
            "final": float(held.iloc[-k:].mean()),
            "peak": float(run[y].max()),
            "drawdown": float((run[y].cummax() - run[y]).max()),
            "reusing": float(np.mean(shares[learning] > 0)) if learning.any() else np.nan,
            "last_reuse_step": float(steps[shares > 0].max()) if (shares > 0).any() else np.nan,
            "gaps": int(run[y].isna().sum()),
        })
    return pd.DataFrame(rows, columns=PER_RUN_COLUMNS)  # the columns even for a frame with no run


PER_RUN_COLUMNS = ["label", "seed", "steps_to_threshold", "reached", "initial", "final", "peak", "drawdown", "reusing",
                   "last_reuse_step", "gaps"]


def peer_shares(run: pd.DataFrame, owner=None) -> tuple[np.ndarray, np.ndarray]:
    """(step, ``peer_share`` of M) at a run's evaluated iterations that recorded M (none for
    SEAC, SePS, or data without the column); with ``owner`` (each seat's network), the share on
    other networks' seats alone."""
    if "reuse_matrix" not in run:
        return np.zeros(0), np.zeros(0)
    run = run[run["reuse_matrix"].notna()]
    return run["step"].to_numpy(float), run["reuse_matrix"].map(lambda m: peer_share(m, owner)).to_numpy(float)


def _owner(run: pd.DataFrame) -> list[int] | None:
    """The network of each seat of a run, from its config columns (``nets.owners`` of its
    networks reading and its env's agent types); None where the rows do not say (every seat
    then counts as its own network)."""
    if not {"env", "algo"} <= set(run.columns) or run["algo"].iloc[0] not in ALGOS:
        return None
    first = run.iloc[0]
    networks = first.get("networks")
    types = _agent_types(str(first["env"]), int(first["max_steps"]) if "max_steps" in run else 50)
    return None if types is None else owners(networks if isinstance(networks, str) else ALGOS[first["algo"]].networks,
                                             types)


@functools.cache
def _agent_types(env: str, max_steps: int) -> tuple | None:
    try:
        return tuple(env_registry.agent_types(env, max_steps))
    except (ValueError, ImportError):  # a map text flattened into one line, an engine not installed here
        return None


def _summary_of(runs: pd.DataFrame) -> pd.DataFrame:
    g = runs.groupby("label", sort=False)
    gain = (runs["final"] - runs["initial"]).groupby(runs["label"], sort=False)
    return pd.DataFrame({
        "seeds": g.size(),
        "reached": g["reached"].sum().astype(int),
        "steps_mean": g["steps_to_threshold"].mean(),
        "steps_std": g["steps_to_threshold"].std(ddof=1).fillna(0.0),
        "final_mean": g["final"].mean(),
        "final_std": g["final"].std(ddof=1).fillna(0.0),
        "initial_mean": g["initial"].mean(),
        "gain_mean": gain.mean(),
        "gain_se": gain.std(ddof=1) / np.sqrt(gain.size()),  # NaN with one seed
        "reusing": g["reusing"].mean(),  # NaN where no run recorded M
        "last_reuse_step": g["last_reuse_step"].max(),
    })


def summary(df: pd.DataFrame, threshold: float | None = None, metric: Metric = FRAC_OPT) -> pd.DataFrame:
    """Per label: mean and std over seeds of steps-to-threshold and final value."""
    return _summary_of(per_run(df, metric.threshold if threshold is None else threshold, tail=metric.tail,
                               y=metric.column))


# --- the evidence a verdict reads: curves compared by interval estimates -------------------

def paired_difference(df: pd.DataFrame, a, b, y: str, tail: float = 0.2) -> tuple[pd.DataFrame, Interval]:
    """Curve ``a`` against curve ``b`` seed by seed: per seed both runs' final value (the mean of
    ``y`` over the last ``tail`` of their evaluation points) and a - b, with the mean difference
    and its bootstrap interval over the seeds that have both runs. The pairs are resampled
    whole, since one seed gives both runs the same initial networks and environments."""
    absent = [x for x in (a, b) if not len(df) or x not in set(df["label"])]
    if absent:
        known = list(dict.fromkeys(df["label"])) if "label" in df else []
        raise ValueError(f"no runs labelled {absent} to pair; the runs' labels are {known}")
    if a == b:
        raise ValueError(f"a and b are both {a!r}; a pair compares two curves")
    runs = per_run(df[df["label"].isin([a, b])], tail=tail, y=y).pivot(index="seed", columns="label", values="final")
    runs = runs.reindex(columns=[a, b]).dropna()
    if runs.empty:
        raise ValueError(f"no seed has runs of both {a!r} and {b!r}, so there is no pair to compare")
    runs["difference"] = runs[a] - runs[b]
    return runs, bootstrap_interval(np.mean, runs["difference"].to_numpy())


class Evidence:
    """One figure's runs and the per-curve numbers every verdict reads."""

    def __init__(self, df: pd.DataFrame, threshold: float | None = None, metric: Metric = FRAC_OPT):
        self.threshold = metric.threshold if threshold is None else threshold
        self.metric = metric
        self.runs = per_run(df, self.threshold, tail=metric.tail, y=metric.column)
        self.summary = _summary_of(self.runs)
        # each curve's algorithm (where the data names it): which curves reuse by Eq. 9
        self.algos = df.groupby("label", sort=False)["algo"].first().to_dict() if "algo" in df else {}
        # which curves' seats share networks (where the data names the reading)
        self.sharing = {label: len(set(owner)) < len(owner) for label, run in df.groupby("label", sort=False)
                        if (owner := _owner(run)) is not None} if len(df) else {}

    def run_values(self, label, stat: str) -> np.ndarray:
        """Per-seed values of the per-run statistic ``stat`` (a key of ``RUN_STATS``) for one curve."""
        if stat not in RUN_STATS:
            raise ValueError(f"unknown run statistic {stat!r}; choose from {sorted(RUN_STATS)}")
        if label not in self.summary.index:
            raise ValueError(f"no runs labelled {label!r}; labels are {list(self.summary.index)}")
        return self.runs.loc[self.runs["label"] == label, RUN_STATS[stat]].to_numpy(float)

    def level(self, label, stat: str) -> Interval:
        """IQM over seeds of ``stat`` with its 95% interval."""
        return bootstrap_interval(iqm, self.run_values(label, stat))

    def improvement(self, a, b, stat: str) -> Interval:
        """P(a better than b) on ``stat`` with its 95% interval; fewer steps or a smaller
        drawdown is better."""
        sign = -1.0 if stat in ("steps", "drawdown") else 1.0
        return bootstrap_interval(probability_of_improvement, sign * self.run_values(a, stat),
                                  sign * self.run_values(b, stat))


def intervals(df: pd.DataFrame, threshold: float | None = None, metric: Metric = FRAC_OPT) -> pd.DataFrame:
    """Per label: IQM over seeds of steps-to-threshold and final value, with 95% intervals."""
    ev = Evidence(df, threshold, metric)
    rows = {}
    for label in ev.summary.index:
        row = {"seeds": ev.summary.loc[label, "seeds"], "reached": ev.summary.loc[label, "reached"]}
        for stat in ("steps", "final"):
            est = ev.level(label, stat)
            row |= {f"{stat}_iqm": est.point, f"{stat}_low": est.low, f"{stat}_high": est.high}
        rows[label] = row
    columns = ["seeds", "reached"] + [f"{stat}_{part}" for stat in ("steps", "final") for part in ("iqm", "low", "high")]
    return pd.DataFrame.from_dict(rows, orient="index", columns=columns).rename_axis("label")


# --- verdicts -------------------------------------------------------------------------------

RULE = f"""How a verdict is decided (oapo_lite.study.verdicts), in this order:
1. Not testable at this budget: a curve has fewer than 2 seeds, or did not learn (its final
   level is not above its initial level by more than {LEARN_SE:g} standard errors of the gain over
   seeds, or ends at or below the metric's floor: a 5% win rate or score), or, for "faster",
   no seed of either curve reached the threshold (for "faster" and "as reliably").
2. Not a test of reuse: a claim that a curve reusing by Eq. 9 (OAPPO, OATRPO) beats another
   curve, where that curve gave the seats of other networks a positive weight at
   fewer than {REUSE_PART:.0%} of its evaluated iterations while it learned (up to its first reaching
   the threshold; all of them if it never did), mean over seeds (seats that share a network
   always weigh each other, at KL 0: that is parameter sharing, not a gate's decision); it says
   when the gate last opened across networks. Where the curve's seats share networks, the claim
   is a test of sharing instead. Either way the interval's reading (step 3) is given beside it.
   Not for a claim that a gated curve beats the same curve reusing always (selection): a gate
   that shuts is what such a claim tests, and its reason says how often the gate let reuse in.
3. Otherwise the 95% bootstrap interval decides: reproduced when the whole interval of
   P(a better than b) (or of the final IQM, for "stays below" / "reaches"; of the share of seeds
   that reached the threshold minus the other curve's, for "as reliably") is on the claimed
   side of 0.5 (of the threshold; of 0, a tie included), contradicted when it is wholly on the
   other side, within noise when just the point estimate is on the claimed side,
   not reproduced otherwise. "Faster" reads the steps to the threshold alone: a seed that never
   got there counts at the budget, behind every seed that did."""


@dataclass(frozen=True)
class Verdict:
    claim: str
    status: str  # ``RULE``
    evidence: str
    estimate: str  # the interval the status reads, e.g. "P(oappo faster) 0.720 [0.400, 0.960]"
    reason: str  # one line: why this status

    @property
    def held(self) -> bool:
        return self.status == REPRODUCED

    def sentence(self) -> str:
        if self.status in (NOT_TESTABLE, NOT_RUN):
            return f"{self.claim}: {self.status}: {self.reason}"
        return f"{self.claim}: {self.status} ({self.reason}). {self.evidence}"


def _side(est: Interval, value: float, claimed_above: bool) -> str:
    """Interval rule for "the estimate is above ``value``" (or below, ``claimed_above=False``);
    NaN bounds (one seed) never decide."""
    sign = 1.0 if claimed_above else -1.0
    low, high = sorted((sign * (est.low - value), sign * (est.high - value)))
    if low > 0:
        return REPRODUCED
    if high < 0:
        return CONTRADICTED
    return WITHIN_NOISE if sign * (est.point - value) > 0 else NOT


def _reason(status: str, estimate: str, side: str, value: float) -> str:
    where = {REPRODUCED: f"wholly {side}", CONTRADICTED: f"wholly on the other side of {value:g}",
             WITHIN_NOISE: f"point estimate {side}, interval across {value:g}", NOT: f"point estimate not {side}"}
    return f"{estimate}: {where[status]}"


def _pairwise(ev: Evidence, a, b, stat: str, claim: str, evidence: str) -> Verdict:
    p = ev.improvement(a, b, stat)
    word = {"steps": "faster", "final": "higher", "drawdown": "steadier"}[stat]
    estimate = f"P({a} {word}) {p.fmt()}"
    status = _side(p, 0.5, True)
    return Verdict(claim, status, f"{evidence}; P({a} {word}) = {p.fmt()}.", estimate,
                   _reason(status, estimate, "above 0.5", 0.5))


def faster(ev: Evidence, a, b, claim: str) -> Verdict:
    """Claim: ``a`` reaches the threshold in fewer env steps than ``b``. A seed that never got
    there counts at its last step, so it ranks behind every seed that did: whether ``a`` gets
    there as often is ``reliable``'s question, not this one's."""
    reach = ev.metric.reach.format(ev.threshold)
    verdict = _pairwise(ev, a, b, "steps", claim,
                        evidence=f"steps to {reach}, IQM [95% CI] over seeds: {_fmt_steps(ev, a)} vs {_fmt_steps(ev, b)}")
    never = [x for x in (a, b) if not ev.summary.loc[x, "reached"]]
    if never:  # a curve that never got there ranks at the budget's end: say so beside the verdict
        return replace(verdict, reason=f"{verdict.reason}; {' and '.join(map(str, never))} did not reach {reach} in "
                                       "the budget (counted at its end)")
    return verdict


def _share_difference(x, y, axis: int = -1):
    return np.mean(x, axis=axis) - np.mean(y, axis=axis)


def reliable(ev: Evidence, a, b, claim: str) -> Verdict:
    """Claim: ``a`` reaches the threshold at least as often as ``b``: the share of ``a``'s seeds
    that reached it minus ``b``'s, with its 95% interval, read against 0 (a tie holds)."""
    s, reach = ev.summary, ev.metric.reach.format(ev.threshold)
    d = bootstrap_interval(_share_difference, ev.run_values(a, "reached"), ev.run_values(b, "reached"))
    status = (REPRODUCED if d.low >= 0 else CONTRADICTED if d.high < 0 else WITHIN_NOISE if d.point >= 0 else NOT)
    estimate = f"share reached, {a} minus {b}: {d.fmt()}"
    return Verdict(claim, status, f"seeds that reached {reach}: {a} {s.loc[a, 'reached']}/{s.loc[a, 'seeds']} vs {b} "
                                  f"{s.loc[b, 'reached']}/{s.loc[b, 'seeds']}; difference of shares {d.fmt()}.",
                   estimate, _reason(status, estimate, "at or above 0", 0))


def higher(ev: Evidence, a, b, claim: str) -> Verdict:
    """Claim: ``a`` ends at a higher level (fraction of the optimum, win rate, return) than ``b``."""
    return _pairwise(ev, a, b, "final", claim,
                     evidence=f"{ev.metric.final}, IQM [95% CI]: {_fmt_final(ev, a)} vs {_fmt_final(ev, b)}")


def paired_higher(ev: Evidence, a, b, claim: str) -> Verdict:
    """Claim: ``a`` ends at a higher level than ``b``, seed by seed: the mean over seeds of
    a's final value minus b's, where one seed gave both runs the same initial networks and
    environments (the pairs resampled whole), read against 0."""
    runs = ev.runs.pivot(index="seed", columns="label", values="final").reindex(columns=[a, b]).dropna()
    d = bootstrap_interval(np.mean, (runs[a] - runs[b]).to_numpy())
    status = _side(d, 0.0, True)
    estimate = f"{a} minus {b}, paired over {len(runs)} seeds: {d.fmt()}"
    return Verdict(claim, status, f"{ev.metric.final} ({ev.metric.window}), IQM [95% CI]: {_fmt_final(ev, a)} vs "
                                  f"{_fmt_final(ev, b)}; paired difference {d.fmt()} ({(runs[a] > runs[b]).sum()} of "
                                  f"{len(runs)} seeds higher).", estimate, _reason(status, estimate, "above 0", 0))


def selects(ev: Evidence, a, b, claim: str) -> Verdict:
    """Claim: the gated curve ``a`` ends above ``b``, the same curve reusing always, seed by seed
    (``paired_higher``). What it tests is Eq. 9's selection, shutting the gate included, so
    ``check`` leaves out the reuse check (``RULE``, step 2); the reason says how often ``a``
    reused across networks while it learned."""
    v = paired_higher(ev, a, b, claim)
    return replace(v, reason=f"{v.reason}; {a} reused across networks at {ev.summary.loc[a, 'reusing']:.1%} of its "
                             "evaluated iterations while it learned")


def stabler(ev: Evidence, a, b, claim: str) -> Verdict:
    """Claim: ``a`` improves more steadily than ``b``: a smaller largest drop of its curve
    below an earlier peak, over the seeds that learned (ended above their start and the metric's
    floor: a seed that never moved has no drop and would count as the steadiest)."""
    runs = ev.runs[(ev.runs["final"] > ev.runs["initial"]) & (ev.runs["final"] > ev.metric.floor)]
    drops = {x: runs.loc[runs["label"] == x, "drawdown"].to_numpy(float) for x in (a, b)}
    few = [f"{x} ({len(d)} of {int(ev.summary.loc[x, 'seeds'])})" for x, d in drops.items() if len(d) < 2]
    if few:
        return Verdict(claim, NOT_TESTABLE, "", "", f"fewer than 2 seeds that learned: {', '.join(few)}")
    p = bootstrap_interval(probability_of_improvement, -drops[a], -drops[b])
    estimate = f"P({a} steadier) {p.fmt()}"
    status = _side(p, 0.5, True)
    fmt = {x: f"{bootstrap_interval(iqm, d).fmt()} over {len(d)} seeds that learned" for x, d in drops.items()}
    return Verdict(claim, status, f"largest drop below an earlier peak, IQM [95% CI]: {a} {fmt[a]} vs {b} {fmt[b]}; "
                                  f"{estimate}.", estimate, _reason(status, estimate, "above 0.5", 0.5))


def better(ev: Evidence, a, b, claim: str) -> Verdict:
    """Claim: ``a`` is better than ``b``: higher at the end or, where both final IQMs are within
    ``FINAL_TIE`` of each other, faster to the threshold."""
    by_final, by_speed = higher(ev, a, b, claim), faster(ev, a, b, claim)
    if abs(ev.level(a, "final").point - ev.level(b, "final").point) > FINAL_TIE:
        return by_final
    return Verdict(claim, by_speed.status, f"{by_final.evidence[:-1]} (a tie within {FINAL_TIE:g}, so speed "
                   f"decides); {by_speed.evidence}", by_speed.estimate, by_speed.reason)


def _single(ev: Evidence, a, claim: str, below: bool) -> Verdict:
    s, thr = ev.summary, ev.threshold
    est = ev.level(a, "final")
    estimate = f"IQM final {est.fmt()}"
    if below:  # "stuck": the whole interval below the threshold
        status, side = _side(est, thr, False), f"below {thr:g}"
    else:  # "optimal": the whole interval at or above it
        status = REPRODUCED if est.low >= thr else CONTRADICTED if est.high < thr else WITHIN_NOISE if est.point >= thr else NOT
        side = f"at or above {thr:g}"
    return Verdict(claim, status,
                   f"{ev.metric.final}, IQM [95% CI]: {_fmt_final(ev, a)}; {s.loc[a, 'reached']} of "
                   f"{s.loc[a, 'seeds']} seeds ever reached {thr:.0%}.", estimate, _reason(status, estimate, side, thr))


def stuck(ev: Evidence, a, claim: str) -> Verdict:
    """Claim: ``a`` stays below the threshold of the optimum (a local optimum)."""
    return _single(ev, a, claim, below=True)


def optimal(ev: Evidence, a, claim: str) -> Verdict:
    """Claim: ``a`` reaches the threshold of the optimum and stays there."""
    return _single(ev, a, claim, below=False)


def _fmt_steps(ev: Evidence, label) -> str:
    s = ev.summary
    return (f"{label} {ev.level(label, 'steps').fmt(',.0f')} (mean {s.loc[label, 'steps_mean']:,.0f}; "
            f"{s.loc[label, 'reached']}/{s.loc[label, 'seeds']} seeds reached)")


def _fmt_final(ev: Evidence, label) -> str:
    return f"{label} {ev.level(label, 'final').fmt()} (mean {ev.summary.loc[label, 'final_mean']:.3f})"


def _learning_failures(ev: Evidence, label) -> list[str]:
    """The tests of the module docstring's learning rule that curve ``label`` fails, each with
    its numbers (none: it learned)."""
    s, floor, final = ev.summary.loc[label], ev.metric.floor, ev.level(label, "final").point
    failures = []
    if not (s["gain_mean"] > LEARN_SE * s["gain_se"] and s["gain_mean"] > 0):
        failures.append(f"gain {s['gain_mean']:+.3g} +- {s['gain_se']:.2g} s.e. over {int(s['seeds'])} seeds, "
                        f"not above {LEARN_SE:g} s.e.")
    if final <= floor:
        failures.append(f"final IQM {final:.3g}, not above the floor {floor:g}")
    return failures


def learned(ev: Evidence, label) -> bool:
    """Whether curve ``label`` learned at this budget (the module docstring's rule)."""
    return not _learning_failures(ev, label)


def why_not_learned(ev: Evidence, label) -> str:
    """Why curve ``label`` did not learn: the tests of ``learned`` it failed, with their numbers."""
    s = ev.summary.loc[label]
    return (f"{label} did not learn (initial {s['initial_mean']:.3g}, final {s['final_mean']:.3g}: "
            f"{'; '.join(_learning_failures(ev, label))})")


def _undecidable(ev: Evidence, test, labels) -> str | None:
    """Why the data cannot decide a claim about ``labels``, or None if it can."""
    s, m = ev.summary, ev.metric
    few = [f"{x} ({int(s.loc[x, 'seeds']) if x in s.index else 0})" for x in labels
           if x not in s.index or s.loc[x, "seeds"] < 2]
    if few:
        return f"fewer than 2 seeds on disk: {', '.join(few)}"
    idle = [why_not_learned(ev, x) for x in labels if not learned(ev, x)]
    if idle:
        return "; ".join(idle)
    if test in (faster, reliable) and not s.loc[list(labels), "reached"].any():
        return f"no seed of {' or '.join(map(str, labels))} reached {m.reach.format(m.threshold)}"
    return None


def reuse_gap(ev: Evidence, labels) -> tuple[str, str] | None:
    """Why a claim about ``labels`` cannot test off-agent reuse (``RULE``, step 2), as (status,
    reason), or None: it says a curve reusing by Eq. 9 beats another curve, and that curve hardly
    gave weight to the seats of other networks. Where the curve shares networks between
    seats, what it tested is parameter sharing (``SHARING``); else nothing of reuse (``NOT_REUSE``)."""
    if len(labels) != 2 or ev.algos.get(labels[0]) not in EQ9_ALGOS:
        return None
    a, s = labels[0], ev.summary.loc[labels[0]]
    if s["reusing"] >= REUSE_PART:
        return None
    if np.isnan(s["reusing"]):
        return NOT_REUSE, f"{a}'s runs hold no reuse matrix, so whether it reused is unknown"
    last = ("no seed ever gave another network's seats weight" if np.isnan(s["last_reuse_step"])
            else f"the gate last opened across networks at {s['last_reuse_step']:,.0f} steps")
    gap = (f"{last}; {a} reused across networks at {s['reusing']:.1%} of its evaluated iterations while it learned "
           f"(mean over seeds), below {REUSE_PART:.0%}")
    if ev.sharing.get(a):
        return SHARING, f"{gap}: its seats share networks, so the claim tests parameter sharing"
    return NOT_REUSE, gap


def check(ev: Evidence | None, test, labels, claim: str) -> Verdict:
    """``test(ev, *labels, claim)`` if the data can decide it (``RULE``, step 1), else a
    ``NOT_TESTABLE`` verdict saying why: for claims a notebook makes beyond the grid's. A claim
    that cannot test reuse (step 2) keeps the test's evidence under ``NOT_REUSE``."""
    if ev is None:
        return Verdict(claim, NOT_RUN, "", "", NO_RUN)
    why = _undecidable(ev, test, labels)
    if why:
        return Verdict(claim, NOT_TESTABLE, "", "", why)
    verdict, gap = test(ev, *labels, claim), None if test is selects else reuse_gap(ev, labels)
    if gap:  # the interval's reading stays beside the status that says what the runs tested
        verdict = replace(verdict, status=gap[0], reason=f"{gap[1]}; {INTERVAL_ALONE} {verdict.status}: {verdict.reason}")
    gaps = ev.runs.groupby("label")["gaps"].sum()
    gaps = [f"{int(gaps[x])} of {x}'s" for x in labels if gaps[x]]
    if gaps:  # (``per_run``) never silently: an evaluation without a value is left out of its run's numbers
        verdict = replace(verdict, reason=f"{verdict.reason}; {' and '.join(gaps)} evaluations hold no value (no "
                                          "evaluation episode ended) and are left out")
    return verdict


def claim_table(verdicts_by_budget: dict[str, list[Verdict]]) -> pd.DataFrame:
    """Tidy: one row per (budget, claim) with the interval the verdict reads, the verdict and why."""
    return pd.DataFrame([{"budget": budget, "claim": v.claim, "estimate [95% CI]": v.estimate,
                          "verdict": v.status, "why": v.reason}
                         for budget, vs in verdicts_by_budget.items() for v in vs])
