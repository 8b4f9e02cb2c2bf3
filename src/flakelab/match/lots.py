"""The shop's toner lots in the matcher: predictions for its tins, and their strengths read
from spray-outs of known recipes (:mod:`flakelab.library.lots`).

**Predicting.** A tin of strength s puts s times its toner's amount into the film
(:func:`~flakelab.physics.layer.layer_from_fractions`, as the world's batches do), so the
recipe x poured from the shop's tins looks as the standard lots' recipe x∘s/Σ(x∘s) does
(renormalised: the learned model knows recipes that sum to one; a film whose every toner is
a few per cent stronger differs mostly by what the renormalisation keeps, the ratios).
:class:`WithLots` wraps any forward model so: the search, the judge and the correction then
find the grams for the shop's tins.

**Reading a tin.** The tinting-strength test of ISO 787-24 reduces the pigment with a
standard white and compares the panel with the standard's. Here the model's prediction is
the standard, the partner may be any toner of the library, and every toner of the panel's
recipe is read at once: a spray-out's L*a*b* offset from the prediction at every geometry is
fitted by the tins' log strengths θ, Gauss–Newton on

    ½ Σₙ rₙ(θ)ᵀ Cₙ⁻¹ rₙ(θ) + ½ (θ − θ₀)ᵀ Σ₀⁻¹ (θ − θ₀),

rₙ the predicted minus the measured L*a*b* of reading n (the mean of its panels), Cₙ = SₙSₙᵀ/k
+ (σ_p² + σ_n²/k)·I its covariance as the correction has it
(:func:`~flakelab.match.correction.split_offset`: the spray's film build and flake spread
along the physics' sensitivities Sₙ, the model's error σ_p, the reading's σ_n, k panels
averaged), θ₀ ± Σ₀ the tins' last readings or the standard ± :data:`~flakelab.library.lots.
LOT_STRENGTH_SD`. Where the panels sit further from the model than C allows (χ² above its
degrees of freedom), C is scaled up by the ratio and the fit run again, so the tins are not
read more surely than the residuals warrant. The posterior's covariance is the inverse of
the last step's normal matrix: a tin read from a panel that hardly depends on it keeps its
prior.

**Against the standard's panel.** The model's error on a panel (σ_p) is the same whichever
tin the panel was sprayed from. Given the paint maker's reading of the same panel from its
standard tins, rₙ compares the panel's offset from that reading with the offset the model
predicts for the tins, and σ_p drops out of Cₙ, which then holds two sprays' application and
noise (the shop's and the standard's). In the harness this reads the tins to 1.29 % RMS
against 1.41 % from the model alone (``benchmarks/toner_lots.py``).

**Which panel.** :func:`calibration_recipes` makes each toner's panel an OEM-like paint of
two toners, a base (an effect toner, or the white) tinted with a pigment, the pair and the
share that say most about the tin: the largest Fisher information JᵀC⁻¹J for its θ. The
generated world's darker solid bases (black, oxides) were tried as bases too: the model's
errors there read black's tin 15 % off and the white's 6 % (stop 72).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
import torch
from numpy.typing import NDArray

from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E
from flakelab.errors import FlakelabError
from flakelab.library.lots import TonerLots
from flakelab.library.toners import Library
from flakelab.match.correction import NOISE_SD, PERSISTENT_SD, application_sensitivities
from flakelab.match.judging import evaluate_recipes

__all__ = [
    "TINT_SHARES",
    "LotCalibration",
    "WithLots",
    "calibrate_lots",
    "calibration_recipes",
    "de00_per_percent",
    "mixed_with",
    "with_lots",
]

TINT_SHARES = (0.005, 0.01, 0.02, 0.05, 0.1)
"""The tint's shares of a calibration panel tried: the generated world's OEM formulas tint
an effect base with 0.3–15 % of each pigment (:meth:`~flakelab.cases.generator.World.
formulations`), and the learned model knows no other paints."""

_STEP = 0.005
"""Finite-difference step in a tin's log strength (0.5 %): a learned model computes in single
precision, and a strength is smooth at this scale."""

_GAUSS_NEWTON_STEPS = 6


def mixed_with(strength: NDArray, fractions):
    """What recipes ``fractions[N, T]`` (numpy or torch) put in the film from tins of relative
    ``strength[T]``, in the standard lots' terms: x∘s, renormalised."""
    if isinstance(fractions, torch.Tensor):
        z = fractions * torch.as_tensor(strength, dtype=fractions.dtype)
        return z / torch.clamp(z.sum(-1, keepdim=True), min=1e-12)
    z = np.asarray(fractions, float) * strength
    return z / np.maximum(z.sum(-1, keepdims=True), 1e-12)


class WithLots:
    """``forward`` for recipes poured from tins of relative ``strength[T]`` (its toners'
    order): every prediction is the standard lots' prediction of :func:`mixed_with`. The
    rest (toners, geometries, model id, …) is ``forward``'s."""

    def __init__(self, forward, strength: NDArray) -> None:
        self.forward = forward
        self.strength = np.asarray(strength, float)
        off = int(np.sum(np.abs(self.strength - 1) > 1e-12))
        self.name = f"{forward.name}, for the shop's tins ({off} read off the standard)"

    def __getattr__(self, name: str):
        # only what this class does not define; guarded for copy, which asks before __init__
        if name.startswith("__") or "forward" not in self.__dict__:
            raise AttributeError(name)
        return getattr(self.forward, name)

    def __call__(self, fractions: torch.Tensor):
        return self.forward(mixed_with(self.strength, fractions))

    def with_members(self, fractions: torch.Tensor):
        return self.forward.with_members(mixed_with(self.strength, fractions))

    def member_reflectance(self, x: NDArray) -> NDArray:
        return self.forward.member_reflectance(mixed_with(self.strength, x))

    # an optimiser's held Jacobian (forward.stepping) belongs to the model it wraps
    @property
    def held(self):
        return self.forward.held

    @held.setter
    def held(self, value) -> None:
        self.forward = copy.copy(self.forward)
        self.forward.held = value


def with_lots(forward, lots: TonerLots | None):
    """``forward`` for the shop's ``lots`` (itself where there are none)."""
    if lots is None or not lots.lots:
        return forward
    return WithLots(forward, lots.strengths(forward.toners))


@dataclass(frozen=True)
class LotCalibration:
    """Tins read from spray-outs: each fitted toner's strength and its standard deviation,
    where it stood before, and each reading's worst-geometry ΔE00 from the prediction
    before (the tins as they stood) and after."""

    toners: tuple[str, ...]
    strength: NDArray
    strength_sd: NDArray
    prior_strength: NDArray
    prior_sd: NDArray
    de00_before: NDArray
    de00_after: NDArray


def _lab(forward, x: NDArray) -> NDArray:
    """CIELAB ``[N, G, 3]`` of recipes ``x[N, T]``."""
    return reflectance_to_Lab(evaluate_recipes(forward, x)[0])


def _whitened(
    forward, library: Library, x: NDArray, sprays: NDArray, persistent_sd: float = PERSISTENT_SD
) -> NDArray:
    """The Cholesky factors' inverses ``[N, 3G, 3G]`` of each reading's covariance Cₙ: its
    ``sprays[N]`` (Σ 1/k over the readings it is made of) each with its own application and
    instrument noise, and the model's error ``persistent_sd``."""
    S = application_sensitivities(library, x, forward.geometries)  # [N, 2, G, 3]
    S = S.reshape(len(x), 2, -1).transpose(0, 2, 1)  # [N, 3G, 2]
    v = np.asarray(sprays, float)[:, None, None]
    eye = np.eye(S.shape[1])
    C = v * (S @ S.transpose(0, 2, 1)) + (persistent_sd**2 + v * NOISE_SD**2) * eye
    return np.linalg.inv(np.linalg.cholesky(C))


def calibrate_lots(
    forward,
    library: Library,
    recipes: NDArray,
    readings: NDArray,
    lots: TonerLots | None = None,
    panels: NDArray | None = None,
    toners: tuple[str, ...] | None = None,
    standards: NDArray | None = None,
) -> LotCalibration:
    """The tins' strengths read from spray-outs ``readings[N, G, 31]`` of known ``recipes[N,
    T]`` (library order; each reading the mean of ``panels[N]`` spray-outs, default one),
    starting from ``lots`` (default: every tin at the standard). The ``toners`` fitted default
    to every toner the recipes hold; the rest stay as ``lots`` has them. With ``standards``,
    readings ``[N, G, 31]`` of the same recipes from the standard's tins (the paint maker's
    reference panels, each one spray), each panel is read against its standard's, as ISO
    787-24 reads a pigment against its standard's reduction: the model's error on the panel,
    which is the same for both, drops out (module notes)."""
    names = list(forward.toners)
    x = np.atleast_2d(np.asarray(recipes, float))
    x = x / x.sum(axis=1, keepdims=True)
    panels = np.ones(len(x)) if panels is None else np.asarray(panels, float)
    lots = lots or TonerLots()
    if toners is None:
        fitted = np.flatnonzero(np.any(x > 0, axis=0))
    else:
        fitted = np.array([names.index(t) for t in toners], int)
    theta, sd = lots.prior(names)
    theta0, precision0 = theta[fitted].copy(), np.diag(1 / sd[fitted] ** 2)
    measured = reflectance_to_Lab(np.asarray(readings, float))
    if standards is None:
        L = _whitened(forward, library, x, 1 / panels)
    else:  # the panel's offset from its standard's reading, about the model's standard panel
        measured = measured - reflectance_to_Lab(np.asarray(standards, float)) + _lab(forward, x)
        L = _whitened(forward, library, x, 1 / panels + 1, persistent_sd=0.0)
    before = _worst_de00(forward, theta, x, measured)
    scale = 1.0  # the covariance's scale, read from the residuals (module notes)
    for _ in range(2):
        theta, normal, chi2 = _gauss_newton(forward, theta, fitted, x, measured, L / np.sqrt(scale),
                                            theta0, precision0)  # fmt: skip
        scale = max(1.0, scale * chi2 / max(measured.size - len(fitted), 1))
    posterior_sd = np.sqrt(np.diag(np.linalg.inv(normal)))
    strength = np.exp(theta[fitted])
    return LotCalibration(
        toners=tuple(names[i] for i in fitted),
        strength=strength,
        strength_sd=strength * posterior_sd,
        prior_strength=np.exp(theta0),
        prior_sd=np.exp(theta0) / np.sqrt(np.diag(precision0)),
        de00_before=before,
        de00_after=_worst_de00(forward, theta, x, measured),
    )


def _gauss_newton(forward, theta, fitted, x, measured, L, theta0, precision0):
    """The log strengths ``theta[T]`` that minimise the objective of the module notes with
    whitening ``L[N, 3G, 3G]``, the last normal matrix, and the whitened residuals' χ²."""
    theta = theta.copy()
    for _ in range(_GAUSS_NEWTON_STEPS):
        r, J = _residual_and_jacobian(forward, theta, fitted, x, measured)
        rw = np.einsum("nij,nj->ni", L, r).reshape(-1)
        Jw = np.einsum("nij,njp->nip", L, J).reshape(-1, len(fitted))
        normal = Jw.T @ Jw + precision0
        gradient = Jw.T @ rw + precision0 @ (theta[fitted] - theta0)
        step = np.linalg.solve(normal, -gradient)
        theta[fitted] += np.clip(step, -0.2, 0.2)  # a tin 20 % off in one step at most
        if np.max(np.abs(step)) < 1e-5:
            break
    r, _ = _residual_and_jacobian(forward, theta, fitted[:0], x, measured)
    chi2 = float(np.sum(np.einsum("nij,nj->ni", L, r) ** 2))
    return theta, normal, chi2


def _residual_and_jacobian(forward, theta, fitted, x, measured) -> tuple[NDArray, NDArray]:
    """Predicted minus measured L*a*b* ``[N, 3G]`` at log strengths ``theta[T]``, and its
    derivatives ``[N, 3G, P]`` with respect to the ``fitted`` ones (forward differences, all
    in one batch of the model)."""
    N, P = len(x), len(fitted)
    thetas = np.tile(theta, (P + 1, 1))
    thetas[np.arange(1, P + 1), fitted] += _STEP
    z = mixed_with(np.exp(thetas)[:, None, :], x[None]).reshape(-1, x.shape[1])
    lab = _lab(forward, z).reshape(P + 1, N, -1)
    residual = lab[0] - measured.reshape(N, -1)
    return residual, np.moveaxis((lab[1:] - lab[0]) / _STEP, 0, -1)


def de00_per_percent(forward, x: NDArray, k: int) -> NDArray:
    """ΔE00 per geometry ``[G]`` that a tin of toner ``k`` 1 % stronger moves panel ``x[T]``,
    as predicted: what a reading of the panel says about the tin."""
    stronger = np.ones(len(x))
    stronger[k] = 1.01
    return delta_E(_lab(forward, x[None]), _lab(forward, mixed_with(stronger, x[None])))[0]


def _worst_de00(forward, theta: NDArray, x: NDArray, measured: NDArray) -> NDArray:
    lab = _lab(forward, mixed_with(np.exp(theta), x))
    return delta_E(lab, measured).max(axis=-1)


def calibration_recipes(
    forward, library: Library, toners: tuple[str, ...] | None = None
) -> NDArray:
    """Each toner's calibration panel ``[len(toners), T]``, an OEM-like two-toner paint: a base
    (an effect toner, or the library's white, as ISO 787-24 reduces with it) tinted with a
    pigment at one of :data:`TINT_SHARES`, the toner either of the two, whichever tells most
    about its tin (module notes). ``toners`` default to every one of ``forward``'s."""
    names = list(forward.toners)
    toners = tuple(names) if toners is None else toners
    white = library.solid_bases()[0]
    bases = [*np.flatnonzero(library.effect), *([] if white is None else [white])]
    tints = np.flatnonzero(~library.effect).tolist()
    chosen = []
    for toner in toners:
        k = names.index(toner)
        pairs = [(k, p) for p in tints if p != k] if k in bases else []
        pairs += [(b, k) for b in bases if b != k] if k in tints else []
        if not pairs:
            raise FlakelabError(f"{toner}: no base or tint in the library to make its panel with")
        x = np.zeros((len(pairs), len(TINT_SHARES), len(names)))
        for row, (base, tint) in enumerate(pairs):
            x[row, :, base] = 1 - np.asarray(TINT_SHARES)
            x[row, :, tint] = TINT_SHARES
        x = x.reshape(-1, len(names))
        chosen.append(x[int(np.argmax(_information(forward, library, x, k)))])
    return np.array(chosen)


def _information(forward, library: Library, x: NDArray, k: int) -> NDArray:
    """Fisher information ``[N]`` of each panel ``x[N, T]`` about toner ``k``'s log strength,
    JᵀC⁻¹J with C a reading's covariance (the spray's application by the ``library``'s
    physics, the model's error, the instrument's noise)."""
    theta = np.zeros(x.shape[1])
    _, J = _residual_and_jacobian(forward, theta, np.array([k]), x, np.zeros((len(x), 1)))
    Jw = np.einsum("nij,nj->ni", _whitened(forward, library, x, np.ones(len(x))), J[..., 0])
    return np.sum(Jw**2, axis=1)
