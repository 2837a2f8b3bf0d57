"""Google Research Football through ``--env grf:<scenario>``: names, repeatability, end to end.

Tests that need the engine skip where it is not installed, except in CI (``CI`` set), where
``make test`` installs it first, so a missing engine fails instead of passing vacuously.
"""
import os
import pickle
import sys
import types

import numpy as np
import pytest
import torch

from oapo_lite.__main__ import main
from oapo_lite.envs import grf
from oapo_lite.neural.config import TrainConfig
from oapo_lite.neural.nets import Actors
from oapo_lite.neural.rollout import episode_scores
from oapo_lite.neural.train import train
from oapo_lite.study.catalogue import figures, grid

SCENARIO = "academy_3_vs_1_with_keeper"
needs_grf = pytest.mark.skipif(not grf.installed() and not os.environ.get("CI"),
                               reason="gfootball not installed (make grf)")


def test_unknown_scenarios_raise_naming_the_scenarios():
    with pytest.raises(ValueError, match="unknown GRF scenario 'academy_nosuch'.*academy_counterattack_hard"):
        TrainConfig(env="grf:academy_nosuch")


def test_a_missing_engine_gives_the_install_command_not_a_traceback(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(grf, "installed", lambda: False)
    with pytest.raises(ImportError, match="make grf"):
        grf.make_vec(SCENARIO, 2, 0, 10)
    assert main(["train", "--env", f"grf:{SCENARIO}", "--out", str(tmp_path), "--no-progress"]) == 2
    assert "install it with `make grf`" in capsys.readouterr().err


def test_copy_seeds_differ_between_copies_and_runs():
    seeds = {grf.copy_seed(s, k) for s in range(4) for k in range(8)}
    assert len(seeds) == 32 and all(0 <= x < 2**31 for x in seeds)


class _Planted:
    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return os.system, (f"touch {self.marker}",)


def test_an_engine_state_from_a_checkpoint_unpickles_gfootballs_envstate_and_nothing_else(monkeypatch, tmp_path):
    """gfootball's set_state calls ``pickle.loads`` on a pickle its get_state put in the engine's
    snapshot; while ``_Copies.set_state`` runs, that builds gfootball's ``EnvState`` and data
    only. (A stand-in module plays gfootball's, so this runs without the engine.)"""
    names = ("gfootball", "gfootball.env", "gfootball.env.football_env_core")
    for name in names:
        monkeypatch.setitem(sys.modules, name, types.ModuleType(name))
    env_state = type("EnvState", (), {"__module__": names[-1]})
    sys.modules[names[-1]].EnvState = env_state
    state = env_state()
    state.previous_score_diff = 1
    good = pickle.dumps({"FootballEnvCore": state, "CheckpointRewardWrapper": {3: 1}})
    marker = tmp_path / "ran"
    bad = pickle.dumps({"FootballEnvCore": _Planted(marker)})
    loads = pickle.loads
    with grf._engine_pickles_as_data():
        back = pickle.loads(good)
        with pytest.raises(pickle.UnpicklingError, match=f"EnvState only, not {os.system.__module__}.system"):
            pickle.loads(bad)
    assert type(back["FootballEnvCore"]) is env_state and vars(back["FootballEnvCore"]) == vars(state)
    assert back["CheckpointRewardWrapper"] == {3: 1} and not marker.exists() and pickle.loads is loads


def _rollout(seed: int, steps: int, n_envs: int = 3, workers: int = 2):
    env = grf.GRFVec(SCENARIO, n_envs, seed=seed, max_steps=400, workers=workers)
    rng = np.random.default_rng(0)
    out = [env.reset()]
    for _ in range(steps):
        out.append(env.step(rng.integers(0, grf.N_ACTIONS, (n_envs, env.n_agents))))
    env.close()
    return out


def _fields(steps):
    return {k: np.stack([getattr(s, k) for s in steps]) for k in ("obs", "reward", "terminated", "truncated",
                                                                  "final_obs", "episode_return", "episode_success")}


@needs_grf
def test_a_fixed_seed_repeats_exactly_across_episodes_and_worker_splits():
    a, b = _fields(_rollout(7, 120)), _fields(_rollout(7, 120, workers=1))
    ended = ~np.isnan(a["episode_return"])
    assert ended.sum() >= 2  # the comparison covers auto-resets, not just one episode
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    assert a["obs"].shape == (121, 3, 3, grf.OBS_DIM)
    # success is read from the scoring reward: a goal makes the return at least 1
    success = a["episode_success"][ended]
    assert set(np.unique(success)) <= {0.0, 1.0}
    assert (a["episode_return"][ended][success == 1] >= 1).all()


@needs_grf
def test_the_seed_sets_the_engine():
    a, b = _fields(_rollout(7, 60)), _fields(_rollout(8, 60))
    assert not np.array_equal(a["obs"], b["obs"])


@needs_grf
def test_engine_snapshots_continue_identically():
    rng = np.random.default_rng(1)
    actions = rng.integers(0, grf.N_ACTIONS, (40, 2, 3))
    env = grf.GRFVec(SCENARIO, 2, seed=3, max_steps=400)
    env.reset()
    for a in actions[:20]:
        env.step(a)
    snap = env.get_state()
    first = [env.step(a).obs for a in actions[20:]]
    env.set_state(snap)
    again = [env.step(a).obs for a in actions[20:]]
    env.close()
    np.testing.assert_array_equal(np.stack(first), np.stack(again))


@needs_grf
def test_step_only_steps_the_chosen_copies_as_their_engines_alone_would():
    seed, n = 5, 3
    env = grf.GRFVec(SCENARIO, n, seed=seed, max_steps=400, workers=2)
    engines = [grf._make_engine(SCENARIO, grf.copy_seed(seed, k)) for k in range(n)]
    np.testing.assert_array_equal(env.reset().obs, np.stack([e.reset() for e in engines]))
    rng, ended = np.random.default_rng(2), 0
    for _ in range(150):
        which, a = rng.random(n) < 0.7, rng.integers(0, grf.N_ACTIONS, (n, env.n_agents))
        step = env.step_only(a, which)
        for k in range(n):
            if not which[k]:
                assert not step.obs[k].any() and np.isnan(step.episode_return[k]) and not step.truncated[k]
                continue
            obs, reward, done, _ = engines[k].step(a[k].tolist())
            np.testing.assert_array_equal(step.final_obs[k], obs)
            assert step.reward[k] == np.float32(np.mean(reward)) and done == (step.terminated[k] | step.truncated[k])
            np.testing.assert_array_equal(step.obs[k], engines[k].reset() if done else obs)
            ended += done
    with pytest.raises(ValueError, match=r"which must be booleans of shape \(3,\), got int64"):
        env.step_only(a, np.ones(n, np.int64))
    env.close()
    assert ended >= 2  # auto-resets are covered


class _EveryCopy:
    """A GRF env without ``step_only``: the evaluation steps every copy to the end."""

    def __init__(self, env):
        self.env, self.n_envs = env, env.n_envs

    def reset(self):
        return self.env.reset()

    def step(self, actions):
        return self.env.step(actions)


@needs_grf
def test_an_evaluation_that_stops_finished_copies_scores_as_one_that_steps_every_copy():
    actors = Actors(3, grf.OBS_DIM, grf.N_ACTIONS, (16,), False, torch.Generator().manual_seed(0))
    scores = []
    for wrap in (lambda env: env, _EveryCopy):
        env = grf.GRFVec(SCENARIO, 4, seed=1, max_steps=60, workers=2)
        gen = torch.Generator().manual_seed(3)
        # two evaluations: the second starts from the engines the first left
        scores.append([episode_scores(actors, [0, 1, 2], wrap(env), gen, 60) for _ in range(2)] + [gen.get_state()])
        env.close()
    (first, second, gen_a), (first_b, second_b, gen_b) = scores
    assert (first, second) == (first_b, second_b) and torch.equal(gen_a, gen_b)


@needs_grf
def test_a_grf_run_trains_end_to_end(tmp_path):
    cfg = TrainConfig(algo="oappo", env=f"grf:{SCENARIO}", n_envs=2, rollout_len=8, steps=48, max_steps=24,
                      eval_every=1, eval_episodes=2, checkpoint_every=1)
    rows = train(cfg, tmp_path, progress=False)
    assert list(rows["iteration"]) == [0, 1, 2, 3]
    assert np.isfinite(rows["eval_return"]).all()
    assert rows["eval_success"].between(0, 1).all()
    kl = rows["kl_matrix"].iloc[-1]
    assert kl.shape == (3, 3) and np.allclose(np.diag(kl), 0)


def test_fig6b_budgets_are_data_and_every_run_has_its_own_id():
    for budget in grid.ENGINE_BUDGETS:
        runs = figures.figure_runs("fig6b", budget)
        assert {label for label, _ in runs} == set(figures.grf.FIG6B_ALGOS)
        assert len({cfg.run_id() for _, cfg in runs}) == len(runs)
    paper = figures.figure_runs("fig6b", "paper")
    assert {cfg.env for _, cfg in paper} == {f"grf:{s}" for s in grf.SCENARIOS}
    assert {cfg.steps for _, cfg in paper if cfg.env == "grf:academy_counterattack_hard"} == {50_000_000}
    with pytest.raises(ValueError, match="unknown budget 'huge'"):
        figures.figure_runs("fig6b", "huge")


@needs_grf
def test_a_run_s_cost_counts_the_engine_s_worker_processes():
    """GRF steps its copies in other processes: their CPU time is the run's too."""
    import time

    from oapo_lite.envs.vec import HasWorkers
    from oapo_lite.neural.cost import cpu_seconds

    env = grf.GRFVec(SCENARIO, 2, seed=0, max_steps=400, workers=2)
    assert isinstance(env, HasWorkers) and len(env.worker_pids()) == 2
    env.reset()
    before, own = cpu_seconds([env]), time.process_time()
    for _ in range(100):
        env.step(np.zeros((2, env.n_agents), dtype=int))
    assert cpu_seconds([env]) - before > 2 * (time.process_time() - own)  # the engines did the stepping
    env.close()
    assert env.worker_pids() == []
