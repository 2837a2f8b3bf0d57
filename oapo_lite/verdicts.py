"""Did a paper claim reproduce? Computed from tidy run data, never typed by hand.

Input: one row per (run, evaluation point) with columns ``label`` (the curve: an
algorithm, a sigma, a scheme...), ``seed``, ``step`` (env steps) and ``frac_opt`` (return
as a fraction of the oracle optimum). A run is one (label, seed). Figures without an oracle
(the real engines) are judged on another column, ``METRIC[figure]`` (the evaluation return).

Two numbers summarise a run: the env steps it took to first reach ``threshold`` of the
optimum (censored at its last step if it never did), and its final fraction of the optimum
(mean over the last ``tail`` share of its evaluation points). A comparison "A beats B"
is *reproduced* when the means differ in the claimed direction by more than twice the
combined standard error over seeds (std with ddof = 1), *direction only* when they differ in
that direction by less, and *not reproduced* otherwise. "Faster" also needs at least as many
seeds to have reached the threshold: a censored seed never counts in a run's favour.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

THRESHOLD = 0.95
FINAL_TIE = 0.02  # final fractions closer than this count as a tie, decided by speed
REPRODUCED, DIRECTION, NOT = "reproduced", "direction only (within noise)", "not reproduced"
NO_DATA = "no data yet"
FINAL_NAMES = {"frac_opt": "final fraction of the optimum", "eval_return": "final evaluation return"}


def per_run(df: pd.DataFrame, threshold: float = THRESHOLD, tail: float = 0.1, y: str = "frac_opt") -> pd.DataFrame:
    """One row per run: steps to threshold (censored), whether it got there, final value of ``y``."""
    rows = []
    for (label, seed), run in df.sort_values("step", kind="stable").groupby(["label", "seed"], sort=False):
        hit = run.loc[run[y] >= threshold, "step"]
        k = max(1, int(round(tail * len(run))))
        rows.append({
            "label": label,
            "seed": seed,
            "steps_to_threshold": float(hit.iloc[0]) if len(hit) else float(run["step"].max()),
            "reached": bool(len(hit)),
            "final_frac": float(run[y].iloc[-k:].mean()),
        })
    return pd.DataFrame(rows)


def summary(df: pd.DataFrame, threshold: float = THRESHOLD, y: str = "frac_opt") -> pd.DataFrame:
    """Per label: mean and std over seeds of steps-to-threshold and final value of ``y``."""
    runs = per_run(df, threshold, y=y)
    g = runs.groupby("label", sort=False)
    out = pd.DataFrame({
        "seeds": g.size(),
        "reached": g["reached"].sum().astype(int),
        "steps_mean": g["steps_to_threshold"].mean(),
        "steps_std": g["steps_to_threshold"].std(ddof=1).fillna(0.0),
        "final_mean": g["final_frac"].mean(),
        "final_std": g["final_frac"].std(ddof=1).fillna(0.0),
    })
    out.attrs["y"] = y
    return out


@dataclass(frozen=True)
class Verdict:
    claim: str
    status: str
    evidence: str

    @property
    def held(self) -> bool:
        return self.status == REPRODUCED

    def sentence(self) -> str:
        return f"{self.claim}: {self.status}. {self.evidence}"


def _stderr(s: pd.DataFrame, label, col: str) -> float:
    """Standard error over seeds; with one seed the noise is unknown, so nothing beats it."""
    seeds = int(s.loc[label, "seeds"])
    return float(s.loc[label, f"{col}_std"]) / np.sqrt(seeds) if seeds > 1 else np.inf


NOISE_SE = 2.0  # a difference must exceed this many combined standard errors


def _status(diff: float, noise: float) -> str:
    if diff > NOISE_SE * noise:
        return REPRODUCED
    return DIRECTION if diff > 0 else NOT


def faster(s: pd.DataFrame, a, b, claim: str) -> Verdict:
    """Claim: ``a`` reaches the threshold in fewer env steps than ``b``."""
    diff = s.loc[b, "steps_mean"] - s.loc[a, "steps_mean"]
    noise = np.hypot(_stderr(s, a, "steps"), _stderr(s, b, "steps"))
    status = NOT if s.loc[a, "reached"] < s.loc[b, "reached"] else _status(diff, noise)
    return Verdict(claim, status, f"steps to {THRESHOLD:.0%} of the optimum: "
                   f"{_fmt_steps(s, a)} vs {_fmt_steps(s, b)}.")


def higher(s: pd.DataFrame, a, b, claim: str) -> Verdict:
    """Claim: ``a`` ends at a higher fraction of the optimum than ``b``."""
    diff = s.loc[a, "final_mean"] - s.loc[b, "final_mean"]
    noise = np.hypot(_stderr(s, a, "final"), _stderr(s, b, "final"))
    return Verdict(claim, _status(diff, noise),
                   f"{FINAL_NAMES[s.attrs.get('y', 'frac_opt')]}: {_fmt_final(s, a)} vs {_fmt_final(s, b)}.")


def better(s: pd.DataFrame, a, b, claim: str) -> Verdict:
    """Claim: ``a`` is better than ``b``: higher at the end or, where both end within
    ``FINAL_TIE`` of each other, faster to the threshold."""
    by_final = higher(s, a, b, claim)
    if abs(s.loc[a, "final_mean"] - s.loc[b, "final_mean"]) > FINAL_TIE:
        return by_final
    by_speed = faster(s, a, b, claim)
    return Verdict(claim, by_speed.status, f"{by_final.evidence[:-1]}; {by_speed.evidence}")


def stuck(s: pd.DataFrame, a, claim: str, threshold: float = THRESHOLD) -> Verdict:
    """Claim: ``a`` stays below ``threshold`` of the optimum (a local optimum)."""
    gap = threshold - s.loc[a, "final_mean"]
    return Verdict(claim, _status(gap, _stderr(s, a, "final")),
                   f"final fraction {_fmt_final(s, a)}; {s.loc[a, 'reached']} of "
                   f"{s.loc[a, 'seeds']} seeds ever reached {threshold:.0%}.")


def optimal(s: pd.DataFrame, a, claim: str, threshold: float = THRESHOLD) -> Verdict:
    """Claim: ``a`` reaches ``threshold`` of the optimum and stays there."""
    gap = s.loc[a, "final_mean"] - threshold
    return Verdict(claim, _status(gap + 1e-12, _stderr(s, a, "final")),
                   f"final fraction {_fmt_final(s, a)}; {s.loc[a, 'reached']} of "
                   f"{s.loc[a, 'seeds']} seeds reached {threshold:.0%}.")


def _fmt_steps(s, label) -> str:
    return (f"{label} {s.loc[label, 'steps_mean']:,.0f} +- {s.loc[label, 'steps_std']:,.0f} "
            f"({s.loc[label, 'reached']}/{s.loc[label, 'seeds']} seeds reached)")


def _fmt_final(s, label) -> str:
    return f"{label} {s.loc[label, 'final_mean']:.3f} +- {s.loc[label, 'final_std']:.3f}"


# The claims of Section 6.1, as data: (test, the curves it compares, the paper's claim).
CLAIMS = {
    "fig3b": [
        (stuck, ("mappo",), "MAPPO (shared parameters) stays below the optimum"),
        (faster, ("oappo", "happo"), "OAPPO converges faster than HAPPO"),
        (faster, ("oatrpo", "happo"), "OATRPO converges faster than HAPPO"),
        (higher, ("oappo", "mappo"), "OAPPO ends above MAPPO"),
        (higher, ("oatrpo", "mappo"), "OATRPO ends above MAPPO"),
        (faster, ("oatrpo", "oappo"), "OATRPO converges faster than OAPPO"),
    ],
    "fig3c": [
        (better, (0.1, 0.01), "sigma = 0.1 beats sigma = 0.01 (own experience only is slower)"),
        (better, (0.1, 1.0), "sigma = 0.1 beats sigma = 1 (irrelevant experience confuses)"),
        (better, (0.1, 10.0), "sigma = 0.1 beats sigma = 10 (all peers' experience hinders)"),
    ],
    "fig3d": [
        (better, (0.7, 0.4), "lambda = 0.7 is marginally better than lambda = 0.4"),
        (better, (0.4, 1.0), "lambda = 0.4 beats lambda = 1 (own experience only)"),
        (better, (0.4, 0.2), "lambda = 0.4 beats lambda = 0.2 (mostly others' experience)"),
    ],
    "fig5b": [
        (stuck, ("UR",), "UR (red and black share) gets stuck below the optimum"),
        (stuck, ("AR",), "AR (everyone shares) gets stuck below the optimum"),
        (optimal, ("RR",), "RR (black and blue share) reaches the optimum"),
        (optimal, ("NR",), "NR (no reuse) reaches the optimum"),
    ],
    # App. A (see ASSUMPTIONS.md): on homogeneous agents, reusing others' experience as it is
    # (SEAC's importance-weighted reuse; MAPPO's one network on everyone's data) ends lower
    # than using one's own (HAPPO), while OAPPO's gated reuse does not
    "figA_mamujoco": [
        (higher, ("happo", "seac"), "direct reuse (SEAC) ends below no reuse (HAPPO)"),
        (higher, ("happo", "mappo"), "full sharing (MAPPO) ends below no reuse (HAPPO)"),
        (higher, ("oappo", "seac"), "OAPPO ends above direct reuse (SEAC)"),
        (higher, ("oappo", "mappo"), "OAPPO ends above full sharing (MAPPO)"),
    ],
}


METRIC = {"figA_mamujoco": "eval_return"}  # figures judged on something else than frac_opt


def claims(figure: str, df: pd.DataFrame) -> list[Verdict]:
    """Check every claim the paper makes about ``figure`` against that figure's data; a claim
    about a curve with no runs yet gets the status ``NO_DATA``."""
    if figure not in CLAIMS:
        raise ValueError(f"no claims recorded for figure {figure!r}; choose from {sorted(CLAIMS)}")
    s = summary(df, y=METRIC.get(figure, "frac_opt")) if len(df) else pd.DataFrame()
    out = []
    for test, labels, claim in CLAIMS[figure]:
        absent = [label for label in labels if label not in s.index]
        out.append(Verdict(claim, NO_DATA, f"no runs of {absent}.") if absent else test(s, *labels, claim))
    return out
