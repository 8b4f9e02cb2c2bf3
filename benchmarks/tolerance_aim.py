"""Matcher: does aiming the search at the colorist's tolerance pass it more often?

The matcher's objective counts each geometry's error as a share of the tolerance's limit
there, with its kL, kC, kH (:mod:`flakelab.match.objective`). Before, it aimed at ΔE00 at
every geometry alike, whatever the tolerance. For each hidden target of the harness
(``flakelab match evaluate``'s shop world and trials), two matches, one aimed at the
tolerance and one at ΔE00 ≤ 1.0 everywhere (the baseline, today's ``de00-1.0`` objective);
each first recipe is sprayed ``--sprays`` times on the same random streams, so that the two
differ only by recipe, and every spray is judged by the tolerance. Printed per tolerance:
the share of sprays that pass for each aim, the paired difference and its standard error
over targets, and the recipes' own predicted share of the limit.

    python benchmarks/tolerance_aim.py [--targets 60] [--sprays 6] [--seed 4242]
        [--tolerance refinish components lightness] [--component-norm 8] [--json]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

import flakelab.match.objective as objective
from _matcher import shipped_matcher
from flakelab.core.tolerance import Limit, Tolerance, tolerance_preset
from flakelab.match.evaluate import harness_trials, worst_share
from flakelab.match.judging import recipe_vector
from flakelab.match.search import match

TOLERANCES = {
    "refinish": tolerance_preset("refinish"),
    "components": tolerance_preset("components"),
    "lightness": Tolerance(
        "lightness", Limit(de00=1.0), kL=2.0, description="ΔE00 (2:1:1) ≤ 1.0 everywhere"
    ),
}
"""The tolerances judged: the CLI's default, the component preset and CIEDE2000 with
lightness weighted down (kL = 2, as in textile practice)."""


def first_shots(world, forward, effect, tolerance: Tolerance, args) -> dict:
    """Per target, the pass rate of the recipe aimed at ``tolerance`` and of the one aimed at
    ΔE00 ≤ 1.0, sprayed on the same streams."""
    baseline = tolerance_preset(objective.OBJECTIVE_DEFAULT)
    rates = {"aimed": [], "baseline": []}
    predicted = {"aimed": [], "baseline": []}
    for i, (_, t) in enumerate(harness_trials(world, args.targets, args.seed, forward.novel)):
        for key, aim in (("aimed", tolerance), ("baseline", baseline)):
            best = match(t.target, forward, effect, tolerance=aim).candidates[0]
            x = recipe_vector(forward, best.fractions)
            sprays = [
                worst_share(tolerance, forward.geometries, t.target, t.spray(x, stream))
                for stream in (np.random.default_rng([args.seed, i, k]) for k in range(args.sprays))
            ]
            rates[key].append(np.mean(np.array(sprays) <= 1.0))
            judged = tolerance.judge(forward.geometries, best.target_lab, best.lab)
            share = tolerance.share_of_limit(forward.geometries, de00=judged[0], dLCH=judged[1])
            predicted[key].append(float(share.max()))
    difference = np.subtract(rates["aimed"], rates["baseline"])
    return {
        "aimed_pass": float(np.mean(rates["aimed"])),
        "baseline_pass": float(np.mean(rates["baseline"])),
        "difference": float(difference.mean()),
        "difference_se": float(difference.std(ddof=1) / np.sqrt(len(difference))),
        "targets_changed": int(np.count_nonzero(difference)),
        "aimed_predicted_share_median": float(np.median(predicted["aimed"])),
        "baseline_predicted_share_median": float(np.median(predicted["baseline"])),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--targets", type=int, default=60)
    parser.add_argument("--sprays", type=int, default=6, help="sprays of each first recipe")
    parser.add_argument("--seed", type=int, default=4242)
    parser.add_argument(
        "--tolerance", nargs="+", choices=list(TOLERANCES), default=list(TOLERANCES)
    )
    parser.add_argument(
        "--component-norm",
        type=float,
        default=objective.COMPONENT_NORM,
        help="p of the smooth maximum over the components' shares of their limits",
    )
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    objective.COMPONENT_NORM = args.component_norm
    start = time.perf_counter()
    world, forward, effect = shipped_matcher("shop")
    report = {
        "targets": args.targets,
        "sprays": args.sprays,
        "seed": args.seed,
        "component_norm": args.component_norm,
        "tolerances": {
            name: first_shots(world, forward, effect, TOLERANCES[name], args)
            for name in args.tolerance
        },
    }
    report["seconds"] = time.perf_counter() - start
    if args.json:
        print(json.dumps(report, indent=2))
        return
    print(f"{args.targets} targets × {args.sprays} sprays, seed {args.seed}: pass rates")
    for name, r in report["tolerances"].items():
        print(
            f"{name:11s} aimed at it {r['aimed_pass']:.3f}  aimed at ΔE00 ≤ 1 (baseline) "
            f"{r['baseline_pass']:.3f}  difference {r['difference']:+.3f} ± "
            f"{r['difference_se']:.3f} ({r['targets_changed']} targets differ); predicted "
            f"worst share of the limit, median {r['aimed_predicted_share_median']:.2f} vs "
            f"{r['baseline_predicted_share_median']:.2f}"
        )
    print(f"{report['seconds']:.0f} s")


if __name__ == "__main__":
    main()
