"""A colour code's variants (``flakelab cases variants``) in the generator's world: how many
variants one formulation's cars need, whether cars of a code sprayed at three plants come
back as those three, how many of the code's next cars the shop's variant chips cover, and
how the grouping scales with the cars of a code.

Each car is a formulation sprayed at the factory (its batches and spray line,
``World.variation(at_shop=False)``) and read once with the instrument's noise; no car is
weathered. A plant's variant is the code's formulation with every toner's share scaled by
its own factor (lognormal, sd ``--plant-sd``), as another plant's or year's formula is, drawn
until the three plants' colours lie at least ``--apart`` (worst ΔE00) apart. The chips
(``cases variants --out``) of the three plants' cars are held against as many cars again,
drawn the same way: the share within the tolerance of their nearest chip, against one chip
alone (the car whose furthest car lies nearest).

    python benchmarks/code_variants.py [--formulations 10] [--cars 40] [--seed 5] [--json]
    python benchmarks/code_variants.py --sizes 20000 [--json]
"""

from __future__ import annotations

import argparse
import time
import tracemalloc

import numpy as np

from flakelab.cases.case import Case
from flakelab.cases.generator import World
from flakelab.cases.variants import car_from_centres, colour_variants
from flakelab.core.tolerance import tolerance_preset
from flakelab.io import read_library
from timing import print_report

WITHIN = (1.0, 2.0)
PLANTS = 3
SIZES = (500, 2000, 5000)
ONE_CHIP = 1e6
"""A share of the limit every car lies within: the cover is one chip."""


def cars_of(world: World, fractions: np.ndarray, rng: np.random.Generator) -> list[Case]:
    """Cars of ``fractions`` (``[N, T]``, one row a car), each sprayed at the factory and
    read once, as cases of one code."""
    R, _ = world.appearance(fractions, world.variation(len(fractions), rng, at_shop=False))
    readings = world.measure(R, rng)
    toners = [t.name for t in world.library.toners]
    return [
        Case(
            case_id=f"car-{k}",
            geometries=world.geometries,
            recipe={t: v for t, v in zip(toners, x, strict=True) if v > 0},
            target=reading,
            sprayout=reading,
            colour_code="BENCH 1",
            synthetic=True,
        )
        for k, (x, reading) in enumerate(zip(fractions, readings, strict=True))
    ]


def plant_formulas(world: World, base: np.ndarray, args, rng: np.random.Generator):
    """``PLANTS`` formulas of one code: ``base`` (``[T]``) and others with each toner's share
    scaled by its own lognormal factor (sd ``args.plant_sd``), drawn again until every two
    plants' nominal colours lie at least ``args.apart`` (worst geometry's ΔE00) apart, as a
    maker's variant chips do; None where 100 draws found none (a formulation of one toner
    has no other plant's)."""
    for _ in range(100):
        scaled = base[None] * np.exp(rng.normal(0.0, args.plant_sd, (PLANTS, base.size)))
        scaled[0] = base
        formulas = scaled / scaled.sum(axis=1, keepdims=True)
        nominal = world.appearance(formulas, world.nominal(PLANTS))[0]
        apart = world.worst_de00(nominal[:, None], nominal[None])[np.triu_indices(PLANTS, 1)]
        if apart.min() >= args.apart:
            return formulas, float(np.median(apart))
    return None


def purity(variants, plant_of: dict[str, int]) -> float:
    """The share of cars in a variant whose most cars come from their own plant."""
    kept = 0
    for variant in variants:
        plants = np.bincount([plant_of[c.case_id] for c in variant.cases], minlength=PLANTS)
        kept += plants.max()
    return kept / len(plant_of)


def covered(chips, cars: list[Case], tolerance) -> float:
    """The share of ``cars`` within ``tolerance`` of their nearest chip (a variant's centre
    car, the standard) at every geometry."""
    return float(np.mean([car_from_centres(chips, c.target, tolerance)[2].any() for c in cars]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--formulations", type=int, default=10)
    parser.add_argument("--cars", type=int, default=40)
    parser.add_argument("--plant-sd", type=float, default=0.15)
    parser.add_argument("--apart", type=float, default=2.0)
    parser.add_argument("--seed", type=int, default=5)
    parser.add_argument(
        "--sizes",
        default=",".join(map(str, SIZES)),
        help="cars of one code to group, each size in turn (20000: about 5 min, 1 GB)",
    )
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()

    world = World(read_library(None), "five-angle")
    tolerance = tolerance_preset("refinish")
    rng = np.random.default_rng(args.seed)
    next_rng = np.random.default_rng((args.seed, 1))  # the next cars: the rest drawn as before
    one, three, apart = {w: [] for w in WITHIN}, {w: [] for w in WITHIN}, []
    purities = {w: [] for w in WITHIN}
    coverage = {w: [] for w in (*WITHIN, ONE_CHIP)}
    while len(apart) < args.formulations:
        base = world.formulations(1, rng)[0]
        plants = plant_formulas(world, base, args, rng)
        if plants is None:
            continue
        formulas, plants_apart = plants
        apart.append(plants_apart)
        cars = cars_of(world, np.repeat(base[None], args.cars, axis=0), rng)
        for within in WITHIN:
            one[within].append(len(colour_variants(cars, tolerance, within)))
        plant = np.repeat(np.arange(PLANTS), args.cars)
        coded = cars_of(world, formulas[plant], rng)
        plant_of = {c.case_id: int(p) for c, p in zip(coded, plant, strict=True)}
        following = cars_of(world, formulas[plant], next_rng)
        for within in (*WITHIN, ONE_CHIP):
            found = colour_variants(coded, tolerance, within)
            coverage[within].append(covered(found, following, tolerance))
            if within in WITHIN:
                three[within].append(len(found))
                purities[within].append(purity(found, plant_of))
    report: dict = {
        "formulations": args.formulations,
        "cars_per_formulation": args.cars,
        "seed": args.seed,
        "plant_sd": args.plant_sd,
        "plants_apart_at_least": args.apart,
        "plants_apart_worst_de00_median": round(float(np.median(apart)), 2),
    }
    for within in WITHIN:
        counts, found = np.array(one[within]), np.array(three[within])
        report[f"one_formulation_variants_within_{within:g}"] = (
            f"median {np.median(counts):g}, {counts.min()}-{counts.max()}"
        )
        report[f"three_plants_variants_within_{within:g}"] = (
            f"median {np.median(found):g}, {found.min()}-{found.max()}"
        )
        report[f"three_plants_purity_within_{within:g}"] = round(
            float(np.mean(purities[within])), 3
        )
        report[f"next_cars_covered_by_chips_within_{within:g}"] = round(
            float(np.mean(coverage[within])), 3
        )
    report["next_cars_covered_by_one_chip"] = round(float(np.mean(coverage[ONE_CHIP])), 3)
    for size in (int(n) for n in args.sizes.split(",")):
        cars = cars_of(world, np.repeat(base[None], size, axis=0), rng)
        tracemalloc.start()
        start = time.perf_counter()
        found = colour_variants(cars, tolerance)
        seconds = time.perf_counter() - start
        peak = tracemalloc.get_traced_memory()[1] / 2**20
        tracemalloc.stop()
        report[f"cars_{size}"] = f"{seconds:.2f} s, {peak:.0f} MB traced, {len(found)} variants"
    print_report(report, args.json)


if __name__ == "__main__":
    main()
