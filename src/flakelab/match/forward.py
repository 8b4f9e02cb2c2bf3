"""Forward models as the matcher uses them: fractions ``[N, T]`` → reflectance ``[N, G, 31]``.

* :class:`LearnedForward` — the MLP (differentiable through torch).
* :class:`HybridForward` — the MLP for known toners, times the physics model's scaling for
  toners marked new (DESIGN.md §3, §6): R = R_MLP(x_base) · R_phys(x) / R_phys(x_base), with
  each new toner standing in the base as its closest known toner; the physics ratio's
  derivatives come from finite differences on the new toners.
* :class:`KubelkaMunkForward` — two-constant Kubelka–Munk with Saunderson for solids, from
  K and S per toner (e.g. measured pigment data).
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import replace

import numpy as np
import torch
from numpy.typing import NDArray

from flakelab.library.toners import Library
from flakelab.models.network import ForwardModel, reflectance_from_log
from flakelab.physics.fast import predict
from flakelab.physics.kubelka_munk import SAUNDERSON_K1, SAUNDERSON_K2
from flakelab.physics.layer import layer_from_fractions

__all__ = ["LearnedForward", "HybridForward", "KubelkaMunkForward"]


class LearnedForward:
    """The learned model; ``texture`` readings predicted alongside. It computes in single
    precision, as it was trained: the matcher optimises in ``dtype`` to avoid conversions."""

    dtype = torch.float32

    def __init__(self, model: ForwardModel) -> None:
        # a frozen copy: the matcher differentiates with respect to the recipe only, and
        # gradients for the weights would cost most of each backward pass (and pile up)
        self.model = replace(model, network=copy.deepcopy(model.network).requires_grad_(False))
        self._forward = self.model.folded()
        self.toners = model.toners
        self.geometries = model.geometries
        self.name = f"learned ({model.instrument}, {model.info.get('name', 'model')})"
        # which model exactly: an adapted model keeps its base's name
        self.model_id = f"{model.info.get('name', 'model')} {model.fingerprint}"
        self.novel: tuple[str, ...] = ()
        # the least effect-toner share of the training cases' effect paints (0: not recorded)
        self.effect_share_floor = float(model.info.get("effect_share_floor", 0.0))

    def __call__(self, fractions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
        y = self._forward(fractions.to(torch.float32)).to(fractions.dtype)
        return self._reflectance(y), y[:, self.model.spectral_outputs :]

    def _reflectance(self, y: torch.Tensor) -> torch.Tensor:
        """Reflectance ``[..., G, 31]`` from the model's outputs ``[..., outputs]``."""
        R = reflectance_from_log(y[..., : self.model.spectral_outputs])
        return R.reshape(*y.shape[:-1], len(self.geometries), 31)

    @property
    def members(self) -> int:
        """Networks the learned model averages (1: no spread to report)."""
        return self.model.members

    def member_reflectance(self, x: NDArray) -> NDArray:
        """Each member's reflectance ``[K, N, G, 31]`` for recipes ``x[N, T]``."""
        return self.model.predict_members(x)

    def with_members(
        self, fractions: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor | None, torch.Tensor]:
        """Differentiable, in one pass: the prediction as :meth:`__call__` gives it, and each
        member's reflectance ``[K, N, G, 31]`` (K = 1 for a single network), what the
        matcher's model-risk term compares."""
        y = self.model.member_outputs(fractions.to(torch.float32)).to(fractions.dtype)
        mean = y.mean(dim=0)
        return self._reflectance(mean), mean[:, self.model.spectral_outputs :], self._reflectance(y)


class _PhysicsRatio(torch.autograd.Function):
    """R_phys(x)/R_phys(x_known) with a finite-difference Jacobian on the used columns."""

    @staticmethod
    def forward(ctx, fractions, hybrid):
        x = fractions.detach().numpy()
        ratio, jacobian = hybrid.physics_ratio(x)
        ctx.dtype = fractions.dtype
        ctx.save_for_backward(torch.as_tensor(jacobian))
        return torch.as_tensor(ratio)

    @staticmethod
    def backward(ctx, grad):
        (jacobian,) = ctx.saved_tensors  # [N, G, W, T]
        return torch.einsum("ngw,ngwt->nt", grad.to(jacobian.dtype), jacobian).to(ctx.dtype), None


class HybridForward(LearnedForward):
    """Learned base, physics scaling for ``novel`` toners (too few cases to learn them).

    Each new toner stands in the learned base as its *proxy*: the known toner of the same
    kind whose physics spectrum in a reference metallic is closest. The base then keeps the
    recipe's concentrations (inside the training data), and the physics ratio only has to
    carry the difference between two similar toners:
    R = R_MLP(x_base) · R_phys(x) / R_phys(x_base), x_base = x with new → proxy amounts.
    A new toner without a same-kind known toner is dropped from the base (renormalised).
    When new toners make up most of the recipe, the base itself is mostly stand-ins, and the
    physics base R_phys(x_base) takes over from the learned one (:meth:`_physics_trust`).
    """

    def __init__(self, model: ForwardModel, library: Library, novel: Sequence[str]) -> None:
        super().__init__(model)
        self.library = library
        self.novel = tuple(novel)
        names = library.names
        self._novel_mask = np.array([n in self.novel for n in names])
        self.proxies = _proxies(library, self._novel_mask)
        self._substitute = np.eye(len(names))
        for j in np.flatnonzero(self._novel_mask):
            self._substitute[j] = 0.0
            if j in self.proxies:
                self._substitute[j, self.proxies[j]] = 1.0
        stand_ins = ", ".join(
            f"{names[j]} (as {names[self.proxies[j]]})" if j in self.proxies else names[j]
            for j in np.flatnonzero(self._novel_mask)
        )
        self.name = f"hybrid: learned + physics scaling for {stand_ins}"
        self._step = 1e-4

    def _physics(self, x: NDArray) -> NDArray:
        return np.pi * predict(layer_from_fractions(self.library, x), self.geometries)

    def base_fractions(self, x: NDArray) -> NDArray:
        """What the learned model sees: new toners moved onto their proxies, renormalised."""
        base = x @ self._substitute
        return base / np.maximum(base.sum(axis=-1, keepdims=True), 1e-12)

    def physics_ratio(self, x: NDArray) -> tuple[NDArray, NDArray]:
        """Ratio R_phys(x) / R_phys(x_base) ``[N, G, W]`` and its Jacobian ``[N, G, W, T]``
        with respect to the new toners' amounts. Rows without new toners scale by one."""
        ratio = np.ones((x.shape[0], len(self.geometries), 31))
        jacobian = np.zeros((*ratio.shape, x.shape[1]))
        rows = np.flatnonzero(np.any(x[:, self._novel_mask] > 1e-9, axis=1))
        if rows.size == 0:
            return ratio, jacobian
        xs = x[rows]
        columns = np.flatnonzero(self._novel_mask & np.any(xs > 1e-9, axis=0))
        # the recipes and each one-column bump in one physics call: the layer model costs
        # several times more per recipe in small batches
        variants = np.repeat(xs[None], columns.size + 1, axis=0)
        variants[np.arange(1, columns.size + 1), :, columns] += self._step
        ratios = self._ratio(variants.reshape(-1, x.shape[1])).reshape(-1, *ratio[rows].shape)
        ratio[rows] = ratios[0]
        for k, column in enumerate(columns, start=1):
            jacobian[rows, ..., column] = (ratios[k] - ratios[0]) / self._step
        return ratio, jacobian

    def _ratio(self, x: NDArray) -> NDArray:
        has_base = (x @ self._substitute).sum(axis=1) > 1e-6
        both = self._physics(np.concatenate([x, self.base_fractions(x)])) + 1e-9
        R, base = both[: len(x)], both[len(x) :]
        return R / np.where(has_base[:, None, None], base, 1.0)

    def __call__(self, fractions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
        base, total = self._base(fractions)
        R, texture = super().__call__(base)
        return self._scaled(R, fractions, total), texture

    def _base(self, fractions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The learned base's fractions (new toners on their proxies, renormalised) and the
        share ``[N, 1]`` they keep of the recipe."""
        base = fractions @ torch.as_tensor(self._substitute, dtype=fractions.dtype)
        total = base.sum(1, keepdim=True)
        return base / torch.clamp(total, min=1e-9), total

    def _scaled(self, R: torch.Tensor, fractions: torch.Tensor, total: torch.Tensor):
        """The learned base's reflectance ``R`` scaled by the physics for the new toners."""
        x = fractions.detach().numpy()
        share = x[:, self._novel_mask].sum(axis=1)
        if not np.any(share > 1e-9):
            return R
        R = torch.where(total[:, :, None] > 1e-6, R, torch.ones_like(R))
        trust = self._physics_trust(share)
        if np.any(trust > 0):
            # a base made mostly of stand-ins is outside what the learned model knows: lean
            # on the physics base there (log-linear blend, no gradient through the blend)
            rows = np.flatnonzero(trust > 0)
            physics = np.ones_like(R.detach().numpy())
            physics[rows] = self._physics(self.base_fractions(x[rows])) + 1e-9
            w = torch.as_tensor(trust[:, None, None], dtype=R.dtype)
            physics = torch.as_tensor(physics, dtype=R.dtype)
            R = torch.exp((1 - w) * torch.log(R) + w * torch.log(physics))
        return R * _PhysicsRatio.apply(fractions, self).to(R.dtype)

    def with_members(
        self, fractions: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor | None, torch.Tensor]:
        """The hybrid prediction and the members of its learned base (new toners on their
        proxies): the physics ratio multiplies every member alike, so their disagreement is
        the base's."""
        base, total = self._base(fractions)
        R, texture, members = super().with_members(base)
        return self._scaled(R, fractions, total), texture, members

    def member_reflectance(self, x: NDArray) -> NDArray:
        """Each member's reflectance ``[K, N, G, 31]`` through the hybrid path: the members
        differ in the learned base only, by the factor each puts on the base's mean, and
        only as far as the base is learned (not where the physics base takes over)."""
        base = self.base_fractions(x)
        members = self.model.predict_members(base)
        factor = members / self.model.predict(base)[0][None]
        with torch.no_grad():
            R, _ = self(torch.as_tensor(x, dtype=self.dtype))
        learned = 1 - self._physics_trust(x[:, self._novel_mask].sum(axis=1))
        return R.double().numpy()[None] * factor ** learned[None, :, None, None]

    @staticmethod
    def _physics_trust(share: NDArray) -> NDArray:
        """Weight of the physics base: 0 below 30 % new toners, 1 above 70 %, smooth between."""
        t = np.clip((share - 0.3) / 0.4, 0.0, 1.0)
        return t * t * (3 - 2 * t)


def _proxies(library: Library, novel: NDArray) -> dict[int, int]:
    """For each new toner, the known toner of its kind closest in log spectrum when each
    makes up 10 % of a reference recipe (the library's first aluminium, else on its own)."""
    names = library.names
    aluminium = [names.index(t.name) for t in library.of_kind("aluminium")]
    proxies = {}
    for j in np.flatnonzero(novel):
        kind = library.toners[j].kind
        candidates = [i for i, t in enumerate(library.toners) if t.kind == kind and not novel[i]]
        if not candidates:
            continue
        in_metallic = bool(aluminium) and kind != "aluminium"
        share = 0.1 if in_metallic else 1.0
        mixes = np.zeros((len(candidates) + 1, len(names)))
        if in_metallic:
            mixes[:, aluminium[0]] = 1.0 - share
        mixes[np.arange(len(candidates)), candidates] += share
        mixes[-1, j] += share
        spectra = np.log(
            predict(layer_from_fractions(library, mixes), ("45as15", "45as45", "45as110")) + 1e-6
        )
        distance = np.sqrt(np.mean((spectra[:-1] - spectra[-1]) ** 2, axis=(1, 2)))
        proxies[int(j)] = candidates[int(np.argmin(distance))]
    return proxies


class KubelkaMunkForward:
    """Solid colours: K = Σ cK_i, S = Σ cS_i, R∞ and Saunderson; one (diffuse) geometry."""

    dtype = torch.float64

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
