"""A new pigment's absorption and scattering read from calibration panels: the library's
physics inverted.

A toner the cases never saw is predicted by the physics (the hybrid path, DESIGN.md §3),
which needs its specific absorption κ(λ) and scattering σ(λ) [1/µm per unit mass fraction].
A paint maker seldom states them; a lab sprays them. The two-constant method of colorant
formulation (Allen, *Colorant formulation and shading*, 1980) reads them from a masstone and
tints in a white: a masstone at hiding tells K/S alone, and a tint in a known scatterer splits
K from S. Here the panels are any recipes of the new pigment with the library's toners (a
masstone, tints in the white, a pigment in an aluminium base), measured at every geometry.

**Start: Kubelka–Munk at 45as45**, the instrument's 45°/0°. Each panel's internal R∞, by the
inverse Saunderson correction, gives K/S, and (K_b + x·K)/(S_b + x·S) = K/S is linear in the
pigment's K and S (K_b, S_b: the panel's other toners, from the library): least squares over
the panels at each wavelength, all wavelengths at once.

**Fit: the library's own physics.** The pigment's log κ and log σ at every wavelength and
each panel's film build are fitted so that
:func:`~flakelab.physics.application.sprayed_reflectance`, with the pigment in the library,
reproduces the panels' reflectance at every geometry they were read at (scipy's bounded
trust-region least squares), each residual in units of its reading's error (relative,
:data:`PANEL_RELATIVE_SD`, and absolute, :data:`PANEL_OFFSET_SD`) and each panel's film build
and flake spread (where it holds flakes) drawn towards the nominal by
:data:`~flakelab.physics.application.FILM_BUILD_SD` and ``SPREAD_SD``. Where dropping
the scattering altogether raises χ² by no more than the wavelengths it frees (the
likelihood-ratio test, χ² scaled by its misfit), the pigment is transparent: a phthalo's
or a dye's scattering, which the panels cannot tell from none, is written as none.
The fitted constants are those with which flakelab's predictions reproduce the panels, which
is what the hybrid path needs of them; they are not a measurement of the pigment's optics
apart from the model. Their uncertainty is the fit's: the inverse of JᵀJ at the solution,
scaled by χ²/dof where that exceeds one.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E_CIE2000
from flakelab.core.geometry import Geometry
from flakelab.core.spectra import WAVELENGTHS
from flakelab.errors import FlakelabError
from flakelab.library.toners import MAX_COEFFICIENT, Library, Pigment
from flakelab.physics.application import FILM_BUILD_SD, SPREAD_SD, sprayed_reflectance
from flakelab.physics.kubelka_munk import inverse_saunderson, km_coefficients, ks_ratio
from flakelab.physics.layer import layer_from_fractions

__all__ = [
    "PANEL_RELATIVE_SD",
    "PANEL_OFFSET_SD",
    "COEFFICIENT_FLOOR",
    "Characterisation",
    "CharacterisationError",
    "check_pigment",
    "with_pigment",
    "characterise_pigment",
]

PANEL_RELATIVE_SD = 0.01
"""Relative error of a panel's reflectance that the fit weighs residuals by [-]: an
instrument's repeatability (a few tenths of a per cent) plus the physics' own misfit on a
spray-out, both about a per cent."""
PANEL_OFFSET_SD = 2e-4
"""Absolute error of a panel's reflectance factor that the fit weighs residuals by, beside
:data:`PANEL_RELATIVE_SD` [-]: an instrument's zero offset, which dominates in a dark
pigment's flop."""
COEFFICIENT_FLOOR = 1e-6
"""Least absorption or scattering the fit may give [1/µm per unit mass fraction]: a million
times below the demo's weakest scatterer. A pigment fitted at this floor at every wavelength
scatters nothing the panels can see, and is written as transparent (zero)."""
KM_GEOMETRY = "45as45"
"""Where the Kubelka–Munk start reads the panels: 45° lamp, detector along the normal."""
_APPLICATION_RANGE = (0.5, 1.5)
"""Relative film builds and flake-spread scales the fit may give a panel [-]."""


class CharacterisationError(FlakelabError):
    """Panels that cannot tell a pigment's absorption from its scattering, naming why."""


@dataclass(frozen=True)
class Characterisation:
    """A pigment's constants fitted to calibration panels.

    ``pigment`` is the fit; ``start`` the Kubelka–Munk start at 45as45. ``film[N]`` and
    ``spread[N]`` are each panel's fitted relative film build and flake-spread scale;
    ``de00[N, G]`` each panel's ΔE00 (D65/10) between its reading and the physics with the
    fitted pigment, ``start_de00`` with the start's (NaN where a panel was not read).
    ``absorption_sd[W]`` and ``scattering_sd[W]`` are the standard deviations of the natural
    logs of κ and σ (about a relative error; NaN at the floor, or where the pigment is
    transparent); ``chi2_per_dof`` the fit's misfit in units of the readings' errors."""

    pigment: Pigment
    start: Pigment
    film: NDArray[np.float64]
    spread: NDArray[np.float64]
    de00: NDArray[np.float64]
    start_de00: NDArray[np.float64]
    absorption_sd: NDArray[np.float64]
    scattering_sd: NDArray[np.float64]
    chi2_per_dof: float
    evaluations: int


def with_pigment(library: Library, pigment: Pigment) -> Library:
    """``library`` with ``pigment`` in place of its toner of that name, else added last."""
    names = library.names
    if pigment.name in names:
        k = names.index(pigment.name)
        return replace(library, toners=(*library.toners[:k], pigment, *library.toners[k + 1 :]))
    return replace(library, toners=(*library.toners, pigment))


def characterise_pigment(
    library: Library,
    name: str,
    fractions: NDArray,
    geometries: tuple[Geometry, ...],
    measured: NDArray,
    panels: Sequence[str],
) -> Characterisation:
    """Fit the absorption and scattering of ``library``'s pigment ``name`` (its constants
    there are ignored, its family, ``g`` and the rest kept) to ``panels`` (their names, for
    messages) of recipes ``fractions[N, T]`` (library order), read as ``measured[N, G, W]``
    reflectance factors at ``geometries`` (NaN where a panel was not read)."""
    k = library.names.index(name)
    x = np.asarray(fractions, dtype=float)
    measured = np.asarray(measured, dtype=float)
    _check_panels(library, k, x, panels)
    read = np.isfinite(measured)
    start = _km_start(library, k, x, geometries, measured)
    model = _PanelModel(library, k, x, geometries)
    target = measured[read]
    weight = 1 / (PANEL_RELATIVE_SD * np.abs(target) + PANEL_OFFSET_SD)
    N, W = len(x), WAVELENGTHS.size

    def residuals_of(kappa: NDArray, sigma: NDArray, film: NDArray, spread: NDArray):
        R = model.reflectance(kappa, sigma, film, spread)
        return np.concatenate([(R[read] - target) * weight, np.log(film) / FILM_BUILD_SD,
                               np.log(spread) / SPREAD_SD])  # fmt: skip

    p0 = np.concatenate([np.log(start.absorption), np.log(start.scattering), np.zeros(2 * N)])
    low = np.log([COEFFICIENT_FLOOR] * (2 * W) + [_APPLICATION_RANGE[0]] * (2 * N))
    high = np.log([MAX_COEFFICIENT] * (2 * W) + [_APPLICATION_RANGE[1]] * (2 * N))
    solution = least_squares(lambda p: residuals_of(*_unpacked(p, N)), np.clip(p0, low, high),
                             bounds=(low, high), method="trf", x_scale=1.0)  # fmt: skip
    kappa, sigma, film, spread = _unpacked(solution.x, N)
    chi2 = float(np.sum(solution.fun**2))
    dof = max(solution.fun.size - solution.x.size, 1)
    scale = max(chi2 / dof, 1.0)
    sd = _log_sd(solution.jac, scale)
    sd[solution.x <= low + 1e-6] = np.nan
    if np.sum(residuals_of(kappa, np.zeros(W), film, spread) ** 2) - chi2 <= W * scale:
        sigma = np.zeros(W)  # scattering nothing the panels can tell from none: transparent
        sd[W : 2 * W] = np.nan
    pigment = replace(library.toners[k], absorption=kappa, scattering=sigma)
    return Characterisation(
        pigment=pigment,
        start=start,
        film=film,
        spread=spread,
        de00=_panel_de00(measured, model.reflectance(kappa, sigma, film, spread)),
        start_de00=_panel_de00(
            measured, model.reflectance(start.absorption, start.scattering, *np.ones((2, N)))
        ),
        absorption_sd=sd[:W],
        scattering_sd=sd[W : 2 * W],
        chi2_per_dof=chi2 / dof,
        evaluations=int(solution.nfev),
    )


class _PanelModel:
    """The panels' reflectance ``[N, G, W]`` by the library's physics, with the pigment at
    index ``k`` given constants and each panel its film build."""

    def __init__(self, library: Library, k: int, x: NDArray, geometries) -> None:
        self.library, self.k, self.x, self.geometries = library, k, x, geometries

    def reflectance(self, kappa: NDArray, sigma: NDArray, film: NDArray, spread: NDArray):
        pigment = replace(self.library.toners[self.k], absorption=kappa, scattering=sigma)
        library = with_pigment(self.library, pigment)
        return sprayed_reflectance(library, self.x, self.geometries, film, spread)


def _unpacked(p: NDArray, panels: int) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """κ, σ, film builds and flake spreads from the fit's parameters (their logs)."""
    W = WAVELENGTHS.size
    kappa, sigma, film, spread = np.split(np.exp(p), [W, 2 * W, 2 * W + panels])
    return kappa, sigma, film, spread


def check_pigment(toner) -> None:
    """Refuse a toner that is no pigment: a flake's or a pearl's optics are not two
    coefficients."""
    if toner.kind != "pigment":
        article = "an" if toner.kind[0] in "aeiou" else "a"
        raise CharacterisationError(
            f"{toner.name!r} is {article} {toner.kind} toner: only a pigment's absorption and "
            "scattering are read from panels"
        )


def _check_panels(library: Library, k: int, x: NDArray, panels: Sequence[str]) -> None:
    """Refuse panels that cannot split the pigment's absorption from its scattering: one
    without the pigment, or masstones alone."""
    name = library.names[k]
    check_pigment(library.toners[k])
    for panel, recipe in zip(panels, x, strict=True):
        if recipe[k] <= 0:
            raise CharacterisationError(f"{panel}: its recipe holds no {name!r}")
    others = np.delete(x, k, axis=1)
    if not np.any(others > 0):
        raise CharacterisationError(
            f"the panels are masstones of {name!r} alone, which tell its K/S and not K and S "
            "apart: add a tint of it in the library's white (or in another toner of the "
            "library)"
        )


def _km_start(
    library: Library, k: int, x: NDArray, geometries: tuple[Geometry, ...], measured: NDArray
) -> Pigment:
    """The pigment by Kubelka–Munk at :data:`KM_GEOMETRY` (module notes); flat where the
    panels were not read there."""
    pigment = library.toners[k]
    names = [g.name for g in geometries]
    flat = np.ones(WAVELENGTHS.size)
    if KM_GEOMETRY not in names:
        return replace(pigment, absorption=flat, scattering=0.1 * flat)
    R = measured[:, names.index(KM_GEOMETRY)]
    use = np.isfinite(R).all(axis=1)
    q = ks_ratio(np.clip(inverse_saunderson(R[use]), 1e-4, 0.9999))  # [n, W]
    others = x[use].copy()
    others[:, k] = 0.0
    layer = layer_from_fractions(library, others)
    K_b, S_b = km_coefficients(layer.absorption, layer.scattering, layer.asymmetry[:, None])
    share = x[use, k][:, None]
    A = np.stack([np.broadcast_to(share, q.shape), -q * share], axis=-1)  # [n, W, 2]
    b = q * S_b - K_b
    normal = np.einsum("nwi,nwj->wij", A, A)
    normal += 1e-12 * np.trace(normal, axis1=1, axis2=2)[:, None, None] * np.eye(2)
    K, S = np.linalg.solve(normal, np.einsum("nwi,nw->wi", A, b)[..., None])[..., 0].T
    # K = 2κ, S = ¾σ(1 − g) (km_coefficients)
    kappa = np.clip(K / 2, COEFFICIENT_FLOOR, MAX_COEFFICIENT)
    sigma = np.clip(S / (0.75 * (1 - pigment.g)), COEFFICIENT_FLOOR, MAX_COEFFICIENT)
    return replace(pigment, absorption=kappa, scattering=sigma)


def _log_sd(jacobian: NDArray, scale: float) -> NDArray:
    """Standard deviations of the fitted parameters (logs) from the solution's Jacobian."""
    J = np.asarray(jacobian)
    covariance = np.linalg.pinv(J.T @ J) * scale
    return np.sqrt(np.clip(np.diag(covariance), 0, None))


def _panel_de00(measured: NDArray, fitted: NDArray) -> NDArray:
    """ΔE00 (D65/10) ``[N, G]`` between readings and predictions, NaN where not read."""
    read = np.isfinite(measured).all(axis=-1)
    de = np.full(read.shape, np.nan)
    de[read] = delta_E_CIE2000(reflectance_to_Lab(measured[read]), reflectance_to_Lab(fitted[read]))
    return de
