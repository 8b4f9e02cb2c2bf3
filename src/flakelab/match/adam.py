"""Adam on one tensor for the recipe search and the correction, through torch's functional form.

``torch.optim.Adam``, like every optimiser class of torch 2.13, imports ``torch._dynamo`` the
first time one is built (its ``add_param_group`` is wrapped to keep the compiler out); that
import pulls in sympy and about 800 modules and took 1.8 s of the first match in a process,
against 0.8 s for the whole of a later one. Every ``flakelab match`` and ``flakelab correct``
is a first match. :func:`torch.optim.adam.adam` is the same update that class calls (the
fused CPU kernel or the single-tensor one), and it imports nothing: the steps are the class's
to the last bit (``tests/test_match.py``).
"""

from __future__ import annotations

import torch
from torch.optim.adam import adam

__all__ = ["TensorAdam"]


class TensorAdam:
    """Adam (β = 0.9, 0.999, ε = 1e-8, no weight decay) on ``parameter`` with step size
    ``lr``, its state as ``torch.optim.Adam(fused=fused)`` keeps it."""

    def __init__(self, parameter: torch.Tensor, lr: float, fused: bool = False) -> None:
        self.parameter, self.lr, self.fused = parameter, lr, fused
        self.exp_avg = torch.zeros_like(parameter, memory_format=torch.preserve_format)
        self.exp_avg_sq = torch.zeros_like(parameter, memory_format=torch.preserve_format)
        # the class keeps the count as a float32 scalar, fused or not (torch's default dtype)
        self.count = torch.zeros((), dtype=torch.float32)

    def step(self, loss: torch.Tensor) -> None:
        """One step down the gradient of the scalar ``loss`` with respect to the parameter."""
        (grad,) = torch.autograd.grad(loss, self.parameter)
        with torch.no_grad():
            adam(
                [self.parameter],
                [grad],
                [self.exp_avg],
                [self.exp_avg_sq],
                [],
                [self.count],
                fused=self.fused,
                foreach=False,
                amsgrad=False,
                beta1=0.9,
                beta2=0.999,
                lr=self.lr,
                weight_decay=0.0,
                eps=1e-8,
                maximize=False,
            )
