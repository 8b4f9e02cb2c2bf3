"""A multi-angle measurement: reflectance per geometry, texture readings and metadata."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from datetime import datetime

import numpy as np
from numpy.typing import NDArray

from flakelab.core.colorimetry import (
    D65_10,
    Conditions,
    Lab_to_LCh,
    reflectance_from_Lab,
    reflectance_to_Lab,
)
from flakelab.core.geometry import Geometry
from flakelab.core.spectra import WAVELENGTHS, resample
from flakelab.core.wording import counted
from flakelab.errors import FlakelabError, MissingGeometryError

__all__ = [
    "Measurement",
    "TEXTURE_READINGS",
    "TEXTURE_FAMILIES",
    "flop_index",
    "FLOP_GEOMETRIES",
    "REFLECTANCE_RANGE",
    "LAB_LIMIT",
    "TEXTURE_RANGE",
    "outside",
    "mean_reading",
    "stacked_readings",
    "recovered_note",
    "colour_stated_elsewhere",
    "daylight_estimate_note",
    "known_by_colour",
]

TEXTURE_READINGS: tuple[str, ...] = (
    "Sa15",
    "Si15",
    "Sa45",
    "Si45",
    "Sa75",
    "Si75",
    "SG",
    "G",
)
"""Texture readings: sparkle area Sa and intensity Si under directional light at 15°, 45°,
75°, sparkle grade SG and graininess G under diffuse light (DESIGN.md §2, §4)."""
TEXTURE_FAMILIES: dict[str, tuple[int, ...]] = {
    family: tuple(i for i, k in enumerate(TEXTURE_READINGS) if k.rstrip("0123456789") == family)
    for family in ("Sa", "Si", "SG", "G")
}
"""Columns of :data:`TEXTURE_READINGS` of each kind of reading (Sa: Sa15, Sa45, Sa75 …)."""

REFLECTANCE_RANGE = (-0.05, 100.0)
"""Accepted reflectance factors: small negatives from instrument noise on black; large values
near specular on bright aluminium. Outside this a file is wrong, not the paint."""

LAB_LIMIT = 2500.0
"""The largest |L*|, |a*| or |b*| a stored reading may hold: reflectance factors within
:data:`REFLECTANCE_RANGE` keep X/Xn, Y/Yn and Z/Zn within −0.05–100 under any illuminant, so
L* within −45–523, |a*| up to 2,446 and |b*| up to 979 (CIE 15:2018 §8.2.1, with its linear
segment below (6/29)³). Beyond it a file is wrong, not the paint."""

TEXTURE_RANGE = (0.0, 1000.0)
"""Accepted texture readings: areas, intensities and grades are never negative, and an
instrument's scales stay within tens (the generated world's reach 0–24). Outside this a file
is wrong, not the paint."""


def outside(values, bounds: tuple[float, float]) -> NDArray[np.bool_]:
    """Where ``values`` lie outside ``bounds`` (low, high; both accepted): what
    :data:`REFLECTANCE_RANGE` and :data:`TEXTURE_RANGE` refuse. NaN lies outside."""
    low, high = bounds
    values = np.asarray(values, dtype=float)
    return ~((values >= low) & (values <= high))


FLOP_GEOMETRIES = ("45as15", "45as45", "45as110")


def flop_index(L15: NDArray | float, L45: NDArray | float, L110: NDArray | float) -> NDArray:
    """X-Rite flop index 2.69·(L*15 − L*110)^1.11 / (L*45)^0.86 at 45° illumination.

    A negative L*15 − L*110 (an inverse flop, seen on some matte or pearl samples) keeps its
    sign: the power applies to the magnitude. NaN where L*45 ≤ 0 (a black read as zero, or
    below it by the instrument's noise), which the index divides by.

    Examples
    --------
    >>> round(float(flop_index(110.0, 50.0, 20.0)), 2)
    13.74
    """
    dL = np.asarray(L15, dtype=float) - np.asarray(L110, dtype=float)
    L45 = np.asarray(L45, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        index = 2.69 * np.sign(dL) * np.abs(dL) ** 1.11 / L45**0.86
    return np.where(L45 > 0, index, np.nan)


@dataclass(frozen=True, eq=False)
class Measurement:
    """Reflectance factors of one sample at several geometries.

    Attributes
    ----------
    sample : str
        Sample or standard name.
    geometries : tuple[Geometry, ...]
        Measurement geometries, in the file's order (unique).
    wavelengths : ndarray [nm]
        Regular wavelength grid of the spectra.
    reflectance : ndarray [geometry, wavelength], reflectance factor [0–1 for a white]
    texture : mapping name → value, names from :data:`TEXTURE_READINGS`
    instrument : str | None
    measured_at : datetime | None
    stored_lab : ndarray [geometry, 3] | None
        L*a*b* as the instrument or file stated it, under ``stored_lab_conditions``.
    metadata : mapping of further text fields kept through conversions.
    spectra_recovered : bool
        The file gave L*a*b* alone (``stored_lab``) and ``reflectance`` was recovered from it
        (:func:`~flakelab.core.colorimetry.reflectance_from_Lab`): its colour under
        ``stored_lab_conditions`` is the file's, its spectral shape one metamer of many, so
        no metamerism index is taken against it and no model learns from it.
    """

    sample: str
    geometries: tuple[Geometry, ...]
    wavelengths: NDArray[np.float64]
    reflectance: NDArray[np.float64]
    texture: Mapping[str, float] = field(default_factory=dict)
    instrument: str | None = None
    measured_at: datetime | None = None
    stored_lab: NDArray[np.float64] | None = None
    stored_lab_conditions: Conditions = D65_10
    metadata: Mapping[str, str] = field(default_factory=dict)
    spectra_recovered: bool = False

    def __post_init__(self) -> None:
        wl = np.asarray(self.wavelengths, dtype=float)
        R = np.asarray(self.reflectance, dtype=float)
        if R.shape != (len(self.geometries), wl.size):
            raise ValueError(
                f"expected reflectance of shape ({len(self.geometries)}, {wl.size}), got {R.shape}"
            )
        if not np.all(np.isfinite(R)):
            raise ValueError("expected finite reflectance values, got NaN or infinity")
        names = [g.name for g in self.geometries]
        if len(set(names)) != len(names):
            raise ValueError(f"expected unique geometries, got {names}")
        unknown = [k for k in self.texture if k not in TEXTURE_READINGS]
        if unknown:
            raise ValueError(
                f"expected texture readings among {', '.join(TEXTURE_READINGS)}, got {unknown}"
            )
        object.__setattr__(self, "wavelengths", wl)
        object.__setattr__(self, "reflectance", R)
        object.__setattr__(self, "texture", {k: float(v) for k, v in self.texture.items()})
        if self.stored_lab is not None:
            lab = np.asarray(self.stored_lab, dtype=float)
            if lab.shape != (len(self.geometries), 3):
                raise ValueError(
                    f"expected stored L*a*b* of shape ({len(self.geometries)}, 3), got {lab.shape}"
                )
            object.__setattr__(self, "stored_lab", lab)

    @property
    def geometry_names(self) -> tuple[str, ...]:
        return tuple(g.name for g in self.geometries)

    def index(self, geometry: str | Geometry) -> int:
        """Position of a geometry (name or object) in this measurement."""
        g = geometry if isinstance(geometry, Geometry) else Geometry.parse(geometry)
        try:
            return self.geometries.index(g)
        except ValueError:
            raise MissingGeometryError(f"{self.sample}: no geometry {g.name}") from None

    def lab(self, conditions: Conditions = D65_10) -> NDArray[np.float64]:
        """CIELAB ``[geometry, 3]`` computed from the spectra (ASTM E308)."""
        return reflectance_to_Lab(self.reflectance, self.wavelengths, conditions)

    def lch(self, conditions: Conditions = D65_10) -> NDArray[np.float64]:
        return Lab_to_LCh(self.lab(conditions))

    def flop_index(self, conditions: Conditions = D65_10) -> float | None:
        """Flop index from 45as15, 45as45, 45as110; None when one of them is missing, or
        where L*45 ≤ 0 leaves it undefined (a report's JSON has no NaN)."""
        if not set(FLOP_GEOMETRIES) <= set(self.geometry_names):
            return None
        L = self.lab(conditions)[:, 0]
        L15, L45, L110 = (L[self.index(name)] for name in FLOP_GEOMETRIES)
        index = float(flop_index(L15, L45, L110))
        return index if np.isfinite(index) else None

    def storage_spectra(self, geometries: tuple[Geometry, ...] | list[str]) -> NDArray[np.float64]:
        """Reflectance ``[G, 31]`` at ``geometries``, in their order, on the storage grid
        (400–700 nm in 10 nm, resampled by colour-science when the file used another)."""
        wanted = [g if isinstance(g, Geometry) else Geometry.parse(g) for g in geometries]
        missing = [g.name for g in wanted if g not in self.geometries]
        if missing:
            raise MissingGeometryError(f"{self.sample}: no geometries {', '.join(missing)}")
        rows = [self.geometries.index(g) for g in wanted]
        if np.array_equal(self.wavelengths, WAVELENGTHS):
            return self.reflectance[rows].copy()
        return resample(self.reflectance[rows], self.wavelengths)

    def select(self, geometries: tuple[Geometry, ...] | list[str]) -> Measurement:
        """The same measurement restricted to (and ordered as) ``geometries``."""
        rows = [self.index(g) for g in geometries]
        return replace(
            self,
            geometries=tuple(self.geometries[i] for i in rows),
            reflectance=self.reflectance[rows],
            stored_lab=None if self.stored_lab is None else self.stored_lab[rows],
        )


def recovered_note(measurement: Measurement) -> str | None:
    """What a report says of a measurement whose spectra were recovered from its L*a*b*
    (None for measured spectra)."""
    if not measurement.spectra_recovered:
        return None
    return (
        f"{measurement.sample}: its file gives its colour alone; its spectra were recovered "
        f"from it (one metamer of many), so its colour under {measurement.stored_lab_conditions} "
        "is the file's, under any other light an estimate"
    )


def colour_stated_elsewhere(measurement: Measurement) -> Conditions | None:
    """The conditions under which a measurement known by its colour alone states it, where
    they are not D65/10: its daylight colour, which matching, cases and tins judge, is then an
    estimate. None for measured spectra, or a colour stated in D65/10, which its recovered
    spectrum gives exactly."""
    stated = measurement.stored_lab_conditions
    return stated if measurement.spectra_recovered and stated != D65_10 else None


def daylight_estimate_note(measurement: Measurement, task: str = "the search") -> str | None:
    """What a report says where ``task`` judges in D65/10 a measurement known by its colour
    alone under other conditions (its daylight colour an estimate); None otherwise."""
    stated = colour_stated_elsewhere(measurement)
    if stated is None:
        return None
    return (
        f"{measurement.sample}: {task} judged its colour in {D65_10}, where its file gives "
        f"none: an estimate from its colour under {stated}"
    )


def known_by_colour(measurement: Measurement, conditions: Conditions = D65_10) -> Measurement:
    """``measurement`` as an instrument that exports L*a*b* alone gives it: its colour under
    ``conditions`` (``stored_lab``) and spectra recovered from that colour
    (:func:`~flakelab.core.colorimetry.reflectance_from_Lab`), one metamer of many, as
    flakelab reads such a file (a dark reading's spectrum dipping below 0 as far as a measured
    one may, :data:`REFLECTANCE_RANGE`)."""
    lab = measurement.lab(conditions)
    return replace(
        measurement,
        reflectance=reflectance_from_Lab(
            lab, measurement.wavelengths, conditions, floor=REFLECTANCE_RANGE[0]
        ),
        stored_lab=lab,
        stored_lab_conditions=conditions,
        spectra_recovered=True,
    )


def stacked_readings(
    readings: Sequence[Measurement],
) -> tuple[tuple[Geometry, ...], NDArray[np.float64], NDArray[np.float64]]:
    """Several samples read at geometries that may differ (calibration panels read by two
    instruments): every geometry any was read at, in instrument order (lamp, then aspecular
    angle), their reflectance ``[N, G, 31]`` on the storage grid and their texture readings
    ``[N, 8]`` in :data:`TEXTURE_READINGS` order, NaN where a sample was not read."""
    geometries = tuple(sorted({g for r in readings for g in r.geometries}))
    spectra = np.full((len(readings), len(geometries), WAVELENGTHS.size), np.nan)
    for row, reading in zip(spectra, readings, strict=True):
        row[[geometries.index(g) for g in reading.geometries]] = reading.storage_spectra(
            reading.geometries
        )
    texture = np.array([[r.texture.get(k, np.nan) for k in TEXTURE_READINGS] for r in readings])
    return geometries, spectra, texture.reshape(len(readings), len(TEXTURE_READINGS))


def mean_reading(readings: Sequence[Measurement]) -> Measurement:
    """The mean of several readings of one surface (a car read at a few spots beside the
    repair, as colorists do): spectra averaged per geometry on the storage grid, texture
    readings averaged where every reading has them. The readings must share their
    geometries (the first's order is kept) and their instrument; a
    :class:`~flakelab.errors.FlakelabError` names the reading that does not."""
    if not readings:
        raise FlakelabError("expected at least one reading to average, got none")
    first = readings[0]
    for reading in readings[1:]:
        if set(reading.geometries) != set(first.geometries):
            raise FlakelabError(
                f"reading {reading.sample!r}: geometries {', '.join(reading.geometry_names)} "
                f"differ from {first.sample!r}'s ({', '.join(first.geometry_names)}): "
                "only readings of one instrument average"
            )
        if reading.instrument != first.instrument:
            raise FlakelabError(
                f"reading {reading.sample!r}: instrument {reading.instrument!r} differs from "
                f"{first.sample!r}'s ({first.instrument!r})"
            )
    spectra = np.stack([r.storage_spectra(first.geometries) for r in readings])
    shared = [k for k in first.texture if all(k in r.texture for r in readings)]
    names = ", ".join(r.sample for r in readings)
    return Measurement(
        sample=f"mean of {counted(len(readings), 'reading')} ({names})",
        geometries=first.geometries,
        wavelengths=WAVELENGTHS,
        reflectance=spectra.mean(axis=0),
        texture={k: float(np.mean([r.texture[k] for r in readings])) for k in shared},
        instrument=first.instrument,
        measured_at=first.measured_at,
        metadata={"averaged": names},
        spectra_recovered=any(r.spectra_recovered for r in readings),
    )
