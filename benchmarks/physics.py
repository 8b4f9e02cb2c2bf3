"""Coating optics throughput and accuracy: the fast model against the Monte Carlo.

Fast model: random recipes from the demo library (an aluminium, up to three pigments, some
pearls), batch of N formulations × 6 BYK-mac geometries × 31 bands; Monte Carlo photons per
second on a flake + dye layer; peak memory of each (tracemalloc). Accuracy: ΔE00 of the fast
model against the Monte Carlo for a ladder of recipes, from dye-only metallics (where the
path-table route is exact) to scattering pigments and pearls (where it approximates).

    python benchmarks/physics.py [--n 10000] [--photons 200000] [--json]
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E
from flakelab.core.geometry import INSTRUMENT_GEOMETRIES
from flakelab.io import read_library
from flakelab.physics.fast import predict
from flakelab.physics.layer import layer_from_fractions
from flakelab.physics.montecarlo import simulate
from timing import measure_peak

GEOMETRIES = INSTRUMENT_GEOMETRIES["byk-mac-i"]
LADDER = {
    "Al medium": {"Al medium": 1.0},
    "Al coarse + Al fine": {"Al coarse": 0.5, "Al fine": 0.5},
    "Al medium + 5% phthalo blue": {"Al medium": 0.95, "Phthalo blue GS": 0.05},
    "Al coarse + 3% transp. iron red": {"Al coarse": 0.97, "Transparent iron oxide red": 0.03},
    "Al + 10% quinacridone + 5% iron red": {
        "Al medium": 0.85,
        "Quinacridone red": 0.10,
        "Iron oxide red": 0.05,
    },
    "Al + 5% TiO2": {"Al medium": 0.95, "Titanium dioxide white": 0.05},
    "pearl blue + Al": {"Pearl interference blue": 0.7, "Al fine": 0.3},
    "solid TiO2 + phthalo": {"Titanium dioxide white": 0.9, "Phthalo blue GS": 0.1},
    "solid iron red + TiO2": {"Iron oxide red": 0.7, "Titanium dioxide white": 0.3},
}


def random_fractions(library, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    names = library.names
    aluminium = [names.index(t.name) for t in library.of_kind("aluminium")]
    pigments = [names.index(t.name) for t in library.of_kind("pigment")]
    x = np.zeros((n, len(names)))
    rows = np.arange(n)
    x[rows, rng.choice(aluminium, n)] = rng.uniform(0.3, 1.0, n)
    for _ in range(3):
        x[rows, rng.choice(pigments, n)] += rng.uniform(0, 0.1, n)
    return x / x.sum(axis=1, keepdims=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=10_000, help="formulations per batch")
    parser.add_argument("--photons", type=int, default=200_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()

    library = read_library(None)
    x = random_fractions(library, args.n, args.seed)
    predict(layer_from_fractions(library, x[:10]), GEOMETRIES)  # load the atlas once
    _, fast_seconds, fast_peak = measure_peak(
        lambda: predict(layer_from_fractions(library, x), GEOMETRIES)
    )
    ladder = {}
    mc_seconds = mc_photons = 0.0
    for name, recipe in LADDER.items():
        coating = layer_from_fractions(library, library.fractions(recipe))
        mc, _, mc_peak = measure_peak(simulate, coating, GEOMETRIES, args.photons)
        mc_seconds += mc.seconds
        mc_photons += mc.photons
        fast = predict(coating, GEOMETRIES)[0]
        de = delta_E(reflectance_to_Lab(np.pi * mc.brdf), reflectance_to_Lab(np.pi * fast))
        ladder[name] = {
            "de00_mean": float(de.mean()),
            "de00_max": float(de.max()),
            "de00_per_geometry": de.round(2).tolist(),
        }
    report = {
        "formulations": args.n,
        "geometries": len(GEOMETRIES),
        "bands": 31,
        "fast_formulations_per_s": args.n / fast_seconds,
        "fast_peak_memory_mb": fast_peak,
        "monte_carlo_photons_per_s": mc_photons / mc_seconds,
        "monte_carlo_peak_memory_mb": mc_peak,
        "photons_per_spectrum": args.photons,
        "fast_vs_monte_carlo": ladder,
    }
    if args.json:
        print(json.dumps(report, indent=1))
        return
    for key, value in report.items():
        if key != "fast_vs_monte_carlo":
            print(f"{key:32s} {value:,.6g}")
    print("\nfast model vs Monte Carlo, ΔE00 over the six BYK-mac geometries:")
    for name, entry in ladder.items():
        print(f"  {name:38s} mean {entry['de00_mean']:5.2f}  max {entry['de00_max']:5.2f}")


if __name__ == "__main__":
    main()
