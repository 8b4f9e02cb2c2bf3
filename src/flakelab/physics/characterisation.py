"""A new toner's optics read from calibration panels: the library's physics inverted.

A toner the cases never saw is predicted by the physics (the hybrid path, DESIGN.md §3),
which needs its optics: a pigment's specific absorption κ(λ) and scattering σ(λ) [1/µm per
unit mass fraction], an aluminium flake's orientation spread, surface quality and volume
fraction. A paint maker seldom states them; a lab sprays them.

**A pigment.** The two-constant method of colorant formulation (Allen, *Colorant formulation
and shading*, 1980) reads κ and σ from a masstone and tints in a white: a masstone at hiding
tells K/S alone, and a tint in a known scatterer splits K from S. Here the panels are any
recipes of the new pigment with the library's toners (a masstone, tints in the white, the
pigment in an aluminium base), measured at every geometry. The fit starts from
Kubelka–Munk at 45as45, the instrument's 45°/0°: each panel's internal R∞, by the inverse
Saunderson correction, gives K/S, and (K_b + x·K)/(S_b + x·S) = K/S is linear in the
pigment's K and S (K_b, S_b: the panel's other toners, from the library), least squares over
the panels at each wavelength, all wavelengths at once. Where dropping the scattering
altogether raises χ² by no more than the wavelengths it frees (the likelihood-ratio test, χ²
scaled by its misfit), the pigment is transparent: a phthalo's or a dye's scattering, which
the panels cannot tell from none, is written as none.

**An aluminium flake** (:data:`FLAKE_FITTED`): its normals' spread sets the flop, its surface
quality the near-specular sparkle of light, its volume fraction how bright and how hiding
the film is, all seen in a masstone and its tints at every geometry; the fit starts from the
flake's values in the library (a similar paste's, for a new one). Its radius shows in the
texture alone and its thickness only with the volume fraction (the flakes' number), so both
are the supplier's (D50/2 and the stated thickness).

**A pearl** (:data:`PEARL_FITTED`): its TiO2 coating's thickness sets its interference colour
(the hue at the specular and how it turns away from it), its normals' spread the flop, its
volume fraction how strong it is. Interference colours repeat with the coating's thickness,
order after order, so a fit from a silver-white's coating finds the nearest order's
minimum, not the pearl's: the coating is first placed on a grid (:data:`COATING_GRID_NM`)
that spans the orders a pearl is made in, the panels' misfit at each, and fitted from the
best. Its substrate (mica, alumina …) and the substrate's thickness, whose fine fringes
the platelets' spread of thicknesses washes out, are the supplier's; its radius, as an
aluminium's, shows in the texture alone.

**The fit: the library's own physics.** The toner's parameters (logs) and each panel's film
build and flake spread are fitted so that
:func:`~flakelab.physics.application.sprayed_reflectance`, with the toner in the library,
reproduces the panels' reflectance at every geometry they were read at (scipy's bounded
trust-region least squares), each residual in units of its reading's error (relative,
:data:`PANEL_RELATIVE_SD`, and absolute, :data:`PANEL_OFFSET_SD`), each panel's film build
and flake spread drawn towards the nominal by
:data:`~flakelab.physics.application.FILM_BUILD_SD` and ``SPREAD_SD``. The fitted optics
are those with which flakelab's predictions reproduce the panels, which is what the hybrid
path needs of them; they are not a measurement of the toner apart from the model. Their
uncertainty is the fit's: the inverse of JᵀJ at the solution, scaled by χ²/dof where that
exceeds one."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E_CIE2000
from flakelab.core.geometry import FACE_GEOMETRY, Geometry
from flakelab.core.measurement import TEXTURE_FAMILIES, TEXTURE_READINGS
from flakelab.core.spectra import WAVELENGTHS
from flakelab.core.wording import with_article
from flakelab.errors import FlakelabError
from flakelab.library.toners import (
    FLAKE_RADIUS_MIN_UM,
    MAX_COEFFICIENT,
    ORIENTATION_SD_MIN_DEG,
    AluminiumFlake,
    Library,
    Pearl,
    Pigment,
    Toner,
)
from flakelab.physics.application import FILM_BUILD_SD, SPREAD_SD, sprayed_layer
from flakelab.physics.hiding import reflectance_over
from flakelab.physics.kubelka_munk import inverse_saunderson, km_coefficients, ks_ratio
from flakelab.physics.layer import layer_from_fractions
from flakelab.texture.readings import GLINT_SHARE, texture_readings

__all__ = [
    "PANEL_RELATIVE_SD",
    "PANEL_OFFSET_SD",
    "TEXTURE_RELATIVE_SD",
    "TEXTURE_OFFSET_SD",
    "COEFFICIENT_FLOOR",
    "Characterisation",
    "CharacterisationError",
    "CHARACTERISED",
    "FLAKE_FITTED",
    "FIT_ITERATIONS",
    "PEARL_FITTED",
    "EFFECT_FITTED",
    "FLAKE_START",
    "FLAKE_START_RADIUS_UM",
    "PEARL_START",
    "COATING_GRID_NM",
    "similar_flake",
    "similar_pearl",
    "check_kind",
    "with_toner",
    "characterise_pigment",
    "characterise_flake",
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
times below the demo's weakest scatterer."""
TEXTURE_RELATIVE_SD = 0.1
"""Relative error of a texture reading that the fit weighs its misfit by [-]: a camera's
count of glints from one spot to the next, and the texture model's own misfit (the generated
world reads Sa, Si and G to a few per cent from spot to spot; a real instrument's formulas
are its maker's)."""
TEXTURE_OFFSET_SD = 0.05
"""Absolute error of a texture reading beside :data:`TEXTURE_RELATIVE_SD`: a reading near
zero (a dark paint's sparkle) is still one of a few glints."""
FEW_GLINTS = 10
"""Glints under one light below which a panel's sparkle intensity Si is not fitted: the mean
brightness of fewer is a sample too small (one glint's spread is ``GLINT_SD``, 57 %), and
with none the instrument reads 0, which no flake population predicts."""
RADIUS_GRID_TOP_UM = 60.0
"""Largest flake radius the texture's first look tries [µm]: beyond the coarsest effect
pastes (D50 about 100 µm)."""
_NOT_SG = np.array([k != "SG" for k in TEXTURE_READINGS])
"""The texture readings fitted: the sparkle grade follows from Sa and Si."""
FIT_ITERATIONS = 100
"""Iterations a panel fit may take (each run): a fit converges in 10 to 60; one that creeps
along directions the panels hardly tell on is stopped there. Isoindoline yellow with its
masstone over a chart's black crept for 7,000 (5.5 minutes) and predicted held-out paints
no better than after 100 (5.5 s): within 0.01 ΔE00."""
_APPLICATION_RANGE = (0.5, 1.5)
"""Relative film builds and flake-spread scales the fit may give a panel [-]."""


class CharacterisationError(FlakelabError):
    """A toner not of the kind asked for, or panels that cannot read it (masstones alone of
    a pigment, a panel without it), naming why."""


@dataclass(frozen=True)
class Characterisation:
    """A toner's optics fitted to calibration panels.

    ``toner`` is the fit; ``start`` where it began (a pigment's Kubelka–Munk start at
    45as45; a flake's values before). ``film[N]`` and ``spread[N]`` are each panel's fitted
    relative film build and flake-spread scale; ``fitted[N, G, W]`` each panel's reflectance
    by the physics with the fitted toner and ``fitted_texture[N, 8]`` its texture readings;
    ``de00[N, G]`` its ΔE00 (D65/10) from the reading, ``start_de00`` the start's (NaN where
    a panel was not read). ``uncertainty`` holds each
    fitted quantity's relative standard deviation (that of its log): a pigment's
    ``absorption`` and ``scattering`` ``[W]`` (NaN at the floor, or where the pigment is
    transparent), an aluminium's or a pearl's :data:`EFFECT_FITTED` and, where read from the
    texture, ``radius_um`` (NaN at a bound).
    ``chi2_per_dof`` is the first fit's misfit in units of the readings' errors (above 1,
    the errors were scaled by it and the fit run again); ``converged`` is False where the fit
    was stopped at :data:`FIT_ITERATIONS`."""

    toner: Toner
    start: Toner
    film: NDArray[np.float64]
    spread: NDArray[np.float64]
    fitted: NDArray[np.float64]
    fitted_texture: NDArray[np.float64]
    de00: NDArray[np.float64]
    start_de00: NDArray[np.float64]
    uncertainty: dict[str, Any]
    chi2_per_dof: float
    evaluations: int
    converged: bool


FLAKE_FITTED = ("orientation_sd_deg", "surface_quality", "volume_fraction")
"""What an aluminium flake's panels read: how its normals spread, how mirror-like it is and how
much of the film it fills. Its radius (texture alone) and thickness (the panels see the
volume fraction over the thickness, the flakes' number) are the supplier's: D50/2 and the
stated thickness."""
PEARL_FITTED = ("coating_nm", "orientation_sd_deg", "volume_fraction")
"""What a pearl's panels read: its coating (its interference colour), how its normals spread
and how much of the film it fills. Its substrate and the substrate's thickness, and its radius
where the panels carry no texture, are the supplier's."""
EFFECT_FITTED = {"aluminium": FLAKE_FITTED, "pearl": PEARL_FITTED}
"""What panels read of each kind of effect flake."""
FLAKE_START = {"orientation_sd_deg": 10.0, "surface_quality": 0.9, "volume_fraction": 0.13}
"""Where a new flake's fit starts in a library of no aluminium to start from: a middling
paste's spread, surface and volume fraction."""
FLAKE_START_RADIUS_UM = 10.0
"""A middling paste's radius [µm]: where a new flake's radius, to be read from its panels'
texture, starts in a library of no flake of its kind."""
PEARL_START = {"coating_nm": 100.0, "substrate_nm": 400.0, "orientation_sd_deg": 10.0,
               "volume_fraction": 0.10}  # fmt: skip
"""Where a new pearl starts in a library of no pearl to start from: a mica pearl's platelet
(400 nm), a middling spread and volume fraction (its coating is then placed on
:data:`COATING_GRID_NM`)."""
COATING_GRID_NM = np.arange(20.0, 405.0, 5.0)
"""The TiO2 coatings [nm] a pearl's fit first looks at: from a thin silver-white's through
the first three orders of interference colours (silver, gold, red, violet, blue, green at
about 40–140 nm, then again, paler), at 5 nm, about an eighth of a hue's span."""
_EFFECT_RANGE = {
    "orientation_sd_deg": (ORIENTATION_SD_MIN_DEG, 45.0),
    "surface_quality": (0.05, 1.0),
    "volume_fraction": (0.005, 0.6),
    "radius_um": (FLAKE_RADIUS_MIN_UM, 100.0),
    "coating_nm": (10.0, 1000.0),
}
"""The values a flake's or a pearl's fit may give: a library's own limits, a surface no
rougher than a twentieth of a mirror's, a volume fraction from half a per cent."""


def with_toner(library: Library, toner: Toner) -> Library:
    """``library`` with ``toner`` in place of its toner of that name, else added last."""
    names = library.names
    if toner.name in names:
        k = names.index(toner.name)
        return replace(library, toners=(*library.toners[:k], toner, *library.toners[k + 1 :]))
    return replace(library, toners=(*library.toners, toner))


def characterise_pigment(
    library: Library,
    name: str,
    fractions: NDArray,
    geometries: tuple[Geometry, ...],
    measured: NDArray,
    panels: Sequence[str],
    grounds: Sequence[str] | None = None,
) -> Characterisation:
    """Fit the absorption and scattering of ``library``'s pigment ``name`` (its constants
    there are ignored, its family, ``g`` and the rest kept) to ``panels`` (their names, for
    messages) of recipes ``fractions[N, T]`` (library order), read as ``measured[N, G, W]``
    reflectance factors at ``geometries`` (NaN where a panel was not read), each sprayed
    over its one of ``grounds`` (:data:`~flakelab.physics.hiding.GROUNDS`; default: the
    library's primer)."""
    k = library.names.index(name)
    check_kind(library.toners[k], ("pigment",))
    fit = _PanelFit(library, k, fractions, geometries, measured, panels, grounds=grounds)
    _check_tinted(library, k, fit.x)
    start = _km_start(library, k, fit.x, geometries, fit.measured)
    W = WAVELENGTHS.size

    def pigment_of(p: NDArray) -> Pigment:
        return replace(start, absorption=np.exp(p[:W]), scattering=np.exp(p[W:]))

    p0 = np.log(np.concatenate([start.absorption, start.scattering]))
    bounds = np.log([[COEFFICIENT_FLOOR] * 2 * W, [MAX_COEFFICIENT] * 2 * W])
    found = fit.run(pigment_of, p0, bounds, start)
    sd = found.sd
    transparent = replace(found.toner, scattering=np.zeros(W))
    if fit.chi2(transparent, found.film, found.spread) - found.chi2 <= W * found.scale:
        found = replace(found, toner=transparent)  # scatters nothing told from none
        sd[W:] = np.nan
    return found.characterisation({"absorption": sd[:W], "scattering": sd[W:]})


def characterise_flake(
    library: Library,
    name: str,
    fractions: NDArray,
    geometries: tuple[Geometry, ...],
    measured: NDArray,
    panels: Sequence[str],
    texture: NDArray | None = None,
    grounds: Sequence[str] | None = None,
) -> Characterisation:
    """Fit :data:`EFFECT_FITTED` of ``library``'s aluminium flake or pearl ``name``, from its
    values there (an aluminium's thickness, a pearl's substrate kept; a pearl's coating from
    the best of :data:`COATING_GRID_NM`), to ``panels``, as :func:`characterise_pigment`; its
    radius too where the panels' ``texture[N, 8]`` readings are given (NaN where not read;
    in :data:`~flakelab.core.measurement.TEXTURE_READINGS` order), else kept; ``grounds`` as
    there."""
    k = library.names.index(name)
    flake = library.toners[k]
    check_kind(flake, tuple(EFFECT_FITTED))
    fit = _PanelFit(library, k, fractions, geometries, measured, panels, grounds=grounds)
    fitted = EFFECT_FITTED[flake.kind]
    near = _coating_from_grid(fit, flake) if flake.kind == "pearl" else flake
    found = _flake_fit(fit, near, fitted, flake)
    if texture is not None and np.isfinite(np.asarray(texture, float)).any():
        # the radius from the texture, from the reflectance's fit and the radius of those
        # on a grid that fits the texture best: jointly from a start far off, the fit can
        # run to a bound (a VMP's count of glints rises steeply as its spread narrows)
        fit = _PanelFit(library, k, fractions, geometries, measured, panels, texture, grounds)
        grid = np.geomspace(_EFFECT_RANGE["radius_um"][0], RADIUS_GRID_TOP_UM, 24)
        chi2 = [fit.chi2(replace(found.toner, radius_um=r), found.film, found.spread)
                for r in grid]  # fmt: skip
        near = replace(found.toner, radius_um=float(grid[int(np.argmin(chi2))]))
        fitted = (*fitted, "radius_um")
        found = _flake_fit(fit, near, fitted, flake)
    return found.characterisation(dict(zip(fitted, found.sd.tolist(), strict=True)))


def _coating_from_grid(fit: _PanelFit, pearl: Pearl) -> Pearl:
    """``pearl`` with the coating of :data:`COATING_GRID_NM` (or its own) that fits the
    panels best at the nominal application, its spread and volume fraction fitted at each
    (module notes: the orders of interference; a silver's coating looks higher orders' pale
    where the spread is not its own)."""
    nominal = np.ones(len(fit.x))
    profiled = ("orientation_sd_deg", "volume_fraction")  # in at()'s order
    bounds = np.log([[_EFFECT_RANGE[f][i] for f in profiled] for i in (0, 1)])

    def at(coating: float, p: NDArray) -> Pearl:
        spread, share = np.exp(p)
        return replace(pearl, coating_nm=coating, orientation_sd_deg=spread, volume_fraction=share)

    def best_at(coating: float) -> tuple[float, Pearl]:
        p0 = np.log([getattr(pearl, f) for f in profiled])
        found = least_squares(lambda p: fit.residuals(at(coating, p), nominal, nominal), p0,
                              bounds=bounds, method="trf", xtol=1e-3, max_nfev=20)  # fmt: skip
        return float(np.sum(found.fun**2)), at(coating, found.x)

    tried = [best_at(float(c)) for c in np.append(COATING_GRID_NM, pearl.coating_nm)]
    return min(tried, key=lambda t: t[0])[1]


def _flake_fit(fit: _PanelFit, flake: Toner, fitted: tuple[str, ...], start: Toner) -> _Found:
    """``fitted`` of ``flake`` (an aluminium or a pearl) fitted to the panels, from its values
    (``start``: the toner reported as where the fit began)."""

    def flake_of(p: NDArray) -> Toner:
        return replace(flake, **dict(zip(fitted, np.exp(p).tolist(), strict=True)))

    p0 = np.log([getattr(flake, f) for f in fitted])
    bounds = np.log([[_EFFECT_RANGE[f][i] for f in fitted] for i in (0, 1)])
    return fit.run(flake_of, p0, bounds, start)


CHARACTERISED = ("pigment", "aluminium", "pearl")
"""The kinds of toner read from panels (:func:`characterise_pigment`,
:func:`characterise_flake`)."""


def similar_flake(library: Library, name: str, radius_um: float, thickness_um: float):
    """A new flake ``name`` of the datasheet's radius and thickness, its spread, surface and
    volume fraction those of the library's flake nearest in radius (:data:`FLAKE_START` where
    it has none): where its fit starts."""
    flakes = library.of_kind("aluminium")
    if not flakes:
        return AluminiumFlake(name, radius_um, thickness_um, **FLAKE_START)
    nearest = min(flakes, key=lambda f: abs(np.log(f.radius_um / radius_um)))
    return replace(nearest, name=name, radius_um=radius_um, thickness_um=thickness_um,
                   description="", density_g_ml=None)  # fmt: skip


def similar_pearl(
    library: Library, name: str, substrate: str, radius_um: float, substrate_nm: float | None
) -> Pearl:
    """A new pearl ``name`` on the datasheet's ``substrate`` (of ``substrate_nm``, else that
    of the library's pearl on it nearest in radius, else :data:`PEARL_START`'s) and of its
    radius: its coating, spread and volume fraction those of the library's pearl nearest in
    radius, on that substrate where one is (:data:`PEARL_START` where it has none); where
    its fit starts (its coating then from :data:`COATING_GRID_NM`)."""
    pearls = library.of_kind("pearl")
    alike = [p for p in pearls if p.substrate == substrate] or pearls
    if not alike:
        start = {k: v for k, v in PEARL_START.items() if k != "substrate_nm"}
        return Pearl(name, substrate=substrate, radius_um=radius_um,
                     substrate_nm=substrate_nm or PEARL_START["substrate_nm"], **start)  # fmt: skip
    nearest = min(alike, key=lambda p: abs(np.log(p.radius_um / radius_um)))
    if substrate_nm is None:
        on_it = nearest.substrate == substrate
        substrate_nm = nearest.substrate_nm if on_it else PEARL_START["substrate_nm"]
    return replace(nearest, name=name, substrate=substrate, substrate_nm=substrate_nm,
                   radius_um=radius_um, description="", density_g_ml=None)  # fmt: skip


def check_kind(toner: Toner, kinds: tuple[str, ...] = CHARACTERISED) -> None:
    """Refuse a toner that is not of one of ``kinds``."""
    if toner.kind not in kinds:
        raise CharacterisationError(
            f"{toner.name!r} is {with_article(toner.kind)} toner: expected "
            f"{' or '.join(map(with_article, kinds))} (a pigment's "
            "absorption and scattering, an aluminium flake's spread, surface and volume "
            "fraction, or a pearl's coating, spread and volume fraction, are read from panels)"
        )


@dataclass(frozen=True)
class _Found:
    """A panel fit's outcome: the toner, each panel's application, the misfit and the
    fitted parameters' standard deviations (of their logs; NaN at a bound)."""

    fit: _PanelFit
    toner: Toner
    start: Toner
    film: NDArray
    spread: NDArray
    chi2: float
    dof: int
    misfit: float
    sd: NDArray
    evaluations: int
    converged: bool

    @property
    def scale(self) -> float:
        """χ²/dof where the panels lie further from the physics than their errors allow,
        else 1: what the parameters' uncertainty is scaled by."""
        return max(self.chi2 / self.dof, 1.0)

    def characterisation(self, uncertainty: dict[str, Any]) -> Characterisation:
        nominal = np.ones(len(self.film))
        fitted, texture = self.fit.appearance(self.toner, self.film, self.spread)
        started = self.fit.reflectance(self.start, nominal, nominal)
        return Characterisation(
            toner=self.toner,
            start=self.start,
            film=self.film,
            spread=self.spread,
            fitted=fitted,
            fitted_texture=texture,
            de00=_panel_de00(self.fit.measured, fitted),
            start_de00=_panel_de00(self.fit.measured, started),
            uncertainty=uncertainty,
            chi2_per_dof=self.misfit,
            evaluations=self.evaluations,
            converged=self.converged,
        )


class _PanelFit:
    """Panels of recipes ``x[N, T]`` read as ``measured[N, G, W]``, and the library's physics
    that predicts them with its toner at ``k`` replaced (module notes)."""

    def __init__(
        self, library: Library, k: int, x, geometries, measured, panels, texture=None,
        grounds: Sequence[str] | None = None,
    ) -> None:  # fmt: skip
        self.library, self.k, self.geometries = library, k, geometries
        self.grounds = np.array(grounds if grounds is not None else ["primer"] * len(x))
        self.x = np.asarray(x, dtype=float)
        self.measured = np.asarray(measured, dtype=float)
        name = library.names[k]
        for panel, recipe in zip(panels, self.x, strict=True):
            if recipe[k] <= 0:
                raise CharacterisationError(f"{panel}: its recipe holds no {name!r}")
        self.misfit = 1.0  # the readings' errors' scale: more where the panels lie further
        self.read = np.isfinite(self.measured)
        self.target = self.measured[self.read]
        self.weight = 1 / (PANEL_RELATIVE_SD * np.abs(self.target) + PANEL_OFFSET_SD)
        self.texture = None if texture is None else np.asarray(texture, dtype=float)
        if self.texture is not None:  # SG follows from Sa and Si: not counted twice
            self.texture_read = np.isfinite(self.texture) & _NOT_SG
            Sa = self.texture[:, list(TEXTURE_FAMILIES["Sa"])]
            few = ~(Sa >= FEW_GLINTS * GLINT_SHARE)  # Si of a few glints, or none: no reading
            self.texture_read[:, list(TEXTURE_FAMILIES["Si"])] &= ~few
            self.texture_target = self.texture[self.texture_read]
            self.texture_weight = 1 / (
                TEXTURE_RELATIVE_SD * np.abs(self.texture_target) + TEXTURE_OFFSET_SD
            )

    def appearance(self, toner: Toner, film: NDArray, spread: NDArray, texture: bool = True):
        """The panels' reflectance ``[N, G, W]`` and, with ``texture``, their texture
        readings ``[N, 8]`` (else None)."""
        library = with_toner(self.library, toner)
        layer = sprayed_layer(layer_from_fractions(library, self.x), library, film, spread)
        R = reflectance_over(layer, library, self.grounds, self.geometries)
        return R, texture_readings(layer, library.flake_radii_um) if texture else None

    def reflectance(self, toner: Toner, film: NDArray, spread: NDArray) -> NDArray:
        return self.appearance(toner, film, spread, texture=False)[0]

    def residuals(self, toner: Toner, film: NDArray, spread: NDArray) -> NDArray:
        """Each reading's misfit in units of its error (the texture readings' too, where
        they are fitted), then each panel's film build and spread in units of their
        spray-to-spray spread."""
        R, texture = self.appearance(toner, film, spread, self.texture is not None)
        misfit = [(R[self.read] - self.target) * self.weight]
        if texture is not None:
            misfit.append((texture[self.texture_read] - self.texture_target) * self.texture_weight)
        data = np.concatenate(misfit) / self.misfit
        return np.concatenate([data, np.log(film) / FILM_BUILD_SD, np.log(spread) / SPREAD_SD])

    def chi2(self, toner: Toner, film: NDArray, spread: NDArray) -> float:
        return float(np.sum(self.residuals(toner, film, spread) ** 2))

    def run(self, toner_of: Callable[[NDArray], Toner], p0, bounds, start: Toner) -> _Found:
        """Least squares over the toner's parameters (``toner_of`` makes it from them, ``p0``
        within ``bounds[2, P]``) and each panel's log film build and spread."""
        N, P = len(self.x), len(p0)
        application = np.log([[_APPLICATION_RANGE[0]] * 2 * N, [_APPLICATION_RANGE[1]] * 2 * N])
        low, high = np.concatenate([bounds, application], axis=1)

        def residuals(p: NDArray) -> NDArray:
            film, spread = np.exp(p[P:]).reshape(2, N)
            return self.residuals(toner_of(p[:P]), film, spread)

        p = np.clip(np.concatenate([p0, np.zeros(2 * N)]), low, high)
        solution = least_squares(residuals, p, bounds=(low, high), method="trf", x_scale=1.0,
                                 max_nfev=FIT_ITERATIONS)  # fmt: skip
        dof = max(solution.fun.size - solution.x.size, 1)
        misfit = float(np.sum(solution.fun**2)) / dof
        if misfit > 1:  # the panels lie further from the physics than their readings' errors
            self.misfit = np.sqrt(misfit)  # the errors made as large, the fit run again
            solution = least_squares(residuals, solution.x, bounds=(low, high), method="trf",
                                     x_scale=1.0, max_nfev=FIT_ITERATIONS)  # fmt: skip
        film, spread = np.exp(solution.x[P:]).reshape(2, N)
        chi2 = float(np.sum(solution.fun**2))
        sd = _log_sd(solution.jac, max(chi2 / dof, 1.0))[:P]
        at_bound = (solution.x[:P] <= low[:P] + 1e-6) | (solution.x[:P] >= high[:P] - 1e-6)
        sd[at_bound] = np.nan
        return _Found(self, toner_of(solution.x[:P]), start, film, spread, chi2, dof, misfit,
                      sd, int(solution.nfev), solution.status > 0)  # fmt: skip


def _check_tinted(library: Library, k: int, x: NDArray) -> None:
    """Refuse masstones alone: they tell a pigment's K/S, not K and S apart (over a hiding
    chart's black and white too, wherever the film hides: in its absorption bands)."""
    if not np.any(np.delete(x, k, axis=1) > 0):
        raise CharacterisationError(
            f"the panels are masstones of {library.names[k]!r} alone, which tell its K/S and "
            "not K and S apart: add a tint of it in the library's white (or in another toner "
            "of the library)"
        )


def _km_start(
    library: Library, k: int, x: NDArray, geometries: tuple[Geometry, ...], measured: NDArray
) -> Pigment:
    """The pigment by Kubelka–Munk at :data:`FACE_GEOMETRY` (module notes); flat where the
    panels were not read there. Every panel is taken to hide: one over a chart's black that
    does not reads darker than its R∞, which the fit then corrects (started from the panels
    over the primer alone, bismuth vanadate's fit stopped in another minimum)."""
    pigment = library.toners[k]
    names = [g.name for g in geometries]
    flat = np.ones(WAVELENGTHS.size)
    if FACE_GEOMETRY not in names:
        return replace(pigment, absorption=flat, scattering=0.1 * flat)
    R = measured[:, names.index(FACE_GEOMETRY)]
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
