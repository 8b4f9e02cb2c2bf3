"""A measured paint's reflectance at geometries its instrument did not read (DESIGN.md §7).

A multi-angle instrument reads a few geometries under one lamp (45as-15 … 45as110). A panel
under another lamp, or a curved body, needs the others. Interpolating over the aspecular
angle alone says the colour 45° from specular is the same under every lamp; for an effect
paint it is not, since the flakes that glint are those tilted to mirror the lamp into the
eye, and how far they must tilt depends on both directions. Here each reading is placed at
that tilt (θ_flake, the flake-based parameter of :func:`~flakelab.core.geometry.flake_angles`)
and the readings are interpolated over it:

    R(l, v) = d + T(θ_l) T(θ_v) / (cos θ'_l cos θ'_v) · h(θ_flake(l, v))

- ``d``, the part of the reading that does not change with the angles (the pigments'
  scattering under the clearcoat), is taken as :data:`FLOOR_SHARE` of the smallest reading
  at each wavelength;
- the rest, the flakes' mirror reflection, passes the clearcoat twice (Fresnel
  transmittances T at the lamp's and the detector's angles from the normal) and is spread
  over the refracted solid angles (1 / cos of the refracted directions θ'), as a microfacet
  lobe inside the coating is;
- ``h`` is interpolated over θ_flake in logarithms (monotone cubic, PCHIP: no overshoot
  between readings), held at the nearest reading beyond the tilts read (nearer specular than
  45as-15 the clearcoat's own highlight rules, which the instrument does not read).

Measured against interpolation of the same readings over the aspecular angle (``python
benchmarks/angular.py``), ΔE00 median / p95: the six 15° readings of the 230 real MA-T12
samples of ../shared/data, predicted from their six 45° readings, 1.53 / 4.74 (aspecular:
5.14 / 17.5); those of 300 generated targets 0.44 / 1.35 (4.33 / 23.3); Günther et al.'s
three silver metallics (fits of measured BRDFs) at lamps of 15–65°, in plane and out of it,
p95 1.6–2.6 (27–31); the MERL database's 16 effect paints, p95 0.35–6.0 as Löw et al.'s
ABC model fits them (9.9–30), and its 12 whose SGD fits (Bagher et al.) reach beyond the
clearcoat's highlight, 1.6–7.1 (16–42).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import PchipInterpolator

from flakelab.core.geometry import (
    N_BINDER,
    directions_at,
    flake_angles_at,
    geometry_angles,
    lit_by,
    refract_into_coating,
)
from flakelab.core.measurement import Measurement
from flakelab.library.optics import fresnel_reflectance

__all__ = [
    "FLOOR_SHARE",
    "TiltInterpolation",
    "clearcoat_factor",
    "interpolate_over_tilt",
    "tilt_interpolation",
]

FLOOR_SHARE = 0.9
"""Share of the smallest reading taken as the part that does not change with the angles
(``python benchmarks/angular.py --floor 0.5,0.9,0.97``): the real MA-T12 samples' 15°
readings came out 1.51, 1.53 and 1.54 ΔE00 from the measured (median); the generated
targets' 0.48, 0.44 and 0.42; Günther's solid paints' p95 up to 1.41, 0.59 and 0.59, the
silver metallics' 2.59, 2.62 and 2.63. Half the smallest reading is too little for a solid
paint, whose readings barely change; beyond 0.9 little changes."""

_SMALLEST = 1e-4
"""Reflectance floor of a reading before logarithms: instrument noise reads a black a
little below zero."""


def clearcoat_factor(
    illumination: ArrayLike, aspecular: ArrayLike, azimuth: ArrayLike = 0.0, n: float = N_BINDER
) -> NDArray[np.float64]:
    """T(θ_l) T(θ_v) / (cos θ'_l cos θ'_v) of geometries given by their angles [degree]: the
    clearcoat's two Fresnel transmittances over the cosines of the refracted directions."""
    light, view = directions_at(illumination, aspecular, azimuth)
    cosines = refract_into_coating(light, n)[..., 2] * refract_into_coating(view, n)[..., 2]
    transmitted = (1 - fresnel_reflectance(light[..., 2], 1.0, n)) * (
        1 - fresnel_reflectance(view[..., 2], 1.0, n)
    )
    return transmitted / cosines


@dataclass(frozen=True)
class TiltInterpolation:
    """Readings under one lamp as a function of flake tilt (module docstring): ``tilt`` [K]
    the readings' θ_flake, increasing; ``log_flake`` [K, C] the logarithm of each reading's
    flake part over its clearcoat factor, per wavelength (or colour channel); ``floor`` [C]
    the part that does not change."""

    tilt: NDArray[np.float64]
    log_flake: NDArray[np.float64]
    floor: NDArray[np.float64]

    def reflectance(
        self, illumination: ArrayLike, aspecular: ArrayLike, azimuth: ArrayLike = 0.0
    ) -> NDArray[np.float64]:
        """Reflectance factors ``[..., C]`` at geometries given by their angles [degree],
        arrays that broadcast together."""
        tilt = flake_angles_at(illumination, aspecular, azimuth)[0]
        held = np.clip(tilt, self.tilt[0], self.tilt[-1])
        flake = np.exp(PchipInterpolator(self.tilt, self.log_flake, axis=0)(held))
        factor = clearcoat_factor(illumination, aspecular, azimuth)
        return self.floor + factor[..., None] * flake


def interpolate_over_tilt(
    geometries, reflectance: ArrayLike, floor_share: float = FLOOR_SHARE
) -> TiltInterpolation:
    """Readings ``reflectance`` [G, C] at in-plane ``geometries`` (or their names)
    interpolated over flake tilt; readings at one tilt are averaged. Needs two or more
    tilts."""
    if not 0.0 <= floor_share < 1.0:  # the smallest reading must keep a flake part to log
        raise ValueError(f"floor_share: expected a share from 0 to below 1, got {floor_share}")
    angles = geometry_angles(geometries)
    tilt = flake_angles_at(*angles)[0]
    knots, where = np.unique(np.round(tilt, 6), return_inverse=True)
    if knots.size < 2:
        raise ValueError(f"expected readings at two or more flake tilts, got {knots.size}")
    reflectance = np.maximum(np.asarray(reflectance, dtype=float), _SMALLEST)
    floor = floor_share * reflectance.min(axis=0)
    log_flake = np.log((reflectance - floor) / clearcoat_factor(*angles)[:, None])
    summed = np.zeros((knots.size, log_flake.shape[1]))
    np.add.at(summed, where, log_flake)
    return TiltInterpolation(knots, summed / np.bincount(where)[:, None], floor)


def tilt_interpolation(measurement: Measurement, lamp: float = 45.0) -> TiltInterpolation:
    """``measurement``'s in-plane readings under a lamp ``lamp``° from the normal, interpolated
    over flake tilt (:func:`interpolate_over_tilt`); a reading without two of them at
    different tilts is refused naming what it has."""
    rows = lit_by(measurement.geometries, lamp)
    lit = [measurement.geometries[i] for i in rows]
    if len({g.aspecular for g in lit}) < 2:
        raise ValueError(
            f"{measurement.sample}: interpolating over flake tilt needs two or more in-plane "
            f"readings under a lamp at {lamp:g}° ({lamp:g}as15, {lamp:g}as45 …), got "
            f"{', '.join(map(str, measurement.geometries))}"
        )
    return interpolate_over_tilt(lit, measurement.reflectance[rows])
