"""Reflectance → XYZ → CIELAB through colour-science (ASTM E308 weighting).

Default: CIE D65 illuminant, CIE 1964 10° observer (automotive practice, DESIGN.md §2).
The ASTM E308 weighting is linear in the reflectance, so its weights are taken once per
(grid, illuminant, observer) from colour-science and applied as a matrix product over any
number of samples × geometries.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import colour
import numpy as np
from numpy.typing import ArrayLike, NDArray

from flakelab.core.spectra import WAVELENGTHS, shape_of

__all__ = [
    "Conditions",
    "D65_10",
    "OBSERVERS",
    "illuminant_name",
    "tristimulus_weights",
    "white_point",
    "reflectance_to_XYZ",
    "reflectance_to_Lab",
    "XYZ_to_Lab",
    "LCh_to_Lab",
    "STATED_AS",
    "stated_to_Lab",
    "Lab_to_XYZ",
    "Lab_to_LCh",
    "reflectance_from_Lab",
    "UnreachableColour",
    "RECOVERED_EXACT",
    "reflectance_to_sRGB",
    "Lab_to_sRGB",
    "Lab_to_linear_sRGB",
    "linear_sRGB_to_Lab",
    "encode_sRGB",
]

OBSERVERS = {
    "2": "CIE 1931 2 Degree Standard Observer",
    "10": "CIE 1964 10 Degree Standard Observer",
}
"""Short observer names as instruments write them (``D65/10``) → colour-science names."""


@lru_cache(maxsize=256)
def is_illuminant(name: str) -> bool:
    """Whether ``name`` is a key of ``colour.SDS_ILLUMINANTS``, as its mapping matches keys
    (case and punctuation aside), remembered: the mapping takes a millisecond to tell, and
    every reading of a file names its conditions (a shop's history, thousands of them)."""
    return name in colour.SDS_ILLUMINANTS


@dataclass(frozen=True)
class Conditions:
    """Illuminant and observer of a colorimetric computation, e.g. ``D65/10``.

    ``illuminant`` is any key of ``colour.SDS_ILLUMINANTS`` (``D65``, ``A``, ``FL11``,
    ``LED-B3`` …); ``observer`` is ``"2"`` or ``"10"`` [degree].
    """

    illuminant: str = "D65"
    observer: str = "10"

    def __post_init__(self) -> None:
        if not is_illuminant(self.illuminant):
            raise ValueError(
                f"expected an illuminant known to colour-science (D65, A, FL11, LED-B3 …), "
                f"got {self.illuminant!r}"
            )
        if self.observer not in OBSERVERS:
            raise ValueError(f"expected observer '2' or '10', got {self.observer!r}")

    @classmethod
    def parse(cls, text: str) -> Conditions:
        """Parse ``"D65/10"``, ``"A/2"``, ``"F11/10"`` (``F11`` means colour-science's ``FL11``).

        Examples
        --------
        >>> Conditions.parse("F11/10")
        Conditions(illuminant='FL11', observer='10')
        """
        illuminant, sep, observer = text.strip().partition("/")
        observer = observer.strip().rstrip("°").removesuffix("deg").strip()
        if not sep or not illuminant:
            raise ValueError(f"expected ILLUMINANT/OBSERVER such as 'D65/10', got {text!r}")
        return cls(illuminant_name(illuminant), observer)

    def __str__(self) -> str:
        return f"{self.illuminant}/{self.observer}"


D65_10 = Conditions()


def illuminant_name(text: str) -> str:
    """colour-science's name of the illuminant ``text``: ``F11`` (as instruments and light
    booths write it) is ``FL11``.

    Examples
    --------
    >>> illuminant_name("F11"), illuminant_name("LED-B3"), illuminant_name("-1")
    ('FL11', 'LED-B3', '-1')
    """
    name = text.strip()
    # only an F: "-1" and "X1" are no fluorescent lamp (they read as FL1 before)
    fluorescent = f"FL{name[1:]}"
    if name[:1] == "F" and not is_illuminant(name) and is_illuminant(fluorescent):
        return fluorescent
    return name


@lru_cache(maxsize=32)
def _weights(start: float, end: float, interval: float, conditions: Conditions) -> NDArray:
    shape = colour.SpectralShape(start, end, interval)
    cmfs = colour.MSDS_CMFS[OBSERVERS[conditions.observer]]
    illuminant = colour.SDS_ILLUMINANTS[conditions.illuminant]
    basis = colour.MultiSpectralDistributions(np.eye(len(shape.wavelengths)), shape.wavelengths)
    # colour-science warns when it trims the illuminant to the observer's range: expected here.
    with colour.utilities.suppress_warnings(colour_runtime_warnings=True):
        weights = colour.msds_to_XYZ(basis, cmfs, illuminant, method="ASTM E308", shape=shape)
    weights = weights / 100
    weights.setflags(write=False)
    return weights


def tristimulus_weights(
    wavelengths: ArrayLike = WAVELENGTHS, conditions: Conditions = D65_10
) -> NDArray[np.float64]:
    """ASTM E308 weights ``W[wavelength, XYZ]`` so that ``XYZ = R @ W`` with Y(white) = 1.

    Taken from colour-science's ``msds_to_XYZ(method="ASTM E308")`` applied to the unit
    spectra of the grid, which is exact because the weighting is linear.
    """
    shape = shape_of(wavelengths)
    return _weights(shape.start, shape.end, shape.interval, conditions)


def white_point(
    wavelengths: ArrayLike = WAVELENGTHS, conditions: Conditions = D65_10
) -> NDArray[np.float64]:
    """XYZ of the perfect reflecting diffuser on the same grid and weighting [Y = 1]."""
    return tristimulus_weights(wavelengths, conditions).sum(axis=0)


def reflectance_to_XYZ(
    reflectance: ArrayLike,
    wavelengths: ArrayLike = WAVELENGTHS,
    conditions: Conditions = D65_10,
) -> NDArray[np.float64]:
    """Tristimulus values of reflectance factors ``R[..., wavelength]`` [0–1] → XYZ [Y 0–1].

    Examples
    --------
    >>> np.round(reflectance_to_XYZ(np.ones(31)), 4)
    array([ 0.9481,  1.    ,  1.073 ])
    """
    R = np.asarray(reflectance, dtype=float)
    return R @ tristimulus_weights(wavelengths, conditions)


def XYZ_to_Lab(XYZ: ArrayLike, white: ArrayLike) -> NDArray[np.float64]:
    """CIELAB [L* 0–100] of XYZ relative to the white's XYZ (same scale)."""
    return colour.XYZ_to_Lab(np.asarray(XYZ, dtype=float), colour.XYZ_to_xy(white))


def Lab_to_XYZ(Lab: ArrayLike, white: ArrayLike) -> NDArray[np.float64]:
    """XYZ [Y 0–1] of CIELAB relative to the white's XYZ."""
    return colour.Lab_to_XYZ(np.asarray(Lab, dtype=float), colour.XYZ_to_xy(white))


def reflectance_to_Lab(
    reflectance: ArrayLike,
    wavelengths: ArrayLike = WAVELENGTHS,
    conditions: Conditions = D65_10,
) -> NDArray[np.float64]:
    """CIELAB ``[..., 3]`` of reflectance factors ``R[..., wavelength]`` under ``conditions``.

    Examples
    --------
    >>> np.round(reflectance_to_Lab(np.full(31, 0.5)), 3) + 0.0  # + 0.0: no negative zero
    array([ 76.069,   0.   ,   0.   ])
    """
    XYZ = reflectance_to_XYZ(reflectance, wavelengths, conditions)
    return XYZ_to_Lab(XYZ, white_point(wavelengths, conditions))


RECOVERED_EXACT = 1e-3
"""ΔE00 within which a spectrum recovered from L*a*b* reproduces it."""

RECOVERY_LUMINANCE = (0.05, 0.8)
"""Luminance factors between which a colour is recovered; a darker or brighter one (a
reflectance factor over 1, as near-specular readings of effect paints give) is recovered at
the nearer bound and scaled back, since XYZ is linear in the reflectance: the basis was learnt
on surfaces between, and the clipping converges slowly near black."""


class UnreachableColour(ValueError):
    """A colour no non-negative spectrum gives; ``position`` is its index in the flattened
    input."""

    def __init__(self, message: str, position: int):
        super().__init__(message)
        self.position = position


def reflectance_from_Lab(
    Lab: ArrayLike,
    wavelengths: ArrayLike = WAVELENGTHS,
    conditions: Conditions = D65_10,
    iterations: int = 2000,
    floor: float = 0.0,
    basis=None,
) -> NDArray[np.float64]:
    """A smooth, non-negative reflectance factor ``R[..., wavelength]`` whose CIELAB under
    ``conditions`` is ``Lab[..., 3]``: one metamer of the many a colour known only as
    L*a*b* has.

    Otsu et al. (2018)'s basis of measured reflectances (colour-science's ``XYZ_to_sd``,
    method "Otsu 2018") gives its shape; the smallest change that the weights allow then
    makes its colour exact (Cohen's fundamental metamer: ``R + (XYZ - R W)(WᵀW)⁻¹ Wᵀ``),
    alternated with clipping at 0 so that it stays a reflectance.

    ``basis`` is an Otsu 2018 dataset (colour-science's ``Dataset_Otsu2018``) to take the
    shape from; None: colour-science's own, learnt on measured reflectances of many surfaces
    (``benchmarks/colour_alone.py --paint-basis`` weighs one learnt on paints).

    With a negative ``floor``, a colour no non-negative spectrum gives is reached by one more
    such change unclipped, where that dips no lower than ``floor``. Near black an
    instrument's noise reads so: a dark metallic's reading at 110° from specular of L* -0.3,
    or L* 0.04 with b* -1.1 (a hue a surface that dark cannot have), comes from a measured
    spectrum a few 1e-4 below 0.

    Raises
    ------
    UnreachableColour
        When a colour lies outside those a surface can reflect (its spectrum cannot be
        non-negative, nor dip no lower than ``floor``).

    Examples
    --------
    >>> R = reflectance_from_Lab([[50.0, 20.0, -30.0], [120.0, 5.0, -8.0]])
    >>> np.round(reflectance_to_Lab(R), 4) + 0.0
    array([[  50.,   20.,  -30.],
           [ 120.,    5.,   -8.]])
    """
    from colour.recovery import XYZ_to_sd_Otsu2018

    from flakelab.core.spectra import resample

    Lab = np.asarray(Lab, dtype=float)
    wl = np.asarray(wavelengths, dtype=float)
    W = tristimulus_weights(wl, conditions)
    XYZ = Lab_to_XYZ(Lab, white_point(wl, conditions)).reshape(-1, 3)
    Y = XYZ[:, 1:2]
    black = Y <= 0.0  # L* 0: no light at any wavelength, if a* and b* are 0 too
    scale = np.where(black, 1.0, Y / np.clip(Y, *RECOVERY_LUMINANCE))
    stated, XYZ = XYZ, np.where(black, 0.0, XYZ)
    cmfs = colour.MSDS_CMFS[OBSERVERS[conditions.observer]]
    illuminant = colour.SDS_ILLUMINANTS[conditions.illuminant]
    with colour.utilities.suppress_warnings(colour_runtime_warnings=True):
        chosen = {} if basis is None else {"dataset": basis}
        shapes = [XYZ_to_sd_Otsu2018(xyz, cmfs, illuminant, **chosen) for xyz in XYZ / scale]
    R = resample(np.stack([sd.values for sd in shapes]), shapes[0].wavelengths, shape_of(wl))
    R = np.where(black, 0.0, R)
    towards = np.linalg.solve(W.T @ W, W.T)  # [3, wavelength]: XYZ → the smallest change
    aimed = XYZ / scale
    missed = aimed - R @ W
    for _ in range(iterations):  # most converge in a few; the darkest and most vivid in 1,000
        R = np.maximum(R + missed @ towards, 0.0)
        missed = aimed - R @ W
        if np.abs(missed).max() < 1e-12:
            break
    R = R * scale
    white = white_point(wl, conditions)
    error = colour.delta_E(XYZ_to_Lab(R @ W, white), Lab.reshape(-1, 3))
    if floor < 0.0 and np.any(error > RECOVERED_EXACT):
        dipped = R + (stated - R @ W) @ towards
        take = (error > RECOVERED_EXACT) & (dipped.min(axis=1) >= floor)
        R = np.where(take[:, None], dipped, R)
        error = np.where(take, colour.delta_E(XYZ_to_Lab(R @ W, white), Lab.reshape(-1, 3)), error)
    if np.any(error > RECOVERED_EXACT):
        at = int(np.argmax(error > RECOVERED_EXACT))
        dipping = f", nor one dipping no lower than {floor:g}" if floor < 0.0 else ""
        raise UnreachableColour(
            f"L*a*b* {np.round(Lab.reshape(-1, 3)[at], 2).tolist()} is no colour a surface "
            f"reflects under {conditions}: no spectrum comes nearer than "
            f"{float(error[at]):.2g} ΔE00{dipping}",
            at,
        )
    return R.reshape(*Lab.shape[:-1], wl.size)


def Lab_to_LCh(Lab: ArrayLike) -> NDArray[np.float64]:
    """CIELCh: lightness, chroma C*ab and hue angle h [degree, 0–360]."""
    return colour.Lab_to_LCHab(np.asarray(Lab, dtype=float))


def LCh_to_Lab(LCh: ArrayLike) -> NDArray[np.float64]:
    """CIELAB of CIE L*C*h* [h in degrees]."""
    return colour.LCHab_to_Lab(np.asarray(LCh, dtype=float))


STATED_AS = ("Lab", "LCh", "XYZ")
"""The forms in which a file may state a reading's colour in place of its spectrum, in the order
one is taken where a reading states several: L*a*b*, L*C*h° and XYZ [Y 0–100]."""


def stated_to_Lab(
    form: str, values: ArrayLike, conditions: Conditions = D65_10
) -> NDArray[np.float64]:
    """CIELAB ``[..., 3]`` of colours stated in ``form`` (one of :data:`STATED_AS`) under
    ``conditions``: L*a*b* as given, L*C*h° [h in degrees], or XYZ [Y 0–100] relative to the
    conditions' white.

    Examples
    --------
    >>> np.round(stated_to_Lab("LCh", [50, 10, 90]), 6) + 0.0
    array([ 50.,   0.,  10.])
    """
    values = np.asarray(values, dtype=float)
    if form == "Lab":
        return values
    if form == "LCh":
        return LCh_to_Lab(values)
    if form == "XYZ":
        return XYZ_to_Lab(values / 100, white_point(conditions=conditions))
    raise ValueError(f"expected a colour stated as one of {', '.join(STATED_AS)}, got {form!r}")


def Lab_to_sRGB(Lab: ArrayLike, white: ArrayLike | None = None) -> NDArray[np.float64]:
    """Display sRGB [0–1, clipped] of CIELAB; chromatic adaptation CAT02 to D65/2°."""
    white = white_point() if white is None else white
    XYZ = Lab_to_XYZ(Lab, white)
    rgb = colour.XYZ_to_sRGB(XYZ, colour.XYZ_to_xy(white))
    return np.clip(rgb, 0.0, 1.0)


def reflectance_to_sRGB(
    reflectance: ArrayLike,
    wavelengths: ArrayLike = WAVELENGTHS,
    conditions: Conditions = D65_10,
) -> NDArray[np.float64]:
    """Display sRGB [0–1, clipped] of reflectance factors under ``conditions``."""
    XYZ = reflectance_to_XYZ(reflectance, wavelengths, conditions)
    white = white_point(wavelengths, conditions)
    return np.clip(colour.XYZ_to_sRGB(XYZ, colour.XYZ_to_xy(white)), 0.0, 1.0)


def Lab_to_linear_sRGB(Lab: ArrayLike, white: ArrayLike | None = None) -> NDArray[np.float64]:
    """Linear-light sRGB (not clipped, no transfer curve) of CIELAB; CAT02 to D65/2°.
    Images are composed in linear light so that averages of pixels are averages of light."""
    white = white_point() if white is None else white
    XYZ = Lab_to_XYZ(Lab, white)
    return colour.XYZ_to_sRGB(XYZ, colour.XYZ_to_xy(white), apply_cctf_encoding=False)


def linear_sRGB_to_Lab(rgb: ArrayLike, white: ArrayLike | None = None) -> NDArray[np.float64]:
    """Inverse of :func:`Lab_to_linear_sRGB`."""
    white = white_point() if white is None else white
    XYZ = colour.sRGB_to_XYZ(
        np.asarray(rgb, float), colour.XYZ_to_xy(white), apply_cctf_decoding=False
    )
    return XYZ_to_Lab(XYZ, white)


def encode_sRGB(rgb: ArrayLike) -> NDArray[np.float64]:
    """Display values [0–1] of linear-light sRGB (IEC 61966-2-1 transfer curve, clipped)."""
    return np.clip(colour.cctf_encoding(np.clip(np.asarray(rgb, float), 0.0, 1.0)), 0.0, 1.0)
