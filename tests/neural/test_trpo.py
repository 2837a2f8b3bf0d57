"""The trust-region machinery: conjugate gradient, Fisher-vector products, the line search."""
import math

import numpy as np
import pytest
import torch
from torch.nn.utils import parameters_to_vector

from oapo_lite.neural.nets import Actors
from oapo_lite.neural.trpo import conjugate_gradient, fisher_vector_product, trpo_step

torch.set_num_threads(1)


def test_conjugate_gradient_solves_a_random_spd_system():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(12, 12))
    spd = a @ a.T + 0.5 * np.eye(12)
    b = rng.normal(size=12)
    A = torch.tensor(spd)
    x = conjugate_gradient(lambda v: A @ v, torch.tensor(b), iters=60)
    np.testing.assert_allclose(x.numpy(), np.linalg.solve(spd, b), rtol=1e-6, atol=1e-8)


def _tiny_actor(continuous: bool):
    gen = torch.Generator().manual_seed(1)
    actors = Actors(1, obs_dim=3, n_actions=2 if continuous else 3, hidden=(4,), continuous=continuous, gen=gen)
    with torch.no_grad():  # move the output layer off its near-zero init so the Fisher is not tiny
        actors.weights[0][2].mul_(100.0)
        actors.weights[0][-1].fill_(-0.3)
    obs = torch.randn(1, 6, 3, generator=gen)
    return actors, obs, actors.net_params(0)


def _jacobian(actors, obs, params, avail):
    """d (distribution parameters, (B, P_out)) / d (flat trainable parameters), by autograd."""
    names = [name for name, p in actors.named_parameters() if any(p is q for q in params)]
    sizes = [p.numel() for p in params]

    def dist(flat):
        tensors = {n: t.view_as(p) for n, t, p in zip(names, flat.split(sizes), params)}
        return torch.func.functional_call(actors, tensors, (obs, [0], avail))[0]

    return torch.autograd.functional.jacobian(dist, parameters_to_vector(params).detach())


def _explicit_fisher(actors, obs, params):
    """F = mean_o E_{a ~ pi(.|o)} [grad log pi(a|o) grad log pi(a|o)^T], from the Jacobian
    of the log-probabilities of every action."""
    avail = torch.ones(1, obs.shape[1], 3, dtype=torch.bool)
    jac = _jacobian(actors, obs, params, avail)  # (B, A, P)
    with torch.no_grad():
        p = actors(obs, [0], avail)[0].exp()
    return torch.einsum("ba,bap,baq->pq", p, jac, jac) / obs.shape[1]


def _explicit_gaussian_fisher(actors, obs, params):
    """Diagonal Gaussian: F = mean_o J_mu^T diag(1/sigma^2) J_mu + 2 J_logstd^T J_logstd."""
    jac = _jacobian(actors, obs, params, None)  # (B, 2D, P)
    with torch.no_grad():
        d = actors(obs, [0], None)[0]
    D = d.shape[-1] // 2
    inv_var = torch.exp(-2 * d[:, D:])
    j_mu, j_ls = jac[:, :D], jac[:, D:]
    return (torch.einsum("bd,bdp,bdq->pq", inv_var, j_mu, j_mu) + 2 * torch.einsum("bdp,bdq->pq", j_ls, j_ls)) \
        / obs.shape[1]


@pytest.mark.parametrize("continuous", [False, True])
def test_fisher_vector_product_equals_the_explicit_fisher_matrix(continuous):
    actors, obs, params = _tiny_actor(continuous)
    avail = None if continuous else torch.ones(1, obs.shape[1], 3, dtype=torch.bool)
    with torch.no_grad():
        d_old = actors(obs, [0], avail)[0]

    def kl():
        return actors.head.kl(d_old, actors(obs, [0], avail)[0]).mean()

    F = (_explicit_gaussian_fisher if continuous else _explicit_fisher)(actors, obs, params)
    assert torch.linalg.matrix_norm(F) > 1e-3  # the check is not vacuous
    v = torch.randn(F.shape[0], generator=torch.Generator().manual_seed(2))
    fvp = fisher_vector_product(kl, params, damping=0.0)
    torch.testing.assert_close(fvp(v), F @ v, rtol=1e-4, atol=1e-6)
    damped = fisher_vector_product(kl, params, damping=0.1)
    torch.testing.assert_close(damped(v), F @ v + 0.1 * v, rtol=1e-4, atol=1e-6)


def _toy_problem(seed: int):
    """A categorical policy on random observations, surrogate mean(r A) with random advantages."""
    actors, obs, params = _tiny_actor(False)
    gen = torch.Generator().manual_seed(seed)
    avail = torch.ones(1, obs.shape[1], 3, dtype=torch.bool)
    with torch.no_grad():
        d_old = actors(obs, [0], avail)[0]
    a = torch.randint(0, 3, (obs.shape[1],), generator=gen)
    adv = torch.randn(obs.shape[1], generator=gen)
    logp_old = d_old.gather(1, a[:, None])[:, 0]

    def objective():
        d = actors(obs, [0], avail)[0]
        return (torch.exp(d.gather(1, a[:, None])[:, 0] - logp_old) * adv).mean()

    def kl():
        return actors.head.kl(d_old, actors(obs, [0], avail)[0]).mean()

    return params, objective, kl


@pytest.mark.parametrize("delta", [1e-4, 1e-2, 0.1, 0.5])
@pytest.mark.parametrize("accept_ratio", [0.0, 0.5])  # 0: the KL test alone guards the step
def test_every_accepted_step_keeps_kl_within_delta_and_improves(delta, accept_ratio):
    accepted = 0
    for seed in range(8):
        params, objective, kl = _toy_problem(seed)
        before = objective().item()
        got = trpo_step(params, objective, kl, delta, cg_iters=10, damping=0.01, line_search_steps=10,
                        backtrack=0.8, accept_ratio=accept_ratio)
        if math.isnan(got):
            continue
        accepted += 1
        assert got <= delta
        assert kl().item() == pytest.approx(got)
        assert objective().item() > before
    assert accepted >= 6


def test_a_rejected_line_search_leaves_the_parameters_unchanged():
    params, objective, kl = _toy_problem(0)
    before = parameters_to_vector(params).detach().clone()
    # an improvement ratio above any achievable value: no step can be accepted
    got = trpo_step(params, objective, kl, 0.01, cg_iters=10, damping=0.1, line_search_steps=3,
                    backtrack=0.8, accept_ratio=1e6)
    assert math.isnan(got)
    assert torch.equal(parameters_to_vector(params), before)


def test_the_full_step_reaches_the_kl_threshold():
    """For a small delta the KL is quadratic along the step, so sqrt(2 delta / s^T F s) s lands
    on KL ~ delta (a little below: damping adds to F) and the line search takes it at once
    (a backtracked step, 0.5x, would have KL ~ delta / 4; a mis-scaled one would miss)."""
    delta = 1e-5
    for seed in range(8):
        params, objective, kl = _toy_problem(seed)
        got = trpo_step(params, objective, kl, delta, cg_iters=10, damping=1e-3, line_search_steps=10,
                        backtrack=0.5, accept_ratio=0.5)
        assert 0.85 * delta <= got <= delta, (seed, got / delta)
