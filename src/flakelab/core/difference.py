"""Colour differences: one dispatcher over colour-science's formulae, plus CIELAB components
and the metamerism index.

``delta_E(Lab_1, Lab_2, method=...)`` with methods listed in :data:`DELTA_E_METHODS`; all
broadcast over samples × geometries. CIEDE2000 with parametric factors kL, kC, kH
(CIE 142-2001) is written out here because colour-science only offers kL ∈ {1, 2}; it is
tested against colour-science for those cases and against Sharma et al. (2005).

A recipe that matches the car in daylight need not match it under the body shop's tubes or
a filament lamp, when its pigments are not the car's. :func:`metamerism_index` is the
metamerism index for a change of illuminant of ISO 18314-4:2024 (colour-science's
``XYZ_to_metamerism_index``): the sample's tristimulus values under the test illuminant
corrected, component by component, by the ratio by which they differ from the standard's
under the reference illuminant, then ΔE00 from the standard under the test illuminant. A
pair that differs only in strength scores 0; a pair metameric under daylight scores what it
becomes under the other light.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import colour
import numpy as np
from numpy.typing import ArrayLike, NDArray

from flakelab.core.colorimetry import (
    D65_10,
    Conditions,
    Lab_to_XYZ,
    illuminant_name,
    reflectance_to_XYZ,
    white_point,
)
from flakelab.core.geometry import Geometry
from flakelab.core.spectra import WAVELENGTHS

__all__ = [
    "BLACK_TRISTIMULUS",
    "DELTA_E_METHODS",
    "METAMERISM_ILLUMINANTS",
    "METAMERISM_NOTICE",
    "colour_travel",
    "delta_E",
    "delta_E_CIE2000",
    "delta_LCH",
    "is_metamer",
    "metamerism_index",
    "metamerism_indices",
    "parse_lights",
    "worst_light",
    "worst_per_light",
]

METAMERISM_ILLUMINANTS = ("A", "FL11", "LED-B3")
"""Test illuminants of the metamerism index (DESIGN.md §2): a filament lamp (CIE A), the
tri-band fluorescent tube of paint shops and showrooms (F11) and a phosphor-converted white
LED (CIE LED-B3, 4,100 K)."""

METAMERISM_NOTICE = 1.0
"""A metamerism index (ΔE00) that a colorist notices under the test light: the harness's limit
per geometry. The car's own paint, sprayed again in the harness's shop world, stays at a
median of 0.16 at worst (``flakelab match evaluate``'s ``oracle_metamerism_median``)."""


def worst_light(indices: dict[str, NDArray]) -> tuple[str, float]:
    """The test light with the largest metamerism index anywhere in ``indices`` (per light,
    as :func:`metamerism_indices` gives them), and that index."""
    light = max(indices, key=lambda name: np.max(indices[name]))
    return light, float(np.max(indices[light]))


def is_metamer(indices: dict[str, NDArray]) -> bool:
    """Whether a recipe with these metamerism indices (per test light, as
    :func:`metamerism_indices` gives them) is a metamer of its target: an index over
    :data:`METAMERISM_NOTICE` under some test light, judged unrounded; none taken: not one."""
    return bool(indices) and worst_light(indices)[1] > METAMERISM_NOTICE


def worst_per_light(indices: dict[str, NDArray]) -> dict[str, float]:
    """The worst geometry's metamerism index under each test light, to the thousandth, as
    the reports give it."""
    return {light: round(float(np.max(index)), 3) for light, index in indices.items()}


def parse_lights(text: str, reference: Conditions = D65_10) -> tuple[str, ...]:
    """Test illuminants of the metamerism index from ``"A,F11,LED-B3"`` (a shop's booth:
    ``"A,F2,F12"``; any of colour-science's illuminants), against ``reference``.

    Examples
    --------
    >>> parse_lights("A, F2,LED-B3")
    ('A', 'FL2', 'LED-B3')
    """
    names = [illuminant_name(part) for part in text.split(",") if part.strip()]
    if not names:
        raise ValueError(
            f"--lights: expected test illuminants such as 'A,F11,LED-B3', got {text!r}"
        )
    for name in names:
        try:
            Conditions(name, reference.observer)
        except ValueError as error:
            raise ValueError(f"--lights: {error}") from None
        if name == reference.illuminant:
            raise ValueError(
                f"--lights: {name} is the reference illuminant ({reference}); against itself "
                "every index is 0"
            )
    return tuple(dict.fromkeys(names))


def delta_E_CIE2000(
    Lab_1: ArrayLike, Lab_2: ArrayLike, *, kL: float = 1.0, kC: float = 1.0, kH: float = 1.0
) -> NDArray[np.float64]:
    """CIEDE2000 with parametric factors (CIE 142-2001; Sharma, Wu & Dalal 2005, eqs. 1–22).

    Examples
    --------
    >>> round(float(delta_E_CIE2000([50, 2.6772, -79.7751], [50, 0, -82.7485])), 4)
    2.0425
    """
    L1, a1, b1 = np.moveaxis(np.asarray(Lab_1, dtype=float), -1, 0)
    L2, a2, b2 = np.moveaxis(np.asarray(Lab_2, dtype=float), -1, 0)
    C_mean = (np.hypot(a1, b1) + np.hypot(a2, b2)) / 2
    G = 0.5 * (1 - np.sqrt(C_mean**7 / (C_mean**7 + 25.0**7)))
    a1p, a2p = (1 + G) * a1, (1 + G) * a2
    C1p, C2p = np.hypot(a1p, b1), np.hypot(a2p, b2)
    h1p = np.degrees(np.arctan2(b1, a1p)) % 360
    h2p = np.degrees(np.arctan2(b2, a2p)) % 360

    dLp = L2 - L1
    dCp = C2p - C1p
    chroma_zero = C1p * C2p == 0
    dh = h2p - h1p
    dh = np.where(dh > 180, dh - 360, np.where(dh < -180, dh + 360, dh))
    dh = np.where(chroma_zero, 0.0, dh)
    dHp = 2 * np.sqrt(C1p * C2p) * np.sin(np.radians(dh) / 2)

    Lp_mean = (L1 + L2) / 2
    Cp_mean = (C1p + C2p) / 2
    h_sum = h1p + h2p
    h_wrapped = np.where(h_sum < 360, (h_sum + 360) / 2, (h_sum - 360) / 2)
    hp_mean = np.where(np.abs(h1p - h2p) <= 180, h_sum / 2, h_wrapped)
    hp_mean = np.where(chroma_zero, h_sum, hp_mean)
    T = (
        1
        - 0.17 * np.cos(np.radians(hp_mean - 30))
        + 0.24 * np.cos(np.radians(2 * hp_mean))
        + 0.32 * np.cos(np.radians(3 * hp_mean + 6))
        - 0.20 * np.cos(np.radians(4 * hp_mean - 63))
    )
    d_theta = 30 * np.exp(-(((hp_mean - 275) / 25) ** 2))
    R_C = 2 * np.sqrt(Cp_mean**7 / (Cp_mean**7 + 25.0**7))
    S_L = 1 + 0.015 * (Lp_mean - 50) ** 2 / np.sqrt(20 + (Lp_mean - 50) ** 2)
    S_C = 1 + 0.045 * Cp_mean
    S_H = 1 + 0.015 * Cp_mean * T
    R_T = -np.sin(np.radians(2 * d_theta)) * R_C
    tL, tC, tH = dLp / (kL * S_L), dCp / (kC * S_C), dHp / (kH * S_H)
    return np.sqrt(tL**2 + tC**2 + tH**2 + R_T * tC * tH)


def _cam16_ucs(Lab_1: ArrayLike, Lab_2: ArrayLike, **kwargs: Any) -> NDArray[np.float64]:
    """ΔE in CAM16-UCS (Li et al. 2017); Lab relative to the D65/10° white, colour-science's
    default viewing conditions (L_A = 64/π·5 cd/m², Y_b = 20, average surround)."""
    white = white_point()
    ucs = [
        colour.XYZ_to_CAM16UCS(Lab_to_XYZ(Lab, white), XYZ_w=white, **kwargs)
        for Lab in (Lab_1, Lab_2)
    ]
    return colour.difference.delta_E_CAM16UCS(ucs[0], ucs[1])


DELTA_E_METHODS: dict[str, Callable[..., NDArray[np.float64]]] = {
    "CIE 2000": delta_E_CIE2000,
    "CIE 1976": lambda Lab_1, Lab_2: colour.difference.delta_E_CIE1976(Lab_1, Lab_2),
    "CMC": lambda Lab_1, Lab_2, *, l=2.0, c=1.0: colour.difference.delta_E_CMC(  # noqa: E741
        Lab_1, Lab_2, l=l, c=c
    ),
    "DIN99": lambda Lab_1, Lab_2: colour.difference.delta_E_DIN99(Lab_1, Lab_2),
    "CAM16-UCS": _cam16_ucs,
}
"""ΔE methods by name: ΔE00 (kL, kC, kH), ΔE*ab, CMC (l, c), DIN99, CAM16-UCS."""

_ALIASES = {
    "de00": "CIE 2000",
    "cie2000": "CIE 2000",
    "dEab": "CIE 1976",
    "cie1976": "CIE 1976",
    "de76": "CIE 1976",
    "cmc": "CMC",
    "din99": "DIN99",
    "cam16-ucs": "CAM16-UCS",
    "cam16ucs": "CAM16-UCS",
}


def _method_key(method: str) -> str:
    if method in DELTA_E_METHODS:
        return method
    key = _ALIASES.get(method.strip().lower()) or _ALIASES.get(method.strip())
    if key is None:
        valid = ", ".join([*DELTA_E_METHODS, *_ALIASES])
        raise ValueError(f"expected a ΔE method among {valid}; got {method!r}")
    return key


def delta_E(
    Lab_1: ArrayLike, Lab_2: ArrayLike, method: str = "CIE 2000", **kwargs: float
) -> NDArray[np.float64]:
    """Colour difference between CIELAB arrays ``[..., 3]`` by the named method.

    Unknown methods and keyword arguments raise with the valid ones listed (unlike
    colour-science's dispatcher, misspelt options are never dropped silently).

    Examples
    --------
    >>> round(float(delta_E([50, 0, 0], [51, 0, 0], method="CIE 1976")), 3)
    1.0
    >>> delta_E([50, 0, 0], [51, 0, 0], method="CIE 2000", k_L=2)
    Traceback (most recent call last):
    ...
    TypeError: CIE 2000 takes options kL, kC, kH; got k_L
    """
    key = _method_key(method)
    function = DELTA_E_METHODS[key]
    allowed = {
        "CIE 2000": ("kL", "kC", "kH"),
        "CMC": ("l", "c"),
        "CAM16-UCS": ("L_A", "Y_b", "surround"),
    }.get(key, ())
    unknown = [k for k in kwargs if k not in allowed]
    if unknown:
        raise TypeError(
            f"{key} takes options {', '.join(allowed) or 'none'}; got {', '.join(unknown)}"
        )
    return np.asarray(function(Lab_1, Lab_2, **kwargs), dtype=float)


def delta_LCH(Lab_reference: ArrayLike, Lab_sample: ArrayLike) -> NDArray[np.float64]:
    """CIELAB components ``[..., (ΔL*, ΔC*ab, ΔH*ab)]`` of sample minus reference.

    ΔH*ab carries the sign of the hue-angle change (counter-clockwise positive), so that
    ΔL*² + ΔC*² + ΔH*² = ΔE*ab².
    """
    ref = np.asarray(Lab_reference, dtype=float)
    smp = np.asarray(Lab_sample, dtype=float)
    C_ref, C_smp = np.hypot(ref[..., 1], ref[..., 2]), np.hypot(smp[..., 1], smp[..., 2])
    d_angle = np.arctan2(smp[..., 2], smp[..., 1]) - np.arctan2(ref[..., 2], ref[..., 1])
    dH = 2 * np.sqrt(C_ref * C_smp) * np.sin(d_angle / 2)
    return np.stack([smp[..., 0] - ref[..., 0], C_smp - C_ref, dH], axis=-1)


def metamerism_index(
    reflectance_standard: ArrayLike,
    reflectance_sample: ArrayLike,
    test: str,
    reference: Conditions = D65_10,
    wavelengths: ArrayLike = WAVELENGTHS,
) -> NDArray[np.float64]:
    """Metamerism index M_t ``[...]`` of reflectance pairs ``[..., wavelength]`` (they
    broadcast) for a change from ``reference`` to the illuminant ``test`` (same observer):
    ISO 18314-4:2024, multiplicative correction in XYZ, ΔE00 (module notes).

    Examples
    --------
    >>> standard = np.linspace(0.1, 0.6, 31)
    >>> round(float(metamerism_index(standard, 0.8 * standard, "A")), 9)  # strength only
    0.0
    """
    indices = metamerism_indices(
        reflectance_standard, reflectance_sample, reference, (test,), wavelengths
    )
    return indices[test]


BLACK_TRISTIMULUS = 1e-9
"""The least tristimulus value (0–100 scale) that divides the multiplicative correction of
the metamerism index: a sample reading black has none (0/0)."""


def metamerism_indices(
    reflectance_standard: ArrayLike,
    reflectance_sample: ArrayLike,
    reference: Conditions = D65_10,
    tests: tuple[str, ...] | None = None,
    wavelengths: ArrayLike = WAVELENGTHS,
) -> dict[str, NDArray[np.float64]]:
    """:func:`metamerism_index` under each illuminant of ``tests`` (None:
    :data:`METAMERISM_ILLUMINANTS`; ``()``: none, for a pair one of which has no measured
    spectrum), by its name; the pair's XYZ under ``reference`` taken
    once for all of them. A sample that reads black under the reference (a tristimulus value
    of 0) has no multiplicative correction: its value is taken at :data:`BLACK_TRISTIMULUS`, so
    that its index is the pair's plain difference under the test light, not 0/0."""
    standard = np.asarray(reflectance_standard, dtype=float)
    sample = np.asarray(reflectance_sample, dtype=float)
    XYZ_standard_r = reflectance_to_XYZ(standard, wavelengths, reference)
    XYZ_sample_r = np.maximum(reflectance_to_XYZ(sample, wavelengths, reference), BLACK_TRISTIMULUS)
    indices = {}
    for test in METAMERISM_ILLUMINANTS if tests is None else tests:
        conditions = Conditions(test, reference.observer)
        white = colour.XYZ_to_xy(white_point(wavelengths, conditions))
        indices[test] = np.asarray(
            colour.difference.XYZ_to_metamerism_index(
                reflectance_to_XYZ(sample, wavelengths, conditions),
                reflectance_to_XYZ(standard, wavelengths, conditions),
                XYZ_sample_r,
                XYZ_standard_r,
                correction="Multiplicative",
                method="CIE 2000",
                illuminant=white,
            ),
            dtype=float,
        )
    return indices


def colour_travel(lab: ArrayLike) -> NDArray[np.float64]:
    """How far a paint's colour travels over its geometries: the largest ΔE00 between two of
    its CIELAB readings ``lab[..., G, 3]``. A solid's barely moves; a metallic's or pearl's
    flop moves it tens of units.

    Examples
    --------
    >>> round(float(colour_travel([[50, 0, 0], [52, 0, 0], [51, 1, 0]])), 2)
    1.99
    """
    lab = np.asarray(lab, dtype=float)
    return delta_E_CIE2000(lab[..., :, None, :], lab[..., None, :, :]).max(axis=(-2, -1))


def travel_off_specular(lab: ArrayLike, geometries, at_least: float) -> NDArray[np.float64]:
    """:func:`colour_travel` over the geometries (``Geometry`` objects or names) at least
    ``at_least``° from specular, of CIELAB readings ``lab[..., G, 3]`` at ``geometries``; over
    them all where fewer than two lie that far. Nearer specular a clearcoat's haze lifts any
    paint's lightness, a dark solid's by several units; flakes move the far readings too.

    Examples
    --------
    >>> lab = [[60, 0, 0], [50, 0, 0], [49, 0, 0], [48.5, 0, 0]]  # a haze at 45as15
    >>> names = ["45as15", "45as25", "45as75", "45as110"]
    >>> round(float(travel_off_specular(lab, names, 25.0)), 2)
    1.5
    """
    angles = np.array([abs(Geometry.parse(str(g)).aspecular) for g in geometries])
    far = np.flatnonzero(angles >= at_least)
    lab = np.asarray(lab, dtype=float)
    return colour_travel(lab[..., far, :] if far.size >= 2 else lab)
