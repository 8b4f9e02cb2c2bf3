"""A spray's application: film build and flake alignment, and how they move a paint's colour.

No two refinish spray-outs are alike: the basecoat's film build varies by a few per cent and
the flakes lie flatter or less flat (the spread of their orientation) with gun distance,
pressure and viscosity. Both change a metallic's lightness and flop; film build also changes
how well a low-hiding colour covers the primer. The generated world draws them
(:mod:`flakelab.cases.generator`); the correction uses their physics to tell one spray's
application from an offset that will persist (:mod:`flakelab.match.correction`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.geometry import Geometry
from flakelab.library.toners import Library
from flakelab.physics.fast import reflectance_factor
from flakelab.physics.layer import Layer, layer_from_fractions

__all__ = [
    "FILM_BUILD_SD",
    "SPREAD_SD",
    "APPLICATION_PARAMETERS",
    "sprayed_layer",
    "sprayed_reflectance",
    "sprayed_lab",
]

FILM_BUILD_SD = 0.04
"""Relative standard deviation of a refinish spray's film build (one sigma)."""

SPREAD_SD = 0.02
"""Standard deviation of the log of the flakes' orientation spread between sprays."""

APPLICATION_PARAMETERS = ("film build", "flake spread")
"""The application's parameters, as reported by the correction."""


def sprayed_layer(layer: Layer, library: Library, film: ArrayLike, spread: ArrayLike) -> Layer:
    """``layer`` sprayed at relative film build ``film[F]`` with its flakes' spread scaled by
    ``spread[F]``."""
    return replace(
        layer, thickness=library.binder.thickness_um * np.asarray(film), spread_scale=spread
    )


def sprayed_reflectance(
    library: Library,
    fractions: ArrayLike,
    geometries: tuple[Geometry, ...],
    film: ArrayLike,
    spread: ArrayLike,
) -> NDArray[np.float64]:
    """Reflectance factors ``[F, G, W]`` of ``fractions[F, T]`` sprayed at relative film build
    ``film[F]`` and flake-spread scale ``spread[F]`` (the library's batches, fast model)."""
    layer = layer_from_fractions(library, fractions)
    return reflectance_factor(sprayed_layer(layer, library, film, spread), geometries)


def sprayed_lab(
    library: Library,
    fractions: NDArray,
    geometries: tuple[Geometry, ...],
    film: ArrayLike,
    spread: ArrayLike,
) -> NDArray[np.float64]:
    """CIELAB ``[P, F, G, 3]`` of every recipe ``fractions[F, T]`` sprayed at each of P
    applications, relative film build ``film[P]`` and flake-spread scale ``spread[P]`` (one
    physics call)."""
    P, F = len(np.atleast_1d(film)), len(fractions)
    R = sprayed_reflectance(
        library,
        np.tile(fractions, (P, 1)),
        geometries,
        np.repeat(film, F),
        np.repeat(spread, F),
    )
    return reflectance_to_Lab(R).reshape(P, F, len(geometries), 3)
