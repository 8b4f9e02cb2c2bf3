"""The spectral grid: one definition of the wavelengths flakelab stores and renders.

Spectra are stored at 400–700 nm in 10 nm steps (31 bands, the native grid of multi-angle
instruments) and rendered at 16 bands (400–700 nm, 20 nm), DESIGN.md §2.
"""

from __future__ import annotations

import colour
import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "SHAPE_STORE",
    "SHAPE_RENDER",
    "WAVELENGTHS",
    "WAVELENGTHS_RENDER",
    "shape_of",
    "resample",
    "shift_spectra",
]

SHAPE_STORE = colour.SpectralShape(400, 700, 10)
"""Storage grid: 400–700 nm, 10 nm [nm]."""

SHAPE_RENDER = colour.SpectralShape(400, 700, 20)
"""Rendering grid: 400–700 nm, 20 nm, 16 bands [nm]."""

WAVELENGTHS: NDArray[np.float64] = np.asarray(SHAPE_STORE.wavelengths, dtype=float)
WAVELENGTHS_RENDER: NDArray[np.float64] = np.asarray(SHAPE_RENDER.wavelengths, dtype=float)


def shape_of(wavelengths: ArrayLike) -> colour.SpectralShape:
    """Return the regular :class:`colour.SpectralShape` of ``wavelengths`` [nm].

    Raises
    ------
    ValueError
        When the wavelengths are not increasing with a constant step.

    Examples
    --------
    >>> shape_of(range(400, 710, 10))
    SpectralShape(400.0, 700.0, 10.0)
    """
    wl = np.asarray(wavelengths, dtype=float)
    if wl.ndim != 1 or wl.size < 3:
        raise ValueError(f"expected at least 3 wavelengths, got {wl.size}")
    steps = np.diff(wl)
    if np.any(steps <= 0) or not np.allclose(steps, steps[0]):
        raise ValueError(
            f"expected increasing wavelengths with a constant step, got {wl[:4].tolist()}…"
        )
    return colour.SpectralShape(float(wl[0]), float(wl[-1]), float(steps[0]))


def resample(
    values: ArrayLike,
    wavelengths: ArrayLike,
    shape: colour.SpectralShape = SHAPE_STORE,
) -> NDArray[np.float64]:
    """Resample spectra ``values[..., wavelength]`` onto ``shape`` with colour-science.

    Interpolation follows colour-science's defaults (Sprague for regular 5 nm-multiple grids,
    CIE 167 extrapolation by constant ends).

    Examples
    --------
    >>> r = resample(np.ones((2, 31)), WAVELENGTHS, SHAPE_RENDER)
    >>> r.shape
    (2, 16)
    """
    values = np.asarray(values, dtype=float)
    wl = np.asarray(wavelengths, dtype=float)
    if values.shape[-1] != wl.size:
        raise ValueError(f"expected {wl.size} values per spectrum, got {values.shape[-1]}")
    wanted = np.asarray(shape.wavelengths, dtype=float)
    at = np.minimum(np.searchsorted(wl, wanted), wl.size - 1)
    if np.all(np.abs(wl[at] - wanted) < 1e-9):
        # every wavelength wanted was given: interpolation would return its value (to 1e-15)
        return values[..., at].copy()
    flat = values.reshape(-1, wl.size)
    msds = colour.MultiSpectralDistributions(flat.T, wl)
    msds = msds.copy().align(shape)
    return np.asarray(msds.values.T, dtype=float).reshape(*values.shape[:-1], -1)


def shift_spectra(spectra: ArrayLike, shift_nm: ArrayLike) -> NDArray[np.float64]:
    """Spectra ``[..., W]`` on the storage grid moved along the wavelength axis by
    ``shift_nm[...]`` (longer for a positive shift; the two broadcast), linearly
    interpolated, the edge bands held: a pigment batch's hue drift, its absorption band a
    little off the standard's."""
    spectra, shift = np.asarray(spectra, dtype=float), np.asarray(shift_nm, dtype=float)
    rows = np.broadcast_shapes(spectra.shape[:-1], shift.shape)
    spectra = np.broadcast_to(spectra, (*rows, spectra.shape[-1]))
    shift = np.broadcast_to(shift, rows)
    step = WAVELENGTHS[1] - WAVELENGTHS[0]
    position = (WAVELENGTHS - shift[..., None] - WAVELENGTHS[0]) / step
    index = np.clip(position, 0, WAVELENGTHS.size - 1)
    low = np.floor(index).astype(int).clip(0, WAVELENGTHS.size - 2)
    frac = index - low
    return (
        np.take_along_axis(spectra, low, -1) * (1 - frac)
        + np.take_along_axis(spectra, low + 1, -1) * frac
    )
