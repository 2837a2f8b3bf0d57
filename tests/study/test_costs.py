"""What a run costs, recorded, and what a grid will cost, planned before it is spent."""
import pandas as pd
import pytest

import fakes

from oapo_lite import __main__ as cli
from oapo_lite.neural.config import TrainConfig
from oapo_lite.study.catalogue import figures, grid
from oapo_lite.study.runs import costs


def _table(path, prices: dict) -> None:
    """A cost table with ``prices``: cost key -> CPU seconds per 1,000 steps."""
    rows = [{**dict(zip(costs.KEY, key)), "cpu_per_kstep": p, "cpu_model": "a test CPU", "cpu_count": 2}
            for key, p in prices.items()]
    pd.DataFrame(rows).to_csv(path, index=False)


def test_a_plan_prices_what_would_train_and_trains_and_writes_nothing(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path / "figures"))
    monkeypatch.setattr(costs, "COSTS", tmp_path / "costs.csv")
    oappo, oatrpo, mappo, happo, hatrpo = (next(r for r in figures.runs_of("fig3b", "smoke") if r.label == label)
                                           for label in ("oappo", "oatrpo", "mappo", "happo", "hatrpo"))
    fakes.write_run(oappo.cfg, "smoke", lambda s: s / 400, cpu_s=2.0, wall_s=1.0, cpu_model="x", cpu_count=2)
    fakes.write_run(oatrpo.cfg, "smoke", lambda s: s / 400)  # finished before costs were recorded
    _table(costs.COSTS, {costs.cost_key(mappo.cfg): 50.0})  # HAPPO and HATRPO have no price
    before = sorted(tmp_path.rglob("*"))
    (fig,), total, wall = costs.plan("smoke", ["fig3b"], workers=2)
    assert sorted(tmp_path.rglob("*")) == before  # read only
    assert (fig.runs, fig.cached_runs, fig.todo_runs, fig.unpriced, fig.sources) == (5, 2, 3, 2, "table")
    assert fig.cpu_hours == pytest.approx(50.0 * mappo.cfg.steps / 1000 / 3600) and wall == pytest.approx(fig.cpu_hours)
    assert total.todo_steps == mappo.cfg.steps + happo.cfg.steps + hatrpo.cfg.steps
    assert cli.main(["reproduce", "--budget", "smoke", "--figures", "fig3b", "--plan"]) == 0
    out = capsys.readouterr().out
    assert "2 run(s) to train have no measured cost" in out and "nothing was trained or written" in out
    assert "a test CPU (2 cores)" in out and sorted(tmp_path.rglob("*")) == before


def test_a_plan_for_some_envs_prices_only_their_runs():
    """What the opening says the never-run envs cost: the plan of their runs alone."""
    env = "smax:MMM2_like_7m2M_vs_8m3M"
    (fig,), total, _ = costs.plan("paper", ["fig4_smax"], from_nothing=True, envs={env})
    (whole,), _, _ = costs.plan("paper", ["fig4_smax"], from_nothing=True)
    runs = [r for r in figures.runs_of("fig4_smax", "paper") if r.cfg.env == env]
    assert (fig.runs, fig.steps, total.runs) == (len(runs), sum(r.cfg.steps for r in runs), len(runs))
    assert 0 < fig.runs < whole.runs and fig.cpu_hours < whole.cpu_hours


def test_runs_with_a_record_price_their_key_by_the_median_and_unmeasured_runs_not_at_all():
    cfg = TrainConfig(algo="happo", steps=2000, n_envs=8, rollout_len=25)
    measured = [pd.DataFrame({"step": [0, 2000], "cpu_s": [0.1, cpu]}) for cpu in (1.0, 3.0, 5.0)]
    unmeasured = pd.DataFrame({"step": [0, 2000], "cpu_s": [float("nan")] * 2})
    prices = costs.recorded([(cfg, df) for df in [*measured, unmeasured]])
    assert prices == {costs.cost_key(cfg): costs.Price(1.5, "records")}  # median 3 CPU-s over 2,000 steps


def test_the_plan_orders_runs_as_the_driver_does_and_no_faster_than_the_cores():
    runs = [grid.Run("f", "a", TrainConfig(algo="happo", seed=seed, steps=steps, n_envs=8, rollout_len=25))
            for seed, steps in ((0, 800), (0, 400), (1, 1200))]
    prices = {costs.cost_key(r.cfg): costs.Price(3600.0, "table") for r in runs}  # 1 hour per 1,000 steps
    # seed 0 first, longest first: 0.8 h and 0.4 h on two workers, then seed 1's 1.2 h on the one free at 0.4 h
    assert costs.wall_hours(runs, prices, workers=2) == pytest.approx(max(0.8, 0.4 + 1.2, 2.4 / 2))
    assert costs.wall_hours(runs, prices, workers=1) == pytest.approx(2.4)


def test_the_readme_carries_the_costs_the_data_gives():
    from oapo_lite.study.runs import readme

    assert readme.block(costs.BEGIN, costs.END) == costs.readme_markdown(), \
        "the README's costs are stale: run python -m oapo_lite.study.runs.costs"
