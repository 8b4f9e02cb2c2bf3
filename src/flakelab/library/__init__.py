"""Library layer: toners (aluminium flakes, pigments, pearls), binder, and their optics."""

from flakelab.library.optics import (
    aluminium_refractive_index,
    flake_reflectance,
    fresnel_reflectance,
    pearl_reflectance,
)
from flakelab.library.toners import (
    PAINT_FAMILIES,
    TONER_KINDS,
    AluminiumFlake,
    Binder,
    Library,
    LibraryError,
    Pearl,
    Pigment,
    check_toners,
    did_you_mean,
)

__all__ = [
    "aluminium_refractive_index", "flake_reflectance", "fresnel_reflectance", "pearl_reflectance",
    "PAINT_FAMILIES", "TONER_KINDS",
    "AluminiumFlake", "Binder", "Library", "LibraryError", "Pearl", "Pigment",
    "check_toners", "did_you_mean",
]  # fmt: skip
