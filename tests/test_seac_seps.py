"""SEAC and SePS: each method's defining property on cases computed by hand or independently."""
import copy
import math

import numpy as np
import pytest
import torch
from gymnasium import spaces
from pettingzoo import ParallelEnv

from oapo_lite import seps
from oapo_lite.a2c import A2C, nstep_returns, seac_loss
from oapo_lite.envs import make_vec
from oapo_lite.nets import Actors
from oapo_lite.train import TrainConfig, collect, train

torch.set_num_threads(1)


def test_seac_weights_and_loss_on_a_tiny_batch_match_a_direct_computation():
    """Two seats, two samples each, learner = seat 0, lambda = 0.5, every number by hand."""
    p_learner = [[0.5, 0.25], [0.2, 0.8]]  # pi_0(a_k | o_k), row k = seat
    p_behaviour = [[0.5, 0.25], [0.4, 0.2]]  # pi_k(a_k | o_k); row 0 is the learner's own
    value = [[1.0, 0.0], [0.5, 2.0]]  # V_0(o_k)
    ret = [[2.0, 1.0], [1.5, 1.0]]  # R_k
    ent = [[0.6, 0.4], [9.0, 9.0]]  # the others' entropies must not count
    lam, ent_coef = 0.5, 0.01
    # direct: w_01 = (0.2 / 0.4, 0.8 / 0.2) = (0.5, 4)
    w = [0.2 / 0.4, 0.8 / 0.2]
    policy = -(math.log(0.5) * 1.0 + math.log(0.25) * 1.0) / 2 \
        + lam * -(w[0] * math.log(0.2) * 1.0 + w[1] * math.log(0.8) * -1.0) / 2
    val = (1.0 ** 2 + 1.0 ** 2) / 2 + lam * (w[0] * 1.0 ** 2 + w[1] * 1.0 ** 2) / 2
    expected = policy + 0.5 * val - ent_coef * (0.6 + 0.4) / 2

    logp = torch.tensor(p_learner).log().requires_grad_()
    loss, parts = seac_loss(logp, torch.tensor(p_behaviour).log(), torch.tensor(value), torch.tensor(ret),
                            torch.tensor(ent), torch.tensor([True, False]), lam, ent_coef)
    assert torch.allclose(parts["weights"][1], torch.tensor(w))
    assert loss.item() == pytest.approx(expected, rel=1e-6)
    # the weights are detached: d loss / d log pi(a_1|o_1) is -lambda w A / B, not more
    loss.backward()
    assert logp.grad[1, 1].item() == pytest.approx(-lam * w[1] * -1.0 / 2, rel=1e-6)


def test_nstep_returns_match_a_hand_computation():
    reward = torch.tensor([[1.0], [0.0], [2.0]])
    done = torch.tensor([[False], [True], [False]])
    R = nstep_returns(reward, done, torch.tensor([10.0]), gamma=0.5)
    # t=2: 2 + 0.5 * 10 = 7; t=1 ends the episode: 0; t=0: 1 + 0.5 * 0 = 1
    assert R.squeeze(1).tolist() == [1.0, 0.0, 7.0]


def _batch(n_envs=4, seed=0):
    env = make_vec("black_blue_red", n_envs, 50)
    actors = Actors(3, env.obs_dim, env.n_actions, (16,), False, torch.Generator().manual_seed(seed))
    batch, step = collect(env, env.reset(), actors, [0, 1, 2], 5, torch.Generator().manual_seed(seed + 1),
                          {"env": 0.0, "policy": 0.0})
    return env, actors, batch, torch.from_numpy(step.obs)


def _learner(actors, obs_dim, lam):
    return A2C(actors, obs_dim, (16,), lam, 0.99, 3e-4, 1e-3, 0.5, 0.01, torch.Generator().manual_seed(5))


def _reference_a2c_step(a2c: A2C, batch, next_obs, owner):
    """Plain A2C written out sample by sample: net c's loss pools the samples of the seats it
    controls; returns by a loop over time; one Adam step per net after clipping."""
    n, B = batch.act.shape
    T, N = batch.reward.shape
    obs = batch.inputs.obs[batch.inputs.index]  # (n, B, d)
    for opt in a2c.opts:
        opt.zero_grad()
    for c in sorted(set(owner)):
        seats = [k for k in range(n) if owner[k] == c]
        terms = []
        for k in seats:
            with torch.no_grad():
                running = a2c.critics[owner[k]](next_obs[:, k])
            R = torch.empty(T, N)
            for t in reversed(range(T)):
                done = batch.terminated[t] | batch.truncated[t]
                running = batch.reward[t] + 0.99 * torch.where(done, 0.0, running)
                R[t] = running
            logits = a2c.actors(obs[k][None], [c], batch.inputs.avail[batch.inputs.index[k]][None])[0]
            logp = logits.gather(-1, batch.act[k][:, None]).squeeze(-1)
            entropy = -(logits.exp() * logits).sum(-1)
            adv = R.reshape(-1) - a2c.critics[c](obs[k])
            terms.append(-logp * adv.detach() + 0.5 * adv.pow(2) - 0.01 * entropy)
        torch.cat(terms).mean().backward()
    for c in sorted(set(owner)):
        torch.nn.utils.clip_grad_norm_(a2c.params(c), 0.5)
        a2c.opts[c].step()


@pytest.mark.parametrize("owner", [[0, 1, 2], [0, 0, 0], [0, 1, 0]])
def test_lambda_zero_is_plain_a2c_independent_shared_or_grouped(owner):
    """lambda = 0: SEAC is independent A2C (owner = identity), SePS with k = 1 is parameter
    sharing (every seat on net 0) and with k = n no sharing; a grouping pools each group."""
    env, actors, batch, next_obs = _batch()
    a2c = _learner(actors, env.obs_dim, 0.0)
    ref = copy.deepcopy(a2c)
    a2c.learn(batch, next_obs, owner)
    _reference_a2c_step(ref, batch, next_obs, owner)
    for c in range(3):
        for p, q in zip(a2c.params(c), ref.params(c)):
            assert torch.allclose(p, q, atol=1e-6), (c, (p - q).abs().max())
    untouched = _learner(copy.deepcopy(_batch()[1]), env.obs_dim, 0.0)
    for c in set(range(3)) - set(owner):  # a net that controls no seat never moves
        assert all(torch.equal(p, q) for p, q in zip(a2c.params(c), untouched.params(c)))


def test_seac_with_lambda_zero_trains_exactly_like_independent_a2c_and_lambda_changes_it(tmp_path):
    """A whole run: SEAC with lambda = 0 never reads another seat's samples, so corrupting
    what the others did (through a different lambda-free path) cannot matter; lambda > 0 does."""
    kw = dict(algo="seac", env="black_blue_red", n_envs=4, steps=400, eval_every=10, eval_episodes=4)
    a = train(TrainConfig(seac_lambda=0.0, **kw), tmp_path / "a", resume=False, progress=False)
    b = train(TrainConfig(seac_lambda=0.0, **kw), tmp_path / "b", resume=False, progress=False)
    c = train(TrainConfig(seac_lambda=1.0, **kw), tmp_path / "c", resume=False, progress=False)
    assert a["eval_return"].tolist() == b["eval_return"].tolist()
    assert np.isnan(a["seac_weight"].iloc[-1]) and not np.isnan(c["seac_weight"].iloc[-1])
