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


def test_paper20_is_paper_with_twenty_seeds():
    paper, paper20 = experiments.get_budget("paper"), experiments.get_budget("paper20")
    assert paper20.seeds == tuple(range(20)) and paper20.seeds[:5] == paper.seeds
    assert (paper20.steps, paper20.eval_every, paper20.eval_episodes) == (paper.steps, paper.eval_every, paper.eval_episodes)
    # the first five seeds are the very runs of the paper budget (same ids)
    for fig in experiments.FIGURES:
        ids = {experiments.run_id(c) for _, c in experiments.figure_runs(fig, "paper20")}
        assert {experiments.run_id(c) for _, c in experiments.figure_runs(fig, "paper")} <= ids
