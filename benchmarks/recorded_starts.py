"""What the shop's recorded recipes bring to a match: a car the shop painted before (a
recorded case's own car, read again) matched by the search alone (the baseline, measured in
the same run) and by the search started from the recipes of the five recorded cases whose
spray-outs lie nearest it (``match --nearest 5``, ``match --colour-code``). Each best
candidate is sprayed in the generator's world, as the harness sprays it (the shop's batches
and application, the same draws for both searches), and judged at every geometry against
the car (ΔE00 ≤ 1.0): the share that passes, the model's predicted worst ΔE00, the search's
seconds, and how often the best is a recorded recipe as it is. The recorded spray-out of
the car's own case says what the shop got when it mixed that recipe. A third way
(``corrected``) takes the nearest case as a first spray-out already made: its recipe
corrected from its recorded spray-out (``flakelab correct --mode reformulate``), which knows
what the model's prediction does not. A fourth (``recorded``) mixes the nearest case's recipe
again as it is, with its recorded spray-out's worst ΔE00 from the car as its prediction.

With ``--colour-codes K`` the world paints every car in one of K OEM colours (``cases
generate --colour-codes``), and the cars matched are the next to come in: each a car of a
code the shop may have painted before, matched from that code's recorded cases alone
(``match --colour-code``), as a colorist reads the code off the car's plate.

    python benchmarks/recorded_starts.py [--history 300] [--targets 30] [--seed 11]
        [--colour-codes K] [--json]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from flakelab.cases.case import select_cases
from flakelab.cases.generator import World, WorldSettings
from flakelab.cases.nearest import nearest_cases, recorded_recipes
from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E
from flakelab.core.geometry import INSTRUMENT_GEOMETRIES
from flakelab.core.tolerance import tolerance_preset
from flakelab.io import read_library
from flakelab.match.correction import correct
from flakelab.match.models import effect_mask, forward_for
from flakelab.match.search import MatchSettings, match
from flakelab.models.registry import shipped_model
from timing import matmul_gflops, print_report

NEAREST = 5


def sprayed_passes(world: World, fractions: dict, toners, car, seed: int) -> bool:
    """Whether ``fractions`` sprayed once in ``world`` (draws of ``seed``) and read lies
    within ΔE00 1.0 of ``car`` at every geometry."""
    rng = np.random.default_rng(seed)
    x = np.array([[fractions.get(t, 0.0) for t in toners]])
    reading = world.measure(world.appearance(x, world.variation(1, rng))[0], rng)
    return bool(world.worst_de00(reading, car[None])[0] <= 1.0)


def history_and_cars(world: World, args) -> tuple[list, list]:
    """The shop's history and the cars to match, each ``(reflectance, code, its case)``:
    without colour codes, cars the shop painted before (a history case's own car, read
    again); with them, the next cars to come in (the cases after the history), each matched
    from its own code's recorded cases alone (``match --colour-code``), none of its own."""
    if args.colour_codes:
        made = [c for b in world.cases(args.history + args.targets, seed=args.seed) for c in b]
        return made[: args.history], [(c.target, c.colour_code, None) for c in made[args.history :]]
    history = [c for batch in world.cases(args.history, seed=args.seed) for c in batch]
    rng = np.random.default_rng(args.seed)
    picked = rng.choice(len(history), args.targets, replace=False)
    return history, [(world.measure(history[i].target[None], rng)[0], "", history[i])
                     for i in picked]  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--history", type=int, default=300)
    parser.add_argument("--targets", type=int, default=30)
    parser.add_argument("--seed", type=int, default=11)
    parser.add_argument("--colour-codes", type=int, default=0)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()

    library = read_library(None)
    world = World(library, "five-angle", WorldSettings(colour_codes=args.colour_codes))
    forward = forward_for(shipped_model("five-angle"), library)
    effect = effect_mask(library, forward.toners)
    tolerance = tolerance_preset("refinish")
    settings = MatchSettings(candidates=1)
    history, cars = history_and_cars(world, args)
    rows = {"alone": [], "started": [], "corrected": [], "recorded": []}
    own_case_nearest, as_recorded, recorded_passed, code_in_history = 0, 0, 0, 0
    gflops = matmul_gflops()
    for k, (car, code, case) in enumerate(cars):
        start = time.perf_counter()
        pool = select_cases(history, colour_code=code) if code else history
        near = nearest_cases(car, pool, tolerance, NEAREST) if pool else []
        recorded = recorded_recipes(near, forward.toners)
        nearest_s = time.perf_counter() - start
        code_in_history += bool(code and pool)
        if case is not None:
            own_case_nearest += case.case_id in recorded
            recorded_passed += bool(world.worst_de00(case.sprayout[None], car[None])[0] <= 1.0)
        elif near:  # the nearest recorded spray-out, as it is, against the new car
            recorded_passed += bool(
                world.worst_de00(near[0].case.sprayout[None], car[None])[0] <= 1.0
            )
        for label, starts in (("alone", None), ("started", list(recorded.values()) or None)):
            start = time.perf_counter()
            best = match(car, forward, effect, settings=settings, starts=starts).candidates[0]
            seconds = time.perf_counter() - start + (nearest_s if starts else 0.0)
            passed = sprayed_passes(world, best.fractions, forward.toners, car, 1000 + k)
            rows[label].append((passed, float(best.de00.max()), seconds))
            if label == "started":
                as_recorded += any(
                    np.allclose([best.fractions.get(t, 0.0) for t in forward.toners], x, atol=1e-9)
                    for x in recorded.values()
                )
        if not near:  # nothing recorded of the code: the colorist takes the search's best
            rows["corrected"].append(rows["alone"][-1])
            rows["recorded"].append(rows["alone"][-1])
            continue
        # the nearest case's recipe mixed again as it is, judged by its recorded spray-out
        first = near[0].case
        passed = sprayed_passes(world, dict(first.recipe), forward.toners, car, 1000 + k)
        rows["recorded"].append((passed, float(near[0].sprayout_de00.max()), nearest_s))
        start = time.perf_counter()
        fix = correct(forward, car, dict(first.recipe), first.sprayout, mode="reformulate",
                      library=library, tolerance=tolerance)  # fmt: skip
        seconds = time.perf_counter() - start + nearest_s
        passed = sprayed_passes(world, fix.fractions, forward.toners, car, 1000 + k)
        expected = delta_E(reflectance_to_Lab(car), fix.expected_lab).max()
        rows["corrected"].append((passed, float(expected), seconds))
    report = {
        "history": args.history,
        "targets": args.targets,
        "seed": args.seed,
        "gflops": round(gflops),
        "instrument": "five-angle",
        "geometries": len(INSTRUMENT_GEOMETRIES["five-angle"]),
        "colour_codes": args.colour_codes,
        "own_case_among_nearest": own_case_nearest,
        "code_in_history": code_in_history,
        "recorded_sprayout_passed": round(recorded_passed / args.targets, 3),
        "best_is_a_recorded_recipe": as_recorded,
    }
    for label, results in rows.items():
        passed, predicted, seconds = (np.array(v) for v in zip(*results, strict=True))
        report[f"{label}_sprayed_success"] = round(float(passed.mean()), 3)
        report[f"{label}_predicted_de00_median"] = round(float(np.median(predicted)), 3)
        report[f"{label}_seconds_median"] = round(float(np.median(seconds)), 2)
        report[f"{label}_seconds_max"] = round(float(seconds.max()), 2)
    alone = np.array([row[0] for row in rows["alone"]], dtype=bool)
    for label in ("started", "corrected", "recorded"):
        report[f"success_ratio_{label}_vs_alone"] = round(
            report[f"{label}_sprayed_success"] / max(report["alone_sprayed_success"], 1e-9), 2
        )
        way = np.array([row[0] for row in rows[label]], dtype=bool)  # paired: the same cars
        report[f"{label}_passed_alone_failed"] = int((way & ~alone).sum())
        report[f"alone_passed_{label}_failed"] = int((alone & ~way).sum())
    print_report(report, args.json)


if __name__ == "__main__":
    main()
