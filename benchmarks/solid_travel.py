"""Matcher: does ``SOLID_TRAVEL`` still part the generated world's solids from its effect paints?

A target read without texture readings is matched as a solid when its colour travels less
than :data:`~flakelab.match.settings.SOLID_TRAVEL` (ΔE00) between any two of its geometries.
The threshold was set on the generated world, so a change to the world's physics can move
either family across it. This draws formulations as the case generator does (the default
family mix), sprays each with the shop's variation, reads it with the instrument's noise,
and prints, per instrument and paint family, the least and the most colour travel and how
many paints fall on the wrong side of the threshold.

    python benchmarks/solid_travel.py [--n 20000] [--seed 11] [--json]
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from flakelab.cases.generator import World
from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import colour_travel
from flakelab.io import read_library
from flakelab.library import PAINT_FAMILIES
from flakelab.match.settings import SOLID_TRAVEL

INSTRUMENTS = ("five-angle", "ma-t12")
BATCH = 2000


def measured_travel(world: World, fractions: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Colour travel ``[N]`` of ``fractions`` sprayed with the shop's variation and read."""
    travel = []
    for start in range(0, len(fractions), BATCH):
        x = fractions[start : start + BATCH]
        R, _ = world.appearance(x, world.variation(len(x), rng))
        travel.append(colour_travel(reflectance_to_Lab(world.measure(R, rng))))
    return np.concatenate(travel)


def family_travel(library, instrument: str, n: int, seed: int) -> dict[str, dict]:
    world = World(library, instrument)
    rng = np.random.default_rng(seed)
    x = world.formulations(n, rng)
    families = library.paint_families(x)
    travel = measured_travel(world, x, rng)
    rows = {}
    for family in PAINT_FAMILIES:
        t = travel[families == family]
        wrong = t >= SOLID_TRAVEL if family == "solid" else t < SOLID_TRAVEL
        rows[family] = {
            "paints": int(t.size),
            "travel_min": float(t.min()),
            "travel_max": float(t.max()),
            "wrong_side": int(wrong.sum()),
        }
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=20_000)
    parser.add_argument("--seed", type=int, default=11)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    library = read_library(None)
    result = {
        "solid_travel": SOLID_TRAVEL,
        "n": args.n,
        "seed": args.seed,
        **{i: family_travel(library, i, args.n, args.seed) for i in INSTRUMENTS},
    }
    if args.json:
        print(json.dumps(result, indent=2))
        return
    print(f"SOLID_TRAVEL {SOLID_TRAVEL} ΔE00; {args.n} formulations, seed {args.seed}")
    for instrument in INSTRUMENTS:
        for family, row in result[instrument].items():
            print(
                f"{instrument:>10} {family:>8}: {row['paints']:>6} paints, travel "
                f"{row['travel_min']:.3f}–{row['travel_max']:.3f}, "
                f"{row['wrong_side']} on the wrong side"
            )


if __name__ == "__main__":
    main()
