"""The hybrid forward's own error on recipes with a new toner, and what its parts buy.

Recipes are made as the harness makes its new-toner targets (a formulation of known toners,
then 1–8 % of one new toner). Each forward's prediction is compared with the world's
nominal physics (no batch, application or instrument noise), as ΔE00 over recipes ×
geometries:

* ``learned, known toners``: the learned model on the same recipes without their new toner,
  against their own physics; the error of the model where it knows every toner (the
  baseline of the same run);
* ``hybrid``: the shipped path; each new toner stands in the learned base as its proxy, at
  its own amount, and the physics ratio carries the difference;
* ``hybrid, proxy strength-matched``: the proxy at the amount whose physics in aluminium
  comes closest to the new toner's (a variant, not shipped);
* ``learned, new toner ignored``: the learned model on the recipe without its new toner,
  against the physics of the whole recipe; what the hybrid's physics has to make up.

    python benchmarks/hybrid_error.py [--recipes 400] [--seed 5] [--json]
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from _matcher import shipped_matcher
from flakelab.cases.generator import World
from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E
from flakelab.match.forward import HybridForward
from flakelab.match.judging import evaluate_recipes
from flakelab.physics.fast import predict
from flakelab.physics.layer import layer_from_fractions

REFERENCE_SHARE = 0.05
"""A new toner's share in aluminium when its proxy's amount is matched to it."""


class StrengthMatchedHybrid(HybridForward):
    """The hybrid with each proxy standing in at ``factor`` times the new toner's amount."""

    def __init__(self, model, library, novel, factors: dict[int, float]) -> None:
        super().__init__(model, library, novel)
        for j, factor in factors.items():
            self._substitute[j, self.proxies[j]] = factor


def strength_factors(library, proxies: dict[int, int]) -> dict[int, float]:
    """For each new toner, the proxy amount (× its own) closest in log spectrum in aluminium."""
    names = library.names
    aluminium = names.index(library.of_kind("aluminium")[0].name)
    grid = np.exp(np.linspace(np.log(0.2), np.log(5.0), 61))

    def log_spectra(x):
        geometries = ("45as15", "45as45", "45as110")
        return np.log(predict(layer_from_fractions(library, x), geometries) + 1e-6)

    factors = {}
    for j, i in proxies.items():
        mixes = np.zeros((grid.size + 1, len(names)))
        mixes[:, aluminium] = 1 - REFERENCE_SHARE
        mixes[:-1, i] = REFERENCE_SHARE * grid
        mixes[-1, j] = REFERENCE_SHARE
        spectra = log_spectra(mixes / mixes.sum(1, keepdims=True))
        distance = np.sqrt(np.mean((spectra[:-1] - spectra[-1]) ** 2, axis=(1, 2)))
        factors[j] = float(grid[np.argmin(distance)])
    return factors


def own_error(world: World, forward, x: np.ndarray, physics_of: np.ndarray) -> np.ndarray:
    """ΔE00 ``[N, G]`` of ``forward`` at recipes ``x`` against the nominal physics of
    ``physics_of``."""
    physics, _ = world.appearance(physics_of, world.nominal(len(physics_of)))
    predicted, _ = evaluate_recipes(forward, x)
    return delta_E(reflectance_to_Lab(physics), reflectance_to_Lab(predicted))


def statistics(de: np.ndarray) -> dict[str, float]:
    return {
        "de00_mean": round(float(de.mean()), 3),
        "de00_p95": round(float(np.percentile(de, 95)), 3),
        "worst_geometry_median": round(float(np.median(de.max(1))), 3),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--recipes", type=int, default=400)
    parser.add_argument("--seed", type=int, default=5)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()

    world, hybrid, _ = shipped_matcher("shop")
    library, names = world.library, list(world.library.names)
    rng = np.random.default_rng(args.seed)
    known = world.without(hybrid.novel)
    x_known = known.formulations(args.recipes, rng)
    x = x_known.copy()
    chosen = rng.integers(len(hybrid.novel), size=args.recipes)
    for row, k in enumerate(chosen):
        x[row, names.index(hybrid.novel[k])] = np.exp(rng.uniform(np.log(0.01), np.log(0.08)))
    x /= x.sum(1, keepdims=True)
    x_known /= x_known.sum(1, keepdims=True)
    factors = strength_factors(library, hybrid.proxies)
    matched = StrengthMatchedHybrid(hybrid.model, library, hybrid.novel, factors)

    errors = {
        "learned, known toners": own_error(world, hybrid, x_known, x_known),
        "hybrid": own_error(world, hybrid, x, x),
        "hybrid, proxy strength-matched": own_error(world, matched, x, x),
        "learned, new toner ignored": own_error(world, hybrid, x_known, x),
    }
    shipped = errors["hybrid"].max(1)
    rows = {}
    for name, de in errors.items():
        paired = de.max(1) - shipped
        rows[name] = statistics(de) | {
            "worst_geometry_vs_hybrid": round(float(paired.mean()), 3),
            "worst_geometry_vs_hybrid_se": round(float(paired.std() / np.sqrt(paired.size)), 3),
        }
    report = {
        "recipes": args.recipes,
        "seed": args.seed,
        "new_toners": {
            names[j]: {"proxy": names[i], "strength_factor": round(factors[j], 2)}
            for j, i in hybrid.proxies.items()
        },
        "forwards": rows,
    }
    if args.json:
        print(json.dumps(report, indent=2))
        return
    for name, new in report["new_toners"].items():
        print(f"{name}: proxy {new['proxy']}, strength-matched ×{new['strength_factor']}")
    for name, row in rows.items():
        print(
            f"{name:32s} mean {row['de00_mean']:.3f}  p95 {row['de00_p95']:.3f}  worst-geometry "
            f"median {row['worst_geometry_median']:.3f}  vs hybrid "
            f"{row['worst_geometry_vs_hybrid']:+.3f} ± {row['worst_geometry_vs_hybrid_se']:.3f}"
        )


if __name__ == "__main__":
    main()
