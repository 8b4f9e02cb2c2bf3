"""How much a texture reading varies from one spot of a panel to the next.

The camera's field holds a finite number of flakes, so two spots of one panel read
differently. Rendering a coating at several spots (:func:`spot_readings`, physical flake
images of :mod:`flakelab.texture.images` measured by :mod:`flakelab.texture.metrics`) gives
that spread; :func:`fit_counting_noise` fits the three constants of the counting model of
:func:`flakelab.texture.readings.counted_readings` to it, which the generated world then
uses as its instrument's texture repeatability.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from flakelab.core.measurement import TEXTURE_FAMILIES
from flakelab.texture.images import FlakePopulation, flake_image
from flakelab.texture.metrics import graininess, sparkle
from flakelab.texture.readings import SPARKLE_LIGHTS, assemble_readings, light_factor

__all__ = ["spot_readings", "fit_counting_noise", "counting_sd", "fit_light_slope"]

_SA, _SI, _G = (list(TEXTURE_FAMILIES[k]) for k in ("Sa", "Si", "G"))


def spot_readings(population: FlakePopulation, spots: int, seed: int = 0) -> NDArray:
    """Readings ``[spots, 8]`` of one coating at ``spots`` places (each its own flakes), in
    :data:`~flakelab.core.measurement.TEXTURE_READINGS` order."""
    places = range(seed, seed + spots)
    sparkles = np.array([[sparkle(flake_image(population, light, seed=place))
                          for light in SPARKLE_LIGHTS] for place in places])  # fmt: skip
    grain = np.array([graininess(flake_image(population, "diffuse", seed=place))
                      for place in places])  # fmt: skip
    return assemble_readings(sparkles[..., 0], sparkles[..., 1], grain)


def fit_counting_noise(readings: list[NDArray]) -> dict[str, float]:
    """``glint_share``, ``glint_sd`` and ``grain_sd`` of the counting model from the spot
    readings ``[spots, 8]`` of several coatings, each the median over coatings and lights:
    Var(Sa) = glint_share·Sa; sd(Si)/Si = glint_sd/√N with N = Sa/glint_share glints;
    sd(G)/G = grain_sd."""
    stack = np.stack(readings)  # [coatings, spots, 8]
    mean, sd = stack.mean(1), stack.std(1, ddof=1)
    Sa, Si = mean[:, _SA], mean[:, _SI]
    seen = Sa > 0
    glint_share = float(np.median(sd[:, _SA][seen] ** 2 / Sa[seen]))
    glints = Sa[seen] / glint_share
    glint_sd = float(np.median(sd[:, _SI][seen] / Si[seen] * np.sqrt(glints)))
    G, sd_G = mean[:, _G[0]], sd[:, _G[0]]
    grain_sd = float(np.median(sd_G[G > 0] / G[G > 0]))
    return {"glint_share": glint_share, "glint_sd": glint_sd, "grain_sd": grain_sd}


def counting_sd(constants: dict[str, float], mean: NDArray) -> NDArray:
    """The counting model's sd ``[C, 8]`` of readings whose means are ``mean`` ``[C, 8]``
    (``constants`` as :func:`fit_counting_noise` gives them); NaN for SG, which follows from
    the counted Sa and Si with no closed form of its own."""
    Sa, Si = mean[:, _SA], mean[:, _SI]
    glints = np.maximum(Sa / constants["glint_share"], 1)
    out = np.full_like(mean, np.nan, dtype=float)
    out[:, _SA] = np.sqrt(constants["glint_share"] * Sa)
    out[:, _SI] = constants["glint_sd"] * Si / np.sqrt(glints)
    out[:, _G] = constants["grain_sd"] * mean[:, _G]
    return out


def fit_light_slope(readings: list[NDArray]) -> float:
    """Slope k of Si_θ ∝ 1 + k·log10(1/cos θ) (:func:`~flakelab.texture.readings.light_factor`)
    from the spot readings ``[spots, 8]`` of several coatings: least squares over coatings and
    lights of r_θ·(1 + k·l_0) = 1 + k·l_θ, with r_θ = Si_θ/Si at the first light and
    l = log10(1/cos θ) (linear in k)."""
    Si = np.stack(readings).mean(1)[:, _SI]
    seen = (Si > 0).all(1)
    ratio = Si[seen, 1:] / Si[seen, :1]
    level = light_factor(np.array(SPARKLE_LIGHTS), 1.0) - 1  # l_θ
    a = level[1:] - ratio * level[0]
    return float(np.sum(a * (ratio - 1)) / np.sum(a * a))
