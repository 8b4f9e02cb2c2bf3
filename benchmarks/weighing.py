"""What rounding to the scale costs in colour: the nearest grams against the rounding chosen
for colour (``flakelab.match.recipe.weigh_for_colour``, ``weigh_additions``).

Recipes are the generated world's OEM-like formulations (an effect base and up to four
pigments), weighed for each can and scale resolution asked. Each is rounded twice: to the
nearest grams (largest remainder, summing to the can), and to the rounding, every toner down
or up, whose colour the shipped model puts closest to the exact recipe's. Each costs the
largest ΔE00 over geometries between the weighed and the exact recipe, as that model predicts
both. The additions rows add one to three of each recipe's pigments, 0.05 % to 1 % of the can
each (a correction's size), to the can weighed by its nearest grams.

With ``--targets N`` the harness's hidden targets (``flakelab match evaluate``, seed
``--harness-seed``) are matched, and each best recipe is sprayed three times on the same
stream (the same batches, application and instrument noise): as computed, as the nearest
grams for the first ``--can``, and as rounded for colour. The harness sprays recipes as
computed; these rows say what the scale costs in first-shot passes (ΔE00 ≤ 1.0).

    python benchmarks/weighing.py [--recipes 500] [--seed 7] [--can 250g:0.1,100g:0.1,1kg:1]
                                  [--targets 100 [--harness-seed 4242]] [--json]
"""

from __future__ import annotations

import argparse
import copy
import json
import time

import numpy as np

from _matcher import generated_recipes, shipped_matcher
from flakelab.match.evaluate import harness_trials, worst_share
from flakelab.match.recipe import (
    RecipeError,
    parse_quantity,
    weigh,
    weigh_additions,
    weigh_for_colour,
)


def cans(text: str) -> list[tuple[str, float, float]]:
    """``"250g:0.1,1kg:1"`` → (label, grams, resolution) per can."""
    parsed = []
    for part in text.split(","):
        quantity, _, resolution = part.partition(":")
        parsed.append((part, parse_quantity(quantity), float(resolution or 0.1)))
    return parsed


def statistics(nearest: list[float], chosen: list[float], seconds: float) -> dict[str, float]:
    nearest, chosen = np.array(nearest), np.array(chosen)
    return {
        "weighed": int(nearest.size),
        "nearest_mean": round(float(nearest.mean()), 4),
        "chosen_mean": round(float(chosen.mean()), 4),
        "nearest_p95": round(float(np.percentile(nearest, 95)), 4),
        "chosen_p95": round(float(np.percentile(chosen, 95)), 4),
        "nearest_max": round(float(nearest.max()), 4),
        "chosen_max": round(float(chosen.max()), 4),
        "share_closer": round(float(np.mean(chosen < nearest - 1e-6)), 3),
        "never_further": bool(np.all(chosen <= nearest + 1e-6)),
        "ms_per_weighing": round(1000 * seconds / nearest.size, 2),
    }


def whole_cans(forward, recipes: list[dict], grams: float, resolution: float) -> dict:
    nearest, chosen, refused = [], [], 0
    start = time.perf_counter()
    for shares in recipes:
        try:
            weighing = weigh_for_colour(forward, shares, grams, resolution)
        except RecipeError:  # a trace too small for this can and scale
            refused += 1
            continue
        nearest.append(weighing.nearest_de00)
        chosen.append(weighing.rounding_de00)
    return statistics(nearest, chosen, time.perf_counter() - start) | {"too_small": refused}


def additions(forward, recipes: list[dict], grams: float, resolution: float, rng) -> dict:
    nearest, chosen = [], []
    start = time.perf_counter()
    for shares in recipes:
        try:
            can = {ln.toner: ln.grams for ln in weigh(shares, grams, resolution)}
        except RecipeError:
            continue
        pigments = [n for n in can if not n.startswith(("Al ", "Pearl", "Xirallic"))] or list(can)
        picked = rng.choice(pigments, size=min(len(pigments), rng.integers(1, 4)), replace=False)
        added = {str(n): float(np.exp(rng.uniform(np.log(5e-4), np.log(1e-2)))) for n in picked}
        weighing = weigh_additions(forward, can, added, resolution)
        nearest.append(weighing.nearest_de00)
        chosen.append(weighing.rounding_de00)
    return statistics(nearest, chosen, time.perf_counter() - start)


def sprayed(world, forward, effect, targets: int, seed: int, grams: float, resolution: float):
    """First-shot pass rates of the harness's best recipes sprayed as computed, as the nearest
    grams and as rounded for colour, each on the same stream; paired differences."""
    from flakelab.core.tolerance import tolerance_preset
    from flakelab.match.judging import recipe_vector
    from flakelab.match.search import match

    tolerance = tolerance_preset("de00-1.0")
    shares = {"computed": [], "nearest grams": [], "rounded for colour": []}
    for _, t in harness_trials(world, targets, seed, forward.novel):
        found = match(t.target, forward, effect, tolerance=tolerance, library=world.library)
        best = found.candidates[0]
        nearest = {ln.toner: ln.grams for ln in weigh(best.fractions, grams, resolution)}
        chosen = weigh_for_colour(forward, best.fractions, grams, resolution).grams
        for key, recipe in zip(shares, (best.fractions, nearest, chosen), strict=True):
            x = recipe_vector(forward, recipe)
            spray = t.spray(x / x.sum(), copy.deepcopy(t.streams[0]))
            shares[key].append(worst_share(tolerance, forward.geometries, t.target, spray))
    passed = {k: np.array(v) <= 1.0 for k, v in shares.items()}
    rows = {k: {"first_shot_success": float(v.mean())} for k, v in passed.items()}
    for key in ("nearest grams", "rounded for colour"):
        paired = passed[key].astype(float) - passed["computed"]
        rows[key]["vs_computed"] = round(float(paired.mean()), 3)
        rows[key]["vs_computed_se"] = round(float(paired.std() / np.sqrt(paired.size)), 3)
        worst = np.array(shares[key]) - np.array(shares["computed"])
        rows[key]["worst_share_vs_computed_median"] = round(float(np.median(worst)), 4)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--recipes", type=int, default=500)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--can", default="250g:0.1,100g:0.1,1kg:1")
    parser.add_argument("--targets", type=int, default=0)
    parser.add_argument("--harness-seed", type=int, default=4242)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()

    world, forward, effect = shipped_matcher("shop")
    rng = np.random.default_rng(args.seed)
    recipes = generated_recipes(world, forward, args.recipes, rng)
    rows = {}
    for label, grams, resolution in cans(args.can):
        rows[f"{label} whole can"] = whole_cans(forward, recipes, grams, resolution)
        rows[f"{label} additions"] = additions(forward, recipes, grams, resolution, rng)
    report = {"recipes": args.recipes, "seed": args.seed, "model": forward.name, "rows": rows}
    if args.targets:
        label, grams, resolution = cans(args.can)[0]
        report["sprayed"] = {"targets": args.targets, "seed": args.harness_seed, "can": label}
        report["sprayed"]["rows"] = sprayed(
            world, forward, effect, args.targets, args.harness_seed, grams, resolution
        )
    if args.json:
        print(json.dumps(report, indent=2))
        return
    print(f"{args.recipes} generated recipes, seed {args.seed}; ΔE00 of rounding, worst geometry")
    for label, row in rows.items():
        print(
            f"{label:24s} nearest mean {row['nearest_mean']:.3f} p95 {row['nearest_p95']:.3f} "
            f"max {row['nearest_max']:.2f} | chosen mean {row['chosen_mean']:.3f} "
            f"p95 {row['chosen_p95']:.3f} max {row['chosen_max']:.2f} | closer in "
            f"{row['share_closer']:.0%}, never further: {row['never_further']}, "
            f"{row['ms_per_weighing']:.1f} ms each"
        )
    if args.targets:
        can = report["sprayed"]["can"]
        print(f"sprayed, {args.targets} harness targets of seed {args.harness_seed}, {can}:")
        for key, row in report["sprayed"]["rows"].items():
            paired = (
                f"  {row['vs_computed']:+.3f} ± {row['vs_computed_se']:.3f} vs computed"
                if "vs_computed" in row
                else ""
            )
            print(f"  {key:20s} first shot {row['first_shot_success']:.3f}{paired}")


if __name__ == "__main__":
    main()
