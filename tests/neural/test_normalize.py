"""Running normalisation (``TrainConfig.normalize``, stable-baselines3's VecNormalize): the
statistics are those of every sample seen, evaluation reads without moving them, rewards are
scaled by the discounted return's spread, results stay in the env's units, and a resumed run
continues identically."""
import numpy as np
import pandas as pd

import fakes

from oapo_lite.envs import make_vec
from oapo_lite.neural.config import TrainConfig
from oapo_lite.neural.normalize import CLIP, Moments, Normalized, RunningMoments
from oapo_lite.neural.results import learning
from oapo_lite.neural.train import train


def test_running_moments_are_the_moments_of_everything_seen():
    rng = np.random.default_rng(0)
    batches = [rng.normal(3.0, 2.0, (n, 4)) for n in (5, 17, 1, 40)]
    m = RunningMoments((4,))
    for b in batches:
        m.update(b)
    seen = np.concatenate(batches)
    # the start's count of 1e-4 (at mean 0, variance 1) weighs 1e-4 / 63 of the result
    np.testing.assert_allclose(m.mean, seen.mean(0), rtol=1e-5)
    np.testing.assert_allclose(m.var, seen.var(0), rtol=1e-5)


def test_training_copies_move_the_statistics_evaluation_copies_read_them():
    train_env, eval_env = make_vec("black_red", 4, 50), make_vec("black_red", 3, 50)
    moments = Moments.of(train_env)
    train_env, eval_env = Normalized(train_env, moments, 0.99, train=True), Normalized(eval_env, moments, 0.99, False)
    twin = make_vec("black_red", 4, 50)  # the same copies, unnormalised, in lock-step
    step, raw = train_env.reset(), twin.reset()
    assert moments.obs.count > 1 and np.abs(step.obs).max() <= CLIP
    rng = np.random.default_rng(0)
    for _ in range(60):  # past the first episodes' end (50 steps)
        actions = rng.integers(0, 5, (4, 2))
        step, raw = train_env.step(actions), twin.step(actions)
        np.testing.assert_allclose(step.reward, np.clip(raw.reward / np.sqrt(moments.ret.var + 1e-8), -CLIP, CLIP),
                                   rtol=1e-6)
        np.testing.assert_array_equal(step.episode_return, raw.episode_return)  # the env's own units
    before = moments.obs.state_dict()
    raw = make_vec("black_red", 3, 50).reset()
    seen = eval_env.reset()
    assert moments.obs.count == before["count"]  # read, not moved
    np.testing.assert_allclose(seen.obs, moments.obs.scale(raw.obs))


def test_a_normalised_run_reports_the_envs_own_returns_and_resumes_identically(tmp_path):
    cfg = TrainConfig(algo="happo", env="black_red", n_envs=8, rollout_len=25, steps=1000, eval_every=1,
                      eval_episodes=8, checkpoint_every=2, normalize=True)
    full = train(cfg, tmp_path / "full", progress=False)
    assert (full["frac_opt"] * 0 == 0).all() and (full["frac_opt"] <= 1).all()  # the oracle's units
    fakes.interrupt(cfg, tmp_path / "resumed", at=3)
    pd.testing.assert_frame_equal(learning(full), learning(train(cfg, tmp_path / "resumed", progress=False)))
    plain = train(TrainConfig(**{**cfg.__dict__, "normalize": False}), tmp_path / "plain", progress=False)
    assert not learning(plain).equals(learning(full))  # the option acts


def test_the_option_is_off_by_default_so_every_committed_run_keeps_its_id():
    assert TrainConfig().normalize is False
    assert "normalize" not in TrainConfig().changed()
