"""Aiming a match off for a shop's habits: how many optimiser steps it takes, and its time.

Hidden formulations of the habits shop (``--world shop-with-habits``) are sprayed at the
factory's mean application (the target, without noise), matched by the shipped model, aimed
off (:func:`flakelab.match.correction.aim_off`) for the habits in ``--habits`` with each
number of ``--steps``, and the aimed recipe "sprayed" at the shop's mean application and
read by its instrument without noise: the worst-geometry ΔE00 to the target, mean over
targets, and the seconds per aim-off. The habits file comes from
``flakelab cases habits CASES --out FILE``.

    python benchmarks/aim_off.py --habits FILE [--targets 12] [--steps 0,30,60,150,300] [--json]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from _matcher import seeds_from, shipped_matcher
from flakelab.match.correction import aim_off
from flakelab.match.evaluate import worst_de00
from flakelab.match.habits import read_habits
from flakelab.match.search import MatchSettings, match, recipe_vector


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--habits", required=True, help="habits file (flakelab cases habits)")
    parser.add_argument("--targets", type=int, default=12)
    parser.add_argument("--steps", default="0,30,60,150,300", help="aim-off steps to try")
    parser.add_argument("--seed", type=int, default=5)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    world, forward, effect = shipped_matcher("shop-with-habits")
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
        print(json.dumps({"targets": args.targets, "habits": habits.report(), "rows": rows}))
        return
    for row in rows:
        print(
            f"{row['steps']:4d} steps  worst-geometry ΔE00 {row['de00_worst_mean']:.3f}  "
            f"{row['seconds']:.3f} s"
        )


if __name__ == "__main__":
    main()
