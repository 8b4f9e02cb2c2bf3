"""Analytic BRDFs fitted to measured car paints: references for angular interpolation.

Günther, Chen, Goesele, Wald and Seidel (VMV 2005, Table 1) fitted a Lambertian term and three
Cook-Torrance lobes to eight measured car paints, in RGB. Evaluated at an instrument's
geometries they give the readings it would take; evaluated anywhere else, what those readings
must be interpolated to (:mod:`flakelab.render.angular`). The fits are third-party data
(../shared/data/reference-brdf, SOURCES.md there), read from the file, never shipped.

Each lobe: f = k_s D(θ_h) F(v·h) G / (4 cos θ_l cos θ_v), with Beckmann's distribution
D = exp(−tan²θ_h / m²) / (π m² cos⁴θ_h), Schlick's Fresnel F = r + (1 − r)(1 − v·h)⁵ and
Cook and Torrance's shadowing G = min(1, 2 cos θ_h cos θ_v / v·h, 2 cos θ_h cos θ_l / v·h).
The reflectance factor is π f (a white diffuser reads 1).
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flakelab.core.geometry import directions_at

__all__ = ["CookTorrancePaint", "read_gunther_fits"]

_CHANNELS = ("R", "G", "B")


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
        light, view = directions_at(illumination, aspecular, azimuth)
        half = light + view
        half /= np.linalg.norm(half, axis=-1, keepdims=True)
        cos_l, cos_v, cos_h = light[..., 2:], view[..., 2:], half[..., 2:]
        v_h = np.sum(view * half, axis=-1, keepdims=True)
        shadowing = np.minimum(1.0, np.minimum(2 * cos_h * cos_v, 2 * cos_h * cos_l) / v_h)
        m2 = self.roughness**2  # [L]
        tan2 = (1 - cos_h**2) / cos_h**2
        beckmann = np.exp(-tan2 / m2) / (np.pi * m2 * cos_h**4)  # [..., L]
        fresnel = self.f0 + (1 - self.f0) * (1 - v_h) ** 5  # [..., L]
        lobes = (beckmann * fresnel)[..., None] * self.specular  # [..., L, 3]
        glossy = lobes.sum(axis=-2) * shadowing / (4 * cos_l * cos_v)
        return np.pi * (self.diffuse / np.pi + glossy)


def read_gunther_fits(path: str | Path) -> list[CookTorrancePaint]:
    """The paints of ``gunther2005_carpaint_ct3.csv`` (name, kd_R…B, ks1_R…ks3_B, r1…r3,
    m1…m3); a missing column or a value that is no positive number is named with the row."""
    paints = []
    with open(path, newline="", encoding="utf-8") as handle:
        for row_number, row in enumerate(csv.DictReader(handle), start=2):
            try:
                paints.append(_paint(row))
            except ValueError as error:
                raise ValueError(f"{path}: row {row_number}: {error}") from None
    return paints


def _paint(row: dict[str, str]) -> CookTorrancePaint:
    def number(column: str, positive: bool = False) -> float:
        text = row.get(column)
        if text is None or not text.strip():
            raise ValueError(f"{column}: missing")
        try:
            value = float(text)
        except ValueError:
            value = np.nan
        if not np.isfinite(value) or value < 0 or (positive and value == 0):
            bound = "> 0" if positive else "≥ 0"
            raise ValueError(f"{column}: expected a number {bound}, got {row[column]!r}")
        return value

    lobes = range(1, 4)
    return CookTorrancePaint(
        row.get("name") or "",
        np.array([number(f"kd_{c}") for c in _CHANNELS]),
        np.array([[number(f"ks{k}_{c}") for c in _CHANNELS] for k in lobes]),
        np.array([number(f"r{k}") for k in lobes]),
        np.array([number(f"m{k}", positive=True) for k in lobes]),
    )
