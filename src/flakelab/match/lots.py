"""The shop's toner lots in the matcher: predictions for its tins, and their strengths and
shades read from spray-outs of known recipes (:mod:`flakelab.library.lots`).

**Predicting.** A tin of strength s puts s times its toner's amount into the film
(:func:`~flakelab.physics.layer.layer_from_fractions`, as the world's batches do), so the
recipe x poured from the shop's tins looks as the standard lots' recipe x∘s/Σ(x∘s) does
(renormalised: the learned model knows recipes that sum to one; a film whose every toner is
a few per cent stronger differs mostly by what the renormalisation keeps, the ratios).
:class:`WithLots` wraps any forward model so: the search, the judge and the correction then
find the grams for the shop's tins.

**Shade.** A pigment tin whose absorption band sits δ nm off the standard's (the world's
batches drift so, :meth:`~flakelab.cases.generator.World.layer`) cannot be told to a learned
model, which knows amounts only. As the hybrid path scales the learned base by the physics for
new toners, :class:`WithLots` scales it by the physics' :func:`shade_ratio`,
R_phys(x∘s, δ) / R_phys(x∘s, 0): the library's physics knows each pigment's absorption and
moves it. The ratio is a constant to the gradient (its change with the amounts is second
order) and, in an optimiser's steps, retaken every few.

**Reading a tin.** The tinting-strength test of ISO 787-24 reduces the pigment with a
standard white and compares the panel with the standard's. Here the model's prediction is
the standard, the partner may be any toner of the library, and every toner of the panel's
recipe is read at once: a spray-out's L*a*b* offset from the prediction at every geometry is
fitted by the tins' log strengths and the pigments' shades θ, Gauss–Newton on

    ½ Σₙ rₙ(θ)ᵀ Cₙ⁻¹ rₙ(θ) + ½ (θ − θ₀)ᵀ Σ₀⁻¹ (θ − θ₀),

rₙ the predicted minus the measured L*a*b* of reading n (the mean of its panels), Cₙ = SₙSₙᵀ/k
+ (σ_p² + σ_n²/k)·I its covariance as the correction has it
(:func:`~flakelab.match.correction.split_offset`: the spray's film build and flake spread
along the physics' sensitivities Sₙ, the model's error σ_p, the reading's σ_n, k panels
averaged), θ₀ ± Σ₀ the tins' last readings or the standard ± :data:`~flakelab.library.lots.
LOT_STRENGTH_SD` (± :data:`~flakelab.library.lots.LOT_SHADE_SD_NM` in shade). Where the
panels sit further from the model than C allows (χ² above its degrees of freedom), C is
scaled up by the ratio and the fit run again, so the tins are not read more surely than the
residuals warrant. The χ² and its degrees of freedom pool the shop's earlier panels read
against the same model the same way (``TonerLots.misfit``): the model's misfit is the
shop's, not one panel's. The posterior's covariance is the inverse of the last step's normal
matrix: a tin read from a panel that hardly depends on it keeps its prior.

**One panel at a time.** A shop sprays and reads its panels one by one, and the lot file
carries what each reading left: every tin's strength and shade, and their correlations
(:class:`~flakelab.library.lots.TonerLots`). Σ₀ is that whole covariance, not each tin's own
spread: a panel of two tins reads their ratio far better than either, and the correlation
keeps it. Once a panel's own tins are read, every other tin follows them as far as Σ₀ ties it
(:func:`_conditioned`; the panel depends on its own tins alone, so this is exact for a
Gaussian), and the file's correlations are replaced by the posterior's (:func:`recorded`).
While the model is linear over the tins' spread, panels read one after another then end
where reading them at once does. Over the 35 panels of 40 harness shops
(``benchmarks/lot_calibration.py``, stop 75) the strengths read to 1.19 % RMS one at a time
and the shades to 0.748 nm, against 1.135 % and 0.757 nm at once; with each tin's own spread
alone and each panel's misfit its own (the lot file before stop 75), 1.355 % and 0.787 nm.
The pooled misfit is what brings the shade: with the correlations alone, 1.22 % and 0.80 nm.
A single panel's χ² scale, drawn towards 1 by a prior of 30 degrees of freedom instead, did
not help (0.803 nm): the model's misfit is the shop's, above 1, and one panel reads it
poorly.

**Against the standard's panel.** The model's error on a panel (σ_p) is the same whichever
tin the panel was sprayed from. Given the paint maker's reading of the same panel from its
standard tins, rₙ compares the panel's offset from that reading with the offset the model
predicts for the tins, and σ_p drops out of Cₙ, which then holds two sprays' application and
noise (the shop's and the standard's). In the harness this reads the tins' strength to
0.59 % RMS against 1.11 % from the model alone, and their shade to 0.29 nm against 0.75
(``benchmarks/toner_lots.py``, stop 74).

**Which panel.** :func:`calibration_recipes` makes each toner's panel an OEM-like paint of
two toners, a base (an effect toner, or the white) tinted with a pigment, the pair and the
share that say most about the tin: D-optimal, the largest determinant of the posterior
precision of its log strength and, a pigment's, its shade (the prior's plus the Fisher
information JᵀC⁻¹J). Chosen for the strength alone (stop 73), 12 of the 20 pigments were
tinted into Al VMP, 6 into Al coarse bright; chosen for both, 13 go into Al coarse bright,
3 into the Xirallic and one each into Al VMP and Al extra coarse (the white's two stay),
where a nanometre of shade shows more. In the harness, read against the standard's panels,
the tins' strength then reads to 0.59 % RMS against 0.81 % and their shade to 0.29 nm
against 0.32; against the model, 1.11 % and 0.75 nm against 1.05 % and 0.68
(``benchmarks/toner_lots.py``, 2026-12-01). A panel of two toners tells the ratio of their
strengths (the learned model sees proportions): where a base serves several panels, the
ratios pin it, elsewhere the priors share each ratio between its two tins. The generated
world's darker solid bases (black, oxides) were tried as bases too: the model's errors there
read black's tin 15 % off and the white's 6 % (stop 72).
"""

from __future__ import annotations

import copy
import inspect
from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np
import torch
from numpy.typing import NDArray

from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E
from flakelab.core.spectra import WAVELENGTHS
from flakelab.errors import FlakelabError
from flakelab.library.lots import (
    LOT_SHADE_SD_NM,
    LOT_STRENGTH_SD,
    READ_TOGETHER,
    TonerLot,
    TonerLots,
)
from flakelab.library.toners import Library
from flakelab.match.correction import application_sensitivities
from flakelab.match.forward import model_name_for
from flakelab.match.judging import evaluate_recipes
from flakelab.match.settings import NOISE_SD, PERSISTENT_SD
from flakelab.models.network import LOG_FLOOR
from flakelab.models.training import CaseArrays
from flakelab.physics.fast import reflectance_factor
from flakelab.physics.layer import layer_from_fractions

__all__ = [
    "TINT_SHARES",
    "LotCalibration",
    "WithLots",
    "at_standard_tins",
    "calibrate_lots",
    "calibration_recipes",
    "de00_per_nm",
    "de00_per_percent",
    "mixed_with",
    "poured_from",
    "read_together",
    "recorded",
    "shade_ratio",
    "with_lots",
]

TINT_SHARES = (0.005, 0.01, 0.02, 0.05, 0.1)
"""The tint's shares of a calibration panel tried: the generated world's OEM formulas tint
an effect base with 0.3–15 % of each pigment (:meth:`~flakelab.cases.generator.World.
formulations`), and the learned model knows no other paints."""

_STEP = 0.005
"""Finite-difference step in a tin's log strength (0.5 %): a learned model computes in single
precision, and a strength is smooth at this scale."""

_SHADE_STEP_NM = 0.1
"""Central-difference step in a tin's shade [nm]."""

_GAUSS_NEWTON_STEPS = 6


def mixed_with(strength: NDArray, fractions):
    """What recipes ``fractions[N, T]`` (numpy or torch) put in the film from tins of relative
    ``strength[T]``, in the standard lots' terms: x∘s, renormalised."""
    if isinstance(fractions, torch.Tensor):
        z = fractions * torch.as_tensor(strength, dtype=fractions.dtype)
        return z / torch.clamp(z.sum(-1, keepdim=True), min=1e-12)
    z = np.asarray(fractions, float) * strength
    return z / np.maximum(z.sum(-1, keepdims=True), 1e-12)


def shade_ratio(library: Library, geometries, film: NDArray, shade: NDArray) -> NDArray:
    """R_phys(film, shade) / R_phys(film) ``[N, G, 31]``: what tins of ``shade[N, T]`` or
    ``[T]`` [nm] change in the reflectance of films ``film[N, T]`` (library order; the tins'
    amounts), by the library's physics at its nominal application (module notes)."""
    film = np.atleast_2d(np.asarray(film, float))
    return _physics(library, geometries, film, shade) / _physics(library, geometries, film)


def _physics(library: Library, geometries, film: NDArray, shade: NDArray | None = None):
    """The library's physics of ``film[N, T]`` from tins of ``shade`` [nm], floored where the
    learned model's training data were (as the hybrid's ratio is)."""
    layer = layer_from_fractions(library, film, shade)
    return np.maximum(reflectance_factor(layer, geometries), LOG_FLOOR)


class WithLots:
    """``forward`` for recipes poured from tins of relative ``strength[T]`` (its toners'
    order) and, with the ``library``, ``shade[T]`` [nm]: every prediction is the standard
    lots' prediction of :func:`mixed_with`, times the physics' :func:`shade_ratio` for the
    tins' shades. The rest (toners, geometries, model id, …) is ``forward``'s."""

    def __init__(
        self,
        forward,
        strength: NDArray,
        shade: NDArray | None = None,
        library: Library | None = None,
    ) -> None:
        self.forward = forward
        self.strength = np.asarray(strength, float)
        self.shade = np.zeros_like(self.strength) if shade is None else np.asarray(shade, float)
        self.library = library
        self._held: _HeldRatio | None = None
        if self.shaded and (library is None or tuple(forward.toners) != library.names):
            raise ValueError("shade: the tins' shades need the library the model was made for")
        off = int(np.sum((np.abs(self.strength - 1) > 1e-12) | (self.shade != 0)))
        self._for_tins = f", for the shop's tins ({off} read off the standard)"
        self.name = forward.name + self._for_tins

    def name_for(self, toners) -> str:
        """:func:`~flakelab.match.forward.model_name_for` ``forward``'s, for the tins."""
        return model_name_for(self.forward, toners) + self._for_tins

    @property
    def shaded(self) -> bool:
        return bool(np.any(self.shade != 0))

    def __getattr__(self, name: str):
        # only what this class does not define; guarded for copy, which asks before __init__
        if name.startswith("__") or "forward" not in self.__dict__:
            raise AttributeError(name)
        found = getattr(self.forward, name)
        if inspect.ismethod(found):  # it would predict from standard tins: wrapped, or refused
            raise AttributeError(
                f"WithLots.{name}: {type(self.forward).__name__}.{name} would leave the tins out"
            )
        return found

    def __call__(self, fractions: torch.Tensor):
        R, texture = self.forward(mixed_with(self.strength, fractions))
        return self._shaded(R, fractions), texture

    def with_members(self, fractions: torch.Tensor):
        R, texture, members = self.forward.with_members(mixed_with(self.strength, fractions))
        if not self.shaded:
            return R, texture, members
        ratio = self._ratio(fractions)
        return R * ratio.to(R.dtype), texture, members * ratio.to(members.dtype)

    def member_reflectance(self, x: NDArray) -> NDArray:
        members = self.forward.member_reflectance(mixed_with(self.strength, x))
        return members * self.film_ratio(x)[None] if self.shaded else members

    def reflectance(self, x: NDArray) -> NDArray:
        """``forward``'s reflectance factors ``[N, G, 31]`` of recipes ``x[N, T]`` poured
        from these tins (the library's physics has them; the hybrid's scaling calls it): not
        passed through to ``forward``, which would leave the tins out."""
        R = self.forward.reflectance(mixed_with(self.strength, x))
        return R * self.film_ratio(x) if self.shaded else R

    def film(self, x: NDArray) -> NDArray:
        """What recipes ``x[N, T]`` poured from these tins put in the film (:func:`mixed_with`),
        in the standard tins' terms: where a shop's habits act."""
        return mixed_with(self.strength, x)

    def film_ratio(self, x: NDArray) -> NDArray:
        """:func:`shade_ratio` of recipes ``x[N, T]`` poured from these tins."""
        return shade_ratio(self.library, self.geometries, x * self.strength, self.shade)

    def _ratio(self, fractions: torch.Tensor) -> torch.Tensor:
        """:meth:`film_ratio` for torch, a constant to the gradient: a shade's per-cent
        effect on the reflectance changes with the amounts only in second order, and finite
        differences on every toner used made a match fourteen times slower (9.4 s against
        0.65 s, six harness targets). In an optimiser's steps it is retaken every few."""
        x = fractions.detach().numpy()
        if self._held is not None and fractions.requires_grad:
            return self._held(x, self.film_ratio)
        return torch.as_tensor(self.film_ratio(x))

    def _shaded(self, R: torch.Tensor, fractions: torch.Tensor) -> torch.Tensor:
        return R * self._ratio(fractions).to(R.dtype) if self.shaded else R

    # an optimiser's held Jacobian (forward.stepping): the shades' own, and the wrapped
    # model's for the model
    @property
    def held(self):
        return self._held if self.shaded else self.forward.held

    @held.setter
    def held(self, value) -> None:
        if hasattr(self.forward, "held"):
            self.forward = copy.copy(self.forward)
            self.forward.held = value
        if self.shaded:
            self._held = None if value is None else _HeldRatio(value.every)


class _HeldRatio:
    """:class:`WithLots`' shade ratio in an optimiser's steps: taken afresh every ``every``
    steps (and whenever the rows change), held between."""

    def __init__(self, every: int) -> None:
        self.every, self.calls, self.value = every, 0, None

    def __call__(self, x: NDArray, ratio) -> torch.Tensor:
        if self.calls % self.every == 0 or self.value is None or len(self.value) != len(x):
            self.value = torch.as_tensor(ratio(x))
        self.calls += 1
        return self.value


def poured_from(forward, library: Library, strength: NDArray | None, shade: NDArray | None):
    """``forward`` for recipes each poured from its own tins, ``strength[N, T]`` and
    ``shade[N, T]`` [nm] row by row (recorded cases: :class:`~flakelab.models.training.
    CaseArrays`); itself where none are given."""
    if strength is None:
        return forward
    return WithLots(forward, strength, shade, library)


def at_standard_tins(data: CaseArrays, library: Library) -> CaseArrays:
    """Recorded cases as if poured from the standard tins, what a model learns from: each
    recipe the film its tins put down (:func:`mixed_with`), each spray-out divided by the
    physics' :func:`shade_ratio` of its tins' shades; cases that record none are as they
    were. The inverse of :func:`poured_from`'s prediction: a model that learns the standard
    tins from them is asked for the shop's through :class:`WithLots`."""
    if data.strength is None:
        return data
    film = data.x * data.strength
    return replace(
        data,
        x=mixed_with(data.strength, data.x),
        R=data.R / shade_ratio(library, data.geometries, film, data.shade),
        strength=None,
        shade=None,
    )


def with_lots(forward, lots: TonerLots | None, library: Library | None = None):
    """``forward`` for the shop's ``lots`` (itself where there are none); their shades need
    the ``library``."""
    if lots is None or not lots.lots:
        return forward
    names = forward.toners
    shade = lots.shades(names) if library is not None else None
    return WithLots(forward, lots.strengths(names), shade, library)


@dataclass(frozen=True)
class LotCalibration:
    """Tins read from spray-outs: each fitted toner's strength and shade [nm] with their
    standard deviations, where they stood before, whether its shade was read (``shaded``: a
    pigment's), each reading's worst-geometry ΔE00 from the prediction before (the tins
    as they stood) and after; and every toner's (``names``, the model's order) log strength
    and shade ``theta[2T]`` with their posterior covariance ``[2T, 2T]``, which holds how the
    tins were read together (:func:`read_together`), and the toners not fitted that moved
    with them (``moved``)."""

    toners: tuple[str, ...]
    prior_strength: NDArray
    prior_sd: NDArray
    de00_before: NDArray
    de00_after: NDArray
    prior_shade: NDArray
    prior_shade_sd: NDArray
    shaded: NDArray
    names: tuple[str, ...]
    theta: NDArray
    covariance: NDArray
    moved: tuple[str, ...]
    misfit: tuple[str, str, float, int]  # (model id, read against, χ², degrees of freedom)

    @property
    def _index(self) -> NDArray:
        return np.array([self.names.index(t) for t in self.toners], int)

    @property
    def _sd(self) -> NDArray:
        return np.sqrt(np.diag(self.covariance))

    @property
    def strength(self) -> NDArray:
        """The fitted toners' tins' strengths ``[n]``."""
        return np.exp(self.theta[self._index])

    @property
    def strength_sd(self) -> NDArray:
        return self.strength * self._sd[self._index]

    @property
    def shade(self) -> NDArray:
        """The fitted toners' tins' shades ``[n]`` [nm] (a shade not read: as it stood)."""
        return self.theta[len(self.names) + self._index]

    @property
    def shade_sd(self) -> NDArray:
        return self._sd[len(self.names) + self._index]

    @property
    def log_strength_cov(self) -> NDArray:
        """The posterior covariance ``[n, n]`` of the fitted toners' log strengths."""
        return self.covariance[np.ix_(self._index, self._index)]

    def tin(self, name: str) -> tuple[float, float, float, float]:
        """Toner ``name``'s tin as read: strength ± its deviation, shade ± its deviation [nm]
        (a tin :attr:`moved` by its correlations as well as a fitted one)."""
        k, T, sd = self.names.index(name), len(self.names), self._sd
        strength = float(np.exp(self.theta[k]))
        return strength, strength * float(sd[k]), float(self.theta[T + k]), float(sd[T + k])


def read_together(found: LotCalibration, threshold: float = READ_TOGETHER) -> list[dict]:
    """The pairs of tins whose strengths ``found`` read correlated beyond ``threshold``, each
    with the correlation and the ratio of the first's strength to the second's ± its standard
    deviation: what the readings told of the pair, where each tin alone stays less sure."""
    cov = found.log_strength_cov
    sd = np.sqrt(np.diag(cov))
    pairs = []
    for i, j in zip(*np.triu_indices(len(sd), k=1), strict=True):
        r = cov[i, j] / (sd[i] * sd[j])
        if abs(r) < threshold:
            continue
        ratio = found.strength[i] / found.strength[j]
        log_sd = np.sqrt(max(cov[i, i] + cov[j, j] - 2 * cov[i, j], 0.0))
        pairs.append({
            "toners": (found.toners[i], found.toners[j]),
            "correlation": float(r),
            "ratio": float(ratio),
            "ratio_sd": float(ratio * log_sd),
        })  # fmt: skip
    return pairs


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
    shades: bool = True,
) -> LotCalibration:
    """The tins' strengths, and with ``shades`` the pigments' shades, read from spray-outs
    ``readings[N, G, 31]`` of known ``recipes[N, T]`` (library order; each reading the mean of
    ``panels[N]`` spray-outs, default one), starting from ``lots`` (default: every tin at the
    standard). The ``toners`` fitted default to every toner the recipes hold; the rest stay
    as ``lots`` has them. With ``standards``, readings ``[N, G, 31]`` of the same recipes from
    the standard's tins (the paint maker's reference panels, each one spray), each panel is
    read against its standard's, as ISO 787-24 reads a pigment against its standard's
    reduction: the model's error on the panel, which is the same for both, drops out (module
    notes)."""
    names = list(forward.toners)
    T = len(names)
    x = np.atleast_2d(np.asarray(recipes, float))
    x = x / x.sum(axis=1, keepdims=True)
    panels = np.ones(len(x)) if panels is None else np.asarray(panels, float)
    lots = lots or TonerLots()
    if toners is None:
        toner_index = np.flatnonzero(np.any(x > 0, axis=0))
    else:
        toner_index = np.array([names.index(t) for t in toners], int)
    shaded = ~library.effect[toner_index] if shades else np.zeros(len(toner_index), bool)
    fitted = np.concatenate([toner_index, T + toner_index[shaded]])
    (log_s, _), (shade, _) = lots.prior(names), lots.shade_prior(names)
    start, prior = np.concatenate([log_s, shade]), lots.covariance(names)
    sd = np.sqrt(np.diag(prior))
    theta, theta0 = start.copy(), start[fitted]
    precision0 = np.linalg.inv(prior[np.ix_(fitted, fitted)])
    tins = _Tins(forward, library, x)
    measured = reflectance_to_Lab(np.asarray(readings, float))
    if standards is None:
        L = _whitened(forward, library, x, 1 / panels)
    else:  # the panel's offset from its standard's reading, about the model's standard panel
        measured = measured - reflectance_to_Lab(np.asarray(standards, float)) + _lab(forward, x)
        L = _whitened(forward, library, x, 1 / panels + 1, persistent_sd=0.0)
    measured = measured.reshape(len(x), -1)
    before = tins.worst_de00(theta, measured)
    against = "model" if standards is None else "standard"
    pooled_chi2, pooled_dof = lots.misfit.get((forward.model_id, against), (0.0, 0))
    dof = max(measured.size - len(fitted), 1)
    scale = 1.0  # the covariance's scale, read from the residuals, the shop's earlier too
    for _ in range(2):
        theta, normal, chi2 = _gauss_newton(tins, theta, fitted, measured, L / np.sqrt(scale),
                                            theta0, precision0)  # fmt: skip
        misfit = scale * chi2  # about the covariance unscaled
        scale = max(1.0, (pooled_chi2 + misfit) / (pooled_dof + dof))
    theta, covariance = _conditioned(start, prior, fitted, theta, np.linalg.inv(normal),
                                     precision0)  # fmt: skip
    return LotCalibration(
        toners=tuple(names[i] for i in toner_index),
        prior_strength=np.exp(start[toner_index]),
        prior_sd=np.exp(start[toner_index]) * sd[toner_index],
        de00_before=before,
        de00_after=tins.worst_de00(theta, measured),
        prior_shade=shade[toner_index],
        prior_shade_sd=sd[T + toner_index],
        shaded=shaded,
        names=tuple(names),
        theta=theta,
        covariance=covariance,
        moved=_moved(names, fitted, start, prior, theta, covariance),
        misfit=(forward.model_id, against, float(misfit), int(dof)),
    )


def recorded(
    lots: TonerLots,
    found: LotCalibration,
    *,
    when: str = "",
    model_id: str = "",
    numbers: Mapping[str, str] | None = None,
    panels: Mapping[str, int] | None = None,
) -> TonerLots:
    """``lots`` once calibration ``found`` was read from them: each tin it fitted read on
    ``when`` against model ``model_id`` (from ``panels`` more panels, default one; its lot
    number from ``numbers``, or the one on file), each tin it :attr:`~LotCalibration.moved`
    at its new reading (its lot, panels and model as they were), and the correlations the
    reading left, with the readings' χ² added to the shop's misfit to the model."""
    numbers, panels = numbers or {}, panels or {}
    tins = []
    for name in found.toners:
        before = lots.lots.get(name)
        strength, strength_sd, shade, shade_sd = found.tin(name)
        tins.append(TonerLot(
            toner=name, strength=strength, strength_sd=strength_sd,
            lot=numbers.get(name, before.lot if before else ""),
            panels=(before.panels if before else 0) + panels.get(name, 1), calibrated=when,
            model_id=model_id,
            shade_nm=shade, shade_sd_nm=shade_sd,
        ))  # fmt: skip
    for name in found.moved:  # a tin moves only by the correlations on file: it is there
        strength, strength_sd, shade, shade_sd = found.tin(name)
        tins.append(replace(lots.lots[name], strength=strength, strength_sd=strength_sd,
                            shade_nm=shade, shade_sd_nm=shade_sd, calibrated=when))  # fmt: skip
    return lots.replaced(tins, found.covariance, found.names).with_misfit(*found.misfit)


def _conditioned(start, prior, fitted, theta, posterior, precision) -> tuple[NDArray, NDArray]:
    """Every tin's state ``[2T]`` and covariance ``[2T, 2T]`` once the ``fitted`` entries of
    ``start`` (prior covariance ``prior``, ``precision`` the inverse of its fitted block) were
    read at ``theta[fitted]`` ± ``posterior``. The
    panels depend on the fitted entries alone, so the rest follow them as far as the prior
    correlates them (Gaussian conditioning, as a Rauch–Tung–Striebel smoother carries a
    state's update to its neighbours): reading a tin's own panel moves the tins read together
    with it before, and reading all panels one at a time ends where reading them at once does
    while the model is linear over the tins' spread."""
    rest = np.setdiff1d(np.arange(len(start)), fitted)
    gain = prior[np.ix_(rest, fitted)] @ precision
    theta = theta.copy()
    theta[rest] = start[rest] + gain @ (theta[fitted] - start[fitted])
    covariance = prior.copy()
    covariance[np.ix_(fitted, fitted)] = posterior
    covariance[np.ix_(rest, fitted)] = gain @ posterior
    covariance[np.ix_(fitted, rest)] = (gain @ posterior).T
    shrunk = prior[np.ix_(fitted, fitted)] - posterior
    covariance[np.ix_(rest, rest)] = prior[np.ix_(rest, rest)] - gain @ shrunk @ gain.T
    return theta, covariance


def _moved(names, fitted, start, prior, theta, covariance) -> tuple[str, ...]:
    """The toners none of whose quantities were ``fitted`` whose tins a calibration moved
    (by their correlations; a tin read --no-shade whose shade moved is a fitted one)."""
    T = len(names)
    changed = (theta != start) | (np.diag(covariance) != np.diag(prior))
    moved = changed[:T] | changed[T:]
    moved[fitted % T] = False
    return tuple(names[k] for k in np.flatnonzero(moved))


class _Tins:
    """Predictions of panels ``x[N, T]`` for tins in states θ = (log strengths ``[T]``,
    shades ``[T]`` nm), many states in one batch of the model and one of the physics."""

    def __init__(self, forward, library: Library, x: NDArray) -> None:
        self.forward, self.library, self.x = forward, library, x

    def lab(self, states: NDArray) -> NDArray:
        """Predicted L*a*b* ``[B, N, 3G]`` of the panels for each of ``states[B, 2T]``. The
        learned model sees each distinct set of strengths once (a Jacobian's shade steps share
        their strengths with the point), the standard shade's physics only those that a
        shaded state holds."""
        N, T = self.x.shape
        log_strength, which = np.unique(states[:, :T], axis=0, return_inverse=True)
        which, shade = which.reshape(-1), states[:, T:]
        strength = np.exp(log_strength)
        z = mixed_with(strength[:, None, :], self.x[None]).reshape(-1, T)
        R = evaluate_recipes(self.forward, z)[0]
        R = R.reshape(len(strength), N, -1, WAVELENGTHS.size)[which]
        rows = np.flatnonzero(np.any(shade != 0, axis=1))
        if rows.size:
            needed, of_row = np.unique(which[rows], return_inverse=True)
            film = self.x[None] * strength[needed, None, :]  # [U', N, T]
            geometries = self.forward.geometries
            standard = _physics(self.library, geometries, film.reshape(-1, T))
            standard = standard.reshape(len(needed), N, *standard.shape[1:])
            shaded = _physics(self.library, geometries, film[of_row].reshape(-1, T),
                              np.repeat(shade[rows], N, axis=0))  # fmt: skip
            R[rows] *= shaded.reshape(rows.size, N, *shaded.shape[1:]) / standard[of_row]
        return reflectance_to_Lab(R).reshape(len(states), N, -1)

    def residual_and_jacobian(
        self, theta: NDArray, fitted: NDArray, measured: NDArray
    ) -> tuple[NDArray, NDArray]:
        """Predicted minus ``measured`` L*a*b* ``[N, 3G]`` at ``theta[2T]``, and its
        derivatives ``[N, 3G, P]`` with respect to the ``fitted`` entries: forward differences
        in a log strength, central ones in a shade (the shift's interpolation bends at whole
        bands, at 0 nm too)."""
        T = self.x.shape[1]
        shade = fitted >= T
        steps = np.where(shade, _SHADE_STEP_NM, _STEP)
        states = np.tile(theta, (1 + len(fitted) + int(shade.sum()), 1))
        rows = np.arange(1, len(fitted) + 1)
        states[rows, fitted] += steps
        back = len(fitted) + 1 + np.arange(int(shade.sum()))
        states[back, fitted[shade]] -= _SHADE_STEP_NM
        lab = self.lab(states)
        ahead = lab[rows] - lab[0]
        ahead[shade] = lab[rows][shade] - lab[back]
        J = ahead / np.where(shade, 2 * _SHADE_STEP_NM, _STEP)[:, None, None]
        return lab[0] - measured, np.moveaxis(J, 0, -1)

    def worst_de00(self, theta: NDArray, measured: NDArray) -> NDArray:
        N = len(self.x)
        lab = self.lab(theta[None])[0].reshape(N, -1, 3)
        return delta_E(lab, measured.reshape(N, -1, 3)).max(axis=-1)


def _gauss_newton(tins: _Tins, theta, fitted, measured, L, theta0, precision0):
    """The tins' state ``theta[2T]`` that minimises the objective of the module notes with
    whitening ``L[N, 3G, 3G]``, the last normal matrix, and the whitened residuals' χ²."""
    theta = theta.copy()
    limit = np.where(fitted >= len(theta) // 2, 2.0, 0.2)  # 20 % or 2 nm in one step at most
    for _ in range(_GAUSS_NEWTON_STEPS):
        r, J = tins.residual_and_jacobian(theta, fitted, measured)
        rw = np.einsum("nij,nj->ni", L, r).reshape(-1)
        Jw = np.einsum("nij,njp->nip", L, J).reshape(-1, len(fitted))
        normal = Jw.T @ Jw + precision0
        gradient = Jw.T @ rw + precision0 @ (theta[fitted] - theta0)
        step = np.linalg.solve(normal, -gradient)
        theta[fitted] += np.clip(step, -limit, limit)
        if np.max(np.abs(step) / limit) < 5e-5:
            break
    r, _ = tins.residual_and_jacobian(theta, fitted[:0], measured)
    chi2 = float(np.sum(np.einsum("nij,nj->ni", L, r) ** 2))
    return theta, normal, chi2


def de00_per_percent(forward, x: NDArray, k: int) -> NDArray:
    """ΔE00 per geometry ``[G]`` that a tin of toner ``k`` 1 % stronger moves panel ``x[T]``,
    as predicted: what a reading of the panel says about the tin."""
    stronger = np.ones(len(x))
    stronger[k] = 1.01
    return delta_E(_lab(forward, x[None]), _lab(forward, mixed_with(stronger, x[None])))[0]


def de00_per_nm(forward, library: Library, x: NDArray, k: int) -> NDArray:
    """ΔE00 per geometry ``[G]`` that a tin of toner ``k`` 1 nm off the standard's shade moves
    panel ``x[T]``, as predicted (zero for an effect toner, which has no shade)."""
    shade = np.zeros(len(x))
    shade[k] = 1.0
    shaded = WithLots(forward, np.ones(len(x)), shade, library)
    return delta_E(_lab(forward, x[None]), _lab(shaded, x[None]))[0]


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
    """What each panel ``x[N, T]`` tells about toner ``k``'s tin ``[N]``: the log determinant
    of the posterior precision of its log strength and, a pigment's, its shade (D-optimal:
    the prior's precision plus the Fisher information JᵀC⁻¹J, C a reading's covariance: the
    spray's application by the ``library``'s physics, the model's error, the instrument's
    noise)."""
    T = x.shape[1]
    fitted = np.array([k] if library.effect[k] else [k, T + k])
    theta = np.zeros(2 * T)
    _, J = _Tins(forward, library, x).residual_and_jacobian(theta, fitted, 0.0)
    Jw = np.einsum("nij,njp->nip", _whitened(forward, library, x, np.ones(len(x))), J)
    prior = np.diag(1 / np.array([LOT_STRENGTH_SD, LOT_SHADE_SD_NM])[: len(fitted)] ** 2)
    return np.linalg.slogdet(Jw.transpose(0, 2, 1) @ Jw + prior)[1]
