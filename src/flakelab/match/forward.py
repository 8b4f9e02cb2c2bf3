"""Forward models as the matcher uses them: fractions ``[N, T]`` → reflectance ``[N, G, 31]``.

* :class:`LearnedForward` — the MLP (differentiable through torch).
* :class:`HybridForward` — the MLP for known toners, times the physics model's scaling for
  toners marked new (DESIGN.md §3, §6): R = R_MLP(x_base) · R_phys(x) / R_phys(x_base), with
  each new toner standing in the base as its closest known toner; the physics ratio's
  derivatives come from finite differences on the new toners, which an optimiser's steps
  retake every few steps and follow along their tangent between (:func:`stepping`).
* :class:`PhysicsForward` — the library's physics (the fast model) alone, derivatives by
  finite differences on every toner a recipe uses: for a library without cases, and in the
  harness the exact model of the generated world's nominal physics (what no learned model
  can beat).
* :class:`KubelkaMunkForward` — two-constant Kubelka–Munk with Saunderson for solids, from
  K and S per toner (e.g. measured pigment data).
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Iterable, Sequence
from dataclasses import replace

import numpy as np
import torch
from numpy.typing import NDArray

from flakelab.core.geometry import FACE_GEOMETRY, Geometry
from flakelab.core.spectra import WAVELENGTHS
from flakelab.library.toners import Library
from flakelab.models.network import LOG_FLOOR, ForwardModel, reflectance_from_log
from flakelab.physics.fast import predict, reflectance_factor
from flakelab.physics.kubelka_munk import SAUNDERSON_K1, SAUNDERSON_K2
from flakelab.physics.layer import layer_from_fractions
from flakelab.texture.readings import texture_readings

__all__ = [
    "LearnedForward",
    "HybridForward",
    "PhysicsForward",
    "KubelkaMunkForward",
    "HeldJacobian",
    "stepping",
    "film_of",
    "model_name_for",
]


class LearnedForward:
    """The learned model; ``texture`` readings predicted alongside. It computes in single
    precision, as it was trained: the matcher optimises in ``dtype`` to avoid conversions."""

    dtype = torch.float32

    def __init__(self, model: ForwardModel, toners: Sequence[str] | None = None) -> None:
        # a frozen copy: the matcher differentiates with respect to the recipe only, and
        # gradients for the weights would cost most of each backward pass (and pile up)
        self.model = replace(model, network=copy.deepcopy(model.network).requires_grad_(False))
        self._forward = self.model.folded()
        self.toners = tuple(model.toners if toners is None else toners)
        # recipes over ``toners`` (a library's) as the model's inputs: a toner the model does
        # not know goes in as none (a hybrid moves it onto a proxy first), one the library
        # lacks is never used
        self._inputs = (
            None
            if self.toners == tuple(model.toners)
            else np.array([[a == b for b in model.toners] for a in self.toners], float)
        )
        self.geometries = model.geometries
        self.name = (
            f"learned ({model.instrument}, {model.info.get('name', 'model')}{_adapted(model)})"
        )
        self.model_id = model.identity  # which model exactly: an adapted one keeps its name
        self.novel: tuple[str, ...] = ()
        # the least effect-toner share of the training cases' effect paints (0: not recorded)
        self.effect_share_floor = float(model.info.get("effect_share_floor", 0.0))

    def __call__(self, fractions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
        y = self._forward(self._model_inputs(fractions).to(torch.float32)).to(fractions.dtype)
        return self._reflectance(y), y[:, self.model.spectral_outputs :]

    def _model_inputs(self, fractions):
        """Recipes ``[N, T]`` over :attr:`toners` as the model's inputs (torch or numpy)."""
        if self._inputs is None:
            return fractions
        if isinstance(fractions, torch.Tensor):
            return fractions @ torch.as_tensor(self._inputs, dtype=fractions.dtype)
        return np.asarray(fractions) @ self._inputs

    def _reflectance(self, y: torch.Tensor) -> torch.Tensor:
        """Reflectance ``[..., G, 31]`` from the model's outputs ``[..., outputs]``."""
        R = reflectance_from_log(y[..., : self.model.spectral_outputs])
        return R.reshape(*y.shape[:-1], len(self.geometries), WAVELENGTHS.size)

    @property
    def members(self) -> int:
        """Networks the learned model averages (1: no spread to report)."""
        return self.model.members

    def member_reflectance(self, x: NDArray) -> NDArray:
        """Each member's reflectance ``[K, N, G, 31]`` for recipes ``x[N, T]``."""
        return self.model.predict_members(self._model_inputs(x))

    def with_members(
        self, fractions: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor | None, torch.Tensor]:
        """Differentiable, in one pass: the prediction as :meth:`__call__` gives it, and each
        member's reflectance ``[K, N, G, 31]`` (K = 1 for a single network), what the
        matcher's model-risk term compares."""
        inputs = self._model_inputs(fractions).to(torch.float32)
        y = self.model.member_outputs(inputs).to(fractions.dtype)
        mean = y.mean(dim=0)
        return self._reflectance(mean), mean[:, self.model.spectral_outputs :], self._reflectance(y)


FINITE_DIFFERENCE_STEP = 1e-4
"""Forward-difference step in a toner's fraction for the physics model's derivatives."""


def finite_difference(
    f: Callable[[NDArray], NDArray], x: NDArray, bump: NDArray
) -> tuple[NDArray, NDArray]:
    """``f(x)`` ``[N, ...]`` and its Jacobian ``[N, ..., T]`` with respect to the entries of
    ``x[N, T]`` where ``bump[N, T]`` (zero elsewhere), by forward differences; the recipes
    and each one-entry bump go through ``f`` in one call, since the layer model costs several
    times more per recipe in small batches."""
    rows, columns = np.nonzero(bump)
    variants = x[rows]
    variants[np.arange(rows.size), columns] += FINITE_DIFFERENCE_STEP
    both = f(np.concatenate([x, variants]))
    value, bumped = both[: len(x)], both[len(x) :]
    jacobian = np.zeros((*value.shape, x.shape[1]))
    jacobian[rows, ..., columns] = (bumped - value[rows]) / FINITE_DIFFERENCE_STEP
    return value, jacobian


class _WithJacobian(torch.autograd.Function):
    """A numpy function of the recipes ``[N, T]`` whose ``jacobian(x)`` gives its value
    ``[N, ...]`` and Jacobian ``[N, ..., T]`` at once (:func:`finite_difference`)."""

    @staticmethod
    def forward(ctx, fractions, jacobian):
        value, J = jacobian(fractions.detach().numpy())
        ctx.dtype = fractions.dtype
        ctx.save_for_backward(torch.as_tensor(J))
        return torch.as_tensor(value)

    @staticmethod
    def backward(ctx, grad):
        (J,) = ctx.saved_tensors
        return torch.einsum("n...,n...t->nt", grad.to(J.dtype), J).to(ctx.dtype), None


def _differentiable(
    fractions: torch.Tensor, value, jacobian, held: HeldJacobian | None = None
) -> torch.Tensor:
    """``value(x)`` for recipes ``fractions``, through :class:`_WithJacobian` only when a
    gradient will be asked for (the Jacobian costs a physics call per toner used), or along
    the tangent that ``held`` keeps."""
    if torch.is_grad_enabled() and fractions.requires_grad:
        if held is not None:
            return held(fractions, jacobian)
        return _WithJacobian.apply(fractions, jacobian)
    return torch.as_tensor(value(fractions.detach().numpy()))


class HeldJacobian:
    """A finite-difference function of the recipes for an optimiser: its value and Jacobian
    taken afresh every ``every`` steps and followed along the tangent between,
    ``f(x₀) + J(x₀)·(x − x₀)``.

    The hybrid's physics ratio is what makes a match through new toners slow: a physics call
    on the recipes, their bases and a bumped copy per new toner at every step, over half of
    the slowest matches' time. Between retakes a step costs one product; the steps' rows and
    masks stay fixed within one run of the optimiser, so one tangent serves them all. The
    search ranks its rows by the exact value (no gradient asked: no tangent).

    Harness, 200 targets + 50 with a new toner, seed 4242, one run each beside the Jacobian
    at every step (2026-11-26, ``benchmarks/match_variants.py … "physics_every=1"``): MA-T12,
    every 4th step / every step, first shot 0.505 / 0.505, after one correction 0.835 /
    0.83, new toner 0.48 / 0.48, latency p50 1.19 / 1.26 s, p95 2.14 / 3.19 s; five-angle
    0.575 / 0.58, 0.865 / 0.865, 0.58 / 0.60, p50 0.79 / 0.83 s, p95 1.48 / 2.09 s.
    The correction's optimiser holds it too: ``correct --physics`` on the 14 failed first
    shots of 40 harness targets (seed 4343), each corrected both ways from the same spray
    and sprayed six times, passed 0.667 against 0.655 and took 0.60 s against 0.95 s, median
    (``benchmarks/correction.py --physics … "physics_every=1"``)."""

    def __init__(self, every: int) -> None:
        self.every, self.calls = every, 0
        self.start = self.value = self.slope = self.columns = None

    def __call__(self, fractions: torch.Tensor, jacobian) -> torch.Tensor:
        if self.calls % self.every == 0:
            self._retake(fractions.detach().to(torch.float64), jacobian)
        self.calls += 1
        step = fractions.to(torch.float64)[:, self.columns] - self.start
        return self.value + torch.einsum("n...t,nt->n...", self.slope, step)

    def _retake(self, x: torch.Tensor, jacobian) -> None:
        value, J = jacobian(x.numpy())
        # only the bumped toners' columns: the new toners, a handful of the library's
        self.columns = np.flatnonzero(np.any(J != 0, axis=tuple(range(J.ndim - 1))))
        self.start = x[:, self.columns]
        self.value = torch.as_tensor(value)
        self.slope = torch.as_tensor(np.ascontiguousarray(J[..., self.columns]))


def stepping(forward, every: int):
    """``forward`` as an optimiser's steps use it: where it differentiates by finite
    differences (the hybrid's physics ratio, the physics alone), a copy that holds its
    Jacobian ``every`` steps (:class:`HeldJacobian`); otherwise, or with ``every`` 1,
    ``forward`` itself. One copy per run of the optimiser: it keeps that run's tangent."""
    if every <= 1 or not hasattr(forward, "held"):
        return forward
    held = copy.copy(forward)
    held.held = HeldJacobian(every)
    return held


def film_of(forward, fractions: NDArray) -> NDArray:
    """What recipes ``fractions[N, T]`` put in the film when ``forward`` weighs for the
    shop's tins (:meth:`WithLots.film <flakelab.match.lots.WithLots.film>`, their strengths),
    the recipes themselves when it weighs for the standard tins: where the physics of
    application acts, as a shop's habits were read (:func:`~flakelab.match.lots.
    at_standard_tins`) and as its world sprays."""
    film = getattr(forward, "film", None)
    return np.asarray(fractions, float) if film is None else film(fractions)


def model_name_for(forward, toners: Iterable[str]) -> str:
    """What predicts a recipe of ``toners``: a hybrid's learned model alone where the recipe
    holds none of its new toners (its physics ratio is one there), with the physics scaling
    for those it holds; any other forward's own name."""
    name_for = getattr(forward, "name_for", None)
    return forward.name if name_for is None else name_for(toners)


def _adapted(model: ForwardModel) -> str:
    """' adapted to SHOP' for a model adapted to a shop's cases, else nothing: an adapted
    model keeps its base's name, and a forward's name says which the numbers came from."""
    shop = (model.adaptation or {}).get("shop")
    return f" adapted to {shop}" if shop else ""


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

    held: HeldJacobian | None = None  # an optimiser's tangent of the ratio (:func:`stepping`)

    def __init__(self, model: ForwardModel, library: Library, novel: Sequence[str]) -> None:
        super().__init__(model, library.names)
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
        self.learned_name = self.name
        self.name = self.name_for(self.novel)
        self.physics = PhysicsForward(library, self.geometries)

    def name_for(self, toners: Iterable[str]) -> str:
        """:func:`model_name_for`: the physics scaling named for the new toners in
        ``toners``, each with its proxy."""
        names, recipe = self.library.names, set(toners)
        held = [j for j in np.flatnonzero(self._novel_mask) if names[j] in recipe]
        if not held:
            return self.learned_name
        stand_ins = ", ".join(
            f"{names[j]} (as {names[self.proxies[j]]})" if j in self.proxies else names[j]
            for j in held
        )
        return f"hybrid: learned{_adapted(self.model)} + physics scaling for {stand_ins}"

    def base_fractions(self, x: NDArray) -> NDArray:
        """What the learned model sees: new toners moved onto their proxies, renormalised."""
        base = x @ self._substitute
        return base / np.maximum(base.sum(axis=-1, keepdims=True), 1e-12)

    def physics_ratio(self, x: NDArray) -> NDArray:
        """Ratio R_phys(x) / R_phys(x_base) ``[N, G, W]``; rows without new toners scale by
        one."""
        ratio = np.ones((x.shape[0], len(self.geometries), WAVELENGTHS.size))
        rows = self._rows_with_new_toners(x)
        if rows.size:
            ratio[rows] = self._ratio(x[rows])
        return ratio

    def physics_ratio_and_jacobian(self, x: NDArray) -> tuple[NDArray, NDArray]:
        """:meth:`physics_ratio` and its Jacobian ``[N, G, W, T]`` with respect to the new
        toners' amounts."""
        ratio = np.ones((x.shape[0], len(self.geometries), WAVELENGTHS.size))
        jacobian = np.zeros((*ratio.shape, x.shape[1]))
        rows = self._rows_with_new_toners(x)
        if rows.size:
            bump = (x[rows] > 1e-9) & self._novel_mask
            ratio[rows], jacobian[rows] = finite_difference(self._ratio, x[rows], bump)
        return ratio, jacobian

    def _rows_with_new_toners(self, x: NDArray) -> NDArray:
        return np.flatnonzero(np.any(x[:, self._novel_mask] > 1e-9, axis=1))

    def _ratio(self, x: NDArray) -> NDArray:
        has_base = (x @ self._substitute).sum(axis=1) > 1e-6
        # the learned base's share of the answer lives on its own scale, floored at LOG_FLOOR
        # as its training data were: a masstone of a strongly absorbing pigment reflects 1e-7
        # in the physics, and a trace of a new toner multiplied that (and the model's floor
        # with it) a thousandfold while the colour stayed black (4 % perylene red in
        # quinacridone violet: R = 47 at 400 nm); where the physics base takes over, so does
        # its own scale, and the floor goes
        learned = 1 - self._physics_trust(x[:, self._novel_mask].sum(axis=1))
        floor = LOG_FLOOR * np.tile(learned, 2)[:, None, None]
        physics = self.physics.reflectance(np.concatenate([x, self.base_fractions(x)]))
        both = np.maximum(physics, floor) + 1e-9
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
            physics[rows] = self.physics.reflectance(self.base_fractions(x[rows])) + 1e-9
            w = torch.as_tensor(trust[:, None, None], dtype=R.dtype)
            physics = torch.as_tensor(physics, dtype=R.dtype)
            R = torch.exp((1 - w) * torch.log(R) + w * torch.log(physics))
        ratio = _differentiable(
            fractions, self.physics_ratio, self.physics_ratio_and_jacobian, self.held
        )
        return R * ratio.to(R.dtype)

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
        members = self.model.predict_members(self._model_inputs(base))
        factor = members / self.model.predict(self._model_inputs(base))[0][None]
        with torch.no_grad():
            R, _ = self(torch.as_tensor(x, dtype=self.dtype))
        learned = 1 - self._physics_trust(x[:, self._novel_mask].sum(axis=1))
        return R.double().numpy()[None] * factor ** learned[None, :, None, None]

    @staticmethod
    def _physics_trust(share: NDArray) -> NDArray:
        """Weight of the physics base: 0 below 30 % new toners, 1 above 70 %, smooth between."""
        t = np.clip((share - 0.3) / 0.4, 0.0, 1.0)
        return t * t * (3 - 2 * t)


def stand_ins(library: Library, novel: Sequence[str]) -> dict[str, str]:
    """The known toner each of the ``novel`` toners stands in as in the hybrid's learned base
    (:class:`HybridForward`); one with no known toner of its kind has none."""
    mask = np.array([n in novel for n in library.names])
    return {library.names[j]: library.names[i] for j, i in _proxies(library, mask).items()}


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


class PhysicsForward:
    """The library's physics alone (the fast model and the texture readings of its flakes,
    DESIGN.md §3–4) at the library's nominal application: every toner known, no cases
    needed. Derivatives by forward differences on the toners each recipe uses, so a gradient
    step costs a physics call per toner used: ten to twenty times slower than the learned
    model."""

    dtype = torch.float64
    held: HeldJacobian | None = None  # an optimiser's tangent (:func:`stepping`)

    def __init__(self, library: Library, geometries: Sequence[str | Geometry]) -> None:
        self.library = library
        self.toners = library.names
        self.geometries = tuple(str(g) for g in geometries)  # names, as a learned model's
        self.name = f"physics ({library.name}, fast model)"
        self.model_id = "physics"
        self.novel: tuple[str, ...] = ()

    def reflectance(self, x: NDArray) -> NDArray:
        """Reflectance factors ``[N, G, 31]`` (π·BRDF) of recipes ``x[N, T]``."""
        return reflectance_factor(layer_from_fractions(self.library, x), self.geometries)

    def outputs(self, x: NDArray) -> NDArray:
        """Reflectance factors and texture readings of recipes ``x[N, T]`` side by side,
        ``[N, G·31 + 8]``, as a learned model's outputs (its reflectance not in logs)."""
        layer = layer_from_fractions(self.library, x)
        R = reflectance_factor(layer, self.geometries)
        texture = texture_readings(layer, self.library.flake_radii_um)
        return np.concatenate([R.reshape(len(x), -1), texture], axis=1)

    def outputs_and_jacobian(self, x: NDArray) -> tuple[NDArray, NDArray]:
        return finite_difference(self.outputs, x, x > 1e-9)

    def __call__(self, fractions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        x = fractions.to(torch.float64)
        y = _differentiable(x, self.outputs, self.outputs_and_jacobian, self.held)
        y = y.to(fractions.dtype)
        spectral = len(self.geometries) * WAVELENGTHS.size
        return y[:, :spectral].reshape(-1, len(self.geometries), WAVELENGTHS.size), y[:, spectral:]


class KubelkaMunkForward:
    """Solid colours: K = Σ cK_i, S = Σ cS_i, R∞ and Saunderson; one (diffuse) geometry."""

    dtype = torch.float64

    def __init__(
        self, names: Sequence[str], K: NDArray, S: NDArray, geometry: str = FACE_GEOMETRY
    ) -> None:
        self.toners = tuple(names)
        self.geometries = (geometry,)
        self.K = torch.as_tensor(np.asarray(K, float))
        self.S = torch.as_tensor(np.asarray(S, float))
        self.name = "Kubelka–Munk (Saunderson)"
        self.model_id = "kubelka-munk"
        self.novel: tuple[str, ...] = ()

    def __call__(self, fractions: torch.Tensor) -> tuple[torch.Tensor, None]:
        K = fractions.to(torch.float64) @ self.K
        S = torch.clamp(fractions.to(torch.float64) @ self.S, min=1e-9)
        ratio = K / S
        R_inf = 1 + ratio - torch.sqrt(ratio**2 + 2 * ratio)
        k1, k2 = SAUNDERSON_K1, SAUNDERSON_K2
        R = k1 + (1 - k1) * (1 - k2) * R_inf / (1 - k2 * R_inf)
        return R[:, None, :], None
