"""Kubelka–Munk two-flux theory with the Saunderson correction (DESIGN.md §3, solid colours).

K/S = (1 − R∞)² / (2R∞); mixtures K = Σ cᵢKᵢ, S = Σ cᵢSᵢ; a layer of thickness X over a
substrate R_g (Kubelka 1948, hyperbolic form); Saunderson (1942):
R_m = k1 + (1 − k1)(1 − k2) R / (1 − k2 R).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "SAUNDERSON_K1",
    "SAUNDERSON_K2",
    "km_coefficients",
    "reflectance_infinite",
    "ks_ratio",
    "layer_reflectance",
    "saunderson",
    "inverse_saunderson",
]

SAUNDERSON_K1 = 0.04
"""External reflectance of the coating's top for the usual 45°/0° or d/8° geometry."""
SAUNDERSON_K2 = 0.6
"""Internal diffuse reflectance of the coating's top (n = 1.5: 0.596)."""


def km_coefficients(
    absorption: ArrayLike, scattering: ArrayLike, asymmetry: ArrayLike = 0.0
) -> tuple[NDArray, NDArray]:
    """(K, S) of the two-flux model from the transport coefficients [1/µm].

    K = 2κ (a diffuse flux crosses a sublayer on a mean path twice its thickness),
    S = ¾·σ_s·(1 − g) (the diffusion-limit match for the reduced scattering coefficient;
    Thennadil 2008 discusses the choice). Checked against the Monte Carlo in the tests.
    """
    absorption = np.asarray(absorption, dtype=float)
    reduced = np.asarray(scattering, dtype=float) * (1 - np.asarray(asymmetry, dtype=float))
    return 2 * absorption, 0.75 * reduced


def reflectance_infinite(K: ArrayLike, S: ArrayLike) -> NDArray[np.float64]:
    """R∞ = 1 + K/S − √((K/S)² + 2K/S).

    Examples
    --------
    >>> round(float(reflectance_infinite(2 / 15, 1.0)), 12)
    0.6
    """
    ratio = np.asarray(K, dtype=float) / np.asarray(S, dtype=float)
    return 1 + ratio - np.sqrt(ratio**2 + 2 * ratio)


def ks_ratio(R_infinite: ArrayLike) -> NDArray[np.float64]:
    """K/S = (1 − R∞)² / (2R∞), the inverse of :func:`reflectance_infinite`."""
    R = np.asarray(R_infinite, dtype=float)
    return (1 - R) ** 2 / (2 * R)


def layer_reflectance(
    K: ArrayLike, S: ArrayLike, thickness: ArrayLike, substrate: ArrayLike
) -> NDArray[np.float64]:
    """Reflectance of a layer (K, S [1/µm], thickness [µm]) over a substrate R_g.

    Kubelka's hyperbolic solution; S → 0 becomes Beer–Lambert R_g·exp(−2KX), K → 0 (a layer
    that scatters and does not absorb: pearls alone) (R_g + (1 − R_g)SX) / (1 + (1 − R_g)SX),
    and a thick layer tends to R∞ whatever the substrate.
    """
    K = np.asarray(K, dtype=float)
    S = np.maximum(np.asarray(S, dtype=float), 1e-12)
    X = np.asarray(thickness, dtype=float)
    Rg = np.asarray(substrate, dtype=float)
    a = 1 + K / S
    b = np.sqrt(a**2 - 1)
    bSX = b * S * X
    # b·coth(bSX) tends to 1/(SX), not to 0, as K → 0: by its series where bSX is small
    b_coth = np.where(
        bSX < 1e-6,
        (1 + bSX**2 / 3) / np.maximum(S * X, 1e-300),
        b / np.tanh(np.maximum(bSX, 1e-300)),
    )
    return (1 - Rg * (a - b_coth)) / (a - Rg + b_coth)


def saunderson(R: ArrayLike, k1: float = SAUNDERSON_K1, k2: float = SAUNDERSON_K2) -> NDArray:
    """Measured reflectance from the internal (body) reflectance R."""
    R = np.asarray(R, dtype=float)
    return k1 + (1 - k1) * (1 - k2) * R / (1 - k2 * R)


def inverse_saunderson(
    R_measured: ArrayLike, k1: float = SAUNDERSON_K1, k2: float = SAUNDERSON_K2
) -> NDArray:
    """Internal reflectance from a measured one (inverse of :func:`saunderson`)."""
    Rm = np.asarray(R_measured, dtype=float)
    x = (Rm - k1) / ((1 - k1) * (1 - k2))
    return x / (1 + k2 * x)
