"""The trust-region step of OATRPO / HATRPO (Eq. 7): natural gradient by conjugate gradient
on Fisher-vector products, then a backtracking line search that keeps the KL within delta."""
from __future__ import annotations

import math
from typing import Callable

import torch
from torch.nn.utils import parameters_to_vector, vector_to_parameters


def conjugate_gradient(matvec: Callable[[torch.Tensor], torch.Tensor], b: torch.Tensor,
                       iters: int, tol: float = 1e-10) -> torch.Tensor:
    """Approximately solve A x = b for symmetric positive-definite A given only x -> A x."""
    x = torch.zeros_like(b)
    r, p = b.clone(), b.clone()
    rr = r @ r
    for _ in range(iters):
        if rr < tol:
            break
        ap = matvec(p)
        alpha = rr / (p @ ap)
        x += alpha * p
        r -= alpha * ap
        rr_new = r @ r
        p = r + (rr_new / rr) * p
        rr = rr_new
    return x


def flat_grad(y: torch.Tensor, params: list[torch.Tensor], **kw) -> torch.Tensor:
    grads = torch.autograd.grad(y, params, allow_unused=True, **kw)
    return torch.cat([(torch.zeros_like(p) if g is None else g).reshape(-1) for g, p in zip(grads, params)])


def fisher_vector_product(kl_fn: Callable[[], torch.Tensor], params: list[torch.Tensor],
                          damping: float) -> Callable[[torch.Tensor], torch.Tensor]:
    """v -> (F + damping I) v, with F the Hessian of the mean KL(pi_old || pi_theta) at
    theta = theta_old, which equals the Fisher information of the policy there."""
    grad_kl = flat_grad(kl_fn(), params, create_graph=True)

    def fvp(v: torch.Tensor) -> torch.Tensor:
        return flat_grad(grad_kl @ v, params, retain_graph=True) + damping * v

    return fvp


def trpo_step(params: list[torch.Tensor], objective_fn: Callable[[], torch.Tensor],
              kl_fn: Callable[[], torch.Tensor], delta: float, cg_iters: int, damping: float,
              line_search_steps: int, backtrack: float, accept_ratio: float) -> float:
    """One natural-gradient step on ``objective_fn`` (maximised) under ``kl_fn() <= delta``.

    Full step sqrt(2 delta / s^T F s) s with s = F^-1 g; then shrink by ``backtrack`` until the
    KL is within delta, the objective improved, and improvement / expected > accept_ratio.
    Updates ``params`` in place; returns the KL of the accepted step (NaN if none was accepted
    and the parameters are left unchanged).
    """
    old = parameters_to_vector(params).detach().clone()
    objective = objective_fn()
    g = flat_grad(objective, params)
    fvp = fisher_vector_product(kl_fn, params, damping)
    s = conjugate_gradient(fvp, g, cg_iters)
    shs = s @ fvp(s)
    if not (shs > 0 and torch.isfinite(shs)):
        return math.nan
    full_step = torch.sqrt(2 * delta / shs) * s
    expected = g @ full_step
    base = objective.item()
    with torch.no_grad():
        for k in range(line_search_steps):
            scale = backtrack**k
            vector_to_parameters(old + scale * full_step, params)
            kl = kl_fn().item()
            improve = objective_fn().item() - base
            if kl <= delta and improve > 0 and improve / (scale * expected.item()) > accept_ratio:
                return kl
        vector_to_parameters(old, params)
    return math.nan
