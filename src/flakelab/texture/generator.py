"""Appearance-based texture images (Kirchner et al., paper 001 eqs 1–4; DESIGN.md §4).

A grey image is built by adding patches at random positions. Four controls drive it:

* **size** — the patch's full width at half maximum [pixels] (a Gaussian spot, the form of a
  point spread function);
* **grey level** — the brightest patch's peak, in units of a white diffuser;
* **count** — mean number of patches centred on each pixel;
* **sparkler** — the paper multiplies the whole pattern by the sparkler k after each patch
  and renormalises. After N patches the i-th has been multiplied k^(N−i) times, so patch
  amplitudes are spread log-uniformly over a range s = k^N. We draw that range directly:
  amplitude = grey · s^(−u), u uniform on [0, 1), and renormalise by clipping at the
  camera's full scale. (A log-uniform amplitude is also what flakes at uniformly random
  depth under exponential attenuation give.)

Each control is a function of the prescribed texture value: power laws A + B·c^e of the
diffuse coarseness c (eq. 2), Fermi–Dirac forms 1 + 100/(1 + exp(A + B·g^e)) of the glint
impression g (eq. 4), times a unit scale per control (:data:`UNITS`). Controls may be arrays
(one value per pixel or column) so a curved panel can sweep its texture across the image;
pixels are then binned by patch size so every bin is one Gaussian filter.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import gaussian_filter

__all__ = [
    "CONTROLS",
    "DENSE_COUNT",
    "FWHM_PER_SIGMA",
    "PROCESSES",
    "FULL_SCALE",
    "TextureProcess",
    "patch_image",
    "control_values",
    "amplitude_moments",
    "expected_mean",
    "expected_graininess",
    "count_for_graininess",
    "expected_sparkle",
    "count_for_sparkle_grade",
]

CONTROLS = ("size", "grey", "count", "sparkler")
"""The four controls of the patch process, in the order of eq. 1 / eq. 3."""
PROCESSES = ("coarseness", "glint")
"""Diffuse coarseness (diffuse light, power laws) and glint impression (directional light,
Fermi–Dirac forms)."""
FULL_SCALE = 1000.0
"""Camera full scale [white diffuser units]: the renormalisation after the sparkler."""
UNITS = {
    "coarseness": {"size": 1.0, "grey": 0.01, "count": 0.1, "sparkler": 1.0},
    "glint": {"size": 0.1, "grey": 10.0, "count": 0.00025, "sparkler": 2.0},
}
"""Scale of each control's function value: the Fermi–Dirac forms span 1–101, so a glint
count (patches per pixel, about 0.0005–0.025) is counted per 4,000 pixels, and so on."""
DENSE_COUNT = 4.0
"""Patches per pixel above which a pixel's sum of patches is drawn from its gamma law."""
_SIZE_BIN_RATIO = 1.12
FWHM_PER_SIGMA = 2.0 * np.sqrt(2.0 * np.log(2.0))
"""Full width at half maximum of a Gaussian, in standard deviations."""


def control_values(process: str, constants: NDArray, value: ArrayLike) -> dict[str, NDArray]:
    """Controls for a prescribed ``value`` (coarseness c or glint g) from ``constants``
    ``[4, 3]`` = (A, B, e) per control (paper 001 eqs 2 and 4)."""
    v = np.maximum(np.asarray(value, dtype=float), 1e-6)
    A, B, e = (constants[:, j].reshape((4,) + (1,) * v.ndim) for j in range(3))
    if process == "coarseness":
        raw = A + B * v**e
    elif process == "glint":
        raw = 1.0 + 100.0 / (1.0 + np.exp(np.clip(A + B * v**e, -50, 50)))
    else:
        raise ValueError(f"process: expected one of {PROCESSES}, got {process!r}")
    raw = np.maximum(raw, 1e-4)  # a power law may dip below zero outside its range
    return {name: raw[i] * UNITS[process][name] for i, name in enumerate(CONTROLS)}


def patch_image(
    size: ArrayLike,
    grey: ArrayLike,
    count: ArrayLike,
    sparkler: ArrayLike,
    shape: tuple[int, int],
    rng: np.random.Generator,
) -> NDArray[np.float64]:
    """Grey image ``shape`` from the patch process; controls are scalars or arrays that
    broadcast to ``shape`` (one value per column for a curved panel, say).

    All patches centred on a pixel share its controls, so the process is drawn as one
    impulse per pixel — the sum of its patches' amplitudes — filtered by the pixel's patch
    shape. Where a pixel averages :data:`DENSE_COUNT` patches or more, that sum is drawn
    from the gamma law with the compound-Poisson mean and variance (the image's mean and
    graininess are those of the exact process; its histogram after filtering, already
    near-Gaussian there, barely changes); sparser pixels draw every patch.
    """
    size, grey, count, sparkler = (
        np.broadcast_to(np.asarray(c, dtype=float), shape) for c in (size, grey, count, sparkler)
    )
    count = np.maximum(count, 0.0)
    sparkler = np.maximum(sparkler, 1.0)
    dense = count >= DENSE_COUNT
    impulses = np.zeros(shape)
    per_pixel = rng.poisson(np.where(dense, 0.0, count)).ravel()
    centre = np.repeat(np.arange(per_pixel.size), per_pixel)
    amplitude = grey.ravel()[centre] * sparkler.ravel()[centre] ** -rng.random(centre.size)
    impulses.flat[:] = np.bincount(centre, amplitude, minlength=per_pixel.size)
    if dense.any():
        mean_amplitude, spread = amplitude_moments(sparkler[dense])
        impulses[dense] = rng.gamma(count[dense] / spread, grey[dense] * mean_amplitude * spread)
    sigma = np.maximum(size, 0.3) / FWHM_PER_SIGMA
    image = np.zeros(shape)
    for bin_sigma, members in _size_bins(sigma):
        masked = impulses if members is None else np.where(members, impulses, 0.0)
        # a unit-area Gaussian times 2πσ² has unit peak: ``grey`` is the patch's peak
        image += gaussian_filter(masked, bin_sigma, mode="wrap") * (2 * np.pi * bin_sigma**2)
    return np.minimum(image, FULL_SCALE)


def amplitude_moments(sparkler: ArrayLike) -> tuple[NDArray, NDArray]:
    """E[a]/grey and E[a²]/E[a]² of log-uniform amplitudes over a range ``sparkler``."""
    s = np.maximum(np.asarray(sparkler, dtype=float), 1.0 + 1e-9)
    mean = (1 - 1 / s) / np.log(s)
    return mean, (1 + 1 / s) * np.log(s) / (2 * (1 - 1 / s))


def expected_mean(size: ArrayLike, grey: ArrayLike, count: ArrayLike, sparkler: ArrayLike):
    """Mean grey level of the process: count · E[a] · 2πσ² (Campbell's theorem)."""
    sigma = np.asarray(size, dtype=float) / FWHM_PER_SIGMA
    return (
        np.asarray(count) * np.asarray(grey) * amplitude_moments(sparkler)[0] * 2 * np.pi * sigma**2
    )


def expected_graininess(
    size: ArrayLike, count: ArrayLike, sparkler: ArrayLike, smoothing_px: float
) -> NDArray:
    """Graininess 100·CV of the process after Gaussian smoothing ``smoothing_px`` (the
    metric's): Campbell's theorem gives CV² = (E[a²]/E[a]²) / (4π·count·(σ² + σ_s²)), free
    of the grey level."""
    sigma = np.asarray(size, dtype=float) / FWHM_PER_SIGMA
    spread = amplitude_moments(sparkler)[1]
    return 100 * np.sqrt(spread / (4 * np.pi * np.asarray(count) * (sigma**2 + smoothing_px**2)))


def count_for_graininess(
    value: ArrayLike, size: ArrayLike, sparkler: ArrayLike, smoothing_px: float
) -> NDArray:
    """The count that gives graininess ``value`` (inverse of :func:`expected_graininess`)."""
    sigma = np.asarray(size, dtype=float) / FWHM_PER_SIGMA
    spread = amplitude_moments(sparkler)[1]
    return spread / (4 * np.pi * (np.asarray(value) / 100) ** 2 * (sigma**2 + smoothing_px**2))


def expected_sparkle(
    size: float, grey: float, count: float, sparkler: float, level: float
) -> tuple[float, float]:
    """Sparkle area and intensity (the metric's Sa, Si above ``level``) of a sparse process:
    each patch lights the pixels of its sampled kernel where amplitude × kernel > level;
    amplitudes log-uniform; coverage Poisson, Sa = 100·(1 − exp(−count·E[lit pixels]))."""
    lit, logs = _lit_pixels(size, grey, sparkler, level)
    if lit <= 0:
        return 0.0, 0.0
    return 100 * float(-np.expm1(-count * lit)), 15 * float(logs / lit)


def count_for_sparkle_grade(
    value: float, size: float, grey: float, sparkler: float, level: float
) -> float:
    """The count that gives sparkle grade √(Sa·Si)/2 = ``value`` (inverse of the above)."""
    lit, logs = _lit_pixels(size, grey, sparkler, level)
    if lit <= 0:
        return np.inf
    area = min((2 * value) ** 2 / (15 * logs / lit), 99.0)
    return float(-np.log1p(-area / 100) / lit)


def _lit_pixels(size: float, grey: float, sparkler: float, level: float) -> tuple[float, float]:
    """E[pixels above ``level``] and E[Σ log10(pixel/level)] per patch."""
    sigma = max(size, 0.3) / FWHM_PER_SIGMA
    half = int(np.ceil(4 * sigma)) + 1
    impulse = np.zeros((2 * half + 1, 2 * half + 1))
    impulse[half, half] = 2 * np.pi * sigma**2
    kernel = gaussian_filter(impulse, sigma, mode="constant").ravel()
    u = (np.arange(256) + 0.5) / 256
    amplitude = grey * max(sparkler, 1.0) ** -u
    ratio = amplitude[:, None] * kernel[None, :] / level
    above = ratio > 1
    return float(above.sum(1).mean()), float(
        np.where(above, np.log10(np.maximum(ratio, 1)), 0).sum(1).mean()
    )


def _size_bins(sigma: NDArray) -> list[tuple[float, NDArray | None]]:
    """Pixels grouped by patch width (bins 12 % apart): (mean width, mask or None for all)."""
    low, high = float(sigma.min()), float(sigma.max())
    if high <= low * (1 + 1e-9):
        return [(low, None)]
    index = np.floor(np.log(sigma / low) / np.log(_SIZE_BIN_RATIO)).astype(np.int32)
    bins = []
    for k in np.unique(index):
        members = index == k
        bins.append((float(sigma[members].mean()), members))
    return bins


@dataclass(frozen=True)
class TextureProcess:
    """A fitted appearance-based process: ``constants[4, 3]`` (A, B, e per control) and the
    usable range of prescribed values (the anchor ladder's span)."""

    process: str
    constants: NDArray[np.float64]
    value_range: tuple[float, float]

    def controls(self, value: ArrayLike) -> dict[str, NDArray]:
        return control_values(self.process, self.constants, value)

    def image(
        self, value: ArrayLike, shape: tuple[int, int] | None = None, seed: int = 0
    ) -> NDArray[np.float64]:
        """Grey image with prescribed coarseness or glint ``value`` (a scalar, or a map that
        broadcasts to ``shape``; ``shape`` defaults to a 2-D map's own, else 256 × 256)."""
        low, high = self.value_range
        value = np.asarray(value, dtype=float)
        shape = shape or (value.shape if value.ndim == 2 else (256, 256))
        if np.any(value < low * 0.999) or np.any(value > high * 1.001):
            raise ValueError(
                f"{self.process}: prescribed values {value.min():.3g}–{value.max():.3g} lie "
                f"outside the fitted range {low:.3g}–{high:.3g}"
            )
        return patch_image(**self.controls(value), shape=shape, rng=np.random.default_rng(seed))
