"""The run cache's names: stable under new defaulted fields, distinct for distinct runs."""
import json

import numpy as np
import pandas as pd
import pytest

from oapo_lite.neural.config import TrainConfig
from oapo_lite.study.catalogue import figures, grid
from oapo_lite.study.runs import experiments

import fakes


def test_a_run_id_depends_only_on_fields_that_differ_from_the_defaults():
    bare = TrainConfig(algo="happo", seed=3)
    assert bare.run_id() == TrainConfig(algo="happo", seed=3, lr=5e-4, n_envs=32).run_id()
    assert bare.run_id() != TrainConfig(algo="happo", seed=3, lr=1e-3).run_id()
    assert bare.run_id().startswith("happo-black_red-s3-")


def test_every_paper_run_has_its_own_id():
    ids = {cfg.run_id() for fig in figures.FIGURES
           for _, cfg in figures.figure_runs(fig, "paper")}
    configs = {str(cfg.flat()) for fig in figures.FIGURES for _, cfg in figures.figure_runs(fig, "paper")}
    assert len(ids) == len(configs)


def test_an_unknown_budget_names_the_known_ones():
    with pytest.raises(ValueError, match="unknown budget 'huge'.*paper"):
        grid.get_budget("huge")


def test_env_names_with_an_unknown_engine_or_map_raise_naming_what_exists():
    with pytest.raises(ValueError, match="unknown engine 'nosuch'"):
        TrainConfig(env="nosuch:map")
    with pytest.raises(ValueError, match="black_red"):
        TrainConfig(env="no_such_maze")


def test_paper20_is_paper_with_twenty_seeds():
    paper, paper20 = grid.get_budget("paper"), grid.get_budget("paper20")
    assert paper20.seeds == tuple(range(20)) and paper20.seeds[:5] == paper.seeds
    assert (paper20.steps, paper20.eval_every, paper20.eval_episodes) == (paper.steps, paper.eval_every, paper.eval_episodes)
    # the first five seeds are the very runs of the paper budget (same ids)
    for fig in figures.MAZE_FIGURES:
        ids = {c.run_id() for _, c in figures.figure_runs(fig, "paper20")}
        assert {c.run_id() for _, c in figures.figure_runs(fig, "paper")} <= ids
        # ... and they are trained once: both budgets read the same cache, each writes its own figures
        for _, c in figures.figure_runs(fig, "paper"):
            assert experiments.run_path(c, "paper20") == experiments.run_path(c, "paper")
    assert experiments.figures_dir("paper20") != experiments.figures_dir("paper")


def test_the_grid_keeps_every_committed_maze_run_valid():
    """``make reproduce BUDGET=paper`` finds every committed run: the ids did not move."""
    runs = [cfg for fig in ("fig3b", "fig3c", "fig3d", "fig5b", "fig1") for _, cfg in figures.figure_runs(fig, "paper")]
    committed = {p.stem for p in (experiments.ROOT / "figures" / "data" / "runs").glob("*.csv")}
    assert len(runs) == 86 and {cfg.run_id() for cfg in runs} <= committed  # 81 and HATRPO's 5


def test_a_new_figure_is_data_with_its_own_budget_overrides():
    fig = grid.Figure("sweep", (("a", dict(algo="happo")), ("b", dict(algo="mappo", lr=1e-3))),
                             common=dict(env="black_blue_red"), seeds=2, budgets={"paper": grid.At(steps=16_000)},
                             cpus=2, gpus=0.5)
    runs = figures.runs_of(fig, "paper")
    assert [(r.label, r.cfg.algo, r.cfg.seed) for r in runs] == [("a", "happo", 0), ("a", "happo", 1),
                                                                ("b", "mappo", 0), ("b", "mappo", 1)]
    assert {(r.cfg.env, r.cfg.steps, r.cfg.eval_every, r.cpus, r.gpus) for r in runs} == \
        {("black_blue_red", 16_000, grid.BUDGETS["paper"].eval_every, 2, 0.5)}
    assert runs[2].cfg.lr == 1e-3 and runs[0].cfg.lr == 5e-4
    assert figures.runs_of(fig, "smoke")[0].cfg.steps == grid.BUDGETS["smoke"].steps
    with pytest.raises(ValueError, match="unknown figure 'fig9'.*fig3b"):
        figures.runs_of("fig9", "paper")


def test_a_budget_override_is_typed_and_names_only_fields_a_budget_has():
    at = grid.At(steps=16_000, envs={"black_red": grid.At(seeds=(3,))})
    fig = grid.Figure("f", (("a", dict(algo="happo", env="black_red")), ("b", dict(algo="happo", env="black_blue_red"))),
                      budgets={"paper": at})
    assert [(r.label, r.cfg.steps, r.cfg.seed) for r in figures.runs_of(fig, "paper")] == [("a", 16_000, 3)]
    with pytest.raises(TypeError, match="unexpected keyword argument 'step'"):
        grid.At(step=1_000)
    with pytest.raises(TypeError, match="figure 'f': the override of budget 'paper' is a dict; write At"):
        grid.Figure("f", (), budgets={"paper": dict(steps=1_000)})
    with pytest.raises(TypeError, match="figure 'f': the override of budget 'paper' for env 'black_red' is a dict"):
        grid.Figure("f", (), budgets={"paper": grid.At(envs={"black_red": dict(steps=1)})})
    with pytest.raises(ValueError, match="figure 'f': unknown budget 'papr'; choose from"):
        grid.Figure("f", (), budgets={"papr": grid.At()})


def test_a_failed_run_makes_reproduce_exit_non_zero_naming_it_and_a_rerun_recovers(tmp_path, monkeypatch, capsys):
    from oapo_lite.study.runs import executors, reproduce

    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    (cfg,) = [cfg for _, cfg in figures.figure_runs("fig1", "smoke")]

    def broken(*args, **kwargs):
        raise RuntimeError("a broken run")

    monkeypatch.setattr(executors, "train", broken)
    argv = ["--budget", "smoke", "--figures", "fig1", "--skip-notebooks", "--check"]
    assert reproduce.main(argv) == 1
    out = capsys.readouterr()
    assert f"FAILED {cfg.run_id()} (fig1, curve 'oappo')" in out.out and "0 trained" in out.out
    assert cfg.run_id() in out.err and "Traceback" in out.err and "'env': 'black_blue_red'" in out.err
    assert not experiments.run_path(cfg, "smoke").exists()
    monkeypatch.undo()
    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    assert reproduce.main(argv) == 0
    assert experiments.run_path(cfg, "smoke").exists() and "1 trained, 0 already on disk, 0 failed" in capsys.readouterr().out


def test_bad_executor_options_name_what_is_allowed(capsys):
    from oapo_lite.study.runs import reproduce

    for argv, message in ((["--figures", "fig9"], "unknown figure 'fig9'"),
                          (["--address", "auto"], "needs --executor ray"),
                          (["--executor", "ray", "--address", "http://x"], "allowed: auto, HOST:PORT")):
        with pytest.raises(SystemExit):
            reproduce.main(argv)
        assert message in capsys.readouterr().err
    with pytest.raises(ValueError, match="unknown executor 'dask'.*local"):
        experiments.run_all("smoke", executor="dask")



def test_the_engine_figures_are_data_with_enough_seeds_and_no_colons_in_file_names():
    for fig in figures.FIGURES:  # every run of every figure is a valid config at every budget
        for budget in grid.BUDGETS:
            figures.runs_of(fig, budget)
    cpu = {f: figures.runs_of(f, "cpu") for f in ("fig4_smax", "figA_mamujoco", "fig6b")}
    for fig, runs in cpu.items():
        labels = {r.label for r in runs}
        per_curve = {(r.label, r.cfg.env): 0 for r in runs}
        for r in runs:
            per_curve[(r.label, r.cfg.env)] += 1
        assert 3 <= min(per_curve.values()) and max(per_curve.values()) <= 5, fig
        assert len({r.cfg.run_id() for r in runs}) == len(runs)
        assert all(":" not in r.cfg.run_id() for r in runs)
        assert {"oappo", "happo", "mappo", "seac"} <= labels, fig
    # SMAX's cpu grid: the small maps and two of the paper's, each with its own steps; MMM2's
    # stand-in at paper only
    assert {r.cfg.env: r.cfg.steps for r in cpu["fig4_smax"]} == {
        "smax:3m": 300_000, "smax:2s3z": 1_000_000, "smax:6h_vs_8z": 1_000_000, "smax:3s5z_vs_3s6z": 3_000_000}
    # issue 32: every family at its sweep's choice, OAPPO's per-type reading only where types differ,
    # and the 3M-step map for MAPPO, HAPPO and the per-type reading alone
    by_env = {e: {r.label for r in cpu["fig4_smax"] if r.cfg.env == e} for e in figures.get_figure("fig4_smax").envs("cpu")}
    assert "oappo type" in by_env["smax:2s3z"] and "oappo type" not in by_env["smax:3m"] | by_env["smax:6h_vs_8z"]
    assert by_env["smax:3s5z_vs_3s6z"] == set(figures.smax.LONG_SMAX_CURVES)
    for r in cpu["fig4_smax"]:
        family = {"oappo": "happo"}.get(r.label, r.label)
        if family in figures.smax.SWEEP_CHOSEN:
            assert (r.cfg.lr, r.cfg.entropy_coef, r.cfg.clip) == figures.smax.SWEEP_CHOSEN[family], r.label
        elif r.cfg.algo in figures.smax.A2C_CHOSEN:
            assert (r.cfg.a2c_lr, r.cfg.entropy_coef) == figures.smax.A2C_CHOSEN[r.cfg.algo]
    paper = {r.cfg.env: r.cfg.steps for r in figures.runs_of("fig4_smax", "paper")}
    assert paper["smax:6h_vs_8z"] == 40_000_000 and len(paper) == 5
    # A2C runs evaluate at the same env steps as the PPO family on an engine's batch shape too
    by_algo = {r.cfg.algo: r.cfg for r in cpu["fig4_smax"] if r.cfg.env == "smax:3m" and r.cfg.seed == 0}
    ppo, a2c = by_algo["oappo"], by_algo["seac"]
    assert ppo.eval_every * ppo.n_envs * ppo.rollout_len == a2c.eval_every * a2c.n_envs * a2c.n_step
    # the engine figures have no runs at the maze-only budgets, and a bad budget is named
    assert figures.runs_of("fig4_smax", "paper20") == []
    with pytest.raises(ValueError, match="unknown budget 'huge'"):
        figures.runs_of("fig4_smax", "huge")


def test_load_figure_can_read_only_the_runs_on_disk(tmp_path, monkeypatch):
    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    runs = figures.runs_of("fig4_smax", "smoke")
    assert experiments.load_figure("fig4_smax", "smoke", skip_missing=True).empty
    cfg = runs[0].cfg
    fakes.write_run(cfg, "smoke", lambda steps: steps / 6400, grid=1, env=cfg.env)
    df = experiments.load_figure("fig4_smax", "smoke", skip_missing=True)
    assert set(df["label"]) == {runs[0].label} and len(df) == len(cfg.eval_steps) == 3
    assert experiments.missing_runs("fig4_smax", "smoke") == runs[1:]
    with pytest.raises(FileNotFoundError, match=f"run {runs[1].cfg.run_id()} of fig4_smax .*not on disk"):
        experiments.load_figure("fig4_smax", "smoke")  # loading never trains


def test_a_paired_figure_reads_a_seed_only_once_every_curve_of_its_env_has_run_it(tmp_path, monkeypatch):
    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    runs = figures.runs_of("fig_selection_smax", "smoke")
    first = (runs[0].cfg.env, runs[0].cfg.seed)
    seed_runs = [r for r in runs if (r.cfg.env, r.cfg.seed) == first]
    assert len(seed_runs) >= 3
    for r in seed_runs[:-1]:  # a grid stopped before the seed's last curve
        fakes.write_run(r.cfg, "smoke", lambda steps: steps / 6400, grid=1, env=r.cfg.env)
    df, left_out = experiments.read_figure("fig_selection_smax", "smoke", skip_missing=True)
    assert df.empty and {r.cfg.run_id() for r in seed_runs[:-1]} <= set(left_out)
    fakes.write_run(seed_runs[-1].cfg, "smoke", lambda steps: steps / 6400, grid=1, env=seed_runs[-1].cfg.env)
    df, left_out = experiments.read_figure("fig_selection_smax", "smoke", skip_missing=True)
    assert set(df["label"]) == {r.label for r in seed_runs} and set(zip(df["env"], df["seed"])) == {first}
    assert not {r.cfg.run_id() for r in seed_runs} & set(left_out)


def test_train_runs_trains_what_is_missing_and_names_failures(tmp_path, monkeypatch):
    from oapo_lite.study.runs import executors

    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    experiments.train_runs("smoke", ["fig1"], workers=1)
    assert experiments.missing_runs("fig1", "smoke") == [] and len(experiments.load_figure("fig1", "smoke")) == 3
    monkeypatch.setattr(executors, "train", lambda *args, **kwargs: 1 / 0)
    with pytest.raises(RuntimeError, match=r"5 run\(s\) of \['fig3b'\] failed"):
        experiments.train_runs("smoke", ["fig3b"], workers=1)


def test_matrices_are_arrays_in_memory_and_json_in_csv(tmp_path):
    from oapo_lite import store

    rng = np.random.default_rng(0)
    mats = [np.round(rng.random((3, 3)), 6), np.array([[1.0, np.inf], [0.0, 1.0]])]
    df = pd.DataFrame({"step": [0, 1, 2], "kl_matrix": [np.nan, *mats], "label": ["a", "b", "c"]})
    store.write_frame(df, tmp_path / "x.csv")
    text = pd.read_csv(tmp_path / "x.csv")
    assert text["kl_matrix"].iloc[1] == json.dumps(mats[0].tolist()) and text["kl_matrix"].isna().iloc[0]
    back = store.read_arrays(text, experiments.MATRICES)
    assert all(np.array_equal(a, b) for a, b in zip(back["kl_matrix"].iloc[1:], mats))
    assert back["kl_matrix"].isna().iloc[0] and list(back["label"]) == ["a", "b", "c"]
