"""A toner poured by mistake: how far the can misses its recipe when the rest is poured as
planned, and after the additions that ``flakelab weigh --poured`` computes to dilute it
(``flakelab.match.correction.correct_what_was_poured``).

Recipes are the generated world's OEM-like formulations, each weighed for a 250 g can on a
0.1 g scale. Into each can its largest toner is poured, then a pigment the recipe lacks,
drawn at random, 0.2 to 3 g (log-uniform). Each can is judged twice, the worst geometry's
ΔE00 against the recipe:

* by the shipped model, which computed the additions (what the command reports);
* by the world's own physics (the library's coating optics at the shop's mean application,
  no batch or instrument noise), which the model only learned: whether the dilution holds in
  the world the model was trained on, not only in the model.

Those rows are the learned model's dilution (``weigh --poured --no-physics-check``). Where
the model's networks disagree on the can or its recipe by over
:data:`~flakelab.match.settings.MODEL_SPREAD_NOTICE` ΔE00, ``weigh --poured`` dilutes through
the library's physics instead (the physics check); the ``checked`` rows are that default's,
judged by the world's physics, and the figures of the cans it checked are paired with the
model's. In this world the library's physics is the world's own: an exact library. With
``--miscalibrated`` the checked cans are diluted once more through a library off by one lot
per pigment (``benchmarks/physics_check.py``'s, drawn from ``--seed``).

With ``--most G`` each can is also diluted within a can of at most G grams (``weigh --poured
--most``): what a bound on the can's size costs in colour.

    python benchmarks/poured_by_mistake.py [--recipes 100] [--seed 11] [--most 300]
        [--miscalibrated] [--json]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from _matcher import generated_recipes, shipped_matcher
from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E
from flakelab.match.correction import correct_what_was_poured
from flakelab.match.judging import recipe_vector
from flakelab.match.recipe import parse_quantity
from flakelab.match.settings import CAN_QUANTITY, SCALE_RESOLUTION_G
from physics_check import lot_errors, physics_off_by, rms_error

CAN_G, RESOLUTION_G = parse_quantity(CAN_QUANTITY), SCALE_RESOLUTION_G
STRAY_G = (0.2, 3.0)
ROWS = ("model_as_planned", "model_after", "model_within_most", "physics_as_planned",
        "physics_after", "physics_within_most", "checked_after")  # fmt: skip
CHECKED_ROWS = ("physics_after", "checked_after", "off_after")
"""The cans the physics checked, judged by the world's physics: the model's dilution, the
check's through the exact library, and (``--miscalibrated``) through one off by a lot."""


def physics_worst(world, forward, recipe: dict, held: dict) -> float:
    """The worst geometry's ΔE00 of ``held`` against ``recipe`` by the world's physics."""
    x = np.stack([recipe_vector(forward, recipe), recipe_vector(forward, held)])
    R, _ = world.appearance(x / x.sum(1, keepdims=True), world.nominal(2, at_shop=True))
    lab = reflectance_to_Lab(R)
    return float(delta_E(lab[0], lab[1]).max())


def one_can(world, forward, recipe: dict, rng, most_g: float | None, off=None) -> dict:
    """A can with a stray pigment, before and after the dilution (and within ``most_g``),
    by model and physics; diluted as checked, and where the physics checked it, through the
    library off by a lot (``off``: :func:`physics_off_by`'s context, or None)."""
    pigments = [t.name for t in world.library.toners if t.kind == "pigment"]
    strays = [n for n in pigments if n not in recipe and n in forward.toners]
    stray = str(rng.choice(strays))
    grams = float(np.exp(rng.uniform(*np.log(STRAY_G))))
    largest = max(recipe, key=recipe.get)
    poured = {largest: round(recipe[largest] * CAN_G, 1), stray: round(grams, 1)}
    start = time.perf_counter()  # weigh --poured's default
    checked = correct_what_was_poured(
        forward, recipe, CAN_G, poured, RESOLUTION_G, library=world.library
    )
    seconds = time.perf_counter() - start
    found = checked  # the model's own, but where the physics stood in for it
    if checked.model_spread is not None:
        found = correct_what_was_poured(
            forward, recipe, CAN_G, poured, RESOLUTION_G, physics_check=False
        )
    row = {
        "physics_checked": checked.model_spread is not None,
        "checked_after": physics_worst(world, forward, recipe, checked.holds),
        "checked_passes": bool(checked.passes.all()),
    }
    if off is not None and row["physics_checked"]:
        with off():
            found_off = correct_what_was_poured(
                forward, recipe, CAN_G, poured, RESOLUTION_G, library=world.library
            )
        row["off_after"] = physics_worst(world, forward, recipe, found_off.holds)
    if most_g is not None:
        bounded = correct_what_was_poured(
            forward, recipe, CAN_G, poured, RESOLUTION_G, most_g=most_g
        )
        row |= {
            "model_within_most": float(bounded.expected_de00.max()),
            "physics_within_most": physics_worst(world, forward, recipe, bounded.holds),
            "can_g_within_most": sum(bounded.holds.values()),
        }
    return row | {
        "stray_g": poured[stray],
        "model_as_planned": float(found.as_planned_de00.max()),
        "model_after": float(found.expected_de00.max()),
        "physics_as_planned": physics_worst(world, forward, recipe, found.as_planned),
        "physics_after": physics_worst(world, forward, recipe, found.holds),
        "passes": bool(found.passes.all()),
        "can_g": sum(found.holds.values()),
        "seconds": seconds,
    }


def summary(rows: list[dict]) -> dict:
    def column(key):
        return np.array([r[key] for r in rows])

    out = {"cans": len(rows)}
    for key in [k for k in ROWS if k in rows[0]]:
        values = column(key)
        out[key] = {
            "median": round(float(np.median(values)), 3),
            "p90": round(float(np.percentile(values, 90)), 3),
            "within_1": round(float(np.mean(values <= 1.0)), 3),
        }
    out["said_to_pass"] = round(float(column("passes").mean()), 3)
    passed = column("passes")
    out["physics_within_1_when_said_to_pass"] = (
        round(float(np.mean(column("physics_after")[passed] <= 1.0)), 3) if passed.any() else None
    )
    out["can_g_median"] = round(float(np.median(column("can_g"))), 1)
    out["can_g_p90"] = round(float(np.percentile(column("can_g"), 90)), 1)
    if "can_g_within_most" in rows[0]:
        out["can_g_within_most_max"] = round(float(column("can_g_within_most").max()), 1)
    out["seconds_median"] = round(float(np.median(column("seconds"))), 3)
    out["checked_said_to_pass"] = round(float(column("checked_passes").mean()), 3)
    passed = column("checked_passes")
    out["checked_physics_within_1_when_said_to_pass"] = (
        round(float(np.mean(column("checked_after")[passed] <= 1.0)), 3) if passed.any() else None
    )
    return out | {"physics_checked": checked_summary(rows)}


def checked_summary(rows: list[dict]) -> dict:
    """The cans the physics checked, each of :data:`CHECKED_ROWS` by the world's physics:
    median, share within 1.0 and the mean change from the model's dilution (paired)."""
    mine = [r for r in rows if r["physics_checked"]]
    out: dict = {"cans": len(mine)}
    if not mine:
        return out
    learned = np.array([r["physics_after"] for r in mine])
    for key in [k for k in CHECKED_ROWS if k in mine[0]]:
        values = np.array([r[key] for r in mine])
        change = values - learned
        out[key] = {
            "median": round(float(np.median(values)), 3),
            "within_1": round(float(np.mean(values <= 1.0)), 3),
            "mean_change": round(float(change.mean()), 3),
            "mean_change_se": round(float(change.std(ddof=1) / np.sqrt(change.size)), 3)
            if change.size > 1
            else None,
        }
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--recipes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=11)
    parser.add_argument("--most", type=float, default=None, help="grams the can may hold")
    parser.add_argument(
        "--miscalibrated",
        action="store_true",
        help="the checked cans diluted once more through a library off by one lot per pigment",
    )
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()

    world, forward, _ = shipped_matcher("shop")
    rng = np.random.default_rng(args.seed)
    recipes = generated_recipes(world, forward, args.recipes, rng)
    off, library_error = None, None
    if args.miscalibrated:
        strength, shade = lot_errors(world.library, args.seed)
        library_error = rms_error(world.library, strength, shade)

        def off():
            return physics_off_by(forward, world.library, strength, shade)

    rows = [one_can(world, forward, recipe, rng, args.most, off) for recipe in recipes]
    report = {"recipes": args.recipes, "seed": args.seed, "most_g": args.most}
    report["model"] = forward.name
    report["library_error"] = library_error
    report |= summary(rows)
    if args.json:
        print(json.dumps(report, indent=2))
        return
    print(
        f"{args.recipes} generated recipes, seed {args.seed}, {CAN_G:g} g cans, a stray pigment "
        f"{STRAY_G[0]}–{STRAY_G[1]} g; worst-geometry ΔE00 against the recipe"
    )
    for key in [k for k in ROWS if k in report]:
        row = report[key]
        print(
            f"  {key:20s} median {row['median']:.2f}  p90 {row['p90']:.2f}  "
            f"within 1.0: {row['within_1']:.0%}"
        )
    print(
        f"  said to pass {report['said_to_pass']:.0%}; of those, within 1.0 by the physics "
        f"{report['physics_within_1_when_said_to_pass']:.0%}; can median "
        f"{report['can_g_median']:.0f} g (p90 {report['can_g_p90']:.0f} g); "
        f"{report['seconds_median']:.2f} s a can"
    )
    if args.most is not None:
        largest = report["can_g_within_most_max"]
        print(f"  within --most {args.most:g} g: the largest can {largest} g")
    print_checked(report)


def print_checked(report: dict) -> None:
    checked = report["physics_checked"]
    print(
        f"  checked (weigh --poured's default): said to pass {report['checked_said_to_pass']:.0%}"
        f", of those within 1.0 by the physics "
        f"{report['checked_physics_within_1_when_said_to_pass']:.0%}; the physics checked "
        f"{checked['cans']} cans, the model's networks unsure of the can or its recipe"
    )
    names = {"physics_after": "the model's dilution", "checked_after": "checked, exact library",
             "off_after": "checked, library off by a lot"}  # fmt: skip
    for key in [k for k in CHECKED_ROWS if k in checked]:
        row = checked[key]
        print(
            f"    {names[key]:30s} median {row['median']:.2f}  within 1.0: {row['within_1']:.0%}"
            f"  mean change {row['mean_change']:+.2f}"
        )


if __name__ == "__main__":
    main()
