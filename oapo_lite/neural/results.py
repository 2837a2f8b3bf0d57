"""What a run's results rows hold (``results.csv``, and the run cache's copy): every column
beyond the config's, what it means, its type and range and when it may be empty; ``check``
refuses rows that break one, naming the column and the row.

A cell is empty (NaN) only where ``Column.empty`` says when. Matrices are n x n, with n the
run's seats, and vectors have n entries; the same n in every row of a file.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

DECIMALS = 6  # the reuse values' precision in the rows and the history (their digits beyond mean nothing)
ROUNDING = 1e-5  # matrices are stored to 6 decimals, so a row of M sums to 1 within n * 5e-7
# the values a learner reports that the rows and the history keep to DECIMALS
ROUNDED = frozenset({"kl_matrix", "reuse_matrix", "peer_share", "kl_nearest", "across_share", "agreement",
                     "peer_shares"})


def stored(values: dict) -> dict:
    """A learner's report (``learner.Update``'s metrics or detail) as the rows and the history
    keep it: the ``ROUNDED`` values to ``DECIMALS``, a number as a number, a list as a list."""
    out = dict(values)
    for key in ROUNDED & out.keys():
        v = out[key]
        out[key] = (round(v, DECIMALS) if isinstance(v, float) else
                    np.round(v, DECIMALS).tolist() if isinstance(v, list) else np.round(v, DECIMALS))
    return out


@dataclass(frozen=True)
class Column:
    meaning: str
    low: float = -math.inf
    high: float = math.inf
    integer: bool = False
    empty: str = ""  # when the cell may be empty; "" never. ``FIRST``: at the evaluation before training only
    shape: str = "number"  # "number", "matrix" (n x n), "vector" (n entries) or "text"
    infinite: bool = False  # +inf allowed (a KL against a policy that gives an action no probability)
    rows_sum_to_one: bool = False
    cumulative: bool = False  # a sum so far: never below its value at an earlier step of the run


FIRST = "at the evaluation before the first iteration"
NO_EPISODE = "where no evaluation episode ended (a real engine)"
UNMEASURED = "where the run was not measured (it resumed from a checkpoint written before costs were recorded)"

COLUMNS = {
    "iteration": Column("iterations trained before this evaluation", 0, integer=True),
    "step": Column("env steps trained before this evaluation", 0, integer=True),
    "eval_return": Column("mean team return of the evaluation episodes (each copy's first)", empty=NO_EPISODE),
    "frac_opt": Column("eval_return as a fraction of the maze's optimal team return", high=1 + ROUNDING,
                       empty="where the env has no oracle (a real engine)"),
    "eval_success": Column("share of evaluation episodes that succeeded (a maze's goal, a SMAX win, a GRF goal)",
                           0, 1, empty="where the env has no success rule (MaMuJoCo) or no evaluation episode ended"),
    "train_return": Column("mean team return of the episodes that ended in the last iteration's rollout",
                           empty=FIRST + ", or where no episode ended in that rollout"),
    "objective": Column("the learners' mean surrogate objective", empty=FIRST),
    "value_loss": Column("the critic's loss", 0, empty=FIRST),
    "policy_loss": Column("SEAC / SePS: the actors' mean policy loss", empty=FIRST),
    "entropy": Column("SEAC / SePS: the actors' mean policy entropy", empty=FIRST),
    "seac_weight": Column("SEAC: the mean importance weight of other agents' samples", 0,
                          empty="in a SePS run, or " + FIRST),
    "trpo_kl": Column("OATRPO / HATRPO: the mean KL of the accepted steps", 0,
                      empty="in a PPO-family run, " + FIRST + ", or where no step was accepted"),
    "trpo_accepted": Column("OATRPO / HATRPO: how many learners' steps the line search accepted", 0, integer=True,
                            empty=FIRST),
    "kl_matrix": Column("Eq. 9's K[i, j]: the KL of seat i's policy from seat j's on j's observations", 0,
                        empty=FIRST, shape="matrix", infinite=True),
    "reuse_matrix": Column("Eq. 9's M[i, j]: the weight learner i gives seat j's samples", 0, 1, empty=FIRST,
                           shape="matrix", rows_sum_to_one=True),
    "peer_share": Column("M's weight on other seats' samples, mean over learners", 0, 1 + ROUNDING, empty=FIRST),
    "across_share": Column("M's weight on the seats of other networks, mean over seats: the reuse the gate decided",
                           0, 1 + ROUNDING, empty=FIRST),
    "kl_nearest": Column("per seat, K to its nearest other seat", 0, empty=FIRST, shape="vector", infinite=True),
    "iterations_reusing": Column("share of the iterations so far with some weight on another seat", 0, 1,
                                 empty=FIRST),
    "agreement": Column("adaptive reuse: each source's gradient agreement with the learner's own (inf: itself)",
                        empty=FIRST, shape="matrix", infinite=True),
    "seps_groups": Column("SePS: its groups of seats", empty="before its groups are chosen", shape="text"),
    "owner": Column("the network of each seat (what the seats' reuse across networks is read against)", 0,
                    integer=True, shape="vector"),
    "agent_types": Column("each seat's agent type, as a JSON list", shape="text"),
    "cpu_s": Column("CPU seconds the run has cost so far (every thread; an engine's worker processes)", 0,
                    empty=UNMEASURED, cumulative=True),
    "wall_s": Column("wall seconds the run has taken so far", 0, empty=UNMEASURED, cumulative=True),
    "cpu_model": Column("the CPU the cost was measured on", empty=UNMEASURED, shape="text"),
    "cpu_count": Column("its logical cores", 1, integer=True, empty=UNMEASURED),
}
COST = ("cpu_s", "wall_s", "cpu_model", "cpu_count")  # what a run cost: no number of its learning
# what a run was, read by the study instead of the installed engines: no number of its learning
STRUCTURE = ("owner", "agent_types")
RETIRED = ("shared",)  # config fields since retired: older run files keep their columns, always empty


def learning(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` less what the run cost (``COST``): what repeats bit for bit for one config and seed."""
    return df.drop(columns=[c for c in COST if c in df])


class BadRows(ValueError):
    """A results row breaks its column's declaration; the message names the column and the row."""


def _fail(column: str, i: int, step, value, allowed: str) -> BadRows:
    at = f"row {i + 1}" + ("" if step is None else f" (step {step})")
    if isinstance(value, np.ndarray):
        value = value.tolist()
    elif isinstance(value, np.generic):
        value = value.item()
    return BadRows(f"its {column} column at {at} holds {value!r}; allowed: {allowed}")


def _allowed(c: Column) -> str:
    kind = {"number": "an integer" if c.integer else "a number", "matrix": "a square matrix",
            "vector": "a list of numbers", "text": "text"}[c.shape]
    low, high = c.low > -math.inf, c.high < math.inf
    bounds = ("" if c.shape == "text" else f" in [{c.low:g}, {c.high:.6g}]" if low and high
              else f" >= {c.low:g}" if low else f" <= {c.high:.6g}" if high else " (finite)")
    extra = (", rows summing to 1" if c.rows_sum_to_one else "") + (", +inf allowed" if c.infinite else "")
    return kind + bounds + extra + (f"; empty only {c.empty}" if c.empty else "; never empty")


def check(df: pd.DataFrame, config_columns) -> None:
    """Raise ``BadRows`` naming the first cell of one run's rows ``df`` (matrices already arrays)
    that breaks its column's declaration (``check_values``), or a column that is neither declared
    nor one of ``config_columns``."""
    unknown = [c for c in df.columns if c not in COLUMNS and c not in RETIRED and c not in config_columns
               and c != "git_rev"]
    if unknown:
        raise BadRows(f"it has columns no results row holds: {unknown}")
    kept = [c for c in RETIRED if c in df and df[c].notna().any()]
    if kept:
        raise BadRows(f"its retired {kept[0]} column holds values; allowed: empty")
    check_values(df)


def check_values(df: pd.DataFrame, runs=()) -> None:
    """Raise ``BadRows`` naming the first cell of ``df`` that breaks its declared column's type,
    range or emptiness (the columns ``COLUMNS`` does not declare are left alone), or where a
    cumulative column falls below its value at an earlier step of the same run. ``runs``: the
    columns that tell the runs of ``df`` apart; none: ``df`` is one run, else its runs were put
    together, where a column one run lacks is empty in the others' rows, so emptiness is not
    checked. The run files are read through it (``check``), and so is a frame of runs handed over
    in memory (``verdicts.judge``)."""
    steps = df["step"].tolist() if "step" in df else [None] * len(df)
    first = (df["iteration"] == 0).to_numpy() if "iteration" in df else np.zeros(len(df), bool)
    run_of = list(zip(*(df[k].astype(str) for k in runs))) if runs else [()] * len(df)
    sizes: dict[tuple, set] = {}  # per run, the seats its matrices and vectors have
    for name, c in COLUMNS.items():
        if name not in df:
            continue
        column = df[name]
        empty = column.isna().to_numpy()
        allowed_empty = (np.ones(len(df), bool) if runs or (c.empty and c.empty != FIRST) else
                         first if c.empty == FIRST else np.zeros(len(df), bool))
        wrong = empty & ~allowed_empty
        if c.shape == "number":
            x = pd.to_numeric(column, errors="coerce").to_numpy(float)
            with np.errstate(invalid="ignore"):
                wrong |= ~empty & (np.isnan(x) | ~np.isfinite(x) | (x < c.low) | (x > c.high)
                                   | (c.integer & (x != np.round(x))) | (column.map(type) == bool).to_numpy())
        else:
            for i in np.flatnonzero(~empty):
                wrong[i] = not _fits(column.iloc[i], c, sizes.setdefault(run_of[i], set()))
                if wrong[i]:
                    break
        if wrong.any():
            i = int(np.flatnonzero(wrong)[0])
            seats = sizes.get(run_of[i], set())
            allowed = (_allowed(c) if len(seats) < 2 else
                       f"the same number of seats in every matrix ({sorted(seats)} here)")
            raise _fail(name, i, steps[i], column.iloc[i], allowed)
        if c.cumulative:
            i, before = _falls(df, name, list(runs))
            if i is not None:
                raise _fail(name, i, steps[i], column.iloc[i],
                            f"a number >= {before!r}, its value at an earlier step of the run (it sums the run so far)")


def _falls(df: pd.DataFrame, name: str, runs: list[str]) -> tuple[int | None, float | None]:
    """The position of the first row where the cumulative column ``name`` is below the largest
    value of its run at an earlier step, and that value; (None, None) where it never falls."""
    frame = pd.DataFrame({"x": pd.to_numeric(df[name], errors="coerce").to_numpy(float), "at": np.arange(len(df)),
                          "step": df["step"].to_numpy() if "step" in df else np.arange(len(df)),
                          **{f"run {k}": df[k].astype(str).to_numpy() for k in runs}})
    keys = [f"run {k}" for k in runs] or (lambda _: 0)
    frame = frame.sort_values([*(f"run {k}" for k in runs), "step"], kind="stable")
    before = frame.groupby(keys)["x"].transform(lambda x: x.cummax().shift())
    fell = (frame["x"] < before).to_numpy()  # NaN (unmeasured) never falls
    if not fell.any():
        return None, None
    first = frame[fell].sort_values("at").iloc[0]
    return int(first["at"]), float(before[first.name])


def _fits(value, c: Column, sizes: set) -> bool:
    """Whether a matrix, vector or text cell fits ``c``; adds a matrix's or vector's size to ``sizes``."""
    if c.shape == "text":
        return isinstance(value, str)
    try:
        x = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        return False
    if x.ndim != (2 if c.shape == "matrix" else 1) or not x.size or (x.ndim == 2 and x.shape[0] != x.shape[1]):
        return False
    sizes.add(x.shape[0])
    finite = np.isfinite(x) | (c.infinite & (x == np.inf))
    return bool(finite.all() and (x >= c.low).all() and (x <= c.high).all() and len(sizes) == 1
                and not (c.rows_sum_to_one and (np.abs(x.sum(axis=1) - 1) > ROUNDING).any()))
