"""Optical constants of effect pigments: aluminium, flake Fresnel reflectance, pearl stacks.

Aluminium follows the Lorentz–Drude fit of Rakić, Djurišić, Elazar & Majewski (1998),
*Applied Optics* 37, 5271, Table 2 (Al). Reflectance of a flake inside the binder uses the
Fresnel equations with a complex index; colour-science's transfer-matrix code takes the
transmission angle from a real ``arcsin`` and returns NaN for an absorbing substrate at
oblique incidence, so the metal interface is written out here (and checked against
colour-science at normal incidence). Pearl stacks (TiO2 on mica or alumina, non-absorbing)
go through colour-science's ``multilayer_tmm``.
"""

from __future__ import annotations

import colour
import numpy as np
from numpy.typing import ArrayLike, NDArray

from flakelab.core.geometry import N_BINDER

__all__ = [
    "aluminium_refractive_index",
    "fresnel_reflectance",
    "flake_reflectance",
    "titania_refractive_index",
    "pearl_reflectance",
    "SUBSTRATE_INDEX",
]

_EV_NM = 1239.84193
# Rakić et al. (1998) Table 2, aluminium: plasma energy, Drude strength and damping, then
# (strength f_j, damping Γ_j [eV], resonance ω_j [eV]) of the four Lorentz oscillators.
_AL_PLASMA, _AL_F0, _AL_GAMMA0 = 14.98, 0.523, 0.047
_AL_OSCILLATORS = np.array(
    [[0.227, 0.333, 0.162], [0.050, 0.312, 1.544], [0.166, 1.351, 1.808], [0.030, 3.382, 3.473]]
)

SUBSTRATE_INDEX = {"mica": 1.58, "alumina": 1.76, "silica": 1.46}
"""Refractive indices of pearl substrates at 550 nm [-] (handbook values)."""


def aluminium_refractive_index(wavelength: ArrayLike) -> NDArray[np.complex128]:
    """Complex refractive index n + ik of aluminium at ``wavelength`` [nm] (Rakić 1998 LD).

    Examples
    --------
    >>> n = aluminium_refractive_index(550)
    >>> round(float(n.real), 2), round(float(n.imag), 2)
    (0.97, 6.46)
    """
    energy = _EV_NM / np.asarray(wavelength, dtype=float)
    plasma2 = _AL_PLASMA**2
    eps = 1 - _AL_F0 * plasma2 / (energy * (energy + 1j * _AL_GAMMA0))
    f, gamma, omega = (c[:, None] for c in _AL_OSCILLATORS.T)
    e = np.atleast_1d(energy)[None, :]
    eps = eps + np.sum(f * plasma2 / (omega**2 - e**2 - 1j * e * gamma), axis=0).reshape(
        np.shape(energy)
    )
    return np.sqrt(eps)


def fresnel_reflectance(
    cos_incidence: ArrayLike, n_1: ArrayLike, n_2: ArrayLike
) -> NDArray[np.float64]:
    """Unpolarised Fresnel reflectance from medium n_1 (real) onto n_2 (complex allowed).

    Broadcasts over angles and wavelengths. Above the critical angle of a dielectric pair it
    returns 1 (total internal reflection).
    """
    cos_i = np.clip(np.asarray(cos_incidence, dtype=float), 0.0, 1.0)
    n_1 = np.asarray(n_1, dtype=complex)
    n_2 = np.asarray(n_2, dtype=complex)
    sin2_t = (n_1 / n_2) ** 2 * (1 - cos_i**2)
    cos_t = np.sqrt(1 - sin2_t + 0j)
    cos_t = np.where(cos_t.imag < 0, -cos_t, cos_t)  # the evanescent / absorbed branch
    r_s = (n_1 * cos_i - n_2 * cos_t) / (n_1 * cos_i + n_2 * cos_t)
    r_p = (n_2 * cos_i - n_1 * cos_t) / (n_2 * cos_i + n_1 * cos_t)
    return np.real((np.abs(r_s) ** 2 + np.abs(r_p) ** 2) / 2)


def flake_reflectance(
    theta_incidence: ArrayLike, wavelength: ArrayLike, n_binder: float = N_BINDER
) -> NDArray[np.float64]:
    """Reflectance ``[..., wavelength]`` of an aluminium flake in the binder at incidence
    ``theta_incidence`` [degree] (broadcast against the wavelengths [nm])."""
    cos_i = np.cos(np.radians(np.asarray(theta_incidence, dtype=float)))[..., None]
    return fresnel_reflectance(cos_i, n_binder, aluminium_refractive_index(wavelength))


def titania_refractive_index(wavelength: ArrayLike) -> NDArray[np.float64]:
    """Rutile TiO2, ordinary ray (DeVore 1951): n² = 5.913 + 0.2441 / (λ² − 0.0803), λ [µm]."""
    lam = np.asarray(wavelength, dtype=float) / 1000
    return np.sqrt(5.913 + 0.2441 / (lam**2 - 0.0803))


def pearl_reflectance(
    coating_nm: float,
    wavelength: ArrayLike,
    theta_incidence: ArrayLike = 0.0,
    *,
    substrate: str = "mica",
    substrate_nm: float = 400.0,
    substrate_spread: float = 0.25,
    n_binder: float = N_BINDER,
) -> NDArray[np.float64]:
    """Reflectance ``[angle, wavelength]`` of a TiO2-coated platelet (TiO2 | substrate | TiO2)
    embedded in the binder, unpolarised, by colour-science's transfer-matrix method.

    Real substrates vary in thickness from platelet to platelet, which washes out the fine
    fringes of the thick substrate while keeping the interference colour of the coating: the
    result is averaged over substrate thicknesses uniformly within ±``substrate_spread``.
    """
    if substrate not in SUBSTRATE_INDEX:
        raise ValueError(
            f"expected a substrate among {', '.join(SUBSTRATE_INDEX)}, got {substrate!r}"
        )
    if coating_nm <= 0 or substrate_nm <= 0:
        raise ValueError(f"expected positive layer thicknesses, got {coating_nm}, {substrate_nm}")
    wl = np.atleast_1d(np.asarray(wavelength, dtype=float))
    titania = titania_refractive_index(wl)
    ones = np.ones_like(wl)
    stack = np.stack([n_binder * ones, titania, SUBSTRATE_INDEX[substrate] * ones, titania,
                      n_binder * ones])  # fmt: skip
    angles = np.atleast_1d(np.asarray(theta_incidence, dtype=float))
    thicknesses = substrate_nm * (1 + substrate_spread * np.linspace(-1, 1, 15))
    R = np.mean(
        [
            colour.phenomena.multilayer_tmm(stack, [coating_nm, d, coating_nm], wl, angles)[0]
            for d in thicknesses
        ],
        axis=0,
    )
    return np.moveaxis(R[:, :, 0, :].mean(axis=-1), 0, -1)
