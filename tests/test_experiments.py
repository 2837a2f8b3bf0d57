"""The run cache's names: stable under new defaulted fields, distinct for distinct runs."""
import pandas as pd
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


def test_figure_budgets_and_missing_runs(tmp_path, monkeypatch):
    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    with pytest.raises(ValueError, match="unknown budget 'paper' for figA_mamujoco.*cpu"):
        experiments.figure_runs("figA_mamujoco", "paper")
    runs = experiments.figure_runs("figA_mamujoco", "cpu")
    assert len(runs) == 5 * len(experiments.FIGA_ALGOS)
    assert {cfg.env for _, cfg in runs} == {"mamujoco:HalfCheetah-2x3"} and all(cfg.n_envs == 8 for _, cfg in runs)
    assert ":" not in experiments.run_id(runs[0][1])  # a portable file name
    # nothing on disk: nothing is trained, every run is listed as missing, no CSV is written
    df = experiments.load_figure("figA_mamujoco", "cpu", run_missing=False)
    assert df.empty and df.attrs["missing"] == [(label, cfg.seed) for label, cfg in runs]
    assert not (tmp_path / "data" / "figA_mamujoco.csv").exists()
    # one run on disk: its rows come back with their label, the rest stay missing
    label, cfg = runs[0]
    path = experiments.run_path(cfg, "cpu")
    path.parent.mkdir(parents=True)
    pd.DataFrame({"seed": [cfg.seed], "step": [0], "eval_return": [1.0], "git_rev": ["x"]}).to_csv(path, index=False)
    df = experiments.load_figure("figA_mamujoco", "cpu", run_missing=False)
    assert list(df["label"]) == [label] and len(df.attrs["missing"]) == len(runs) - 1
