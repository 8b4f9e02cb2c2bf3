"""Aiming a match off for a shop's habits: how many optimiser steps it takes, its time, and
how small an offset is worth aiming for.

Hidden formulations of the habits shop (``--world shop-with-habits``) are sprayed at the
factory's mean application (the target, without noise), matched by the shipped model, aimed
off (:func:`flakelab.match.correction.aim_off`) for the habits in ``--habits`` with each
number of ``--steps``, and the aimed recipe "sprayed" at the shop's mean application and
read by its instrument without noise: the worst-geometry ΔE00 to the target, mean over
targets, and the seconds per aim-off. The habits file comes from
``flakelab cases habits CASES --out FILE``.

With ``--offsets``, every candidate of the matches (targets of the ordinary shop's world,
``--world shop``) is aimed off whatever its offset (``floor=0``): how far the habits move it
(the worst geometry's ΔE00, what :data:`~flakelab.match.correction.AIM_OFF_FLOOR` is set
against), how far the aim-off moves its prediction, and whether that comes nearer the target
(worst geometry, prediction plus offset).

    python benchmarks/aim_off.py --habits FILE [--targets 12] [--steps 0,30,60,150,300]
        [--world-habits FILM,SPREAD,GAIN] [--json]
    python benchmarks/aim_off.py --habits FILE --offsets --targets 30 [--json]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from _matcher import (
    WORLD_HABITS_HELP,
    parse_world_habits,
    seeds_from,
    shipped_matcher,
    world_habits,
)
from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E
from flakelab.match.correction import aim_off
from flakelab.match.evaluate import worst_de00
from flakelab.match.habits import read_habits
from flakelab.match.judging import evaluate_recipes, recipe_vector
from flakelab.match.search import MatchSettings, match
from timing import print_report


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--habits", required=True, help="habits file (flakelab cases habits)")
    parser.add_argument("--targets", type=int, default=12)
    parser.add_argument("--steps", default="0,30,60,150,300", help="aim-off steps to try")
    parser.add_argument("--seed", type=int, default=5)
    parser.add_argument(
        "--world-habits",
        type=parse_world_habits,
        help=WORLD_HABITS_HELP + " (default: shop-with-habits's 1.05,0.96,0.005)",
    )
    parser.add_argument("--offsets", action="store_true", help="offsets against the floor")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    if args.offsets:
        report = offsets_report(read_habits(args.habits), args.targets, args.seed)
        print_report(report, args.json, ".3f")
        return
    world, forward, effect = shipped_matcher("shop-with-habits", shop_habits=args.world_habits)
    habits = read_habits(args.habits)
    steps = seeds_from(args.steps)
    hidden = world.formulations(args.targets, np.random.default_rng(args.seed))
    targets = world.appearance(hidden, world.nominal(args.targets))[0]
    gain = 1 + world.settings.shop_gain
    landed = {s: [] for s in steps}
    seconds = {s: [] for s in steps}
    for target in targets:
        best = match(target, forward, effect, settings=MatchSettings(candidates=1))
        x = recipe_vector(forward, best.candidates[0].fractions)[None]
        for s in steps:
            start = time.perf_counter()
            aimed = aim_off(forward, target, x, habits, world.library, steps=s)[0] if s else x
            seconds[s].append(time.perf_counter() - start)
            R = world.appearance(aimed, world.nominal(1, at_shop=True))[0][0] * gain
            landed[s].append(worst_de00(target, R))
    rows = [
        {
            "steps": s,
            "de00_worst_mean": float(np.mean(landed[s])),
            "seconds": float(np.mean(seconds[s])),
        }
        for s in steps
    ]
    if args.json:
        report = {"targets": args.targets, "world": world_habits(world), "habits": habits.report()}
        print(json.dumps({**report, "rows": rows}))
        return
    for row in rows:
        print(
            f"{row['steps']:4d} steps  worst-geometry ΔE00 {row['de00_worst_mean']:.3f}  "
            f"{row['seconds']:.3f} s"
        )


def offsets_report(habits, targets: int, seed: int) -> dict:
    """Every candidate of the matches to ``targets`` of the ordinary shop, aimed off for
    ``habits`` with no floor (see the module's docstring)."""
    world, forward, effect = shipped_matcher("shop")
    hidden = world.formulations(targets, np.random.default_rng(seed))
    offset, moved, change, seconds = [], [], [], []
    for target in world.appearance(hidden, world.nominal(targets))[0]:
        candidates = match(target, forward, effect).candidates
        x = np.array([recipe_vector(forward, c.fractions) for c in candidates])
        R = evaluate_recipes(forward, x)[0]
        plain = reflectance_to_Lab(R) + habits.offset(world.library, x, R, forward.geometries)
        start = time.perf_counter()
        aimed = aim_off(forward, target, x, habits, world.library, floor=0.0)[1]
        seconds.append(time.perf_counter() - start)
        target_lab = reflectance_to_Lab(target)[None]
        offset.extend(delta_E(reflectance_to_Lab(R), plain).max(axis=1))
        moved.extend(delta_E(plain, aimed).max(axis=1))
        farther = delta_E(target_lab, aimed).max(axis=1) - delta_E(target_lab, plain).max(axis=1)
        change.extend(farther)
    offset, change = np.array(offset), np.array(change)
    return {
        "targets": targets,
        "candidates": len(offset),
        "offset_de00_median": float(np.median(offset)),
        "offset_de00_max": float(offset.max()),
        "aim_moved_de00_median": float(np.median(moved)),
        "aim_worst_de00_change_mean": float(change.mean()),
        "aim_farther_share": float(np.mean(change > 1e-3)),
        "seconds_per_aim_off": float(np.mean(seconds)),
    }


if __name__ == "__main__":
    main()
