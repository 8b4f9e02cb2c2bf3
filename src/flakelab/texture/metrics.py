"""Texture metrics of grey images: sparkle area Sa, sparkle intensity Si, sparkle grade SG,
graininess G — flakelab's own definitions (the instruments' are not published).

* A pixel *sparkles* when it is brighter than ``SPARKLE_LEVEL`` × a white diffuser under
  the same lamp (images are calibrated so that the white standard reads 1) — an absolute
  level, so more flakes cannot raise the bar as a median-relative one would.
* **Sa** = 100 × the share of sparkling pixels (per cent of the field of view).
* **Si** = 15 × the mean decadic log of sparkling pixels' brightness over that level.
* **SG** = √(Sa·Si) / 2 per lamp angle (the images of one reading averaged by the caller).
* **G** = 100 × the coefficient of variation of the diffuse-light image smoothed at
  ``GRAIN_SCALE_UM`` (the mm-scale light/dark pattern, not single flakes).

With these scales, readings of the demo flakes fall in the instruments' usual 0–30 range.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy.ndimage import gaussian_filter

__all__ = ["sparkle", "sparkle_grade", "graininess", "SPARKLE_LEVEL", "GRAIN_SCALE_UM"]

SPARKLE_LEVEL = 3.0
"""Brightness, in units of a white diffuser, above which a pixel sparkles."""
GRAIN_SCALE_UM = 60.0
"""Smoothing scale of graininess [µm]."""


def sparkle(image: ArrayLike) -> tuple[float, float]:
    """(Sa, Si) of a directional-light image."""
    image = np.asarray(image, dtype=float)
    bright = image > SPARKLE_LEVEL
    if not bright.any():
        return 0.0, 0.0
    return 100 * float(bright.mean()), 15 * float(np.mean(np.log10(image[bright] / SPARKLE_LEVEL)))


def sparkle_grade(area: float, intensity: float) -> float:
    return float(np.sqrt(max(area, 0.0) * max(intensity, 0.0)) / 2)


def graininess(image: ArrayLike, pixel_um: float = 15.0) -> float:
    """G of a diffuse-light image."""
    smooth = gaussian_filter(np.asarray(image, dtype=float), GRAIN_SCALE_UM / pixel_um, mode="wrap")
    mean = float(smooth.mean())
    if mean <= 0:
        raise ValueError("image: expected a positive mean grey level")
    return 100 * float(smooth.std() / mean)
