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

from flakelab.texture.images import FlakePopulation, flake_image
from flakelab.texture.metrics import graininess, sparkle
from flakelab.texture.readings import SPARKLE_LIGHTS

__all__ = ["spot_readings", "fit_counting_noise"]


def spot_readings(population: FlakePopulation, spots: int, seed: int = 0) -> NDArray:
    """Readings ``[spots, 7]`` of one coating at ``spots`` places (each its own flakes):
    Sa, Si under 15°, 45°, 75°, then G."""
    rows = []
    for spot in range(spots):
        images = [flake_image(population, light, seed=seed + spot) for light in SPARKLE_LIGHTS]
        row = [value for image in images for value in sparkle(image)]
        rows.append(row + [graininess(flake_image(population, "diffuse", seed=seed + spot))])
    return np.array(rows)


def fit_counting_noise(readings: list[NDArray]) -> dict[str, float]:
    """``glint_share``, ``glint_sd`` and ``grain_sd`` of the counting model from the spot
    readings ``[spots, 7]`` of several coatings, each the median over coatings and lights:
    Var(Sa) = glint_share·Sa; sd(Si)/Si = glint_sd/√N with N = Sa/glint_share glints;
    sd(G)/G = grain_sd."""
    stack = np.stack(readings)  # [coatings, spots, 7]
    mean, sd = stack.mean(1), stack.std(1, ddof=1)
    Sa, Si = mean[:, 0:6:2], mean[:, 1:6:2]
    seen = Sa > 0
    glint_share = float(np.median(sd[:, 0:6:2][seen] ** 2 / Sa[seen]))
    glints = Sa[seen] / glint_share
    glint_sd = float(np.median(sd[:, 1:6:2][seen] / Si[seen] * np.sqrt(glints)))
    grain = mean[:, 6] > 0
    grain_sd = float(np.median(sd[grain, 6] / mean[grain, 6]))
    return {"glint_share": glint_share, "glint_sd": glint_sd, "grain_sd": grain_sd}
