"""The run cache's names: stable under new defaulted fields, distinct for distinct runs."""
import pytest

from oapo_lite import experiments
from oapo_lite.train import TrainConfig


def test_a_run_id_depends_only_on_fields_that_differ_from_the_defaults():
    bare = TrainConfig(algo="happo", seed=3)
    assert experiments.run_id(bare) == experiments.run_id(TrainConfig(algo="happo", seed=3, lr=5e-4, n_envs=32))
    assert experiments.run_id(bare) != experiments.run_id(TrainConfig(algo="happo", seed=3, lr=1e-3))
    assert experiments.run_id(bare).startswith("happo-black_red-s3-")


def test_every_paper_run_has_its_own_id():
    ids = {experiments.run_id(cfg) for fig in experiments.FIGURES
           for _, cfg in experiments.figure_runs(fig, "paper")}
    configs = {str(cfg.flat()) for fig in experiments.FIGURES for _, cfg in experiments.figure_runs(fig, "paper")}
    assert len(ids) == len(configs)


def test_an_unknown_budget_names_the_known_ones():
    with pytest.raises(ValueError, match="unknown budget 'huge'.*paper"):
        experiments.get_budget("huge")


def test_env_names_with_an_unknown_engine_or_map_raise_naming_what_exists():
    with pytest.raises(ValueError, match="unknown engine 'nosuch'"):
        TrainConfig(env="nosuch:map")
    with pytest.raises(ValueError, match="black_red"):
        TrainConfig(env="no_such_maze")


def test_the_smax_grid_is_data_with_enough_seeds_and_no_colons_in_file_names():
    for budget in ("smoke", "cpu", "paper"):
        runs = experiments.figure_runs("fig4_smax", budget)
        table = experiments.SMAX_BUDGETS[budget]
        assert len(runs) == len(experiments.SMAX_ALGOS) * sum(n for n, _, _ in table.values())
        assert len({experiments.run_id(c) for _, c in runs}) == len(runs)
        assert all(":" not in experiments.run_id(c) and c.env.startswith("smax:") for _, c in runs)
    assert all(3 <= n <= 5 for n, _, _ in experiments.SMAX_BUDGETS["cpu"].values())
    assert "fig4_smax" in experiments.figures_for("cpu") and "fig3b" in experiments.figures_for("cpu")
    with pytest.raises(ValueError, match="unknown budget 'huge' for SMAX"):
        experiments.figure_runs("fig4_smax", "huge")


def test_load_figure_can_read_only_the_runs_on_disk(tmp_path, monkeypatch):
    import pandas as pd

    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    runs = experiments.figure_runs("fig4_smax", "smoke")
    with pytest.raises(FileNotFoundError, match="no run of fig4_smax"):
        experiments.load_figure("fig4_smax", "smoke", run_missing=False)
    label, cfg = runs[0]
    fake = pd.DataFrame({"step": [0, 3200], "eval_success": [0.0, 0.5], "seed": 0, "env": cfg.env, "git_rev": "x"})
    experiments.write_csv_atomic(fake, experiments.run_path(cfg, "smoke"))
    df = experiments.load_figure("fig4_smax", "smoke", run_missing=False)
    assert set(df["label"]) == {label} and len(df) == 2
    assert experiments.missing_runs("fig4_smax", "smoke") == [c for _, c in runs[1:]]
