"""Coating optics throughput and accuracy: the fast model against the Monte Carlo.

Fast model: random recipes from the demo library (an aluminium, up to three pigments, some
pearls), batch of N formulations × 6 BYK-mac geometries × 31 bands; Monte Carlo photons per
second on a flake + dye layer; peak memory of each (tracemalloc). Accuracy: ΔE00 of the fast
model against the Monte Carlo for a ladder of recipes, from dye-only metallics (where the
path-table route is exact) to scattering pigments and pearls (where it approximates).

With ``--world N``, instead: how faithful the generated world is to the Monte Carlo. N
formulations drawn as the case generator draws them (its mix of metallics, pearls and solids,
seed ``--seed``), each sprayed at the world's mean application, computed by the fast model
(the world's physics) and by the Monte Carlo; ΔE00 per family, split by whether the recipe
holds a pigment that hides (whites, iron oxides, bismuth vanadate, carbon black: the ones that
scatter or absorb strongly). ``monte_carlo_noise`` is the ΔE00 a one-standard-error shift of
the Monte Carlo's own reflectance makes: the reference's noise.

The fast model is timed on the random recipes and on N formulations drawn as the case
generator draws them (``fast_world_formulations_per_s``: half its metallics blend two
aluminiums, each a lobe of its own); ``--fast-only`` leaves out the Monte Carlo ladder.

    python benchmarks/physics.py [--n 10000] [--photons 200000] [--fast-only] [--json]
    python benchmarks/physics.py --world 40 --photons 100000 [--instrument five-angle] [--json]
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from flakelab.cases.generator import World
from flakelab.cli.common import tracked
from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E
from flakelab.core.geometry import INSTRUMENT_GEOMETRIES
from flakelab.io import read_library
from flakelab.physics.fast import predict, reflectance_factor
from flakelab.physics.layer import layer_from_fractions
from flakelab.physics.montecarlo import simulate
from timing import best_time, measure_peak

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


def fast_model(library, x: np.ndarray) -> np.ndarray:
    """The fast model of formulations ``x`` at the benchmark's geometries, layers built."""
    return predict(layer_from_fractions(library, x), GEOMETRIES)


def world_fidelity(library, instrument: str, n: int, photons: int, seed: int) -> dict:
    """ΔE00 of the fast model against the Monte Carlo over ``n`` of the world's own
    formulations: each row's mean and worst over the geometries, and the Monte Carlo's noise."""
    world = World(library, instrument)
    x = world.formulations(n, np.random.default_rng(seed))
    layer = world.layer(x, world.nominal(n))
    lab = reflectance_to_Lab(reflectance_factor(layer, world.geometries))
    hiding = np.array([t.kind == "pigment" and t.hides for t in library.toners])
    rows = []
    for i in tracked(range(n), "Monte Carlo of the world's formulations"):
        mc = simulate(layer[i : i + 1], world.geometries, photons, seed=seed + i)
        truth = reflectance_to_Lab(np.pi * mc.brdf)
        noise = delta_E(reflectance_to_Lab(np.pi * (mc.brdf + mc.stderr)), truth)
        de = delta_E(lab[i], truth)
        rows.append((de.mean(), de.max(), noise.mean(), mc.seconds))
    mean, worst, noise, seconds = np.array(rows).T
    family = library.paint_families(x)
    holds = (x[:, hiding] > 0).any(axis=1)
    groups = {"all": np.ones(n, bool)}
    for name in ("metallic", "pearl", "solid"):
        groups[f"{name}, with a hiding pigment"] = (family == name) & holds
        groups[f"{name}, without"] = (family == name) & ~holds
    summary = {
        group: {
            "n": int(m.sum()),
            "de00_mean": float(mean[m].mean()),
            "de00_median": float(np.median(mean[m])),
            "worst_geometry_median": float(np.median(worst[m])),
            "worst_geometry_max": float(worst[m].max()),
            "monte_carlo_noise": float(np.median(noise[m])),
        }
        for group, m in groups.items()
        if m.any()
    }
    return {
        "instrument": instrument,
        "formulations": n,
        "photons_per_spectrum": photons,
        "seed": seed,
        "monte_carlo_seconds": float(seconds.sum()),
        "fast_vs_monte_carlo": summary,
    }


def print_world(report: dict) -> None:
    print(f"fast model (the generated world) vs Monte Carlo, {report['formulations']} of the "
          f"world's formulations at the {report['instrument']}, seed {report['seed']}, "
          f"{report['photons_per_spectrum']:,} photons each:")  # fmt: skip
    print(f"  {'':32s} {'n':>3s} {'mean':>5s} {'median':>6s}  worst geometry: "
          f"{'median':>6s} {'max':>6s}  {'MC noise':>8s}")  # fmt: skip
    for group, e in report["fast_vs_monte_carlo"].items():
        print(f"  {group:32s} {e['n']:3d} {e['de00_mean']:5.2f} {e['de00_median']:6.2f}"
              f"  {'':15s} {e['worst_geometry_median']:6.2f} {e['worst_geometry_max']:6.2f}"
              f"  {e['monte_carlo_noise']:8.2f}")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=10_000, help="formulations per batch")
    parser.add_argument("--photons", type=int, default=200_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--world", type=int, default=0, help="the world's formulations instead")
    parser.add_argument("--instrument", default="five-angle", help="with --world")
    parser.add_argument("--fast-only", action="store_true", help="no Monte Carlo ladder")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()

    library = read_library(None)
    if args.world:
        world = world_fidelity(library, args.instrument, args.world, args.photons, args.seed)
        if args.json:
            print(json.dumps(world, indent=1))
        else:
            print_world(world)
        return
    x = random_fractions(library, args.n, args.seed)
    fast_model(library, x[:10])  # load the atlas once
    # speed untraced, best of three (tracemalloc slows numpy's allocations), then the peak
    fast_seconds = best_time(fast_model, library, x)
    _, _, fast_peak = measure_peak(fast_model, library, x)
    drawn = World(library, "five-angle").formulations(args.n, np.random.default_rng(args.seed))
    world_seconds = best_time(fast_model, library, drawn)
    ladder = {}
    mc_seconds = mc_photons = 0.0
    for name, recipe in {} if args.fast_only else LADDER.items():
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
        "fast_world_formulations_per_s": args.n / world_seconds,
    }
    if not args.fast_only:
        report |= {
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
    if args.fast_only:
        return
    print("\nfast model vs Monte Carlo, ΔE00 over the six BYK-mac geometries:")
    for name, entry in ladder.items():
        print(f"  {name:38s} mean {entry['de00_mean']:5.2f}  max {entry['de00_max']:5.2f}")


if __name__ == "__main__":
    main()
