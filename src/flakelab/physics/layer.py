"""Optical description of a basecoat: what the fast model and the Monte Carlo both read.

A :class:`Layer` holds, for a batch of F formulations, the per-depth collision rates of each
flake species (aluminium and pearl toners), the pigments' absorption and scattering
coefficients, the binder and the primer. Built from a library and recipes by
:func:`layer_from_fractions`, or directly for experiments (the hybrid paper's dye series).

Flake orientation: each flake's tilt θ from the surface normal is the length of a 2-D
Gaussian vector of standard deviation s (azimuth uniform), so the density per solid angle is
p(θ) = θ/sin θ · exp(−θ²/2s²) / (2π s² Z), Z = 1 − exp(−(π/2)²/2s²) (hemisphere).
Flakes are disks hit by a ray of direction d at a rate N·πa²·|d·n| per unit length; with
φ = N·πa²·t this is σ_f = φ/t per unit depth for flat flakes (DESIGN.md §3).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flakelab.core.geometry import N_BINDER, directions, refract_into_coating
from flakelab.core.spectra import WAVELENGTHS, shift_spectra
from flakelab.library.optics import flake_reflectance, fresnel_reflectance, pearl_reflectance
from flakelab.library.toners import AluminiumFlake, Library, Pearl

__all__ = [
    "Layer",
    "REFLECTANCE_ANGLES",
    "layer_from_fractions",
    "species_reflectance",
    "orientation_pdf",
    "mean_projected_cosine",
    "interface_directions",
    "internal_diffuse_reflectance",
]

REFLECTANCE_ANGLES = np.arange(91.0)
"""Incidence angles [degree] of the flake reflectance tables (1° steps, linear in between)."""


@dataclass(frozen=True)
class Layer:
    """A basecoat for F formulations on the storage grid (W = 31 bands).

    ``flake_rate[F, S]`` σ_f of each flake species [1/µm per depth]; ``flake_sd[S]`` their
    orientation spread [radian]; ``flake_reflectance[S, 91, W]`` reflectance versus incidence
    angle (surface quality included); ``flake_transmits[S]`` True for pearls (what is not
    reflected passes through). ``absorption``/``scattering[F, W]`` [1/µm], ``asymmetry[F]``
    the Henyey–Greenstein g, ``thickness`` [µm] (one for all, or ``[F]``), ``primer[W]`` the
    primer's reflectance; ``spread_scale[F]`` multiplies every species' spread (spray
    conditions change how well flakes align).
    """

    flake_rate: NDArray[np.float64]
    flake_sd: NDArray[np.float64]
    flake_reflectance: NDArray[np.float64]
    flake_transmits: NDArray[np.bool_]
    absorption: NDArray[np.float64]
    scattering: NDArray[np.float64]
    asymmetry: NDArray[np.float64]
    thickness: float | NDArray[np.float64]
    primer: NDArray[np.float64]
    n: float = N_BINDER
    spread_scale: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        F, S = np.shape(self.flake_rate)
        if np.shape(self.absorption) != (F, WAVELENGTHS.size):
            raise ValueError(
                f"absorption: expected shape ({F}, {WAVELENGTHS.size}), "
                f"got {np.shape(self.absorption)}"
            )
        if np.shape(self.flake_reflectance) != (S, REFLECTANCE_ANGLES.size, WAVELENGTHS.size):
            raise ValueError(
                f"flake_reflectance: expected one {REFLECTANCE_ANGLES.size} × {WAVELENGTHS.size} "
                "table per flake species"
            )

    @property
    def size(self) -> int:
        return int(np.shape(self.flake_rate)[0])

    @property
    def spreads(self) -> NDArray[np.float64]:
        """Orientation spread of each species in each formulation ``[F, S]`` [radian]."""
        scale = np.ones(self.size) if self.spread_scale is None else self.spread_scale
        return np.asarray(scale, dtype=float)[:, None] * self.flake_sd[None, :]

    @property
    def flake_normal_reflectance(self) -> NDArray[np.float64]:
        """Each flake species' reflectance at normal incidence, mean over the bands ``[S]``
        (what a glint's brightness scales with)."""
        return self.flake_reflectance[:, 0].mean(axis=1)

    @property
    def reduced_scattering(self) -> NDArray[np.float64]:
        """σ_s·(1 − g) of each formulation ``[F, W]`` [1/µm]: the scattering that turns
        light off its path (what scatters forward stays on it)."""
        return self.scattering * (1 - self.asymmetry[:, None])

    @property
    def film(self) -> NDArray[np.float64]:
        """Basecoat thickness of each formulation ``[F]`` [µm]."""
        return np.broadcast_to(np.asarray(self.thickness, dtype=float), (self.size,))

    def __getitem__(self, index: int | slice) -> Layer:
        """The formulations ``index`` as a layer of their own (a slice keeps the batch axis)."""
        rows = slice(index, index + 1) if isinstance(index, int | np.integer) else index
        return replace(
            self,
            flake_rate=self.flake_rate[rows],
            absorption=self.absorption[rows],
            scattering=self.scattering[rows],
            asymmetry=self.asymmetry[rows],
            thickness=self.film[rows].copy() if np.ndim(self.thickness) else self.thickness,
            spread_scale=None if self.spread_scale is None else self.spread_scale[rows],
        )

    def with_absorption(self, absorption: ArrayLike) -> Layer:
        """The same flakes and binder with other dye absorption ``[F, W]`` (the dye series)."""
        absorption = np.asarray(absorption, dtype=float)
        F = absorption.shape[0]
        return replace(
            self,
            flake_rate=np.broadcast_to(self.flake_rate[:1], (F, self.flake_rate.shape[1])).copy(),
            absorption=absorption,
            scattering=np.broadcast_to(self.scattering[:1], absorption.shape).copy(),
            asymmetry=np.broadcast_to(self.asymmetry[:1], (F,)).copy(),
        )


def orientation_pdf(theta: ArrayLike, sd: ArrayLike) -> NDArray[np.float64]:
    """Density per solid angle of flake normals at tilt ``theta`` [radian], spread ``sd``.

    Examples
    --------
    >>> t = np.linspace(0, np.pi / 2, 20001)
    >>> w = 2 * np.pi * np.sin(t) * orientation_pdf(t, np.radians(10))
    >>> round(float(np.sum((w[1:] + w[:-1]) / 2 * np.diff(t))), 6)
    1.0
    """
    theta = np.asarray(theta, dtype=float)
    sd = np.asarray(sd, dtype=float)
    norm = 2 * np.pi * sd**2 * (1 - np.exp(-((np.pi / 2) ** 2) / (2 * sd**2)))
    ratio = np.where(theta > 1e-8, theta / np.sin(np.maximum(theta, 1e-8)), 1.0)
    return np.where(theta <= np.pi / 2, ratio * np.exp(-(theta**2) / (2 * sd**2)) / norm, 0.0)


def mean_projected_cosine(direction: ArrayLike, sd: float, samples: int = 4096) -> NDArray:
    """E[|d·n|] over the flake normal distribution for unit directions ``[..., 3]``.

    Deterministic quadrature (a fixed low-discrepancy set of normals), so the fast model and
    the Monte Carlo's exit attenuation use the same value.
    """
    i = np.arange(samples) + 0.5
    u, v = i / samples, (i * 0.6180339887498949) % 1.0
    theta = sd * np.sqrt(-2 * np.log(1 - u * (1 - np.exp(-((np.pi / 2) ** 2) / (2 * sd**2)))))
    phi = 2 * np.pi * v
    normals = np.stack(
        [np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=-1
    )
    return np.mean(np.abs(np.asarray(direction, dtype=float) @ normals.T), axis=-1)


def species_reflectance(toner: AluminiumFlake | Pearl, n_binder: float = N_BINDER) -> NDArray:
    """Reflectance table ``[91, 31]`` of one flake species in the binder versus incidence
    (read-only; computed once for each optics and binder, however the toner's spread or
    volume fraction change, as a fit of them changes them)."""
    if isinstance(toner, AluminiumFlake):
        return _aluminium_table(toner.surface_quality, n_binder)
    return _pearl_table(toner.coating_nm, toner.substrate, toner.substrate_nm, n_binder)


@cache
def _aluminium_table(surface_quality: float, n_binder: float) -> NDArray:
    return _read_only(
        surface_quality * flake_reflectance(REFLECTANCE_ANGLES, WAVELENGTHS, n_binder)
    )


@cache
def _pearl_table(coating_nm: float, substrate: str, substrate_nm: float, n_binder: float):
    return _read_only(
        pearl_reflectance(
            coating_nm,
            WAVELENGTHS,
            np.minimum(REFLECTANCE_ANGLES, 89.5),
            substrate=substrate,
            substrate_nm=substrate_nm,
            n_binder=n_binder,
        )
    )


def _read_only(table: NDArray) -> NDArray:
    table.setflags(write=False)
    return table


def layer_from_fractions(
    library: Library, fractions: ArrayLike, shade_nm: ArrayLike | None = None
) -> Layer:
    """The layer of each recipe: ``fractions[F, T]`` are mass fractions in library order.

    A toner's optical properties are those of the dry film when the recipe is that toner
    alone, so each one scales with its fraction: σ_f = x·φ/t for flakes and pearls,
    κ = Σ x·K, σ_s = Σ x·S for pigments (Beer–Lambert additivity, as in Kubelka–Munk).
    With ``shade_nm[F, T]`` (or ``[T]``) each pigment's absorption is its batch's, moved
    along the wavelength axis by that many nm (:func:`~flakelab.core.spectra.shift_spectra`).
    """
    x = np.atleast_2d(np.asarray(fractions, dtype=float))
    if x.shape[1] != len(library.toners):
        raise ValueError(
            f"fractions: expected {len(library.toners)} columns (library {library.name!r}), "
            f"got {x.shape[1]}"
        )
    toners = library.toners
    effect = [i for i, t in enumerate(toners) if t.kind in ("aluminium", "pearl")]
    pigments = [i for i, t in enumerate(toners) if t.kind == "pigment"]
    n = library.binder.refractive_index
    per_rate = np.array([toners[i].volume_fraction / toners[i].thickness_um for i in effect])
    K = np.array([toners[i].absorption for i in pigments]).reshape(-1, WAVELENGTHS.size)
    S = np.array([toners[i].scattering for i in pigments]).reshape(-1, WAVELENGTHS.size)
    g = np.array([toners[i].g for i in pigments])
    xp = x[:, pigments]
    shade = None if shade_nm is None else np.asarray(shade_nm, dtype=float)[..., pigments]
    if shade is None or not shade.any():
        absorption = xp @ K
    elif shade.ndim == 1:  # one set of tins for every recipe: their spectra moved once
        absorption = xp @ shift_spectra(K, shade)
    else:  # each distinct set of tins' spectra moved once
        shades, which = np.unique(shade, axis=0, return_inverse=True)
        absorption = np.einsum("fp,fpw->fw", xp, shift_spectra(K, shades)[which.ravel()])
    scattering = xp @ S
    strength = xp @ S.mean(axis=1) if pigments else np.zeros(x.shape[0])
    asymmetry = np.where(
        strength > 0, (xp * S.mean(axis=1)) @ g / np.maximum(strength, 1e-300), 0.0
    )
    return Layer(
        flake_rate=x[:, effect] * per_rate,
        flake_sd=np.radians([toners[i].orientation_sd_deg for i in effect]),
        flake_reflectance=_tables_in_use(toners, effect, x[:, effect], n),
        flake_transmits=np.array([toners[i].kind == "pearl" for i in effect], dtype=bool),
        absorption=absorption,
        scattering=scattering,
        asymmetry=asymmetry,
        thickness=library.binder.thickness_um,
        primer=library.binder.primer_reflectance,
        n=n,
    )


def _tables_in_use(toners, effect: list[int], fractions: NDArray, n: float) -> NDArray:
    """Reflectance tables ``[S, 91, W]`` of the effect toners ``effect``, zero for a species
    that no recipe holds (``fractions[F, S]`` of those toners): it contributes nothing, and
    a pearl's table costs 0.1 s of transfer matrices the first time it is asked for."""
    tables = np.zeros((len(effect), REFLECTANCE_ANGLES.size, WAVELENGTHS.size))
    for s in np.flatnonzero(np.any(fractions > 0, axis=0)):
        tables[s] = species_reflectance(toners[effect[s]], n)
    return tables


def interface_directions(
    geometries: ArrayLike, n: float = N_BINDER
) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Inside directions and Fresnel transmittances of each geometry.

    Returns ``(incoming[G, 3], outgoing[G, 3], T_in[G], T_out[G])``: the incoming direction
    travels down into the coating, the outgoing one up toward the detector.
    """
    light, view = directions(geometries)
    light_in, view_in = refract_into_coating(light, n), refract_into_coating(view, n)
    T_in = 1 - fresnel_reflectance(light[:, 2], 1.0, n)
    T_out = 1 - fresnel_reflectance(view[:, 2], 1.0, n)
    return -light_in, view_in, T_in, T_out


@cache
def internal_diffuse_reflectance(n: float = N_BINDER, steps: int = 20001) -> float:
    """Hemispherical reflectance of the coating's top for diffuse light from inside (≈0.60).

    Examples
    --------
    >>> round(internal_diffuse_reflectance(1.5), 3)
    0.596
    """
    theta = np.linspace(0, np.pi / 2, steps)
    R = fresnel_reflectance(np.cos(theta), n, 1.0)
    w = R * 2 * np.sin(theta) * np.cos(theta)
    return float(np.sum((w[1:] + w[:-1]) / 2 * np.diff(theta)))
