"""Forward models as the matcher uses them: fractions ``[N, T]`` → reflectance ``[N, G, 31]``.

* :class:`LearnedForward` — the MLP (differentiable through torch).
* :class:`HybridForward` — the MLP for known toners, times the physics model's scaling for
  toners marked new (DESIGN.md §3, §6): R = R_MLP(x_known) · R_phys(x) / R_phys(x_known);
  the physics ratio's derivatives come from finite differences on the toners in play.
* :class:`KubelkaMunkForward` — two-constant Kubelka–Munk with Saunderson for solids, from
  K and S per toner (e.g. measured pigment data).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from numpy.typing import NDArray

from flakelab.library.toners import Library
from flakelab.models.network import LOG_CEILING, LOG_FLOOR, ForwardModel
from flakelab.physics.fast import predict
from flakelab.physics.kubelka_munk import SAUNDERSON_K1, SAUNDERSON_K2
from flakelab.physics.layer import layer_from_fractions

__all__ = ["LearnedForward", "HybridForward", "KubelkaMunkForward"]


class LearnedForward:
    """The learned model; ``texture`` readings predicted alongside."""

    def __init__(self, model: ForwardModel) -> None:
        self.model = model
        self.toners = model.toners
        self.geometries = model.geometries
        self.name = f"learned ({model.instrument}, {model.info.get('name', 'model')})"
        self.novel: tuple[str, ...] = ()

    def __call__(self, fractions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
        y = self.model.torch_forward(fractions.to(torch.float32)).to(torch.float64)
        spectral = self.model.spectral_outputs
        log_R = torch.clamp(y[:, :spectral], np.log(LOG_FLOOR) - 3, LOG_CEILING)
        R = torch.exp(log_R).reshape(-1, len(self.geometries), 31)
        return R, y[:, spectral:]


class _PhysicsRatio(torch.autograd.Function):
    """R_phys(x)/R_phys(x_known) with a finite-difference Jacobian on the used columns."""

    @staticmethod
    def forward(ctx, fractions, hybrid):
        x = fractions.detach().numpy()
        ratio, jacobian = hybrid.physics_ratio(x)
        ctx.save_for_backward(torch.as_tensor(jacobian))
        return torch.as_tensor(ratio)

    @staticmethod
    def backward(ctx, grad):
        (jacobian,) = ctx.saved_tensors  # [N, G, W, T]
        return torch.einsum("ngw,ngwt->nt", grad, jacobian), None


class HybridForward(LearnedForward):
    """Learned base, physics scaling for ``novel`` toners (too few cases to learn them)."""

    def __init__(self, model: ForwardModel, library: Library, novel: Sequence[str]) -> None:
        super().__init__(model)
        self.library = library
        self.novel = tuple(novel)
        self.name = f"hybrid: learned + physics scaling for {', '.join(self.novel)}"
        names = library.names
        self._novel_mask = np.array([n in self.novel for n in names])
        self._step = 1e-4

    def _physics(self, x: NDArray) -> NDArray:
        return np.pi * predict(layer_from_fractions(self.library, x), self.geometries)

    def physics_ratio(self, x: NDArray) -> tuple[NDArray, NDArray]:
        """Ratio R_phys(x) / R_phys(x_known) ``[N, G, W]`` (x_known: the known toners,
        renormalised, as the learned model sees them; R_phys(x) alone when nothing is known)
        and its Jacobian ``[N, G, W, T]``. Rows without new toners scale by one."""
        ratio = np.ones((x.shape[0], len(self.geometries), 31))
        jacobian = np.zeros((*ratio.shape, x.shape[1]))
        rows = np.flatnonzero(np.any(x[:, self._novel_mask] > 1e-9, axis=1))
        if rows.size == 0:
            return ratio, jacobian
        xs = x[rows]
        known = np.where(self._novel_mask, 0.0, xs)
        total = known.sum(axis=1, keepdims=True)
        base = np.where(
            total[:, :, None] > 1e-6,
            self._physics(known / np.maximum(total, 1e-12)) + 1e-9,
            1.0,
        )
        ratio[rows] = (self._physics(xs) + 1e-9) / base
        for column in np.flatnonzero(self._novel_mask & np.any(xs > 1e-9, axis=0)):
            bumped = xs.copy()
            bumped[:, column] += self._step
            jacobian[rows, ..., column] = (
                (self._physics(bumped) + 1e-9) / base - ratio[rows]
            ) / self._step
        return ratio, jacobian

    def __call__(self, fractions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
        mask = torch.as_tensor(~self._novel_mask, dtype=fractions.dtype)
        known = fractions * mask
        total = known.sum(1, keepdim=True)
        R, texture = super().__call__(known / torch.clamp(total, min=1e-9))
        if not np.any(fractions.detach().numpy()[:, self._novel_mask] > 1e-9):
            return R, texture
        R = torch.where(total[:, :, None] > 1e-6, R, torch.ones_like(R))
        return R * _PhysicsRatio.apply(fractions, self), texture


class KubelkaMunkForward:
    """Solid colours: K = Σ cK_i, S = Σ cS_i, R∞ and Saunderson; one (diffuse) geometry."""

    def __init__(
        self, names: Sequence[str], K: NDArray, S: NDArray, geometry: str = "45as45"
    ) -> None:
        self.toners = tuple(names)
        self.geometries = (geometry,)
        self.K = torch.as_tensor(np.asarray(K, float))
        self.S = torch.as_tensor(np.asarray(S, float))
        self.name = "Kubelka–Munk (Saunderson)"
        self.novel: tuple[str, ...] = ()

    def __call__(self, fractions: torch.Tensor) -> tuple[torch.Tensor, None]:
        K = fractions.to(torch.float64) @ self.K
        S = torch.clamp(fractions.to(torch.float64) @ self.S, min=1e-9)
        ratio = K / S
        R_inf = 1 + ratio - torch.sqrt(ratio**2 + 2 * ratio)
        k1, k2 = SAUNDERSON_K1, SAUNDERSON_K2
        R = k1 + (1 - k1) * (1 - k2) * R_inf / (1 - k2 * R_inf)
        return R[:, None, :], None
