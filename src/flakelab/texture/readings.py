"""Texture readings (Sa, Si at 15/45/75°, SG, G) predicted from a coating's flake population.

The instruments do not publish their formulas (DESIGN.md §2), so flakelab defines its own
from the physics of a camera looking along the normal at a coating lit from 15°, 45°, 75°:

* a flake sparkles when its tilt mirrors the source into the camera: inside the binder the
  needed tilt is θ_n = ½·asin(sin θ_light / n) (5.0°, 14.0°, 20.1° for n = 1.5);
* flakes visible per image area: those within the top optical depth,
  N_A = Σ_s N_s · d_vis with N_s = φ_s/(π a_s² t_s) and d_vis = 1/(σ_f + 2κ̄ + σ̄_s);
* **sparkle area** Sa = 100·(1 − exp(−Σ_s N_A,s · π a_s² · p_s(θ_n) · Ω_cam)), the share of
  the image covered by glints (Ω_cam = 0.02 sr, the camera's acceptance in the binder);
* **sparkle intensity** Si_θ = 10·R̄·(a/10 µm)^½·exp(−2κ̄·d_vis)·(1 + k·log10(1/cos θ)):
  brighter for larger, more reflective and less buried flakes, and under a lower light: a
  glint shows the lamp's radiance while the white standard it is read against receives
  irradiance ∝ cos θ, and Si is logarithmic in the glint's brightness (k =
  ``SPARKLE_LIGHT_SLOPE``, fitted to rendered images);
* **sparkle grade** SG = ⅓·Σ_θ √(Sa_θ·Si_θ)/2;
* **graininess** G (diffuse light): contrast of flake clusters at the mm scale,
  G = 12·(a/20 µm)^0.75·√(coverage·(1 − coverage)) with coverage = 1 − exp(−N_A·π a²).

Scales are chosen so that readings fall in the instruments' usual ranges (Sa, Si up to about
30, SG and G about 0–20). Issue 6 measures the same quantities on rendered flake images.

A camera sees a finite field, so a reading is a sample (:func:`counted_readings`): it counts
N = Sa/``glint_share`` glints (Poisson), Si is their mean brightness, ± its spread over one
glint /√N, and G the contrast of a finite number of flake clusters, ± a relative spread.
``benchmarks/texture_repeatability.py`` fits the three constants to the spot-to-spot spread of
rendered images (:mod:`flakelab.texture.images`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flakelab.core.measurement import TEXTURE_FAMILIES, TEXTURE_READINGS
from flakelab.physics.layer import Layer, orientation_pdf

__all__ = [
    "texture_readings",
    "counted_readings",
    "assemble_readings",
    "SPARKLE_LIGHTS",
    "SPARKLE_LIGHT_SLOPE",
    "light_factor",
    "CAMERA_SOLID_ANGLE",
    "GLINT_SHARE",
    "GLINT_SD",
    "GRAIN_SD",
]

SPARKLE_LIGHTS = (15.0, 45.0, 75.0)
"""Directional light angles [degree] of the sparkle readings."""
SPARKLE_LIGHT_SLOPE = 0.49
"""Rise of Si per decade of 1/cos θ_light, relative to Si under normal light, fitted to
rendered images, which read Si15 : Si45 : Si75 = 1 : 1.06 : 1.29
(``benchmarks/texture_repeatability.py``)."""
CAMERA_SOLID_ANGLE = 0.02
"""Acceptance of the camera pixel's glint cone, inside the binder [sr]."""
GLINT_SHARE = 0.012
"""Sa of one glint [% of the camera's field] (``benchmarks/texture_repeatability.py``)."""
GLINT_SD = 0.57
"""Spread of one glint's sparkle intensity, relative to Si (same benchmark)."""
GRAIN_SD = 0.026
"""Relative spread of G from one spot to the next (same benchmark)."""


def texture_readings(layer: Layer, radius_um: ArrayLike) -> NDArray[np.float64]:
    """Readings ``[F, 8]`` in :data:`~flakelab.core.measurement.TEXTURE_READINGS` order for
    each formulation; ``radius_um`` ``[S]`` of the flake species."""
    radius = np.asarray(radius_um, dtype=float)
    rate = layer.flake_rate  # σ_s = φ_s / t_s  [1/µm]
    if rate.shape[1] == 0:
        return np.zeros((layer.size, len(TEXTURE_READINGS)))
    absorption = layer.absorption.mean(axis=1, keepdims=True)
    scattering = layer.scattering.mean(axis=1, keepdims=True)
    visible_depth = 1 / (rate.sum(1, keepdims=True) + 2 * absorption + scattering + 1 / 60.0)
    area = np.pi * radius**2
    per_area = rate / area * visible_depth  # N_A,s = φ/(πa²t)·d_vis [1/µm²]
    covered = per_area * area  # expected flake cover within the visible depth
    reflect = layer.flake_normal_reflectance
    buried = np.exp(-2 * absorption * visible_depth)[:, 0]
    weight = covered / np.maximum(covered.sum(1, keepdims=True), 1e-12)
    mean_radius = (weight * radius).sum(1)
    normal_intensity = 10 * (weight * reflect).sum(1) * np.sqrt(mean_radius / 10) * buried
    readings = []
    for light in SPARKLE_LIGHTS:
        tilt = 0.5 * np.arcsin(np.sin(np.radians(light)) / layer.n)
        glint = covered * orientation_pdf(tilt, layer.spreads) * CAMERA_SOLID_ANGLE
        sparkle_area = 100 * (1 - np.exp(-glint.sum(1)))
        intensity = normal_intensity * light_factor(light)
        readings += [sparkle_area, intensity * (sparkle_area > 0)]
    Sa, Si = np.array(readings[0::2]).T, np.array(readings[1::2]).T
    coverage = 1 - np.exp(-covered.sum(1))
    G = 12 * (mean_radius / 20) ** 0.75 * np.sqrt(coverage * (1 - coverage))
    return assemble_readings(Sa, Si, G)


def light_factor(light: ArrayLike, slope: float = SPARKLE_LIGHT_SLOPE) -> NDArray[np.float64]:
    """Si under a light at ``light`` degrees relative to Si under normal light:
    1 + ``slope``·log10(1/cos θ)."""
    return 1 + slope * np.log10(1 / np.cos(np.radians(light)))


def counted_readings(
    readings: ArrayLike,
    rng: np.random.Generator,
    *,
    glint_share: float,
    glint_sd: float,
    grain_sd: float,
) -> NDArray[np.float64]:
    """One reading ``[F, 8]`` of coatings whose expected readings are ``readings``, by a
    camera whose field holds a finite number of glints: under each light it counts
    N ~ Poisson(Sa/``glint_share``) glints, Sa = N·``glint_share``, Si = Si·(1 + ``glint_sd``·z/√N)
    (0 without a glint); G = G·(1 + ``grain_sd``·z); SG follows from the counted Sa and Si."""
    readings = np.asarray(readings, dtype=float)
    Sa, Si = readings[:, TEXTURE_FAMILIES["Sa"]], readings[:, TEXTURE_FAMILIES["Si"]]
    G = readings[:, TEXTURE_FAMILIES["G"][0]]
    glints = rng.poisson(Sa / glint_share)
    spread = glint_sd * rng.standard_normal(Si.shape) / np.sqrt(np.maximum(glints, 1))
    counted_Si = np.where(glints > 0, Si * (1 + spread), 0.0).clip(0)
    counted_G = G * (1 + grain_sd * rng.standard_normal(G.shape))
    return assemble_readings(glints * glint_share, counted_Si, counted_G.clip(0))


def assemble_readings(Sa: NDArray, Si: NDArray, G: NDArray) -> NDArray[np.float64]:
    """Readings ``[F, 8]`` in :data:`~flakelab.core.measurement.TEXTURE_READINGS` order from
    Sa, Si ``[F, 3]`` (per light) and G ``[F]``; the sparkle grade SG = ⅓·Σ_θ √(Sa_θ·Si_θ)/2."""
    SG = np.sqrt(Sa * Si).sum(1) / 6
    return np.column_stack([Sa[:, 0], Si[:, 0], Sa[:, 1], Si[:, 1], Sa[:, 2], Si[:, 2], SG, G])
