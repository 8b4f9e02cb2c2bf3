"""The adaptation phase for one shop: how many of its cases it takes, and what the paper's 150
epochs and the default's best epoch do.

A shop has habits the generated world it learned from lacks (``WorldSettings.shop_*``): by
default ``SHOP_WITH_HABITS``, which sprays 5 % more film, lays its flakes 4 % flatter and
whose instrument reads 0.5 % high. The shipped model is adapted (``flakelab model adapt``'s
library call) to the first N of that shop's cases (``--cases``) in two ways:

* ``every epoch``: the paper's phase, all ``--epochs`` at the adaptation rate;
* ``best epoch``: the default, a fifth of the cases held out and the best epoch kept.

Each is judged by its ΔE00 (mean over cases × geometries) on ``--test`` fresh cases of the
same shop and of the generated world (what the shop's model forgets, which it does not need),
over ``--repeats`` adaptation seeds (mean ± s.d.). The baseline is the shipped model on the
same cases. ``--no-habits`` runs a shop without habits of its own, where adaptation has
nothing to learn and can only fit noise.

Against both, the habits read from the same N cases (``flakelab cases habits``' library call,
against the shipped model): the shipped model moved by them (``shipped_with_habits``), and
each adapted model moved by them as well (``habits_again``), which counts the habits twice;
the matcher no longer adds them to a model adapted to the shop
(``ShopHabits.learned_by``, stop 68).

    python benchmarks/adaptation.py [--cases 200,500,2000,5000] [--repeats 3] [--json]
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace

import numpy as np

from _matcher import seeds_from
from flakelab.cases.generator import SHOP_WITH_HABITS, World, WorldSettings
from flakelab.io import read_library
from flakelab.match.habits import PRIOR_SD, screened_habits
from flakelab.match.models import forward_for
from flakelab.models.registry import shipped_model
from flakelab.models.training import (
    CaseArrays,
    adapt_model,
    evaluate_model,
    generated_case_arrays,
    recorded_config,
)
from timing import peak_rss_mb

VARIANTS = {"every epoch": 0.0, "best epoch": 0.2}
"""Adaptation variants: the share of the shop's cases that chooses the epoch."""


def shop_cases(model, settings: WorldSettings, n: int, seed: int) -> CaseArrays:
    """``n`` cases of a shop with ``settings``' habits, without toners new to ``model``."""
    library = read_library(None)
    novel = model.new_toners
    world = World(library, model.instrument, settings, exclude=novel)
    return generated_case_arrays(world, n, seed, shop="benchmark shop")


def error(model, cases: CaseArrays, habits=None) -> float:
    """ΔE00 mean of ``model`` on ``cases``, its predictions moved by a shop's ``habits``."""
    if habits is None:
        return evaluate_model(model, cases)["de00_mean"]
    library = read_library(None)
    geometries = model.geometries

    def offset(x, R):
        return habits.offset(library, x, R, geometries)

    return evaluate_model(model, cases, lab_offset=offset)["de00_mean"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", default="200,500,2000,5000", help="shop cases to adapt on")
    parser.add_argument("--test", type=int, default=1000, help="fresh cases to judge on")
    parser.add_argument("--epochs", type=int, default=150, help="adaptation epochs")
    parser.add_argument("--repeats", type=int, default=3, help="adaptation seeds")
    parser.add_argument("--seed", type=int, default=21, help="seed of the shop's cases")
    parser.add_argument("--film-build", type=float, default=SHOP_WITH_HABITS["shop_film_build"])
    parser.add_argument("--spread", type=float, default=SHOP_WITH_HABITS["shop_spread"])
    parser.add_argument("--gain", type=float, default=SHOP_WITH_HABITS["shop_gain"])
    parser.add_argument("--no-habits", action="store_true", help="a shop like the world")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    sizes = seeds_from(args.cases)

    model = shipped_model("five-angle")
    habits = WorldSettings(
        shop_film_build=args.film_build, shop_spread=args.spread, shop_gain=args.gain
    )
    shop = WorldSettings() if args.no_habits else habits
    all_cases = shop_cases(model, shop, max(sizes), args.seed)
    shop_test = shop_cases(model, shop, args.test, args.seed + 1)
    world_test = shop_cases(model, WorldSettings(), args.test, args.seed + 2)
    report = {
        "shop": "no habits"
        if args.no_habits
        else {"film_build": args.film_build, "spread": args.spread, "gain": args.gain},  # fmt: skip
        "epochs": args.epochs,
        "test_cases": args.test,
        "shipped": {"shop": error(model, shop_test), "world": error(model, world_test)},
        "rows": [],
    }
    library, report["habits"] = read_library(None), {}
    for n in sizes:
        cases = all_cases.subset(np.arange(n))
        habits = screened_habits(forward_for(model, library), library, cases.x, cases.R,
                                 prior_sd=PRIOR_SD)[0]  # fmt: skip
        report["habits"][n] = habits.report() | {"shipped_with_habits": error(
            model, shop_test, habits)}  # fmt: skip
        for variant, share in VARIANTS.items():
            runs = []
            for repeat in range(args.repeats):
                config = replace(
                    recorded_config(model),
                    adapt_epochs=args.epochs,
                    adapt_validation=share,
                    seed=repeat,
                )
                start = time.perf_counter()
                adapted, adaptation = adapt_model(model, cases, config)
                seconds = time.perf_counter() - start
                scores = (error(adapted, shop_test), error(adapted, world_test))
                again = error(adapted, shop_test, habits)
                runs.append((*scores, again, adaptation["kept_epochs"], seconds))
            shop_error, world_error, again, kept, seconds = np.array(runs).T
            report["rows"].append(
                {
                    "cases": n,
                    "variant": variant,
                    "shop_de00_mean": float(shop_error.mean()),
                    "shop_de00_sd": float(shop_error.std(ddof=1)) if args.repeats > 1 else 0.0,
                    "world_de00_mean": float(world_error.mean()),
                    "habits_again_de00_mean": float(again.mean()),
                    "kept_epochs": kept.astype(int).tolist(),
                    "seconds": float(seconds.mean()),
                }
            )
            row = report["rows"][-1]
            if not args.json:
                print(
                    f"{n:6d} cases  {variant:11s}  shop {row['shop_de00_mean']:.3f} ± "
                    f"{row['shop_de00_sd']:.3f}  world {row['world_de00_mean']:.3f}  "
                    f"habits again {row['habits_again_de00_mean']:.3f}  "
                    f"kept {row['kept_epochs']}  {row['seconds']:.1f} s",
                    flush=True,
                )
    report["peak_rss_mb"] = peak_rss_mb()
    if args.json:
        print(json.dumps(report, indent=2))
        return
    shipped = report["shipped"]
    print(
        f"shipped, unadapted: shop {shipped['shop']:.3f}  world {shipped['world']:.3f} "
        f"(ΔE00 mean on {args.test} fresh cases each); peak RSS {report['peak_rss_mb']:.0f} MB"
    )
    for n, habits in report["habits"].items():
        print(f"shipped with the habits of {n} cases: shop {habits['shipped_with_habits']:.3f}")


if __name__ == "__main__":
    main()
