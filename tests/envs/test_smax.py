"""SMAX engine: masks reach the policy, wins are counted by the rule, the loop trains end to end.

JAX compiles a scenario once per process and batch shape (tens of seconds), so every test
here uses one tiny map (3m), 16 copies and one episode limit, and shares one compiled env.
"""
import numpy as np
import pytest
import torch

pytest.importorskip("jaxmarl")

from oapo_lite.envs import registry  # noqa: E402
from oapo_lite.envs.smax import NOOP, SmaxVec, check  # noqa: E402
from oapo_lite.neural.nets import Actors  # noqa: E402
from oapo_lite.neural.config import TrainConfig  # noqa: E402
from oapo_lite.neural.rollout import sample_actions  # noqa: E402
from oapo_lite.neural.runstate import load_checkpoint  # noqa: E402
from oapo_lite.neural.train import train  # noqa: E402

import fakes

N, MAX_STEPS = 16, 40
UNIT_FEATURES = 10  # SMAX's world state: 10 features per unit (health first), then teams and types
MOVE_EAST = 1  # a move that brings 3m's allies into range (found by trying the four moves)


@pytest.fixture(scope="module")
def env():
    return SmaxVec("3m", N, seed=0, max_steps=MAX_STEPS)


def focus_fire(step) -> np.ndarray:
    """Every ally shoots the first enemy in range, else walks towards them; dead ones stop."""
    shoot = step.avail[..., 5:]
    a = np.where(shoot.any(-1), 5 + shoot.argmax(-1), MOVE_EAST)
    return np.where(np.take_along_axis(step.avail, a[..., None], -1)[..., 0], a, NOOP)


def test_unknown_scenario_names_the_scenarios_without_jax():
    with pytest.raises(ValueError, match="unknown SMAX scenario 'MMM2'.*6h_vs_8z.*MMM2_like"):
        check("MMM2")
    with pytest.raises(ValueError, match="unknown SMAX scenario"):
        TrainConfig(env="smax:nope")
    registry.check("smax:3s5z_vs_3s6z")


def test_shapes_follow_the_scenario(env):
    step = env.reset()
    assert env.agents == ("ally_0", "ally_1", "ally_2") and env.n_actions == 5 + 3
    assert step.obs.shape == (N, 3, env.obs_dim) and step.state.shape == (N, env.state_dim)
    assert step.avail.shape == (N, 3, 8) and step.avail.dtype == bool and step.active.all()


def test_a_win_is_counted_exactly_when_every_enemy_is_dead_and_an_ally_lives(env):
    step, ended = env.reset(), []
    for _ in range(3 * MAX_STEPS):
        step = env.step(focus_fire(step))
        done = step.terminated | step.truncated
        assert np.array_equal(done, ~np.isnan(step.episode_success))
        alive = step.final_state[:, : 6 * UNIT_FEATURES].reshape(N, 6, UNIT_FEATURES)[..., 0] > 0
        for e in np.flatnonzero(done):
            ended.append((step.episode_success[e], alive[e, 3:].any(), alive[e, :3].any(), step.reward[e],
                          step.terminated[e]))
    success, enemies_alive, allies_alive, reward, terminated = map(np.array, zip(*ended))
    assert np.array_equal(success == 1, ~enemies_alive & allies_alive)
    assert np.array_equal(terminated, ~enemies_alive | ~allies_alive)  # otherwise the time limit
    assert np.array_equal(success == 1, reward >= 1)  # SMAX's own win bonus agrees
    assert 0 < success.mean() < 1  # both outcomes occurred, so the comparison had teeth


def test_masks_reach_the_policy_no_unavailable_action_is_ever_sampled(env):
    gen = torch.Generator().manual_seed(0)
    actors = Actors(3, env.obs_dim, env.n_actions, (16,), False, gen)
    step, masked, dead = env.reset(), 0, 0
    with torch.inference_mode():
        weights = actors.stack([0, 1, 2])
        for _ in range(2 * MAX_STEPS):
            a = sample_actions(actors, weights, step, gen)[0].transpose(0, 1).numpy()
            assert np.take_along_axis(step.avail, a[..., None], -1).all()
            assert (a[~step.active] == NOOP).all()  # a dead ally can only stop
            masked += (~step.avail).sum()
            dead += (~step.active).sum()
            step = env.step(a)
    assert masked > 0 and dead > 0  # masks and dead allies did occur


def test_same_seed_same_episodes_and_state_round_trip(env):
    actions = np.full((N, 3), MOVE_EAST)
    env.reset()
    first = [env.step(actions).obs for _ in range(5)]
    saved = env.get_state()
    after = [env.step(actions).state for _ in range(5)]
    env.reset()
    assert all(np.array_equal(x, env.step(actions).obs) for x in first)
    env.set_state(saved)
    assert all(np.array_equal(x, env.step(actions).state) for x in after)
    with pytest.raises(ValueError, match="actions must be integers in 0..7"):
        env.step(np.full((N, 3), 8))


def test_oappo_trains_end_to_end_and_resumes_identically(env, tmp_path):
    cfg = dict(algo="oappo", env="smax:3m", n_envs=N, rollout_len=10, eval_every=1, eval_episodes=N,
               max_steps=MAX_STEPS, checkpoint_every=1, hidden=(16,))
    full = train(TrainConfig(steps=3 * N * 10, **cfg), tmp_path / "full", progress=False)
    assert list(full["step"]) == [0, 160, 320, 480]
    assert full["eval_success"].between(0, 1).all() and full["eval_return"].notna().all()
    train(TrainConfig(steps=2 * N * 10, **cfg), tmp_path / "split", progress=False)
    resumed = train(TrainConfig(steps=3 * N * 10, **cfg), tmp_path / "split", progress=False)
    cols = ["step", "eval_return", "eval_success", "objective", "value_loss"]
    assert resumed[cols].equals(full[cols])


def test_the_tuned_settings_fit_every_algorithm_and_resume_identically(env, tmp_path):
    """``figures.smax.SMAX_TUNED`` (Fig. 4's settings on every map) is a valid config for every
    algorithm of Fig. 4, and a MAPPO run with it (4 minibatches) resumes to the same numbers."""
    from oapo_lite.study.catalogue import figures

    for algo in figures.smax.SMAX_ALGOS:
        TrainConfig(algo=algo, env="smax:3m", **figures.smax.SMAX_BATCH, **figures.smax.SMAX_TUNED)
    cfg = TrainConfig(**{**figures.smax.SMAX_TUNED, **dict(algo="mappo", env="smax:3m", n_envs=N, rollout_len=10, steps=3 * N * 10,
                                                    eval_every=1, eval_episodes=N, max_steps=MAX_STEPS, checkpoint_every=1,
                                                    hidden=(16,))})
    full = train(cfg, tmp_path / "full", progress=False)

    fakes.interrupt(cfg, tmp_path / "split", at=2)
    resumed = train(cfg, tmp_path / "split", progress=False)
    cols = ["step", "eval_return", "eval_success", "objective", "value_loss"]
    assert resumed[cols].equals(full[cols])


def test_oappo_warmed_up_for_the_whole_run_is_bitwise_happo_on_smax(env, tmp_path):
    """The same identity on an engine with action masks and agents that die (``active``)."""
    cfg = dict(env="smax:3m", n_envs=N, rollout_len=10, steps=3 * N * 10, eval_every=3, eval_episodes=N,
               max_steps=MAX_STEPS, hidden=(16,))
    train(TrainConfig(algo="happo", **cfg), tmp_path / "happo", progress=False)
    train(TrainConfig(algo="oappo", reuse_warmup=3, **cfg), tmp_path / "oappo", progress=False)
    train(TrainConfig(algo="oappo", **cfg), tmp_path / "reuse", progress=False)
    a, b, c = (load_checkpoint(tmp_path / name)["actors"] for name in ("happo", "oappo", "reuse"))
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    assert not all(torch.equal(a[k], c[k]) for k in a)  # without the warm-up, reuse changes the update


def test_the_readings_of_the_networks_on_smax(env, tmp_path):
    """Issue 31's readings on an engine with action masks and agents that die: 3m's three
    marines are one type, so one net per type is one shared net and OAPPO is MAPPO bit for bit;
    a shared net updated seat by seat with M = I (lambda = 1) is the shared-actor HAPPO bit for
    bit; one net per seat updated seat by seat is HAPPO bit for bit."""
    cfg = dict(env="smax:3m", n_envs=N, rollout_len=10, steps=3 * N * 10, eval_every=3, eval_episodes=N,
               max_steps=MAX_STEPS, hidden=(16,))
    runs = {"mappo": dict(algo="mappo"), "type": dict(algo="oappo", networks="type"),
            "happo": dict(algo="happo"), "happo_seat": dict(algo="happo", update_by="seat"),
            "shared_happo": dict(algo="happo", networks="one", update_by="seat"),
            "shared_oappo": dict(algo="oappo", networks="one", update_by="seat", reuse_lambda=1.0)}
    for name, kw in runs.items():
        train(TrainConfig(**kw, **cfg), tmp_path / name, progress=False)
    params = {name: load_checkpoint(tmp_path / name)["actors"] for name in runs}

    def same(a, b):
        return params[a].keys() == params[b].keys() and all(torch.equal(params[a][k], params[b][k]) for k in params[a])

    assert same("mappo", "type") and same("happo", "happo_seat") and same("shared_happo", "shared_oappo")
    assert not same("mappo", "shared_happo") and not same("happo", "mappo")


def test_smax_declares_each_seat_s_unit_type():
    assert SmaxVec("3m", 1).agent_types == ("marine",) * 3
    assert SmaxVec("2s3z", 1).agent_types == ("stalker",) * 2 + ("zealot",) * 3


def test_importing_jaxmarl_through_the_engine_keeps_the_notebook_s_output_streams():
    """jaxmarl's import replaces sys.stdout (in a notebook kernel every later print then goes to
    the kernel's terminal); the engine imports it with the streams kept. Fresh interpreters, since
    a module is imported once per process."""
    import subprocess
    import sys

    probe = ("import io, sys\nstream = io.TextIOWrapper(io.BytesIO())\nsys.stdout = stream\n{}\n"
             "sys.__stdout__.write(str(sys.stdout is stream))")
    bare = subprocess.run([sys.executable, "-c", probe.format("import jaxmarl.environments.smax")],
                          capture_output=True, text=True, check=True)
    kept = subprocess.run([sys.executable, "-c", probe.format("from oapo_lite.envs.smax import _jaxmarl_smax\n"
                                                              "_jaxmarl_smax()")],
                          capture_output=True, text=True, check=True)
    assert bare.stdout.endswith("False") and "Importing" in bare.stdout
    assert kept.stdout == "True"  # and nothing of jaxmarl's own printing reaches the output


def test_two_accepted_seeds_never_replay_one_smax_episode(env):
    """SMAX's key holds the seed's 32 bits (2**32 would alias 0, and is refused by the config):
    the seeds at the ends of the accepted range start other battles than seed 0."""
    first = {}
    for seed in (0, 1, 2**31, 2**32 - 1):
        env.seed = seed  # as SmaxVec(..., seed=seed) would, without building another env
        first[seed] = env.reset().state.tobytes()
    env.seed = 0
    assert len(set(first.values())) == 4
    with pytest.raises(ValueError, match=r"seed = 4294967296 is invalid; allowed: an integer in \[0, 4294967295\]"):
        TrainConfig(algo="happo", env="smax:3m", seed=2**32)


def test_an_evaluation_counts_the_battles_that_reach_the_time_limit():
    """SMAX ends a battle at its time limit on the step after the max_steps-th: in 3 steps nobody
    can die, so every one of them ends there, and counts, as a battle not won."""
    from oapo_lite.neural.rollout import episode_scores

    short = SmaxVec("3m", 4, seed=0, max_steps=3)
    gen = torch.Generator().manual_seed(0)
    actors = Actors(1, short.obs_dim, short.n_actions, (16,), False, gen)
    ret, won = episode_scores(actors, [0, 0, 0], short, gen, 3)
    assert np.isfinite(ret) and won == 0.0
