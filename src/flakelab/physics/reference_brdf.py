"""Analytic BRDFs fitted to measured car paints: references for angular interpolation.

Evaluated at an instrument's geometries they give the readings it would take; evaluated
anywhere else, what those readings must be interpolated to (:mod:`flakelab.render.angular`).
The fits are third-party data (../shared/data/reference-brdf, SOURCES.md there), read from
the file, never shipped. All are in RGB; the reflectance factor is π f (a white diffuser
reads 1).

- Günther, Chen, Goesele, Wald and Seidel (VMV 2005, Table 1) fitted a Lambertian term and
  three Cook-Torrance lobes to eight measured car paints. Each lobe:
  f = k_s D(θ_h) F(v·h) G / (4 cos θ_l cos θ_v), with Beckmann's distribution
  D = exp(−tan²θ_h / m²) / (π m² cos⁴θ_h), Schlick's Fresnel F = r + (1 − r)(1 − v·h)⁵ and
  Cook and Torrance's V-groove shadowing
  G = min(1, 2 cos θ_h cos θ_v / v·h, 2 cos θ_h cos θ_l / v·h).
- The MERL database (Matusik et al. 2003) measured 100 BRDFs, 25 of them paints (metallic,
  pearl, colour-changing, two-layer and solid). Löw, Kronander, Ynnerman and Unger (ACM TOG
  31(1), 2012) fitted their ABC model to each: f = k_d / π + F(l·h) D(θ_h) G / (π cos θ_l
  cos θ_v), with D = A / (1 + B (1 − cos θ_h))^C (A per colour channel, B and C shared), the
  exact unpolarised Fresnel reflectance of a dielectric of index ``ior`` and the V-groove G.
- Bagher, Soler and Holzschuch (Computer Graphics Forum 31(4), 2012) fitted their shifted
  gamma distribution (SGD) model to the same 100, every parameter per channel, so a lobe's
  colour may change with the angles: f = (ρ_d + ρ_s F D G1(l) G1(v) / (cos θ_l cos θ_v)) / π,
  with D = κ exp(−x) / (π x^p cos⁴θ_h), x = α + tan²θ_h / α, F = f0 − f1 cos θ_d +
  (1 − cos θ_d)⁵ (1 − f0) and G1 = 1 + λ (1 − exp(c max(0, θ − θ0)^k)), held to [0, 1]
  (as ``jdupuy/dj_brdf`` evaluates them).
"""

from __future__ import annotations

import csv
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flakelab.core.geometry import directions_at
from flakelab.library.optics import fresnel_reflectance

__all__ = [
    "GUNTHER_METALLICS",
    "GUNTHER_SOLIDS",
    "REFERENCE_FITS",
    "AbcPaint",
    "comparison_geometries",
    "CookTorrancePaint",
    "is_merl_effect_paint",
    "is_merl_paint",
    "SgdPaint",
    "read_bagher_sgd_fits",
    "read_gunther_fits",
    "read_low_abc_fits",
]

_CHANNELS = ("R", "G", "B")

GUNTHER_METALLICS = ("polaris silber", "opel titan", "bmw339")
"""Günther et al.'s three silver metallics."""

GUNTHER_SOLIDS = ("2k acrylack", "white", "blue", "blue matte")
"""Günther et al.'s four solid paints; their eighth, the dark "ford f8", is neither here."""

_MERL_EFFECT_WORDS = ("metallic", "pearl", "color-changing", "two-layer")


def is_merl_paint(name: str) -> bool:
    """Whether a MERL material is a paint: 25 of the 100, the 23 whose names say so and the
    two two-layer car paints (gold and silver)."""
    return "paint" in name or name.startswith("two-layer")


def is_merl_effect_paint(name: str) -> bool:
    """Whether a MERL material's name calls it an effect paint (metallic, pearl,
    colour-changing, two-layer): 16 of its 25 paints. Its "gold-paint" and "silver-paint"
    say neither, though their fits' broad lobes are a metallic's."""
    return any(word in name for word in _MERL_EFFECT_WORDS)


def _half_vector_cosines(
    illumination: ArrayLike, aspecular: ArrayLike, azimuth: ArrayLike
) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """cos θ_l, cos θ_v, cos θ_h and v·h, each ``[..., 1]``, of geometries given by their
    angles [degree]."""
    light, view = directions_at(illumination, aspecular, azimuth)
    half = light + view
    half /= np.linalg.norm(half, axis=-1, keepdims=True)
    v_h = np.sum(view * half, axis=-1, keepdims=True)
    return light[..., 2:], view[..., 2:], half[..., 2:], v_h


def _v_groove_shadowing(cos_l: NDArray, cos_v: NDArray, cos_h: NDArray, v_h: NDArray) -> NDArray:
    """Cook and Torrance's G = min(1, 2 cos θ_h cos θ_v / v·h, 2 cos θ_h cos θ_l / v·h)."""
    return np.minimum(1.0, np.minimum(2 * cos_h * cos_v, 2 * cos_h * cos_l) / v_h)


@dataclass(frozen=True)
class CookTorrancePaint:
    """A Lambertian term ``diffuse`` [3] and lobes of albedo ``specular`` [L, 3], Schlick F0
    ``f0`` [L] and Beckmann roughness ``roughness`` [L], in RGB."""

    name: str
    diffuse: NDArray[np.float64]
    specular: NDArray[np.float64]
    f0: NDArray[np.float64]
    roughness: NDArray[np.float64]

    def reflectance_factor(
        self, illumination: ArrayLike, aspecular: ArrayLike, azimuth: ArrayLike = 0.0
    ) -> NDArray[np.float64]:
        """π f ``[..., 3]`` at geometries given by their angles [degree]."""
        cos_l, cos_v, cos_h, v_h = _half_vector_cosines(illumination, aspecular, azimuth)
        shadowing = _v_groove_shadowing(cos_l, cos_v, cos_h, v_h)
        m2 = self.roughness**2  # [L]
        tan2 = (1 - cos_h**2) / cos_h**2
        beckmann = np.exp(-tan2 / m2) / (np.pi * m2 * cos_h**4)  # [..., L]
        fresnel = self.f0 + (1 - self.f0) * (1 - v_h) ** 5  # [..., L]
        lobes = (beckmann * fresnel)[..., None] * self.specular  # [..., L, 3]
        glossy = lobes.sum(axis=-2) * shadowing / (4 * cos_l * cos_v)
        return np.pi * (self.diffuse / np.pi + glossy)


@dataclass(frozen=True)
class AbcPaint:
    """Löw et al.'s ABC model: a Lambertian term ``diffuse`` [3], the distribution's ``scale``
    A [3], ``sharpness`` B and ``falloff`` C, and the Fresnel index ``ior``, in RGB."""

    name: str
    diffuse: NDArray[np.float64]
    scale: NDArray[np.float64]
    sharpness: float
    falloff: float
    ior: float

    def reflectance_factor(
        self, illumination: ArrayLike, aspecular: ArrayLike, azimuth: ArrayLike = 0.0
    ) -> NDArray[np.float64]:
        """π f ``[..., 3]`` at geometries given by their angles [degree]."""
        cos_l, cos_v, cos_h, v_h = _half_vector_cosines(illumination, aspecular, azimuth)
        shadowing = _v_groove_shadowing(cos_l, cos_v, cos_h, v_h)
        distribution = self.scale / (1 + self.sharpness * (1 - cos_h)) ** self.falloff
        fresnel = fresnel_reflectance(v_h, 1.0, self.ior)  # v·h = l·h
        return self.diffuse + fresnel * distribution * shadowing / (cos_l * cos_v)


@dataclass(frozen=True)
class SgdPaint:
    """Bagher et al.'s shifted gamma distribution model, every parameter per colour channel
    [3]: Lambertian ``diffuse`` ρ_d and specular ``specular`` ρ_s albedos; the distribution's
    ``alpha``, ``p`` and ``kappa``; Fresnel ``f0`` and ``f1``; and the shadowing's ``lam``,
    ``c``, ``k`` and ``theta0`` [radian]."""

    name: str
    diffuse: NDArray[np.float64]
    specular: NDArray[np.float64]
    alpha: NDArray[np.float64]
    p: NDArray[np.float64]
    kappa: NDArray[np.float64]
    f0: NDArray[np.float64]
    f1: NDArray[np.float64]
    lam: NDArray[np.float64]
    c: NDArray[np.float64]
    k: NDArray[np.float64]
    theta0: NDArray[np.float64]

    def reflectance_factor(
        self, illumination: ArrayLike, aspecular: ArrayLike, azimuth: ArrayLike = 0.0
    ) -> NDArray[np.float64]:
        """π f ``[..., 3]`` at geometries given by their angles [degree]."""
        cos_l, cos_v, cos_h, v_h = _half_vector_cosines(illumination, aspecular, azimuth)
        shifted = self.alpha + (1 - cos_h**2) / cos_h**2 / self.alpha  # α + tan²θ_h / α
        distribution = self.kappa * np.exp(-shifted) / (np.pi * shifted**self.p * cos_h**4)
        cos_d = np.clip(v_h, 0.0, 1.0)
        fresnel = self.f0 - cos_d * self.f1 + (1 - cos_d) ** 5 * (1 - self.f0)
        shadowing = self._masking(cos_l) * self._masking(cos_v)
        return self.diffuse + self.specular * fresnel * distribution * shadowing / (cos_l * cos_v)

    def _masking(self, cosine: NDArray) -> NDArray:
        """G1 = 1 + λ (1 − exp(c max(0, θ − θ0)^k)), held to [0, 1]."""
        beyond = np.maximum(0.0, np.arccos(np.clip(cosine, -1.0, 1.0)) - self.theta0)
        with np.errstate(over="ignore"):  # some fits' c is 1e38: G1 held at 0 beyond θ0
            growth = np.exp(np.minimum(self.c * beyond**self.k, 700.0))
            return np.clip(1 + self.lam * (1 - growth), 0.0, 1.0)


def read_gunther_fits(path: str | Path) -> list[CookTorrancePaint]:
    """The paints of ``gunther2005_carpaint_ct3.csv`` (name, kd_R…B, ks1_R…ks3_B, r1…r3,
    m1…m3); a missing column or a value that is no positive number is named with the row."""
    return _read_fits(path, _gunther_paint)


def read_low_abc_fits(path: str | Path) -> list[AbcPaint]:
    """The materials of ``merl_abc_fits_low2012.csv`` (name, kD_R…B, A_R…B, B, C, ior); a
    missing column or a value out of its range is named with the row."""
    return _read_fits(path, _abc_paint)


def read_bagher_sgd_fits(path: str | Path) -> list[SgdPaint]:
    """The materials of ``merl_sgd_fits_bagher2012.csv`` (name, otherName, rhoD_R…B, rhoS,
    alpha, p, f0, f1, kap, lambda, c, k, theta0, error, each per channel); a missing column
    or a value out of its range is named with the row."""
    return _read_fits(path, _sgd_paint)


REFERENCE_FITS = {
    "gunther": ("gunther2005_carpaint_ct3.csv", read_gunther_fits),
    "merl_abc": ("merl_abc_fits_low2012.csv", read_low_abc_fits),
    "merl_sgd": ("merl_sgd_fits_bagher2012.csv", read_bagher_sgd_fits),
}
"""Each fit in ../shared/data/reference-brdf (SOURCES.md there): its file and its reader."""


def comparison_geometries() -> tuple[NDArray, NDArray, NDArray]:
    """(illumination, aspecular, azimuth) [degree] where a fit is compared with what its six
    readings under the 45° lamp are interpolated to (``benchmarks/angular.py``,
    ``tests/test_angular.py``): lamps of 15–65° but 45°, aspecular 15–110° in steps of 5°, in
    plane and 30°, 60° and 90° out of it, the detector within 80° of the normal."""
    lamps, aspecular, azimuth = np.meshgrid([15.0, 25.0, 35.0, 55.0, 65.0],
                                            np.arange(15.0, 111.0, 5.0),
                                            [0.0, 30.0, 60.0, 90.0], indexing="ij")  # fmt: skip
    above = np.abs(lamps - aspecular) <= 80.0
    return lamps[above], aspecular[above], azimuth[above]


def _read_fits(path: str | Path, paint: Callable[[dict[str, str]], Any]) -> list:
    paints = []
    with open(path, newline="", encoding="utf-8") as handle:
        for row_number, row in enumerate(csv.DictReader(handle), start=2):
            try:
                paints.append(paint(row))
            except ValueError as error:
                raise ValueError(f"{path}: row {row_number}: {error}") from None
    return paints


def _number(
    row: dict[str, str], column: str, above: float | None = None, signed: bool = False
) -> float:
    """``row[column]`` as a finite number ≥ 0 (of either sign where ``signed``), or above
    ``above`` where given."""
    text = row.get(column)
    if text is None or not text.strip():
        raise ValueError(f"{column}: missing")
    try:
        value = float(text)
    except ValueError:
        value = np.nan
    negative = value < 0 and not signed
    if not np.isfinite(value) or negative or (above is not None and value <= above):
        bound = f" > {above:g}" if above is not None else "" if signed else " ≥ 0"
        raise ValueError(f"{column}: expected a number{bound}, got {row[column]!r}")
    return value


def _channels(row: dict[str, str], name: str, above: float | None = None, signed: bool = False):
    return np.array([_number(row, f"{name}_{c}", above, signed) for c in _CHANNELS])


def _gunther_paint(row: dict[str, str]) -> CookTorrancePaint:
    lobes = range(1, 4)
    return CookTorrancePaint(
        row.get("name") or "",
        _channels(row, "kd"),
        np.array([[_number(row, f"ks{k}_{c}") for c in _CHANNELS] for k in lobes]),
        np.array([_number(row, f"r{k}") for k in lobes]),
        np.array([_number(row, f"m{k}", above=0) for k in lobes]),
    )


def _abc_paint(row: dict[str, str]) -> AbcPaint:
    return AbcPaint(
        row.get("name") or "",
        _channels(row, "kD"),
        _channels(row, "A"),
        _number(row, "B", above=0),
        _number(row, "C", above=0),
        _number(row, "ior", above=1),
    )


def _sgd_paint(row: dict[str, str]) -> SgdPaint:
    return SgdPaint(
        row.get("name") or "",
        _channels(row, "rhoD"),
        _channels(row, "rhoS"),
        _channels(row, "alpha", above=0),
        _channels(row, "p", signed=True),
        _channels(row, "kap"),
        _channels(row, "f0", signed=True),
        _channels(row, "f1", signed=True),
        _channels(row, "lambda", signed=True),
        _channels(row, "c"),
        _channels(row, "k"),
        _channels(row, "theta0", signed=True),
    )
