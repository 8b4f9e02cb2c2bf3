"""Readings at geometries the instrument did not read: flake-tilt interpolation against the
aspecular interpolation of the same readings (the baseline, measured in the same run).

Five sets, each predicted from its six readings under the 45° lamp (45as-15 … 45as110):
- the 230 real MA-T12 samples of ../shared/data/ma-t12 (matte pigments on marble), their six
  readings under the 15° lamp (ΔE00, D65/10);
- generated targets at the MA-T12's geometries (metallic, pearl and solid paints of the demo
  library, as `flakelab cases generate -i ma-t12` makes them), their 15° readings;
- Günther et al.'s eight car paints (../shared/data/reference-brdf, Cook-Torrance fits of
  measured BRDFs, RGB taken as linear sRGB), at lamps of 15–65° other than 45°, in plane and
  30°/60°/90° out of plane, detectors within 80° of the normal, aspecular angles 15–110°;
- the 25 paints of the MERL database (metallic, pearl, colour-changing, two-layer and solid),
  as Löw et al.'s ABC model fits them and as Bagher et al.'s SGD model does, at the same
  geometries (and how far those two fits of one measurement lie apart there).

    python benchmarks/angular.py [--targets 300] [--seed 11] [--floor 0.5,0.9] [--json]
"""

from __future__ import annotations

import argparse
import functools
import json
from pathlib import Path

import numpy as np

from flakelab.cases.generator import World
from flakelab.core.colorimetry import linear_sRGB_to_Lab, reflectance_to_Lab
from flakelab.core.difference import delta_E_CIE2000
from flakelab.core.geometry import geometry_angles, instrument_geometries
from flakelab.io import read_library, read_measurements
from flakelab.physics.reference_brdf import (
    REFERENCE_FITS,
    comparison_geometries,
    is_merl_effect_paint,
    is_merl_paint,
)
from flakelab.render.angular import FLOOR_SHARE, interpolate_over_tilt
from flakelab.render.appearance import same_aspecular_reading

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
SOURCE = tuple(g for g in instrument_geometries("ma-t12") if g.illumination == 45)
PREDICTED = tuple(g for g in instrument_geometries("ma-t12") if g.illumination == 15)


def by_aspecular(readings: np.ndarray, illumination, aspecular, azimuth=0.0) -> np.ndarray:
    """The baseline: the reading at the same aspecular angle under the 45° lamp."""
    at = np.broadcast_to(aspecular, np.broadcast(illumination, aspecular, azimuth).shape)
    return same_aspecular_reading(SOURCE, readings, at)


def by_tilt(readings: np.ndarray, floor: float):
    return interpolate_over_tilt(SOURCE, readings, floor).reflectance


def statistics(errors: np.ndarray) -> dict[str, float]:
    return {"median": round(float(np.median(errors)), 3),
            "p95": round(float(np.percentile(errors, 95)), 3)}  # fmt: skip


def spectral_set(readings: list[tuple[np.ndarray, np.ndarray]], floor: float) -> dict:
    """ΔE00 of each predicted 15° reading from the measured: ``readings`` (source [6, W],
    measured [6, W]) per sample."""
    angles = geometry_angles(PREDICTED)
    tilt, aspec = [], []
    for source, measured in readings:
        truth = reflectance_to_Lab(measured)
        tilt.append(delta_E_CIE2000(reflectance_to_Lab(by_tilt(source, floor)(*angles)), truth))
        aspec.append(delta_E_CIE2000(reflectance_to_Lab(by_aspecular(source, *angles)), truth))
    tilt, aspec = np.concatenate(tilt), np.concatenate(aspec)
    return {"samples": len(readings), "tilt": statistics(tilt), "aspecular": statistics(aspec),
            "median_ratio": round(float(np.median(aspec) / np.median(tilt)), 2)}  # fmt: skip


def real_ma_t12(floor: float) -> dict | None:
    path = SHARED / "ma-t12" / "all_samples_spectra.csv"
    if not path.is_file():
        return None
    pairs = [(m.select(SOURCE).reflectance, m.select(PREDICTED).reflectance)
             for m in read_measurements(path)]  # fmt: skip
    return spectral_set(pairs, floor)


def generated(targets: int, seed: int, floor: float) -> dict:
    world = World(read_library(None), "ma-t12")
    cases = [case for batch in world.cases(targets, seed) for case in batch]
    names = [str(g) for g in cases[0].geometries]
    source = [names.index(str(g)) for g in SOURCE]
    predicted = [names.index(str(g)) for g in PREDICTED]
    pairs = [(np.asarray(c.target)[source], np.asarray(c.target)[predicted]) for c in cases]
    return spectral_set(pairs, floor)


def reference_set(paints, floor: float) -> list[dict]:
    """Each fitted paint read at the 45° lamp's six geometries, rebuilt on the grid."""
    grid = comparison_geometries()
    source_angles = geometry_angles(SOURCE)
    report = []
    for paint in paints:
        readings = paint.reflectance_factor(*source_angles)
        truth = linear_sRGB_to_Lab(paint.reflectance_factor(*grid))
        tilt = delta_E_CIE2000(linear_sRGB_to_Lab(by_tilt(readings, floor)(*grid)), truth)
        aspec = delta_E_CIE2000(linear_sRGB_to_Lab(by_aspecular(readings, *grid)), truth)
        report.append({"paint": paint.name, "geometries": int(tilt.size),
                       "tilt": statistics(tilt), "aspecular": statistics(aspec)})  # fmt: skip
    return report


MERL_FITS = ("merl_abc", "merl_sgd")
"""The two fits of the MERL database's BRDFs: Löw et al.'s ABC and Bagher et al.'s SGD."""


@functools.cache
def fitted_paints(fit: str) -> tuple | None:
    """The paints of one of :data:`~flakelab.physics.reference_brdf.REFERENCE_FITS` (the
    MERL database's paints alone), read once a run; None where ../shared/data is absent."""
    file, read = REFERENCE_FITS[fit]
    path = SHARED / "reference-brdf" / file
    if not path.is_file():
        return None
    return tuple(p for p in read(path) if fit == "gunther" or is_merl_paint(p.name))


def reference(floor: float, fit: str) -> list[dict] | None:
    paints = fitted_paints(fit)
    return None if paints is None else reference_set(paints, floor)


@functools.cache
def fits_apart() -> list[dict] | None:
    """How far the MERL database's two fits of each paint lie apart on the grid (ΔE00): how
    well a fit knows the measured BRDF between the angles it was fitted at."""
    abc, sgd = (fitted_paints(fit) for fit in MERL_FITS)
    if abc is None or sgd is None:
        return None
    grid = comparison_geometries()
    sgd_of = {p.name: p for p in sgd}
    report = []
    for paint in abc:
        truth = linear_sRGB_to_Lab(sgd_of[paint.name].reflectance_factor(*grid))
        apart = delta_E_CIE2000(linear_sRGB_to_Lab(paint.reflectance_factor(*grid)), truth)
        report.append({"paint": paint.name, **statistics(apart)})
    return report


def ranges(report: list[dict]) -> dict[str, dict[str, list[float]]]:
    """The MERL paints' figures from least to most, effect paints (by name) and the others."""
    groups = {"effect": [r for r in report if is_merl_effect_paint(r["paint"])]}
    groups["other"] = [r for r in report if r not in groups["effect"]]
    return {
        group: {
            f"{method} {figure}": [
                min(r[method][figure] for r in rows),
                max(r[method][figure] for r in rows),
            ]  # fmt: skip
            for method in ("tilt", "aspecular")
            for figure in ("median", "p95")
        }
        | {"paints": len(rows)}
        for group, rows in groups.items()
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--targets", type=int, default=300)
    parser.add_argument("--seed", type=int, default=11)
    parser.add_argument(
        "--floor", default=str(FLOOR_SHARE), help="Floor shares to compare, e.g. 0.5,0.9"
    )
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    report = {}
    for floor in (float(f) for f in args.floor.split(",")):
        report[f"floor {floor:g}"] = {
            "real_ma_t12": real_ma_t12(floor),
            "generated": generated(args.targets, args.seed, floor),
        } | {fit: reference(floor, fit) for fit in ("gunther", *MERL_FITS)}
        sets = report[f"floor {floor:g}"]
        sets |= {f"{fit}_ranges": ranges(sets[fit]) for fit in MERL_FITS if sets[fit] is not None}
        sets["merl_fits_apart"] = fits_apart()
    if args.json:
        print(json.dumps(report, indent=2))
        return
    for floor, sets in report.items():
        print(f"{floor} (ΔE00 median / p95; aspecular interpolation, the baseline, after)")
        for name in ("real_ma_t12", "generated"):
            r = sets[name]
            if r is None:
                print(f"  {name}: ../shared/data absent")
                continue
            print(f"  {name} ({r['samples']} samples, 15° from 45°): "
                  f"{r['tilt']['median']:.2f} / {r['tilt']['p95']:.2f}, aspecular "
                  f"{r['aspecular']['median']:.2f} / {r['aspecular']['p95']:.2f} "
                  f"(median ×{r['median_ratio']:.1f})")  # fmt: skip
        for name in ("gunther", *MERL_FITS):
            print(f"  {name}:" if sets[name] is not None else f"  {name}: ../shared/data absent")
            for r in sets[name] or []:
                tilt, base = r["tilt"], r["aspecular"]
                print(f"    {r['paint']:22s} {tilt['median']:.2f} / {tilt['p95']:.2f}, "
                      f"aspecular {base['median']:.2f} / {base['p95']:.2f}")  # fmt: skip
        for fit in MERL_FITS:
            for group, r in sets.get(f"{fit}_ranges", {}).items():
                print(f"  {fit}, {r['paints']} {group} paints: median "
                      f"{r['tilt median'][0]:.2f}–{r['tilt median'][1]:.2f}, p95 "
                      f"{r['tilt p95'][0]:.2f}–{r['tilt p95'][1]:.2f}; aspecular median "
                      f"{r['aspecular median'][0]:.2f}–{r['aspecular median'][1]:.2f}, p95 "
                      f"{r['aspecular p95'][0]:.2f}–{r['aspecular p95'][1]:.2f}")  # fmt: skip
        if apart := sets["merl_fits_apart"]:
            medians, p95s = ([r[k] for r in apart] for k in ("median", "p95"))
            print(f"  merl_abc against merl_sgd, the same {len(apart)} paints: median "
                  f"{min(medians):.2f}–{max(medians):.2f}, "
                  f"p95 {min(p95s):.2f}–{max(p95s):.2f}")  # fmt: skip


if __name__ == "__main__":
    main()
