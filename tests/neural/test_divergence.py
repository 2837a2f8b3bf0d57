"""A NaN or an infinity stops a run naming the iteration, the learner and the quantity, and
leaves the last good checkpoint as it was."""
import re

import numpy as np
import pytest
import torch
from gymnasium import spaces
from pettingzoo import ParallelEnv

from oapo_lite.algorithms import ALGOS
from oapo_lite.neural.config import TrainConfig
from oapo_lite.neural.losses import Diverged
from oapo_lite.neural.nets import Actors
from oapo_lite.neural.ppo_family import policy_distances, update_actors, update_units
from oapo_lite.neural.rollout import Inputs, Rollout
from oapo_lite.neural.runstate import load_checkpoint
from oapo_lite.neural.train import train

torch.set_num_threads(1)


class NanAfter(ParallelEnv):
    """Two agents, 5-step episodes, reward 1 - (agent a's action == 0); each copy's reward turns
    NaN from its ``bad_step``-th step on (a broken simulator)."""

    metadata = {"name": "nan_after_v0"}
    possible_agents = ["a", "b"]

    def __init__(self, bad_step: int):
        self.bad_step, self.steps = bad_step, 0

    def observation_space(self, agent):
        return spaces.Box(0, 1, (2,), np.float32)

    def action_space(self, agent):
        return spaces.Discrete(3)

    def reset(self, seed=None, options=None):
        self.agents, self.t = list(self.possible_agents), 0
        return {k: np.array([self.t / 5, 1.0], np.float32) for k in self.agents}, {k: {} for k in self.agents}

    def step(self, actions):
        self.t, self.steps = self.t + 1, self.steps + 1
        r = float("nan") if self.steps >= self.bad_step else float(actions["a"] != 0)
        agents, done = self.agents, self.t >= 5
        self.agents = [] if done else agents
        obs = {k: np.array([self.t / 5, 1.0], np.float32) for k in agents}
        return obs, {k: r for k in agents}, {k: done for k in agents}, {k: False for k in agents}, {k: {} for k in agents}


@pytest.mark.parametrize("algo", ["oappo", "oatrpo", "seac"])
def test_a_nan_reward_stops_the_run_and_keeps_the_last_good_checkpoint(tmp_path, algo):
    # 2 copies x 10 steps per iteration (SEAC: x its 5-step rollouts, twice as many iterations):
    # each copy's 41st step is in iteration 5 (SEAC: 9)
    a2c = algo == "seac"
    kw = dict(algo=algo, env_fn=lambda: NanAfter(bad_step=41), n_envs=2, rollout_len=10, eval_episodes=2,
              eval_every=1, checkpoint_every=4 if a2c else 2)
    with pytest.raises(Diverged) as err:
        train(TrainConfig(steps=20 * 8, **kw), tmp_path / "broken", progress=False)
    message = str(err.value)
    words = (("n-step returns", "iteration 9 of", "(learner all: they share the team reward)",
              "(iteration 8) is left as it was") if a2c else
             ("joint advantage", "iteration 5 of", "(learner all: it is joint)", "(iteration 4) is left as it was"))
    for w in words:
        assert w in message
    # the checkpoint is the one an uninterrupted 4-iteration run writes, bit for bit
    broken = load_checkpoint(tmp_path / "broken")
    train(TrainConfig(steps=20 * 4, **kw), tmp_path / "clean", progress=False)
    clean = load_checkpoint(tmp_path / "clean")
    good = 8 if a2c else 4
    assert broken["iteration"] == clean["iteration"] == good
    assert all(torch.equal(broken["actors"][k], clean["actors"][k]) for k in clean["actors"])
    assert [r["iteration"] for r in broken["rows"]] == list(range(good + 1))


def _batch(actors: Actors, B: int = 32, seed: int = 1) -> Rollout:
    """Seats observe different random vectors and act by their own policies."""
    g = torch.Generator().manual_seed(seed)
    obs = torch.randn(2, B, 4, generator=g) + torch.tensor([0.0, 3.0])[:, None, None]
    avail = torch.ones(2, B, 3, dtype=torch.bool)
    with torch.no_grad():
        d = actors(obs, range(2), avail)
    act = actors.head.sample(d, g)
    return Rollout(Inputs.of(obs.numpy(), avail.numpy()), act, actors.head.log_prob(d, act), *[None] * 5)


def _actors(nan_net: int | None = None) -> Actors:
    actors = Actors(2, 4, 3, (16,), False, torch.Generator().manual_seed(0))
    if nan_net is not None:
        with torch.no_grad():
            actors.weights[nan_net][0].fill_(float("nan"))
    return actors


@pytest.mark.parametrize("algo, quantity", [("oappo", "the PPO loss (Eq. 8)"), ("oatrpo", "the TRPO surrogate (Eq. 7)")])
def test_a_learner_with_nan_weights_is_named_by_its_loss(algo, quantity):
    actors = _actors()
    batch = _batch(actors)
    with torch.no_grad():
        actors.weights[1][0].fill_(float("nan"))  # learner 1 broke after the rollout
    opts = [torch.optim.Adam(actors.net_params(k), lr=1e-3) for k in range(2)]
    adv = torch.randn(32, generator=torch.Generator().manual_seed(2))
    with pytest.raises(Diverged, match="^" + re.escape(f"{quantity} is not finite (learner 1)")):
        update_actors(actors, [] if ALGOS[algo].trust_region else opts, batch, update_units(np.eye(2), [0, 1], "net"),
                      [0, 1], adv,
                      ALGOS[algo], TrainConfig(algo=algo, ppo_epochs=1), np.random.default_rng(0))
    assert torch.isfinite(actors.weights[0][0]).all()  # learner 0 had stepped normally


def test_an_overflowing_factor_is_caught_at_the_learner_that_overflowed_it():
    """Learner 0's behaviour probabilities of e^-1e4 make its own ratio, and so rho, infinite;
    the clipped loss stays finite (every advantage is positive), so the factor is what breaks."""
    actors = _actors()
    batch = _batch(actors)
    batch.logp[0] = -1e4
    opts = [torch.optim.Adam(actors.net_params(k), lr=1e-3) for k in range(2)]
    with pytest.raises(Diverged, match=r"^the sequential factor rho is not finite \(learner 0\)"):
        update_actors(actors, opts, batch, update_units(np.eye(2), [0, 1], "net"), [0, 1], torch.ones(32), ALGOS["oappo"],
                      TrainConfig(ppo_epochs=1), np.random.default_rng(0))


def test_a_nan_policy_makes_the_policy_distances_raise_naming_the_pair():
    actors = _actors(nan_net=1)
    batch = _batch(_actors())
    with pytest.raises(Diverged, match=r"^the policy distance KL K\[0, 1\] \(Eq. 9\) is not finite \(learner 0\)"):
        policy_distances(actors, batch.inputs, [0, 1], "max")
    K = policy_distances(_actors(), batch.inputs, [0, 1], "max")  # and a healthy pair passes
    assert np.isfinite(K).all() and (K >= 0).all()
