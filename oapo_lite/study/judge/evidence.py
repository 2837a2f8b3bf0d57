"""What a figure's runs give a verdict to read: per run, its speed, final value and how much it
reused across networks; per curve, those numbers over seeds with interval estimates.

Input: one row per (run, evaluation point) with columns ``label`` (the curve), ``seed``, ``step``
(env steps) and the metric's column (``catalogue.metrics``: a fraction of the optimum, a win rate,
a return); where the runs reuse by Eq. 9, also ``reuse_matrix`` (M at evaluated iterations),
``owner`` (each seat's network, as the run recorded it) and ``algo``. A run is one (label, seed).

Per run: the env steps it took to first reach the metric's threshold (censored at its last step
if it never did), its final value (mean over the last ``tail`` of its evaluation points, at
least ``FINAL_MIN``), its initial value (its first ``INITIAL``), its largest drop below an earlier
peak, and, from M and the owner map, how it reused the seats of other networks: at what share of
its evaluated iterations *while it learned* (``LEARNED``: up to its first evaluation at 90% of its
way from its initial to its final value, the same for a win rate, a return and a fraction of the
optimum; all of them if it gained nothing) and overall, and the last step its gate let another
network's seats in (``last_reuse_step``)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from oapo_lite.algorithms import ALGOS
from oapo_lite.reuse import peer_share
from oapo_lite.study.catalogue.metrics import FINAL_MIN, FRAC_OPT, Metric
from oapo_lite.study.judge.statistics import Interval, bootstrap_interval, iqm, probability_of_improvement

INITIAL = 0.1  # a run's initial level: its first tenth of evaluation points (the untrained policy at step 0)
LEARNED = 0.9  # a run has learned once it first reaches this share of its way from its initial to its final value
# a curve reusing by Eq. 9 tests reuse when it gave other networks' seats weight at this share of
# its evaluated iterations while it learned (the gate-statistic study's rule too); a gate that last
# opened within this share of a run's steps shut for good early
REUSE_PART = 0.25
EQ9_ALGOS = tuple(a for a, spec in ALGOS.items() if spec.reuse_rule == "oapo")
# per-run numbers a verdict reads; "steps" and "drawdown" are better when lower
RUN_STATS = {"steps": "steps_to_threshold", "final": "final", "drawdown": "drawdown", "reached": "reached"}
LOWER_IS_BETTER = ("steps", "drawdown")
PER_RUN_COLUMNS = ["label", "seed", "steps_to_threshold", "reached", "initial", "final", "peak", "drawdown",
                   "learned_at", "last_step", "reusing", "reusing_overall", "last_reuse_step", "gate_open", "networks",
                   "gaps"]


def _checked(df: pd.DataFrame, y: str) -> pd.DataFrame:
    if not isinstance(df, pd.DataFrame):
        raise TypeError(f"the runs must be a pandas DataFrame (e.g. experiments.load_figure's), got {type(df).__name__}")
    if df.empty:
        return pd.DataFrame(columns=["label", "seed", "step", y])
    lacking = [c for c in ("label", "seed", "step", y) if c not in df]
    if lacking:
        raise ValueError(f"the runs lack the columns {lacking}; they need label, seed, step and {y!r} "
                         "(e.g. experiments.load_figure's rows)")
    if len(df) and not pd.api.types.is_numeric_dtype(df[y]):
        raise ValueError(f"the runs' {y!r} column holds text (e.g. {df[y].iloc[0]!r}); allowed: numbers")
    if "reuse_matrix" in df and df["reuse_matrix"].notna().any() and "owner" not in df:
        raise ValueError("the runs hold reuse matrices but no owner column (each seat's network, which every run "
                         "records); runs written before it: `python -m oapo_lite.study.runs.migrate`")
    twice = df[df.duplicated(["label", "seed", "step"])]
    if len(twice):
        first = twice.iloc[0]
        raise ValueError(f"curve {first['label']!r} has two rows for seed {first['seed']} at step {first['step']}; "
                         "a run has one row per evaluation (two runs with one seed under one label?)")
    return df


def across_shares(run: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    """(step, M's weight on the seats of other networks) at a run's evaluated iterations that
    recorded M (none for SEAC, SePS, or rows without the column), each row's M read against the
    owner map the run recorded in that row."""
    if "reuse_matrix" not in run:
        return np.zeros(0), np.zeros(0)
    run = run[run["reuse_matrix"].notna()]
    shares = [peer_share(m, list(np.asarray(o, int))) for m, o in zip(run["reuse_matrix"], run["owner"])]
    return run["step"].to_numpy(float), np.asarray(shares, float)


def gate_open(run: pd.DataFrame) -> float:
    """The share of a run's (evaluated iteration, learner, source on another network) whose K was
    within the run's sigma (NaN where the rows hold no K or no sigma): 1 for a gate that never shut."""
    if not {"kl_matrix", "sigma", "owner"} <= set(run.columns):
        return np.nan
    run = run[run["kl_matrix"].notna()]
    k = [np.asarray(m, float)[~np.equal.outer(o, o)] for m, o in zip(run["kl_matrix"], run["owner"])]
    k = np.concatenate(k) if k else np.zeros(0)
    return float(np.mean(k <= float(run["sigma"].iloc[0]))) if len(k) else np.nan


def learned_at(steps: np.ndarray, values: np.ndarray, initial: float, final: float) -> float:
    """The step at which a run first reached ``LEARNED`` of its way from ``initial`` to ``final``
    (its last step if it gained nothing): where its learning is counted to end."""
    if not final > initial:
        return float(steps[-1])
    with np.errstate(invalid="ignore"):
        hit = steps[values >= initial + LEARNED * (final - initial)]
    return float(hit[0]) if len(hit) else float(steps[-1])


def per_run(df: pd.DataFrame, metric: Metric = FRAC_OPT, threshold: float | None = None) -> pd.DataFrame:
    """One row per run (module docstring), in ``PER_RUN_COLUMNS``; ``gaps``: evaluations whose value
    is empty (an engine's evaluation in which no episode ended), which every number leaves out and
    a verdict names; ``networks``: how many networks its seats had (NaN without an owner map)."""
    if not isinstance(metric, Metric):
        raise TypeError(f"metric must be a catalogue.metrics.Metric (e.g. WIN_RATE), got {type(metric).__name__}")
    y, tail = metric.column, metric.tail
    threshold = metric.threshold if threshold is None else threshold
    if not (isinstance(threshold, (int, float)) and not np.isnan(threshold)):
        raise ValueError(f"threshold = {threshold!r} is invalid; allowed: a number (inf: never reached)")
    if not (isinstance(tail, (int, float)) and 0 < tail <= 1):
        raise ValueError(f"tail = {tail!r} is invalid; allowed: a share of the evaluation points in (0, 1]")
    rows = []
    for (label, seed), run in _checked(df, y).sort_values("step", kind="stable").groupby(["label", "seed"], sort=False):
        steps_all, values = run["step"].to_numpy(float), run[y].to_numpy(float)
        hit = steps_all[values >= threshold]
        k, k0 = max(FINAL_MIN, int(round(tail * len(run)))), max(1, int(round(INITIAL * len(run))))
        held = run[y].dropna()  # the windows hold k and k0 evaluations with a value
        initial, final = float(held.iloc[:k0].mean()), float(held.iloc[-k:].mean())
        end = learned_at(steps_all, values, initial, final)
        steps, shares = across_shares(run)
        learning = steps <= max(end, steps[0]) if len(steps) else steps.astype(bool)
        owner = run["owner"].dropna().iloc[0] if "owner" in run and run["owner"].notna().any() else None
        rows.append({
            "label": label, "seed": seed,
            "steps_to_threshold": float(hit[0]) if len(hit) else float(steps_all.max()),
            "reached": bool(len(hit)), "initial": initial, "final": final, "peak": float(np.nanmax(values)),
            "drawdown": float((run[y].cummax() - run[y]).max()),
            "learned_at": end, "last_step": float(steps_all.max()),
            "reusing": float(np.mean(shares[learning] > 0)) if learning.any() else np.nan,
            "reusing_overall": float(np.mean(shares > 0)) if len(shares) else np.nan,
            "last_reuse_step": float(steps[shares > 0].max()) if (shares > 0).any() else np.nan,
            "gate_open": gate_open(run),
            "networks": len(set(np.asarray(owner, int).tolist())) if owner is not None else np.nan,
            "gaps": int(run[y].isna().sum()),
        })
    return pd.DataFrame(rows, columns=PER_RUN_COLUMNS)  # the columns even for a frame with no run


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
        "reusing_overall": g["reusing_overall"].mean(),
        "last_reuse_step": g["last_reuse_step"].max(),
    })


def summary(df: pd.DataFrame, metric: Metric = FRAC_OPT, threshold: float | None = None) -> pd.DataFrame:
    """Per label: mean and std over seeds of steps-to-threshold and final value, and reuse."""
    return _summary_of(per_run(df, metric, threshold))


@dataclass(frozen=True)
class Reuse:
    """How a curve reused the seats of other networks, over its seeds (``per_run``): the mean share
    of its evaluated iterations with some weight there while it learned and overall; the last step
    any seed's gate let another network in (NaN: never); the seeds whose gate last opened within
    ``REUSE_PART`` of their steps, or never (shut for good early), and those whose gate never shut
    (every across-network K within sigma at every evaluated iteration); how many networks its seats
    had (the gate of one of them has ``networks - 1`` to choose between); whether seats share networks."""

    curve: object
    seeds: int
    while_learning: float
    overall: float
    last_open: float
    shut_early: int
    never_shut: int
    networks: int
    sharing: bool

    @property
    def peers(self) -> int:
        return self.networks - 1


class Evidence:
    """One figure's (or env's) runs and the per-curve numbers every verdict reads. ``without``
    gives the same evidence less one seed (the leave-one-seed-out check)."""

    def __init__(self, df: pd.DataFrame, metric: Metric = FRAC_OPT, threshold: float | None = None):
        self.metric = metric
        self.threshold = metric.threshold if threshold is None else threshold
        self.runs = per_run(df, metric, self.threshold)
        # each curve's algorithm (where the data names it): which curves reuse by Eq. 9
        self.algos = df.groupby("label", sort=False)["algo"].first().to_dict() if "algo" in df and len(df) else {}
        # a run without an owner map (a single-agent anchor) has no seats to count
        owned = df[df["owner"].notna()] if "owner" in df else None
        self.seats = ({} if owned is None else
                      owned.groupby("label", sort=False)["owner"].first().map(lambda o: len(np.asarray(o))).to_dict())
        self.summary = _summary_of(self.runs)

    def without(self, seed) -> "Evidence":
        """This evidence less the runs of ``seed``."""
        ev = object.__new__(Evidence)
        ev.metric, ev.threshold, ev.algos, ev.seats = self.metric, self.threshold, self.algos, self.seats
        ev.runs = self.runs[self.runs["seed"] != seed]
        ev.summary = _summary_of(ev.runs)
        return ev

    @property
    def labels(self) -> list:
        return list(self.summary.index)

    def seeds(self, *labels) -> list:
        """The seeds every one of ``labels`` has a run of."""
        sets = [set(self.runs.loc[self.runs["label"] == x, "seed"]) for x in labels]
        return sorted(set.intersection(*sets)) if sets else []

    def run_values(self, label, stat: str) -> np.ndarray:
        """Per-seed values of the per-run statistic ``stat`` (a key of ``RUN_STATS``) for one curve."""
        if stat not in RUN_STATS:
            raise ValueError(f"unknown run statistic {stat!r}; choose from {sorted(RUN_STATS)}")
        if label not in self.summary.index:
            raise ValueError(f"no runs labelled {label!r}; labels are {self.labels}")
        return self.runs.loc[self.runs["label"] == label, RUN_STATS[stat]].to_numpy(float)

    def level(self, label, stat: str) -> Interval:
        """IQM over seeds of ``stat`` with its 95% interval."""
        return bootstrap_interval(iqm, self.run_values(label, stat))

    def improvement(self, a, b, stat: str) -> Interval:
        """P(a better than b) on ``stat`` with its 95% interval; fewer steps or a smaller drawdown is better."""
        sign = -1.0 if stat in LOWER_IS_BETTER else 1.0
        return bootstrap_interval(probability_of_improvement, sign * self.run_values(a, stat),
                                  sign * self.run_values(b, stat))

    def pairs(self, a, b, stat: str = "final") -> pd.DataFrame:
        """Per seed that has runs of both: a's and b's ``stat`` and ``difference`` = a - b (for a
        statistic where lower is better, b - a: positive means a is better)."""
        absent = [x for x in (a, b) if x not in self.summary.index]
        if absent:
            raise ValueError(f"no runs labelled {absent} to pair; the runs' labels are {self.labels}")
        if a == b:
            raise ValueError(f"a and b are both {a!r}; a pair compares two curves")
        col = RUN_STATS[stat]
        runs = self.runs[self.runs["label"].isin([a, b])].pivot(index="seed", columns="label", values=col)
        runs = runs.reindex(columns=[a, b]).dropna()
        if runs.empty:
            raise ValueError(f"no seed has runs of both {a!r} and {b!r}, so there is no pair to compare")
        sign = -1.0 if stat in LOWER_IS_BETTER else 1.0
        return runs.assign(difference=sign * (runs[a] - runs[b]))

    def paired(self, a, b, stat: str = "final") -> Interval:
        """The IQM over seeds of a's ``stat`` minus b's, seed by seed (``pairs``), its 95% interval
        from resampling the pairs whole (one seed gives both runs the same initial networks and
        environments): the curves' own estimator, so that one seed far from the rest moves it as
        little as it moves the curves' IQMs."""
        return bootstrap_interval(iqm, self.pairs(a, b, stat)["difference"].to_numpy())

    def reuse(self, label) -> Reuse:
        """``Reuse`` of curve ``label``."""
        runs = self.runs[self.runs["label"] == label]
        early = runs["last_reuse_step"].isna() | (runs["last_reuse_step"] <= REUSE_PART * runs["last_step"])
        s = self.summary.loc[label]
        networks = runs["networks"].dropna()
        return Reuse(label, int(s["seeds"]), float(s["reusing"]), float(s["reusing_overall"]),
                     float(s["last_reuse_step"]), int(early.sum()), int((runs["gate_open"] == 1.0).sum()),
                     int(networks.min()) if len(networks) else 0,
                     bool(len(networks) and networks.min() < self.seats.get(label, 0)))


def intervals(df: pd.DataFrame, metric: Metric = FRAC_OPT, threshold: float | None = None) -> pd.DataFrame:
    """Per label: IQM over seeds of steps-to-threshold and final value, with 95% intervals."""
    ev = Evidence(df, metric, threshold)
    rows = {}
    for label in ev.labels:
        row = {"seeds": ev.summary.loc[label, "seeds"], "reached": ev.summary.loc[label, "reached"]}
        for stat in ("steps", "final"):
            est = ev.level(label, stat)
            row |= {f"{stat}_iqm": est.point, f"{stat}_low": est.low, f"{stat}_high": est.high}
        rows[label] = row
    columns = ["seeds", "reached"] + [f"{stat}_{part}" for stat in ("steps", "final") for part in ("iqm", "low", "high")]
    return pd.DataFrame.from_dict(rows, orient="index", columns=columns).rename_axis("label")


LEARN_SE = 2.0  # a curve learned when its gain exceeds this many standard errors over seeds


@dataclass(frozen=True)
class NotLearned:
    """Why a curve did not learn at this budget: its gain over seeds against ``LEARN_SE`` standard
    errors, and its final IQM against the metric's floor (``failures`` names the tests it failed)."""

    curve: object
    seeds: int
    initial: float
    final_mean: float
    gain: float
    gain_se: float
    final_iqm: float
    floor: float
    failures: tuple[str, ...]  # "gain", "floor"


def not_learned(ev: Evidence, label) -> NotLearned | None:
    """Why curve ``label`` did not learn (None: it learned): its gain must exceed ``LEARN_SE``
    standard errors of the gain over seeds, and its final IQM the metric's floor."""
    s, floor, final = ev.summary.loc[label], ev.metric.floor, ev.level(label, "final").point
    failures = (("gain",) if not (s["gain_mean"] > LEARN_SE * s["gain_se"] and s["gain_mean"] > 0) else ()) + \
        (("floor",) if final <= floor else ())
    if not failures:
        return None
    return NotLearned(label, int(s["seeds"]), float(s["initial_mean"]), float(s["final_mean"]), float(s["gain_mean"]),
                      float(s["gain_se"]), float(final), float(floor), failures)


def learned(ev: Evidence, label) -> bool:
    """Whether curve ``label`` learned at this budget (``not_learned``)."""
    return not_learned(ev, label) is None
