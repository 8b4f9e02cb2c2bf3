"""Physical flake images: a coating patch as a texture camera sees it (DESIGN.md §4).

A camera looks along the normal at a patch lit by a small directional lamp at 15°, 45° or
75°, or by a diffuse dome. Flakes are placed at random (positions, depths uniform in the
film, tilts from the species' orientation spread):

* **directional light** — a flake glints when its normal lies near the bisector of the
  refracted lamp direction and the camera (tilt θ_L'/2 toward the lamp); its brightness
  follows a Gaussian acceptance of half-width ``acceptance_deg`` (lamp and aperture size),
  times its reflectance, the dye's attenuation on the way in and out, and the chance that no
  flake above shadows it (exp(−σ_f·z·(1 + 1/μ_L'))).
* **diffuse light** — every flake mirrors part of the bright surround: brightness is its
  reflectance times the same attenuation; the mm-scale clustering of flakes makes the
  light/dark pattern the eye calls graininess.

Images are linear grey levels (1 = a white diffuser under the same light), ``[rows, cols]``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import gaussian_filter

__all__ = ["FlakePopulation", "flake_image", "flake_populations", "LIGHTS"]

LIGHTS = (15.0, 45.0, 75.0, "diffuse")
"""Lighting of the instrument's texture camera."""


@dataclass(frozen=True)
class FlakePopulation:
    """Flake species in a film: ``radius_um[S]``, ``rate[S]`` (σ_f per µm of depth),
    ``spread_deg[S]``, ``reflectance[S]``; the film's ``thickness_um``, mean dye absorption
    ``absorption`` [1/µm], diffuse background grey level ``background`` and index ``n``."""

    radius_um: NDArray
    rate: NDArray
    spread_deg: NDArray
    reflectance: NDArray
    thickness_um: float = 15.0
    absorption: float = 0.0
    background: float = 0.02
    n: float = 1.5


def flake_populations(layer, radius_um) -> list[FlakePopulation]:
    """The flake population of each formulation of ``layer`` (a
    :class:`~flakelab.physics.layer.Layer`), species of radius ``radius_um[S]``: what the
    texture camera images, with the layer's film, mean dye absorption and index."""
    radius = np.asarray(radius_um, dtype=float)
    spreads, reflectance = np.degrees(layer.spreads), layer.flake_normal_reflectance
    return [
        FlakePopulation(
            radius,
            layer.flake_rate[i],
            spreads[i],
            reflectance,
            thickness_um=float(layer.film[i]),
            absorption=float(layer.absorption[i].mean()),
            n=layer.n,
        )
        for i in range(layer.size)
    ]


def _place(population: FlakePopulation, area_um2: float, rng: np.random.Generator):
    """Flakes of every species: radius, depth, tilt (θ, φ), reflectance, as flat arrays."""
    counts = rng.poisson(
        population.rate * population.thickness_um * area_um2 / (np.pi * population.radius_um**2)
    )
    species = np.repeat(np.arange(counts.size), counts)
    sd = np.radians(population.spread_deg)[species]
    tilt = sd * np.hypot(rng.normal(size=species.size), rng.normal(size=species.size))
    azimuth = rng.uniform(0, 2 * np.pi, species.size)
    depth = rng.uniform(0, population.thickness_um, species.size)
    return species, depth, tilt, azimuth


def flake_image(
    population: FlakePopulation,
    light: float | str,
    *,
    size_px: int = 256,
    pixel_um: float = 15.0,
    acceptance_deg: float = 1.5,
    blur_px: float = 0.7,
    seed: int = 0,
) -> NDArray[np.float64]:
    """Grey image ``[size_px, size_px]`` of the patch under ``light`` (degrees or 'diffuse')."""
    if light not in LIGHTS:
        raise ValueError(f"light: expected one of {LIGHTS}, got {light!r}")
    rng = np.random.default_rng(seed)
    side = size_px * pixel_um
    species, depth, tilt, azimuth = _place(population, side * side, rng)
    sigma = float(np.sum(population.rate))
    reflectance = population.reflectance[species]
    if light == "diffuse":
        mu = 1.0 / np.sqrt(2.0)  # a representative inside direction of the dome
        weight = reflectance * np.exp(-(population.absorption + sigma) * depth * (1 + 1 / mu))
    else:
        inside = np.arcsin(np.sin(np.radians(light)) / population.n)
        mu = np.cos(inside)
        # normal needed: tilt inside/2 toward the lamp (azimuth π, the lamp on the −x side)
        nx, ny, nz = np.sin(tilt) * np.cos(azimuth), np.sin(tilt) * np.sin(azimuth), np.cos(tilt)
        hx, hz = -np.sin(inside / 2), np.cos(inside / 2)
        off = np.arccos(np.clip(nx * hx + ny * 0.0 + nz * hz, -1, 1))
        # a normal within half the lamp's angular radius mirrors the lamp into the camera
        glint = np.exp(-0.5 * (off / np.radians(acceptance_deg / 2)) ** 2)
        # a mirror shows the lamp's radiance: π/(Ω_lamp·cos θ) times a white diffuser's
        lamp = np.pi * np.radians(acceptance_deg) ** 2
        peak = np.pi / (lamp * np.cos(np.radians(light)))
        attenuation = np.exp(-(population.absorption + sigma) * depth * (1 + 1 / mu))
        weight = peak * glint * reflectance * attenuation
    image = np.full((size_px, size_px), population.background)
    x = rng.uniform(0, size_px, species.size)
    y = rng.uniform(0, size_px, species.size)
    area_px = np.pi * (population.radius_um[species] / pixel_um) ** 2
    # each flake covers min(1, its area) of its pixel, larger flakes spill into neighbours
    share = np.minimum(area_px, 1.0)
    np.add.at(image, (y.astype(int), x.astype(int)), weight * share)
    spill = np.maximum(area_px - 1.0, 0.0) / 4.0
    for dy, dx in ((0, 1), (1, 0), (0, -1), (-1, 0)):
        yy, xx = (y.astype(int) + dy) % size_px, (x.astype(int) + dx) % size_px
        np.add.at(image, (yy, xx), weight * np.minimum(spill, 1.0))
    return gaussian_filter(image, blur_px, mode="wrap") if blur_px > 0 else image
