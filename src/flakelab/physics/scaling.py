"""The hybrid paper's scaling experiment, redone with the Monte Carlo as the truth.

A coarse aluminium (t = 0.5 µm, 10° spread, 15 µm basecoat) with one transparent blue dye
at the six flake/dye ratios of the paper's Table 1. For each sample the Monte Carlo gives
the spectrum f at the six BYK-mac geometries; f0 is the dye-free base. The paper's
observations: g = f0/f − 1 has the shape of the dye's extinction spectrum (normalised
g̃ = g / max g matches the normalised extinction) and its span grows linearly with the dye
concentration. Three predictions are compared with the Monte Carlo: flakelab's fast model
(path table of an independent dye-free run), the shipped atlas, and the paper's
single-collision scaling. A second series repeats it at a narrower and a wider spread.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E
from flakelab.core.geometry import INSTRUMENT_GEOMETRIES
from flakelab.core.spectra import WAVELENGTHS
from flakelab.library.optics import flake_reflectance
from flakelab.physics.fast import predict, single_collision
from flakelab.physics.layer import REFLECTANCE_ANGLES, Layer
from flakelab.physics.montecarlo import simulate

__all__ = [
    "TABLE1_DYE",
    "TABLE1_FLAKES",
    "SERIES_RUNS",
    "ScalingSeries",
    "run_series",
    "scaling_report",
    "dye_extinction",
]

TABLE1_DYE = np.array([1.12, 2.91, 4.23, 5.23, 5.98, 6.58]) / 100
"""Dye pigment volume concentrations of the hybrid paper's Table 1 (dry film)."""
TABLE1_FLAKES = np.array([12.85, 12.62, 12.47, 12.36, 12.24, 12.14]) / 100
"""Flake volume concentrations of the same samples (diluted by the dye paste)."""
SERIES_RUNS = 2 + TABLE1_DYE.size
"""Monte Carlo runs of one series: the base twice (truth and fast-model table), each sample."""
FLAKE_THICKNESS = 0.5
"""Coarse aluminium flake thickness [µm]."""
LAYER_THICKNESS = 15.0
"""Basecoat thickness [µm]."""
PRIMER = 0.05
"""Grey primer reflectance (flat)."""


def dye_extinction() -> NDArray[np.float64]:
    """Extinction per unit volume fraction [1/µm] of the series' dye: a phthalocyanine-like
    blue (bands at 615 and 695 nm, the demo library's shape), scaled to a peak of 6/µm."""
    wl = WAVELENGTHS
    bands = 9.0 * np.exp(-(((wl - 615) / 45) ** 2)) + 8.0 * np.exp(-(((wl - 695) / 40) ** 2))
    bands += 3.0 * np.exp(-(((wl - 330) / 60) ** 2))
    return 6.0 * bands / bands.max()


def _layer(flake_fraction: NDArray, dye_fraction: NDArray, spread_deg: float) -> Layer:
    F = np.size(flake_fraction)
    R = flake_reflectance(REFLECTANCE_ANGLES, WAVELENGTHS)[None]
    return Layer(
        flake_rate=np.reshape(flake_fraction, (F, 1)) / FLAKE_THICKNESS,
        flake_sd=np.radians([spread_deg]),
        flake_reflectance=R,
        flake_transmits=np.array([False]),
        absorption=np.outer(dye_fraction, dye_extinction()),
        scattering=np.zeros((F, WAVELENGTHS.size)),
        asymmetry=np.zeros(F),
        thickness=LAYER_THICKNESS,
        primer=np.full(WAVELENGTHS.size, PRIMER),
    )


@dataclass(frozen=True)
class ScalingSeries:
    """One spread: spectra ``[sample, G, W]`` of each method, f0 ``[G, W]`` and timings.

    ``single`` is the paper's scaling: the Monte Carlo base f0 times the single-collision
    ratio f_sc(κ)/f_sc(0) (the base is measured, only the dye's effect is computed)."""

    spread_deg: float
    geometries: tuple[str, ...]
    monte_carlo: NDArray
    monte_carlo_stderr: NDArray
    base: NDArray
    fast: NDArray
    atlas: NDArray
    single: NDArray
    single_base: NDArray
    single_absolute: NDArray
    single_bounce_share: NDArray
    monte_carlo_seconds: float
    fast_seconds: float
    photons: int

    def g(self, spectra: NDArray, base: NDArray | None = None) -> NDArray:
        """g = f0/f − 1 ``[sample, G, W]``."""
        return (self.base if base is None else base)[None] / spectra - 1


def run_series(
    spread_deg: float = 10.0,
    photons: int = 200_000,
    seed: int = 51,
    progress: Callable[[int], None] | None = None,
) -> ScalingSeries:
    """Monte Carlo of the base (twice: truth and fast-model table) and of the six samples
    (:data:`SERIES_RUNS` runs); ``progress`` is called with the photons traced as they are."""
    geometries = INSTRUMENT_GEOMETRIES["byk-mac-i"]
    samples = _layer(TABLE1_FLAKES, TABLE1_DYE, spread_deg)
    base_layer = _layer(TABLE1_FLAKES[:1], np.zeros(1), spread_deg)
    base = simulate(base_layer, geometries, photons, seed=seed, progress=progress)
    table_run = simulate(base_layer, geometries, photons, seed=seed + 1000, progress=progress)
    runs = [
        simulate(samples[i], geometries, photons, seed=seed + 1 + i, progress=progress)
        for i in range(samples.size)
    ]
    start = time.perf_counter()
    # The dye paste dilutes the flakes a little: path lengths stretch as 1/σ_f
    fast = np.concatenate(
        [
            table_run.table.brdf(
                samples.absorption[i : i + 1] * (TABLE1_FLAKES[0] / TABLE1_FLAKES[i])
            )
            * 1.0
            for i in range(samples.size)
        ]
    )
    fast_seconds = time.perf_counter() - start
    return ScalingSeries(
        spread_deg=spread_deg,
        geometries=geometries,
        monte_carlo=np.stack([r.brdf for r in runs]),
        monte_carlo_stderr=np.stack([r.stderr for r in runs]),
        base=base.brdf,
        fast=fast,
        atlas=predict(samples, geometries),
        single=base.brdf[None]
        * single_collision(samples, geometries)
        / single_collision(base_layer, geometries),
        single_base=base.brdf,
        single_absolute=single_collision(samples, geometries),
        single_bounce_share=table_run.table.weight[:, 1].sum(-1)
        / table_run.table.weight.sum((1, 2)),
        monte_carlo_seconds=sum(r.seconds for r in runs),
        fast_seconds=fast_seconds,
        photons=photons,
    )


def _lab(brdf: NDArray) -> NDArray:
    """CIELAB (D65/10°) of the reflectance factor π·f."""
    return reflectance_to_Lab(np.pi * brdf)


def _de00(reference: NDArray, sample: NDArray) -> NDArray:
    return delta_E(_lab(reference), _lab(sample), method="CIE 2000")


def _shape_correlations(series: ScalingSeries) -> NDArray:
    """Correlation of each normalised g̃ ``[sample, G]`` with the normalised extinction."""
    g = series.g(series.monte_carlo)
    g_norm = g / g.max(axis=-1, keepdims=True)
    eps = dye_extinction() / dye_extinction().max()
    gc = g_norm - g_norm.mean(-1, keepdims=True)
    ec = eps - eps.mean()
    return (gc @ ec) / (np.linalg.norm(gc, axis=-1) * np.linalg.norm(ec))


def _span_linearity(series: ScalingSeries) -> NDArray:
    """R² of the straight-line fit of the span of g (max − min over λ) on the dye
    concentration, per geometry ``[G]``."""
    g = series.g(series.monte_carlo)
    span = g.max(-1) - g.min(-1)  # [sample, G]
    r2 = []
    for column in span.T:
        fit = np.polyval(np.polyfit(TABLE1_DYE, column, 1), TABLE1_DYE)
        r2.append(1 - np.sum((column - fit) ** 2) / np.sum((column - column.mean()) ** 2))
    return np.array(r2)


def _summary(de: NDArray, prefix: str) -> dict[str, float]:
    return {f"{prefix}de00_mean": float(de.mean()), f"{prefix}de00_max": float(de.max())}


def scaling_report(series: ScalingSeries, others: list[ScalingSeries] = ()) -> dict:
    """The JSON report of ``flakelab validate scaling`` (names as issue 3 asks)."""
    de_fast = _de00(series.monte_carlo, series.fast)
    de_atlas = _de00(series.monte_carlo, series.atlas)
    de_single = _de00(series.monte_carlo, series.single)
    # the Monte Carlo's own noise, in the same units: one standard error apart
    de_noise = _de00(series.monte_carlo, series.monte_carlo + series.monte_carlo_stderr)
    span_r2 = _span_linearity(series)
    report = {
        "experiment": "hybrid paper Table 1: coarse aluminium + blue dye, six ratios",
        "geometries": list(series.geometries),
        "dye_pvc": TABLE1_DYE.tolist(),
        "flake_pvc": TABLE1_FLAKES.tolist(),
        "spread_deg": series.spread_deg,
        "photons_per_spectrum": series.photons,
        "shape_correlation_min": float(_shape_correlations(series).min()),
        "span_linearity_r2": float(span_r2.min()),
        "span_linearity_r2_per_geometry": span_r2.round(5).tolist(),
        **_summary(de_fast, ""),
        "de00_per_geometry_max": de_fast.max(0).round(3).tolist(),
        **_summary(de_atlas, "atlas_"),
        **_summary(de_single, "single_collision_"),
        "single_collision_de00_per_geometry_max": de_single.max(0).round(3).tolist(),
        **_summary(_de00(series.monte_carlo, series.single_absolute), "single_collision_absolute_"),
        "single_bounce_share": series.single_bounce_share.round(3).tolist(),
        "monte_carlo_noise_de00_mean": float(de_noise.mean()),
        "monte_carlo_seconds": series.monte_carlo_seconds,
        "fast_model_seconds": series.fast_seconds,
        "speedup": series.monte_carlo_seconds / max(series.fast_seconds, 1e-9),
    }
    if others:
        report["orientation_series"] = [_spread_entry(series, other) for other in others]
    return report


def _spread_entry(reference: ScalingSeries, other: ScalingSeries) -> dict:
    """How each method's g changes from the reference spread to ``other``'s."""

    def change(a: NDArray, b: NDArray) -> float:
        return float(np.median(np.abs(a / b - 1)))

    mc = change(other.g(other.monte_carlo), reference.g(reference.monte_carlo))
    fast = change(other.g(other.fast), reference.g(reference.fast))
    single = change(
        other.g(other.single, other.single_base),
        reference.g(reference.single, reference.single_base),
    )
    return {
        "spread_deg": other.spread_deg,
        "g_relative_change_median": {"monte_carlo": mc, "fast": fast, "single_collision": single},
        **_summary(_de00(other.monte_carlo, other.fast), ""),
        **_summary(_de00(other.monte_carlo, other.single), "single_collision_"),
        "shape_correlation_min": float(_shape_correlations(other).min()),
        "span_linearity_r2": float(_span_linearity(other).min()),
    }
