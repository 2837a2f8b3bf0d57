"""Objectives and distributions of the neural track against independent computations."""
import copy
import math
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from oapo_lite import reuse
from oapo_lite.neural.adam import Adam
from oapo_lite.neural.config import TrainConfig
from oapo_lite.neural.losses import gae, normalise, off_agent_objective, source_mean, update_factor, value_loss, weighted_kl
from oapo_lite.neural.nets import Actors, Categorical, Critic, Gaussian, ValueNorm
from oapo_lite.neural.ppo_family import _minibatches, advantages, critic_values, descend, update_critic
from oapo_lite.neural.rollout import States

torch.set_num_threads(1)


def test_gae_matches_the_discounted_sum_of_td_errors():
    """A_t = sum_k (gamma lam)^k delta_{t+k} up to the end of the episode, by brute force."""
    rng = np.random.default_rng(0)
    T, N, gamma, lam = 12, 3, 0.9, 0.8
    reward, value, next_value = rng.normal(size=(3, T, N))
    done = rng.random((T, N)) < 0.2
    delta = reward + gamma * next_value - value
    expected = np.zeros((T, N))
    for e in range(N):
        for t in range(T):
            for k in range(t, T):
                expected[t, e] += (gamma * lam) ** (k - t) * delta[k, e]
                if done[k, e]:
                    break
    got = gae(*(torch.tensor(x) for x in (reward, value, next_value, done)), gamma, lam)
    np.testing.assert_allclose(got.numpy(), expected, rtol=1e-10)


def test_gae_with_lambda_one_is_the_monte_carlo_return_minus_value():
    reward = torch.tensor([[1.0], [0.0], [2.0]])
    value = torch.tensor([[0.5], [0.1], [0.3]])
    next_value = torch.tensor([[0.1], [0.3], [0.0]])  # the episode terminates at t = 2
    done = torch.tensor([[False], [False], [True]])
    got = gae(reward, value, next_value, done, 0.5, 1.0)
    returns = torch.tensor([[1 + 0.5 * 0 + 0.25 * 2], [0 + 0.5 * 2], [2.0]])
    torch.testing.assert_close(got, returns - value)


@pytest.mark.parametrize("bootstrap, env0", [
    # env 0 is truncated at t = 1; its V(final state) = 10 continues the return only with bootstrap
    (True, [1.8 + 0.72 * 7.0, 7.0, 2.6]),
    (False, [1.8 + 0.72 * -2.0, -2.0, 2.6]),
])
def test_advantages_of_a_hand_computed_three_step_rollout(bootstrap, env0):
    """gamma 0.9, lambda 0.8 (gamma lambda = 0.72); V(s) is the state's first entry.
    env 0: values 1, 2, 3, 4; rewards 1, 0, 2; truncated at t = 1 (V(final) = 10):
      delta_2 = 2 + 0.9 * 4 - 3 = 2.6; delta_1 = 0 + 0.9 * 10 - 2 = 7 (or -2 without bootstrap);
      delta_0 = 1 + 0.9 * 2 - 1 = 1.8; the recursion stops at t = 1.
    env 1: values 0.5, 1.5, 2.5, 3.5; rewards 0, 1, 1; terminated at t = 0 (next value 0 either way):
      A_0 = -0.5; delta_2 = 1 + 0.9 * 3.5 - 2.5 = 1.65; A_1 = 1 + 0.9 * 2.5 - 1.5 + 0.72 * 1.65."""
    value = torch.tensor([[1.0, 0.5], [2.0, 1.5], [3.0, 2.5], [4.0, 3.5]])
    batch = SimpleNamespace(
        states=States.of(value[..., None]),
        final_state=torch.tensor([[7.0, 7.0], [10.0, 7.0], [7.0, 7.0]])[..., None],  # 7: never read
        reward=torch.tensor([[1.0, 0.0], [0.0, 1.0], [2.0, 1.0]]),
        terminated=torch.tensor([[False, True], [False, False], [False, False]]),
        truncated=torch.tensor([[False, False], [True, False], [False, False]]))
    def critic(state):
        return state[..., 0]

    identity = SimpleNamespace(denormalize=lambda x: x)
    adv, returns, v_old = advantages(critic, identity, batch, TrainConfig(gamma=0.9, gae_lambda=0.8), bootstrap)
    expected = torch.tensor([[env0[0], -0.5], [env0[1], 1.75 + 0.72 * 1.65], [env0[2], 1.65]])
    torch.testing.assert_close(returns - value[:-1].reshape(-1), expected.reshape(-1))
    torch.testing.assert_close(adv, normalise(expected.reshape(-1)))
    torch.testing.assert_close(v_old, value[:-1].reshape(-1))



@pytest.mark.parametrize("n_minibatch", [1, 2])
def test_the_critic_on_distinct_states_moves_as_on_every_samples_own_state(n_minibatch):
    """update_critic forwards every distinct state once and reads each sample's value from it;
    plain SGD steps then move the critic as the value loss on every sample's own state does, up
    to float32 sums taken in another order (1e-5 relative)."""
    g = torch.Generator().manual_seed(0)
    T, N, D = 10, 8, 6
    state = torch.randn(5, D, generator=g)[torch.randint(0, 5, (T + 1, N), generator=g)]  # 5 states, repeating
    returns, v_old = torch.randn(2, T * N, generator=g)
    cfg = TrainConfig(n_envs=N, rollout_len=T, ppo_epochs=3, n_minibatch=n_minibatch, max_grad_norm=1e6)
    critic = Critic(D, (16, 16), g)
    plain = copy.deepcopy(critic)
    states = States.of(state)
    assert len(states.rows) <= 5
    update_critic(critic, torch.optim.SGD(critic.parameters(), lr=0.1), ValueNorm(), states, v_old, returns, cfg,
                  np.random.default_rng(0))

    value_norm, rng, opt = ValueNorm(), np.random.default_rng(0), torch.optim.SGD(plain.parameters(), lr=0.1)
    value_norm.update(returns)
    own_state, target = state[:-1].reshape(T * N, D), value_norm.normalize(returns)
    for _ in range(cfg.ppo_epochs):
        for idx in _minibatches(T * N, n_minibatch, rng):
            opt.zero_grad()
            value_loss(plain(own_state[idx]), v_old[idx], target[idx], cfg.clip).backward()
            opt.step()
    for moved, reference in zip(critic.parameters(), plain.parameters()):
        torch.testing.assert_close(moved, reference, rtol=1e-5, atol=1e-6)

def test_values_forward_states_that_do_not_repeat_as_they_come():
    """Where few states repeat (the engines' batches), ``critic_values`` forwards the samples' own rows
    in their order: the same numbers and the same gradient, bit for bit, as the plain forward;
    where most repeat it reads each sample's value from its distinct state."""
    g = torch.Generator().manual_seed(1)
    rows, critic = torch.randn(40, 6, generator=g), Critic(6, (16, 16), g)
    index = torch.randperm(40, generator=g)[torch.tensor([*range(30), 0, 1, 2])]  # 3 repeats of 33
    plain = critic(rows[index])
    assert torch.equal(critic_values(critic, rows, index), plain)
    grads = [torch.autograd.grad(f().square().mean(), list(critic.parameters()))
             for f in (lambda: critic_values(critic, rows, index), lambda: critic(rows[index]))]
    assert all(torch.equal(a, b) for a, b in zip(*grads))
    repeating = index[torch.randint(0, 10, (50,), generator=g)]  # 10 distinct states in 50
    torch.testing.assert_close(critic_values(critic, rows, repeating), critic(rows[repeating]))


def _sources(seed=0, S=3, B=50):
    g = torch.Generator().manual_seed(seed)
    logp_old = -torch.rand(S, B, generator=g) * 2
    logp_new = (logp_old + 0.5 * torch.randn(S, B, generator=g)).requires_grad_()
    factor = torch.exp(0.3 * torch.randn(B, generator=g))
    adv = torch.randn(B, generator=g)
    weights = torch.softmax(torch.randn(S, generator=g), 0)
    return logp_new, logp_old, weights, factor, adv


def test_surrogate_eq7_is_the_weighted_mean_of_ratio_times_factor_times_advantage():
    logp_new, logp_old, w, factor, adv = _sources()
    got = off_agent_objective(logp_new, logp_old, w, factor, adv, clip=None)
    ratio = np.exp(logp_new.detach().numpy() - logp_old.numpy())
    expected = sum(w[j].item() * np.mean(ratio[j] * factor.numpy() * adv.numpy()) for j in range(3))
    assert got.item() == pytest.approx(expected, rel=1e-5)


def test_clipped_samples_carry_no_gradient_eq8():
    """PPO clip: a sample whose ratio left [1 - eps, 1 + eps] in the advantage's direction
    stops pushing; every other sample's gradient is w_j rho A r / B."""
    logp_new, logp_old, w, factor, adv = _sources(1)
    clip = 0.2
    off_agent_objective(logp_new, logp_old, w, factor, adv, clip).backward()
    ratio = torch.exp(logp_new - logp_old).detach()
    scaled = factor * adv
    stopped = ((ratio > 1 + clip) & (scaled > 0)) | ((ratio < 1 - clip) & (scaled < 0))
    assert stopped.any() and (~stopped).any()
    assert (logp_new.grad[stopped] == 0).all()
    expected = (w[:, None] * scaled * ratio / adv.shape[0])[~stopped]
    torch.testing.assert_close(logp_new.grad[~stopped], expected)


def test_uniform_weights_over_sources_is_mappo_on_the_concatenated_batch():
    """MAPPO's loss is one mean over every agent's samples; with a shared net and M = 1/n the
    off-agent mixture gives the same number (equal batch sizes, factor 1)."""
    logp_new, logp_old, _, _, adv = _sources(2)
    S = logp_new.shape[0]
    mixture = off_agent_objective(logp_new, logp_old, torch.full((S,), 1 / S), torch.ones(adv.shape), adv, 0.2)
    r = torch.exp(logp_new - logp_old).reshape(-1)
    a = adv.repeat(S)
    mappo = torch.min(r * a, r.clamp(0.8, 1.2) * a).mean()
    torch.testing.assert_close(mixture, mappo)


def test_factor_is_the_product_of_own_seat_ratios():
    g = torch.Generator().manual_seed(3)
    new, old = -torch.rand(2, 4, 10, generator=g)  # 4 learners, 10 samples each
    factor = torch.ones(10)
    for k in range(4):
        factor = update_factor(factor, new[k : k + 1], old[k : k + 1])
    explicit = torch.prod(torch.exp(new) / torch.exp(old), 0)
    torch.testing.assert_close(factor, explicit)


def test_weighted_kl_mixes_per_source_means():
    kl = torch.tensor([[1.0, 3.0], [10.0, 30.0]])
    assert weighted_kl(kl, torch.tensor([0.25, 0.75])).item() == pytest.approx(0.25 * 2 + 0.75 * 20)


def test_inactive_samples_contribute_nothing_to_objective_kl_and_factor():
    """With an ``active`` mask, each source's mean runs over its active samples only: the
    same numbers as dropping the inactive samples; a factor ignores an inactive seat's ratio."""
    logp_new, logp_old, w, factor, adv = _sources(4)
    active = torch.rand(logp_new.shape, generator=torch.Generator().manual_seed(0)) < 0.6
    active[2] = False  # a source that never acted adds nothing
    got = off_agent_objective(logp_new, logp_old, w, factor, adv, 0.2, active)
    expected = sum(w[j] * off_agent_objective(logp_new[j, active[j]][None], logp_old[j, active[j]][None],
                                              torch.ones(1), factor[active[j]], adv[active[j]], 0.2)
                   for j in range(2))
    torch.testing.assert_close(got, expected)
    kl = torch.rand(logp_new.shape, generator=torch.Generator().manual_seed(1))
    torch.testing.assert_close(weighted_kl(kl, w, active), sum(w[j] * kl[j, active[j]].mean() for j in range(2)))
    assert torch.equal(source_mean(kl, None), kl.mean(-1))  # no mask: the plain mean, bit for bit
    torch.testing.assert_close(update_factor(factor, logp_new[:1].detach(), logp_old[:1], active[:1]),
                               factor * torch.where(active[0], torch.exp(logp_new[0].detach() - logp_old[0]), 1.0))


def test_clipped_value_loss_takes_the_worse_of_raw_and_clipped():
    value, old, target = torch.tensor([1.0, 0.0]), torch.tensor([0.0, 0.0]), torch.tensor([1.0, 0.05])
    # sample 0: raw error 0, clipped prediction 0.2 -> error 0.8; sample 1: both 0.05
    expected = np.mean([0.5 * 0.8**2, 0.5 * 0.05**2])
    assert value_loss(value, old, target, clip=0.2).item() == pytest.approx(expected)


def test_normalise_gives_zero_mean_unit_std():
    x = normalise(torch.randn(1000, generator=torch.Generator().manual_seed(0)) * 5 + 3)
    assert abs(x.mean().item()) < 1e-6 and x.std().item() == pytest.approx(1.0, abs=1e-4)


def test_value_norm_after_one_batch_uses_that_batch_mean_and_variance():
    x = torch.randn(500, generator=torch.Generator().manual_seed(1)) * 3 + 2
    norm = ValueNorm()
    norm.update(x)
    z = norm.normalize(x)
    assert z.mean().item() == pytest.approx(0.0, abs=1e-4)
    assert z.double().pow(2).mean().item() == pytest.approx(1.0, abs=1e-4)  # population variance
    torch.testing.assert_close(norm.denormalize(z), x)


def test_categorical_head_agrees_with_torch_distributions_and_respects_masks():
    g = torch.Generator().manual_seed(0)
    out, out2 = torch.randn(2, 40, 5, generator=g)
    avail = torch.rand(40, 5, generator=g) > 0.3
    avail[:, 0] = True
    d, d2 = Categorical.params(out, avail, None), Categorical.params(out2, avail, None)
    ref = torch.distributions.Categorical(logits=out.masked_fill(~avail, -1e10))
    ref2 = torch.distributions.Categorical(logits=out2.masked_fill(~avail, -1e10))
    a = Categorical.sample(d, g)
    assert avail.gather(1, a[:, None]).all()
    torch.testing.assert_close(Categorical.log_prob(d, a), ref.log_prob(a))
    torch.testing.assert_close(Categorical.entropy(d), ref.entropy())
    torch.testing.assert_close(Categorical.kl(d, d2), torch.distributions.kl_divergence(ref, ref2))


def test_categorical_sampling_matches_the_probabilities():
    d = torch.log(torch.tensor([[0.1, 0.6, 0.0, 0.3]])).expand(20000, 4)
    a = Categorical.sample(d, torch.Generator().manual_seed(0))
    freq = torch.bincount(a, minlength=4).double() / len(a)
    np.testing.assert_allclose(freq.numpy(), [0.1, 0.6, 0.0, 0.3], atol=0.015)


def test_gaussian_head_agrees_with_torch_distributions():
    g = torch.Generator().manual_seed(0)
    mean, mean2 = torch.randn(2, 30, 3, generator=g)
    log_std, log_std2 = 0.3 * torch.randn(2, 1, 3, generator=g)
    d = Gaussian.params(mean[None], None, log_std)[0]
    d2 = Gaussian.params(mean2[None], None, log_std2)[0]
    ref = torch.distributions.Normal(mean, log_std[0].exp())
    ref2 = torch.distributions.Normal(mean2, log_std2[0].exp())
    a = Gaussian.sample(d, g)
    torch.testing.assert_close(Gaussian.log_prob(d, a), ref.log_prob(a).sum(-1))
    torch.testing.assert_close(Gaussian.entropy(d), ref.entropy().sum(-1))
    torch.testing.assert_close(Gaussian.kl(d, d2), torch.distributions.kl_divergence(ref, ref2).sum(-1))


def _reduced(kl: torch.Tensor, reduce: str) -> float:
    """One statistic of a pair's per-observation KLs, computed its own way (torch)."""
    return {"max": kl.max, "mean": kl.mean, "q90": lambda: torch.quantile(kl.double(), 0.9)}[reduce]().item()


@pytest.mark.parametrize("reduce", reuse.KL_REDUCES)
def test_kl_matrix_of_both_heads_agree_with_a_per_pair_loop(reduce):
    """K[i, j] = reduce_b KL(pi_j(.|o_j) || pi_i(.|o_j)), checked pair by pair."""
    g = torch.Generator().manual_seed(5)
    for head, P in ((Categorical, 4), (Gaussian, 6)):
        d = torch.randn(3, 3, 20, P, generator=g)
        if head is Categorical:
            d = torch.log_softmax(d, -1)
        K = reuse.reduce_kl(head.pairwise_kl(d), reduce)
        for i in range(3):
            for j in range(3):
                kl = head.kl(d[j, j], d[i, j])
                assert K[i, j] == pytest.approx(_reduced(kl, reduce), rel=1e-5, abs=1e-7)
        assert np.allclose(np.diag(K), 0.0, atol=1e-7)


def test_batched_actors_equal_separate_forwards():
    """One baddbmm forward over stacked nets = each net run on its own rows."""
    gen = torch.Generator().manual_seed(0)
    actors = Actors(3, obs_dim=7, n_actions=4, hidden=(8, 8), continuous=False, gen=gen)
    obs = torch.randn(3, 11, 7, generator=gen)
    avail = torch.ones(3, 11, 4, dtype=torch.bool)
    together = actors(obs, [2, 0, 2], avail)
    for row, net in enumerate([2, 0, 2]):
        alone = actors(obs[row : row + 1], [net], avail[row : row + 1])[0]
        torch.testing.assert_close(together[row], alone)
    assert math.isclose(together.exp().sum(-1).mean().item(), 1.0, rel_tol=1e-6)


def test_kl_matrix_feeds_the_reuse_rule():
    """The categorical KLs go through reuse.pairwise_kl and reduce_kl: identical nets are at distance 0."""
    gen = torch.Generator().manual_seed(0)
    actors = Actors(2, 5, 3, (8,), False, gen)
    with torch.no_grad():
        for p1, p0 in zip(actors.weights[1], actors.weights[0]):
            p1.copy_(p0)
    obs = torch.randn(1, 10, 5, generator=gen).expand(2, 10, 5)
    d = actors(obs, [0, 1], torch.ones(2, 10, 3, dtype=torch.bool))
    K = reuse.reduce_kl(Categorical.pairwise_kl(torch.stack([d, d])), "max")
    assert (K == 0).all()
    assert (reuse.oapo_matrix(K, 0.0, 0.5) == 0.5).all()


@pytest.mark.parametrize("max_norm", [1e-3, 1e3], ids=["clipped", "not clipped"])
def test_descend_is_torchs_clipped_step_bit_for_bit(max_norm):
    g = torch.Generator().manual_seed(0)
    ours = Critic(7, (16, 16), g)
    torchs = copy.deepcopy(ours)
    x, y = torch.randn(2, 50, 7, generator=g)
    opts = [torch.optim.Adam(net.parameters(), lr=1e-2, fused=True) for net in (ours, torchs)]
    for _ in range(3):
        descend(opts[0], list(ours.parameters()), (ours(x) - y[:, 0]).pow(2).mean(), max_norm)
        opts[1].zero_grad()
        (torchs(x) - y[:, 0]).pow(2).mean().backward()
        torch.nn.utils.clip_grad_norm_(torchs.parameters(), max_norm)
        opts[1].step()
    assert all(torch.equal(a, b) for a, b in zip(ours.parameters(), torchs.parameters()))


def test_adam_is_torchs_foreach_adam_bit_for_bit_and_shares_its_checkpoints():
    """The learners' Adam against torch's (foreach): parameters and state equal after steps
    under a changing learning rate (annealing) and a parameter that misses its gradient at
    first (its own step count then lags); a state saved by one loads into the other."""
    g = torch.Generator().manual_seed(0)
    ours = Critic(7, (16, 16), g)
    torchs = copy.deepcopy(ours)
    opts = [Adam(ours.parameters(), lr=1e-2, eps=1e-5),
            torch.optim.Adam(torchs.parameters(), lr=1e-2, eps=1e-5, foreach=True)]
    x, y = torch.randn(2, 50, 7, generator=g)
    for k in range(40):
        for net, opt in zip((ours, torchs), opts):
            opt.param_groups[0]["lr"] = 1e-2 * (1 - k / 40)
            opt.zero_grad()
            (net(x) - y[:, 0]).pow(2).mean().backward()
            if k < 3:
                net.net[0].bias.grad = None
            opt.step()
        if k == 20:  # each continues from the other's state
            states = [o.state_dict() for o in opts]
            opts[0].load_state_dict(states[1])
            opts[1].load_state_dict(states[0])
    assert all(torch.equal(a, b) for a, b in zip(ours.parameters(), torchs.parameters()))
    ours_state, torchs_state = (o.state_dict()["state"] for o in opts)
    assert ours_state[1]["step"] == 37 and ours_state[0]["step"] == 40  # the bias missed 3 steps
    assert all(torch.equal(ours_state[i][key], torchs_state[i][key]) for i in ours_state for key in ours_state[i])
    with pytest.raises(ValueError, match="2 parameter groups given; allowed: one"):
        Adam([{"params": [torch.zeros(1)]}, {"params": [torch.zeros(1)]}], lr=1e-2, eps=1e-5)


def test_feature_norm_is_a_layernorm_per_net_in_front_of_each_mlp():
    """HARL's feature normalisation: each net's output is its MLP on nn.LayerNorm(obs) with the
    net's own scale and shift, so it does not change when an observation is scaled and shifted;
    without it the first layer sees the raw observation."""
    gen = torch.Generator().manual_seed(0)
    actors = Actors(2, obs_dim=6, n_actions=3, hidden=(8,), continuous=False, gen=gen, feature_norm=True)
    with torch.no_grad():
        for k in range(2):
            actors.norms[k][0].uniform_(0.5, 1.5, generator=gen)
            actors.norms[k][1].uniform_(-0.5, 0.5, generator=gen)
    obs = torch.randn(2, 5, 6, generator=gen)
    avail = torch.ones(2, 5, 3, dtype=torch.bool)
    out = actors(obs, [0, 1], avail)
    for k in range(2):
        ln = torch.nn.LayerNorm(6)
        with torch.no_grad():
            ln.weight.copy_(actors.norms[k][0])
            ln.bias.copy_(actors.norms[k][1])
        w0, b0, w1, b1 = list(actors.weights[k])[:4]
        ref = torch.log_softmax(torch.relu(ln(obs[k]) @ w0 + b0) @ w1 + b1, -1)
        torch.testing.assert_close(out[k], ref)
    torch.testing.assert_close(actors(3.0 * obs + 2.0, [0, 1], avail), out, atol=1e-4, rtol=1e-4)
    assert len(actors.net_params(0)) == 2 + 4  # the LayerNorm's scale and shift are trained with the net
    plain = Actors(2, 6, 3, (8,), False, torch.Generator().manual_seed(0))
    assert plain.stack([0, 1])[2] is None and not torch.allclose(plain(3.0 * obs + 2.0, [0, 1], avail),
                                                                 plain(obs, [0, 1], avail))
    critic = Critic(6, (8,), torch.Generator().manual_seed(0), feature_norm=True)
    states = torch.randn(4, 6, generator=gen)
    torch.testing.assert_close(critic(5.0 * states - 1.0), critic(states), atol=1e-4, rtol=1e-4)
