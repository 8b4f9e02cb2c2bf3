"""Core layer: spectral grid, colorimetry, colour differences, geometry, measurements,
tolerances. Everything above it speaks these types."""

from flakelab.core.colorimetry import D65_10, Conditions, reflectance_to_Lab, reflectance_to_XYZ
from flakelab.core.comparison import Comparison, compare, describe
from flakelab.core.difference import DELTA_E_METHODS, delta_E, delta_E_CIE2000, delta_LCH
from flakelab.core.geometry import (
    INSTRUMENT_GEOMETRIES,
    N_BINDER,
    Geometry,
    directions,
    flake_angles,
    instrument_geometries,
    refract_into_coating,
)
from flakelab.core.measurement import TEXTURE_READINGS, Measurement, flop_index
from flakelab.core.spectra import SHAPE_RENDER, SHAPE_STORE, WAVELENGTHS, resample
from flakelab.core.tolerance import TOLERANCE_PRESETS, Limit, Tolerance, tolerance_preset

__all__ = [
    "D65_10",
    "Conditions",
    "reflectance_to_Lab",
    "reflectance_to_XYZ",
    "Comparison",
    "compare",
    "describe",
    "DELTA_E_METHODS",
    "delta_E",
    "delta_E_CIE2000",
    "delta_LCH",
    "INSTRUMENT_GEOMETRIES",
    "N_BINDER",
    "Geometry",
    "directions",
    "flake_angles",
    "instrument_geometries",
    "refract_into_coating",
    "TEXTURE_READINGS",
    "Measurement",
    "flop_index",
    "SHAPE_RENDER",
    "SHAPE_STORE",
    "WAVELENGTHS",
    "resample",
    "TOLERANCE_PRESETS",
    "Limit",
    "Tolerance",
    "tolerance_preset",
]
