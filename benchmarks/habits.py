"""A shop's habits read from its spray-outs: how many it takes, and what they buy the model.

The shop (by default ``SHOP_WITH_HABITS``: 5 % more film, flakes 4 % flatter, instrument
0.5 % high) gives its first N cases (``--cases``); its habits are estimated against the
shipped model (``flakelab cases habits``' library call), for ``--repeats`` draws of the
shop's cases, with the prior ``PRIOR_SD`` (``--no-prior``: without). Each estimate is judged
two ways:

* against the truth: the habits' mean ± s.d. over the draws, and the share of draws whose
  truth lies within two standard errors the estimate states (its coverage);
* by what it buys: ΔE00 (mean over cases × geometries) of the model's predictions plus the
  habits' offset against ``--test`` fresh spray-outs of the shop, against the model alone
  (the baseline) and with the true habits (the most three numbers can buy).

That last figure compares with ``benchmarks/adaptation.py``, which retrains the network on
the same shop's cases. ``--no-habits`` runs a shop without habits of its own.
``--against physics`` reads the habits against the world's own physics at its nominal
application instead of the learned model: the estimator alone, without the model's error
(a bias there is the estimator's; a bias only against the model is the model's).

``--tins calibrated|referenced|known`` makes the shop's cases record the tins they were poured
from (as ``cases generate --tins``): its habits are read at the standard tins, as ``flakelab cases
habits`` reads them (:func:`~flakelab.match.lots.at_standard_tins`), and the fresh
spray-outs are judged for their tins; with ``--no-tins`` the habits are read from the same
cases taken as poured from the standard (``cases habits --no-tins``), the baseline.

    python benchmarks/habits.py [--cases 20,50,100,200,500,2000] [--repeats 5] [--no-prior]
        [--no-habits] [--against model|physics]
        [--tins none|calibrated|referenced|known [--no-tins]] [--json]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
import torch

from _matcher import seeds_from
from flakelab.cases.generator import SHOP_WITH_HABITS, World, WorldSettings
from flakelab.io import read_library
from flakelab.library.lots import TIN_KNOWLEDGE
from flakelab.match.habits import PRIOR_SD, ShopHabits, estimate_habits, habits_fit
from flakelab.match.lots import at_standard_tins
from flakelab.match.models import forward_for
from flakelab.models.registry import shipped_model
from flakelab.models.training import CaseArrays, generated_case_arrays
from timing import peak_rss_mb

KEYS = ("film_build", "log_flake_spread", "instrument_gain")
"""The habits as estimated (``ShopHabits.theta``)."""


class WorldPhysics:
    """The generated world's physics at its nominal application, as a forward model: what
    the habits are read against with ``--against physics``."""

    dtype = torch.float64
    novel: tuple[str, ...] = ()
    model_id = "the world's physics"

    def __init__(self, world: World) -> None:
        self.world = world
        self.toners = world.library.names
        self.geometries = world.geometries

    def __call__(self, fractions: torch.Tensor) -> tuple[torch.Tensor, None]:
        x = fractions.double().numpy()
        R, _ = self.world.appearance(x, self.world.nominal(len(x)))
        return torch.as_tensor(R), None


def error(forward, library, cases: CaseArrays, habits: ShopHabits) -> float:
    """ΔE00 mean of the model's predictions plus the habits' offset against the cases."""
    return float(habits_fit(forward, library, habits, cases.x, cases.R)["de00_habits"].mean())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", default="20,50,100,200,500,2000", help="shop cases read")
    parser.add_argument("--test", type=int, default=1000, help="fresh cases to judge on")
    parser.add_argument("--repeats", type=int, default=5, help="draws of the shop's cases")
    parser.add_argument("--seed", type=int, default=21, help="seed of the first draw")
    parser.add_argument("--no-habits", action="store_true", help="a shop like the world")
    parser.add_argument("--no-prior", action="store_true", help="read without PRIOR_SD")
    parser.add_argument("--against", choices=("model", "physics"), default="model")
    parser.add_argument("--tins", choices=TIN_KNOWLEDGE, default="none", help="cases record")
    parser.add_argument("--no-tins", action="store_true", help="read as poured from standard")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    sizes = seeds_from(args.cases)
    prior = None if args.no_prior else PRIOR_SD

    library = read_library(None)
    model = shipped_model("five-angle")
    forward = forward_for(model, library)
    habits = {} if args.no_habits else SHOP_WITH_HABITS
    settings = WorldSettings(**habits, tins=args.tins)
    world = World(library, "five-angle", settings, exclude=forward.novel)
    if args.against == "physics":
        forward = WorldPhysics(world)
    truth = np.array(
        [
            habits.get("shop_film_build", 1.0) - 1,
            np.log(habits.get("shop_spread", 1.0)),
            habits.get("shop_gain", 0.0),
        ]
    )
    test = at_standard_tins(generated_case_arrays(world, args.test, args.seed + 1000), library)
    draws = [generated_case_arrays(world, max(sizes), args.seed + r) for r in range(args.repeats)]
    draws = [d.without_tins() if args.no_tins else at_standard_tins(d, library) for d in draws]
    true_habits = ShopHabits(truth, np.zeros(3), 0)
    report = {
        "shop": habits or "no habits",
        "against": args.against,
        "tins": args.tins,
        "read_at_the_tins": args.tins != "none" and not args.no_tins,
        "prior_sd": None if prior is None else prior.tolist(),
        "test_cases": args.test,
        "model_alone_de00": error(forward, library, test, ShopHabits.none()),
        "true_habits_de00": error(forward, library, test, true_habits),
        "rows": [],
    }
    for n in sizes:
        estimates, errors, seconds = [], [], []
        for cases in draws:
            cases = cases.subset(np.arange(n))
            start = time.perf_counter()
            found = estimate_habits(forward, library, cases.x, cases.R, prior_sd=prior)
            seconds.append(time.perf_counter() - start)
            estimates.append((found.theta, found.standard_error))
            errors.append(error(forward, library, test, found))
        theta = np.array([t for t, _ in estimates])
        se = np.array([s for _, s in estimates])
        row = {"cases": n, "seconds": float(np.mean(seconds))}
        for k, key in enumerate(KEYS):
            row[key] = float(theta[:, k].mean())
            row[key + "_sd"] = float(theta[:, k].std(ddof=1)) if args.repeats > 1 else 0.0
            row[key + "_stated_se"] = float(se[:, k].mean())
            row[key + "_coverage"] = float(np.mean(np.abs(theta[:, k] - truth[k]) < 2 * se[:, k]))
        row["shop_de00"] = float(np.mean(errors))
        row["shop_de00_sd"] = float(np.std(errors, ddof=1)) if args.repeats > 1 else 0.0
        report["rows"].append(row)
        if not args.json:
            print(
                f"{n:5d} cases  film {row['film_build']:+.3f} ± {row['film_build_sd']:.3f}  "
                f"log spread {row['log_flake_spread']:+.4f} ± {row['log_flake_spread_sd']:.4f}  "
                f"gain {row['instrument_gain']:+.4f} ± {row['instrument_gain_sd']:.4f}  "
                f"coverage {row['film_build_coverage']:.1f}/{row['log_flake_spread_coverage']:.1f}/"
                f"{row['instrument_gain_coverage']:.1f}  ΔE00 {row['shop_de00']:.3f} ± "
                f"{row['shop_de00_sd']:.3f}  {1000 * row['seconds']:.0f} ms",
                flush=True,
            )
    report["peak_rss_mb"] = peak_rss_mb()
    if args.json:
        print(json.dumps(report, indent=2))
        return
    print(
        f"truth film {truth[0]:+.3f}, log spread {truth[1]:+.4f}, gain {truth[2]:+.4f}; "
        f"model alone ΔE00 {report['model_alone_de00']:.3f}, with the true habits "
        f"{report['true_habits_de00']:.3f} ({args.test} fresh cases); "
        f"peak RSS {report['peak_rss_mb']:.0f} MB"
    )


if __name__ == "__main__":
    main()
