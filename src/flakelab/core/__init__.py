"""Core layer: spectral grid, colorimetry, colour differences, geometry, measurements,
tolerances. Everything above it speaks these types.

The names below are imported on first use (PEP 562), not with the package: a module that
needs the geometry alone (the command line's start, ``flakelab --help``) does not pay for
colour-science's import, about a second here."""

from importlib import import_module

_WHERE = {
    "D65_10": "flakelab.core.colorimetry",
    "Conditions": "flakelab.core.colorimetry",
    "reflectance_to_Lab": "flakelab.core.colorimetry",
    "reflectance_to_XYZ": "flakelab.core.colorimetry",
    "Comparison": "flakelab.core.comparison",
    "compare": "flakelab.core.comparison",
    "describe": "flakelab.core.comparison",
    "DELTA_E_METHODS": "flakelab.core.difference",
    "delta_E": "flakelab.core.difference",
    "delta_E_CIE2000": "flakelab.core.difference",
    "delta_LCH": "flakelab.core.difference",
    "INSTRUMENT_GEOMETRIES": "flakelab.core.geometry",
    "N_BINDER": "flakelab.core.geometry",
    "Geometry": "flakelab.core.geometry",
    "directions": "flakelab.core.geometry",
    "directions_at": "flakelab.core.geometry",
    "flake_angles": "flakelab.core.geometry",
    "flake_angles_at": "flakelab.core.geometry",
    "geometry_angles": "flakelab.core.geometry",
    "lit_by": "flakelab.core.geometry",
    "instrument_geometries": "flakelab.core.geometry",
    "refract_into_coating": "flakelab.core.geometry",
    "TEXTURE_READINGS": "flakelab.core.measurement",
    "Measurement": "flakelab.core.measurement",
    "flop_index": "flakelab.core.measurement",
    "SHAPE_RENDER": "flakelab.core.spectra",
    "SHAPE_STORE": "flakelab.core.spectra",
    "WAVELENGTHS": "flakelab.core.spectra",
    "resample": "flakelab.core.spectra",
    "TOLERANCE_PRESETS": "flakelab.core.tolerance",
    "Limit": "flakelab.core.tolerance",
    "Tolerance": "flakelab.core.tolerance",
    "tolerance_preset": "flakelab.core.tolerance",
}

__all__ = list(_WHERE)


def __getattr__(name: str):
    if name not in _WHERE:
        raise AttributeError(f"module 'flakelab.core' has no attribute {name!r}")
    value = getattr(import_module(_WHERE[name]), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_WHERE))
