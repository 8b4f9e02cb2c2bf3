"""Measurement geometries: ASTM E2194 / E2539 names, directions and flake-based parameters.

Conventions (DESIGN.md §2). The surface normal is +z; the illuminator lies in the x–z plane
on the −x side, at ``illumination`` degrees from the normal. ``45as15`` means detection 15°
from the specular direction toward the illuminator, so the detector sits at polar angle
``illumination − aspecular`` on the specular (+x) side; a negative polar angle puts it on
the light's side (45as110 → 65° from the normal beside the lamp). ``az±φ`` (out of plane,
``45as25az90``) rotates the illuminator by φ degrees about the normal, the detector staying
where the in-plane name puts it (CxF3 ``BRDFAngle``: "Azimuth is specified if an
out-of-plane illumination angle is used").

All direction vectors point away from the surface (toward lamp or detector).
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "Geometry",
    "INSTRUMENT_GEOMETRIES",
    "DEFAULT_INSTRUMENT",
    "FACE_GEOMETRY",
    "LAMP_OF_AN_ASPECULAR_ANGLE",
    "FLOP_AXES",
    "N_BINDER",
    "parse_geometry",
    "parse_geometries",
    "instrument_geometries",
    "instrument_name",
    "instrument_of",
    "instruments_reading",
    "directions",
    "directions_at",
    "refract_into_coating",
    "flake_angles",
    "flake_angles_at",
    "geometry_angles",
    "lit_by",
]

FLOP_AXES = {"aspecular": "aspecular angle [°]", "flake-tilt": "flake tilt θ_flake [°]"}
"""What a flop chart's L* and C* are drawn against: the aspecular angle, or the tilt a flake
needs to mirror the lamp into the detector (DESIGN.md §2), over which an effect paint's
readings under different lamps fall on one curve."""

N_BINDER = 1.5
"""Refractive index of binder and clearcoat [-], DESIGN.md §3."""

_NAME = re.compile(
    r"^\s*(?P<i>\d+(?:\.\d+)?)\s*as\s*(?P<a>[-+]?\d+(?:\.\d+)?)"
    r"(?:\s*az\s*(?P<z>[-+]?\d+(?:\.\d+)?))?\s*$",
    re.IGNORECASE,
)


_CIE_NAME = re.compile(r"^\s*(?P<i>\d+(?:\.\d+)?)\s*°?\s*[:/]\s*(?P<v>\d+(?:\.\d+)?)\s*°?\s*$")
"""CIE 15's name of a bidirectional geometry, illumination then detection from the normal:
``45°:0°``, as an instrument for solid colours exports it (also ``45:0``, ``45/0``)."""

_SPHERE_NAME = re.compile(r"^\s*(?:d[ie]?\s*[:/]\s*8|8\s*[:/]\s*d)\s*°?\s*$", re.IGNORECASE)
"""A sphere's diffuse geometry, CIE 15's ``d:8°`` (``di:8``, ``de:8``, ``8:d``)."""


def _number(value: float) -> str:
    return f"{value:g}"


@dataclass(frozen=True, order=True)
class Geometry:
    """One bidirectional measurement geometry [degree].

    Examples
    --------
    >>> g = Geometry.parse("45as-15")
    >>> g.illumination, g.aspecular, g.viewing
    (45.0, -15.0, 60.0)
    >>> str(Geometry(45, 25, 90))
    '45as25az90'
    """

    illumination: float
    aspecular: float
    azimuth: float = 0.0

    def __post_init__(self) -> None:
        if not 0.0 <= self.illumination < 90.0:
            raise ValueError(f"expected illumination angle in [0, 90)°, got {self.illumination}")
        if not -90.0 < self.viewing < 90.0:
            raise ValueError(
                f"expected a detector above the surface, got {self} (polar angle {self.viewing:g}°)"
            )

    @classmethod
    @functools.cache  # immutable, and parsed for every case read from a database
    def parse(cls, name: str) -> Geometry:
        """Parse an ASTM E2194/E2539 name such as ``45as15`` or ``45as25az90``; CIE 15's
        ``45°:0°``, the detector along the normal, is ``45as45`` (another detection angle
        leaves unsaid on which side of the normal the detector stands, and is refused
        naming both)."""
        match = _NAME.match(str(name))
        if match is None:
            return cls._parse_cie(str(name))
        azimuth = float(match["z"]) if match["z"] is not None else 0.0
        return cls(float(match["i"]), float(match["a"]), azimuth)

    @classmethod
    def _parse_cie(cls, name: str) -> Geometry:
        expected = f"expected a geometry name such as '45as15' or '45as25az90', got {name!r}"
        if _SPHERE_NAME.match(name):
            raise ValueError(
                f"{expected}: a sphere's diffuse reading has no angle to tell flop by; "
                "flakelab reads a multi-angle instrument's"
            )
        match = _CIE_NAME.match(name)
        if match is None:
            raise ValueError(expected)
        illumination, detection = float(match["i"]), float(match["v"])
        if detection != 0:
            sides = sorted({illumination - detection, illumination + detection})
            raise ValueError(
                f"{expected}: which side of the normal its detector stands on is unsaid; as "
                f"{_number(illumination)}as{_number(sides[0])} or "
                f"{_number(illumination)}as{_number(sides[1])}, name it so"
            )
        return cls(illumination, illumination)

    @property
    def name(self) -> str:
        base = f"{_number(self.illumination)}as{_number(self.aspecular)}"
        return base if self.azimuth == 0 else f"{base}az{_number(self.azimuth)}"

    @property
    def viewing(self) -> float:
        """Signed polar angle of the detector [degree]; negative on the illuminator's side."""
        return self.illumination - self.aspecular

    @property
    def in_plane(self) -> bool:
        return self.azimuth == 0

    def __str__(self) -> str:
        return self.name


def parse_geometry(name: str) -> Geometry:
    """Parse a geometry name (see :class:`Geometry`)."""
    return Geometry.parse(name)


def parse_geometries(names: ArrayLike) -> tuple[Geometry, ...]:
    return tuple(Geometry.parse(str(n)) for n in np.atleast_1d(names))


INSTRUMENT_GEOMETRIES: dict[str, tuple[str, ...]] = {
    "byk-mac-i": ("45as-15", "45as15", "45as25", "45as45", "45as75", "45as110"),
    "ma-t6": ("45as-15", "45as15", "45as25", "45as45", "45as75", "45as110"),
    "ma-t12": (
        "15as-45",
        "15as-30",
        "15as-15",
        "15as15",
        "15as45",
        "15as80",
        "45as-15",
        "45as15",
        "45as25",
        "45as45",
        "45as75",
        "45as110",
    ),
    "five-angle": ("45as15", "45as25", "45as45", "45as75", "45as110"),
}
"""Geometry sets of common multi-angle instruments, in their export order."""

FACE_GEOMETRY = "45as45"
"""45°:0°, the lamp at 45° and the detector along the normal, which every instrument of
:data:`INSTRUMENT_GEOMETRIES` reads: where a solid's colour is read by Kubelka–Munk, a
contrast ratio is read, and a matte ground (a primer, a contrast chart) is taken as read."""

LAMP_OF_AN_ASPECULAR_ANGLE = 45.0
"""The illumination angle [°] an aspecular angle given alone (``15°``, a spreadsheet's ``L*
15°``) is taken at: every instrument of :data:`INSTRUMENT_GEOMETRIES` lights at 45°, and the
MA-T12's second lamp (15°) is named in full in its exports."""

DEFAULT_INSTRUMENT = "five-angle"
"""The geometry set (and so the shipped model) used where no option names one: five-angle
readings are part of every common multi-angle instrument's set (benchmarks/instrument_choice.py:
an MA-T12 target is matched no worse with it than with the MA-T12 model)."""


def instrument_name(instrument: str) -> str:
    """The key of :data:`INSTRUMENT_GEOMETRIES` a user's spelling names (``MA-T12``, ``ma_t12``
    → ``ma-t12``), as cases and models record it."""
    key = instrument.strip().lower().replace(" ", "-").replace("_", "-")
    if key not in INSTRUMENT_GEOMETRIES:
        raise ValueError(f"expected one of {', '.join(INSTRUMENT_GEOMETRIES)}, got {instrument!r}")
    return key


def instrument_geometries(instrument: str) -> tuple[Geometry, ...]:
    """Geometries of a named instrument (``byk-mac-i``, ``ma-t6``, ``ma-t12``, ``five-angle``)."""
    return parse_geometries(INSTRUMENT_GEOMETRIES[instrument_name(instrument)])


def _key(text: str) -> str:
    return re.sub(r"[^a-z0-9]", "", text.lower())


def _name_set(names: ArrayLike) -> set[str]:
    return {Geometry.parse(str(n)).name for n in np.atleast_1d(names)}


def instrument_of(names: ArrayLike, hint: str | None = None) -> str | None:
    """The instrument whose geometry set is exactly ``names`` (in any order); where two share
    a set (``byk-mac-i``, ``ma-t6``), the one ``hint`` names (a file's instrument, e.g. "BYK-mac
    i"), else the first; None when no instrument reads just these."""
    wanted = _name_set(names)
    same = [k for k, v in INSTRUMENT_GEOMETRIES.items() if set(v) == wanted]
    hinted = [k for k in same if hint and _key(k) in _key(hint)]
    return (hinted or same or [None])[0]


def instruments_reading(names: ArrayLike) -> tuple[str, ...]:
    """The instruments whose every geometry is among ``names``: the models that can learn from
    (and be judged on) a case read at ``names``."""
    have = _name_set(names)
    return tuple(k for k, v in INSTRUMENT_GEOMETRIES.items() if set(v) <= have)


def geometry_angles(geometries: ArrayLike | Geometry) -> tuple[NDArray, NDArray, NDArray]:
    """Illumination, aspecular and azimuth angles [degree] of geometries or their names, as
    :func:`directions_at` and :func:`flake_angles_at` take them.

    Examples
    --------
    >>> [a.tolist() for a in geometry_angles(["45as15", "15as-45", "45as25az90"])]
    [[45.0, 15.0, 45.0], [15.0, -45.0, 25.0], [0.0, 0.0, 90.0]]
    """
    items = [geometries] if isinstance(geometries, Geometry | str) else list(geometries)
    geoms = [g if isinstance(g, Geometry) else Geometry.parse(g) for g in items]
    table = np.array([(g.illumination, g.aspecular, g.azimuth) for g in geoms], float)
    table = table.reshape(-1, 3)
    return table[:, 0], table[:, 1], table[:, 2]


def lit_by(geometries, lamp: float) -> list[int]:
    """Indices of the in-plane geometries of ``geometries`` a lamp ``lamp``° from the normal
    lit (45as-15, 45as15 … for 45; the out-of-plane ones are lit from aside)."""
    return [i for i, g in enumerate(geometries) if g.illumination == lamp and g.in_plane]


def directions(geometries: ArrayLike | Geometry) -> tuple[NDArray, NDArray]:
    """Unit vectors to the illuminator and to the detector, each ``[n, 3]``, in air.

    Examples
    --------
    >>> light, view = directions(["45as45"])
    >>> np.round(view, 6).tolist()
    [[0.0, 0.0, 1.0]]
    """
    return directions_at(*geometry_angles(geometries))


def directions_at(
    illumination: ArrayLike, aspecular: ArrayLike, azimuth: ArrayLike = 0.0
) -> tuple[NDArray, NDArray]:
    """:func:`directions` of geometries given by their angles [degree] (arrays that broadcast
    together, ``[...]`` → ``[..., 3]``): a curved panel's columns, each its own geometry.

    Examples
    --------
    >>> light, view = directions_at([45.0, 15.0], [45.0, 15.0])
    >>> np.round(view, 6).tolist()
    [[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]]
    """
    theta_i, aspecular, azimuth = np.broadcast_arrays(
        *(np.radians(np.asarray(a, dtype=float)) for a in (illumination, aspecular, azimuth))
    )
    light = np.stack(
        [
            -np.sin(theta_i) * np.cos(azimuth),
            -np.sin(theta_i) * np.sin(azimuth),
            np.cos(theta_i),
        ],
        axis=-1,
    )
    theta_v = theta_i - aspecular
    view = np.stack([np.sin(theta_v), np.zeros_like(theta_v), np.cos(theta_v)], axis=-1)
    return light, view


def refract_into_coating(direction: ArrayLike, n: float = N_BINDER) -> NDArray[np.float64]:
    """Directions ``[..., 3]`` in air → the refracted directions inside a medium of index n.

    Snell's law keeps the azimuth and shrinks the tangential part by 1/n; the result still
    points away from the surface (the direction light travels, reversed).

    Examples
    --------
    >>> d = refract_into_coating([np.sin(np.radians(45)), 0, np.cos(np.radians(45))])
    >>> round(float(np.degrees(np.arccos(d[2]))), 1)
    28.1
    """
    if n < 1:
        raise ValueError(f"expected a refractive index ≥ 1, got {n}")
    d = np.asarray(direction, dtype=float)
    tangential = d[..., :2] / n
    normal = np.sqrt(1.0 - np.sum(tangential**2, axis=-1, keepdims=True))
    return np.concatenate([tangential, normal], axis=-1)


def flake_angles(
    geometries: ArrayLike | Geometry, n: float = N_BINDER
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Flake-based parameters (θ_flake, θ_inc) [degree] of each geometry (DESIGN.md §2).

    θ_flake is the tilt from the surface normal that a flake needs to mirror the refracted
    illumination into the refracted viewing direction; θ_inc is the angle of incidence on
    that flake.

    Examples
    --------
    >>> theta_flake, theta_inc = flake_angles(["45as15"])
    >>> round(float(theta_flake[0]), 1), round(float(theta_inc[0]), 1)
    (4.3, 23.8)
    """
    return flake_angles_at(*geometry_angles(geometries), n=n)


def flake_angles_at(
    illumination: ArrayLike, aspecular: ArrayLike, azimuth: ArrayLike = 0.0, n: float = N_BINDER
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """:func:`flake_angles` of geometries given by their angles [degree], arrays that
    broadcast together.

    Examples
    --------
    >>> theta_flake, _ = flake_angles_at(45.0, [15.0, 45.0, 75.0])
    >>> np.round(theta_flake, 1).tolist()
    [4.3, 14.1, 23.8]
    """
    light, view = directions_at(illumination, aspecular, azimuth)
    light_in, view_in = refract_into_coating(light, n), refract_into_coating(view, n)
    bisector = light_in + view_in
    bisector /= np.linalg.norm(bisector, axis=-1, keepdims=True)
    theta_flake = np.degrees(np.arccos(np.clip(bisector[..., 2], -1.0, 1.0)))
    cos_inc = np.clip(np.sum(light_in * bisector, axis=-1), -1.0, 1.0)
    return theta_flake, np.degrees(np.arccos(cos_inc))
