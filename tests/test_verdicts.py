"""Verdicts are functions of the data: synthetic curves with a known answer."""
import numpy as np
import pandas as pd
import pytest

from oapo_lite import verdicts as v


def curves(spec, seeds=5, steps=np.arange(0, 100_001, 5_000), noise=0.0):
    """spec: label -> (steps at which the curve hits 1.0 (linear ramp from 0), plateau)."""
    rng = np.random.default_rng(0)
    rows = []
    for label, (reach, plateau) in spec.items():
        for seed in range(seeds):
            r = reach * (1 + noise * rng.standard_normal())
            frac = np.minimum(steps / r, 1.0) * plateau
            rows += [dict(label=label, seed=seed, step=s, frac_opt=f) for s, f in zip(steps, frac)]
    return pd.DataFrame(rows)


def test_per_run_steps_and_censoring():
    df = curves({"a": (40_000, 1.0), "b": (40_000, 0.5)}, seeds=1)
    runs = v.per_run(df).set_index("label")
    assert runs.loc["a", "steps_to_threshold"] == 40_000  # first grid point with 40k/40k >= 0.95
    assert runs.loc["a", "reached"] and not runs.loc["b", "reached"]
    assert runs.loc["b", "steps_to_threshold"] == 100_000  # censored at the last step
    assert runs.loc["b", "final_frac"] == pytest.approx(0.5)


def test_faster_and_higher_directions():
    df = curves({"fast": (20_000, 1.0), "slow": (80_000, 1.0), "low": (20_000, 0.5)}, noise=0.05)
    s = v.summary(df)
    assert v.faster(s, "fast", "slow", "x").status == v.REPRODUCED
    assert v.faster(s, "slow", "fast", "x").status == v.NOT
    assert v.higher(s, "fast", "low", "x").status == v.REPRODUCED
    assert v.higher(s, "low", "fast", "x").status == v.NOT


def test_within_noise_is_direction_only():
    df = curves({"a": (50_000, 1.0), "b": (51_000, 1.0)}, noise=0.3)
    s = v.summary(df)
    verdict = v.faster(s, "a", "b", "a faster")
    assert verdict.status in (v.DIRECTION, v.NOT) and not verdict.held


def test_better_uses_final_then_speed():
    df = curves({"hi": (80_000, 1.0), "lo": (10_000, 0.6), "twin": (20_000, 1.0)})
    s = v.summary(df)
    assert v.better(s, "hi", "lo", "x").held  # higher plateau wins despite being slower
    assert not v.better(s, "lo", "hi", "x").held
    assert v.better(s, "twin", "hi", "x").held  # same plateau: decided by speed


def test_stuck_and_optimal():
    df = curves({"stuck": (10_000, 0.5), "ok": (10_000, 1.0)})
    s = v.summary(df)
    assert v.stuck(s, "stuck", "x").held and not v.stuck(s, "ok", "x").held
    assert v.optimal(s, "ok", "x").held and not v.optimal(s, "stuck", "x").held


def test_figure_claims_follow_the_data():
    good = curves({"mappo": (20_000, 0.5), "happo": (90_000, 1.0), "oappo": (50_000, 1.0),
                   "oatrpo": (30_000, 1.0)})
    assert all(x.held for x in v.claims("fig3b", good))
    bad = curves({"mappo": (20_000, 1.0), "happo": (30_000, 1.0), "oappo": (50_000, 1.0),
                  "oatrpo": (90_000, 1.0)})
    held = {x.claim: x.held for x in v.claims("fig3b", bad)}
    assert not held["MAPPO (shared parameters) stays below the optimum"]
    assert not held["OATRPO converges faster than OAPPO"]
    sentence = v.claims("fig3b", bad)[0].sentence()
    assert "not reproduced" in sentence and "mappo 1.000" in sentence


def test_one_seed_is_never_more_than_direction():
    df = curves({"fast": (20_000, 1.0), "slow": (80_000, 1.0)}, seeds=1)
    verdict = v.faster(v.summary(df), "fast", "slow", "x")
    assert verdict.status == v.DIRECTION


def test_censored_seeds_never_make_a_run_faster():
    # a: 3 seeds converge at 20k, 2 never do; b: every seed converges, later.
    a = curves({"a": (20_000, 1.0)}, seeds=3)
    a_stuck = curves({"a": (20_000, 0.5)}, seeds=2).assign(seed=lambda d: d["seed"] + 3)
    b = curves({"b": (70_000, 1.0)})
    s = v.summary(pd.concat([a, a_stuck, b]))
    assert s.loc["a", "reached"] == 3 and s.loc["a", "steps_mean"] < s.loc["b", "steps_mean"]
    assert v.faster(s, "a", "b", "a faster").status == v.NOT


def test_unknown_figure_raises():
    with pytest.raises(ValueError, match="fig9"):
        v.claims("fig9", curves({"a": (1, 1.0)}))


def test_returns_figures_are_judged_on_the_return_and_absent_curves_have_no_data():
    # App. A: HAPPO plateaus at 1000, MAPPO at 400 (and OAPPO at 900); SEAC has no runs
    df = curves({"happo": (50_000, 1000.0), "mappo": (50_000, 400.0), "oappo": (50_000, 900.0)}, noise=0.1)
    df = df.rename(columns={"frac_opt": "eval_return"}).assign(frac_opt=np.nan)
    verdicts = {x.claim: x for x in v.claims("figA_mamujoco", df)}
    assert verdicts["full sharing (MAPPO) ends below no reuse (HAPPO)"].held
    assert "final evaluation return: happo 1000.000" in verdicts["full sharing (MAPPO) ends below no reuse (HAPPO)"].evidence
    assert verdicts["OAPPO ends above full sharing (MAPPO)"].held
    seac = verdicts["direct reuse (SEAC) ends below no reuse (HAPPO)"]
    assert seac.status == v.NO_DATA and "seac" in seac.evidence and not seac.held
    swapped = df.assign(label=df["label"].replace({"happo": "mappo", "mappo": "happo"}))
    assert not {x.claim: x for x in v.claims("figA_mamujoco", swapped)}[
        "full sharing (MAPPO) ends below no reuse (HAPPO)"].held
    assert all(x.status == v.NO_DATA for x in v.claims("figA_mamujoco", pd.DataFrame()))
