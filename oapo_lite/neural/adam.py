"""The learners' optimiser."""
from __future__ import annotations

import torch


class Adam(torch.optim.Adam):
    """torch's Adam with ``foreach=True``, bit for bit, stepped without torch.optim's machinery
    around the arithmetic (profiler hooks, compiler guards, grouping the tensors by device at every
    step), which on these small nets cost more than the arithmetic: the same foreach kernels in
    the same order, on the same state (so checkpoints load either way). One parameter group, no
    weight decay, no amsgrad: what the learners use."""

    def __init__(self, params, lr: float, eps: float):
        super().__init__(params, lr=lr, eps=eps, foreach=True)
        if len(self.param_groups) != 1:
            raise ValueError(f"{len(self.param_groups)} parameter groups given; allowed: one (a list of tensors)")

    @torch.no_grad()
    def step(self) -> None:
        group = self.param_groups[0]
        params = [p for p in group["params"] if p.grad is not None]
        for p in params:
            if not self.state[p]:
                self.state[p].update(step=torch.tensor(0.0), exp_avg=torch.zeros_like(p), exp_avg_sq=torch.zeros_like(p))
        states = [self.state[p] for p in params]
        grads, m, v = [p.grad for p in params], [s["exp_avg"] for s in states], [s["exp_avg_sq"] for s in states]
        (beta1, beta2), lr, eps = group["betas"], group["lr"], group["eps"]
        steps = [s["step"] for s in states]
        torch._foreach_add_(steps, torch.tensor(1.0), alpha=1.0)
        torch._foreach_lerp_(m, grads, 1 - beta1)
        torch._foreach_mul_(v, beta2)
        torch._foreach_addcmul_(v, grads, grads, 1 - beta2)
        t = [s.item() for s in steps]  # a tensor's own count: one that missed a gradient lags
        denom = torch._foreach_sqrt(v)
        torch._foreach_div_(denom, [(1 - beta2 ** k) ** 0.5 for k in t])
        torch._foreach_add_(denom, eps)
        torch._foreach_addcdiv_(params, m, denom, [(lr / (1 - beta1 ** k)) * -1 for k in t])


# torch.optim wraps a subclass's ``step`` in its profiler hook when the first optimiser is built,
# unless the function says it is hooked already: the wrapper costs as much as this step
Adam.step.hooked = True
