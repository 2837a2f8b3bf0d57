import numpy as np
import pandas as pd

from oapo_lite.study.studies import gate_study


def _rows(env: str, values: dict, same_kind=(True, False), gap: dict | None = None) -> list[dict]:
    """Two learners, each with one peer; ``values[stat]`` is K per iteration of the first pair,
    the second (cross-type) pair is ``gap[stat]`` (default 1) farther."""
    gap = {s: 1.0 for s in values} | (gap or {})
    return [{"env": env, "seed": 0, "iteration": it + 1, "step": (it + 1) * 100, "learner": learner,
             "peer": 1 - learner, "same_kind": same, **{s: v[it] + (0.0 if same else gap[s]) for s, v in values.items()}}
            for it in range(len(next(iter(values.values())))) for learner, same in enumerate(same_kind)]


def test_summary_counts_open_iterations_pairs_and_the_kind_separation():
    df = pd.DataFrame(_rows("smax:2s3z", {"max": [5.0, 5.0, 5.0, 5.0], "mean": [0.0, 0.05, 0.5, 5.0],
                                          "q90": [0.05, 5.0, 5.0, 5.0]}))
    t = gate_study.summary(df, sigmas=(0.1,)).xs(0.1, level="sigma").loc["smax:2s3z"]
    # the same-type pair is within 0.1 at iterations 1-2 (mean), 1 (q90), never (max)
    assert t["any open"].to_dict() == {"max": 0.0, "mean": 0.5, "q90": 0.25}
    assert t["open"].to_dict() == {"max": 0.0, "mean": 0.25, "q90": 0.125}
    assert t["last open"].to_dict() == {"max": 0, "mean": 200, "q90": 100}
    assert (t["auc"] == 1.0).all()  # the same-type pair is always the nearer one


def test_choose_follows_the_rule_fixed_before_the_runs():
    """(1) open >= 0.25 and (2) pairs <= 0.9 everywhere, then the largest 2s3z auc; else the
    statistic passing (2) with the largest smallest open share."""
    both = pd.DataFrame(_rows("smax:2s3z", {"max": [5.0] * 4, "mean": [0.0, 0.0, 5.0, 5.0], "q90": [0.0] * 4},
                              gap={"q90": 0.0}))
    table = gate_study.summary(both, sigmas=(gate_study.SIGMA,))
    assert gate_study.choose(table)[0] == "mean"  # q90 fails (2): every pair is within sigma all the time
    both = pd.DataFrame(_rows("smax:2s3z", {"max": [5.0] * 4, "mean": [0.0, 0.0, 5.0, 5.0], "q90": [0.0] * 4},
                              gap={"mean": 0.0, "q90": 0.5}))
    assert gate_study.choose(gate_study.summary(both, sigmas=(gate_study.SIGMA,)))[0] == "q90"  # both pass; larger auc
    few = pd.DataFrame(_rows("smax:2s3z", {"max": [5.0] * 8, "mean": [0.0] + [5.0] * 7, "q90": [5.0] * 8}))
    stat, why = gate_study.choose(gate_study.summary(few, sigmas=(gate_study.SIGMA,)))
    assert stat == "mean" and "none keeps the gate open" in why
    assert np.isnan(gate_study.summary(pd.DataFrame(_rows("smax:3m", {s: [0.0] for s in ("max", "mean", "q90")},
                                                          same_kind=(True, True))), sigmas=(0.1,))["auc"]).all()
