"""Whether a change of a shop's habits is seen, and where: false alarms in steady shops, and
changes found and placed.

For each number of spray-outs (``--cases``) and ``--repeats`` draws, the cases of a steady
shop (without habits, and with ``SHOP_WITH_HABITS``) and of shops that changed part-way
(``--at``: at that share of their cases; before it without habits, after it with them: 5 %
more film, flakes 4 % flatter, instrument 0.5 % high) are read in time order by
:func:`flakelab.match.habits.habits_drift`, against the shipped model. Two ways are
compared on the same cases: the scan of every split (the default, :func:`change_scan`) and
the baseline of the same run, the two halves. Printed per size: the largest |z| of any habit
in the steady shops (and its 90th percentile over them) and the share of them flagged
(false alarms, at |z| > ``DRIFT_Z``); for each changed shop the share flagged, the median
and 90th percentile of the distance in cases of the split found from the change, and the
mean z of each habit.

``--tin-sprayouts K`` makes every shop's tins last K spray-outs (``WorldSettings``), so that
a new tin of a toner moves every later case that uses it, as a change of habits would;
``--tins calibrated|referenced|known`` makes the cases record their tins, and ``--at-tins`` reads
them at the standard tins, as ``flakelab cases habits`` does (else as poured from the
standard).

    python benchmarks/habits_drift.py [--cases 100,200,400,1000] [--at 0.5,0.8] [--repeats 5]
        [--tin-sprayouts K] [--tins none|calibrated|referenced|known] [--at-tins] [--json]

``flakelab cases habits`` looks for a change from ``MIN_DRIFT_CASES`` (100) spray-outs on;
smaller sizes (from 40) show why.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from _matcher import seeds_from
from flakelab.cases.generator import SHOP_WITH_HABITS, World, WorldSettings
from flakelab.io import read_library
from flakelab.library.lots import TIN_KNOWLEDGE
from flakelab.match.habits import DRIFT_Z, MIN_HABIT_CASES, habits_drift
from flakelab.match.lots import at_standard_tins
from flakelab.match.models import forward_for
from flakelab.models.registry import shipped_model
from flakelab.models.training import CaseArrays, generated_case_arrays
from timing import peak_rss_mb

LEAST = 2 * MIN_HABIT_CASES
"""Sizes below the command's own floor (``MIN_DRIFT_CASES``) may be tried: each half must
still be readable."""

WAYS = ("scan", "halves")


def joined(first: CaseArrays, second: CaseArrays, n: int, at: int) -> tuple[np.ndarray, ...]:
    """Recipes and spray-outs of ``n`` cases: the first ``at`` from ``first``, the rest from
    ``second``."""
    return (
        np.concatenate([first.x[:at], second.x[at:n]]),
        np.concatenate([first.R[:at], second.R[at:n]]),
    )


def drift(forward, library, x, R, way: str) -> dict:
    split = None if way == "scan" else len(x) // 2
    return habits_drift(forward, library, x, R, minimum=LEAST, split=split)


def summary(steady: list[dict], changed: dict[float, list[dict]], n: int) -> dict:
    """One way's figures at one size."""
    largest = [np.abs(d["z"]).max() for d in steady]
    row = {
        "steady_max_abs_z": float(max(largest)),
        "steady_p90_abs_z": float(np.percentile(largest, 90)),
        "steady_flagged": float(np.mean([d["changed"].any() for d in steady])),
    }
    for at, found in changed.items():
        errors = [abs(d["split"] - round(at * n)) for d in found]
        row[f"changed_at_{at:g}"] = {
            "flagged": float(np.mean([d["changed"].any() for d in found])),
            "split_error_cases": float(np.median(errors)),
            "split_error_p90_cases": float(np.percentile(errors, 90)),
            "mean_z": np.mean([d["z"] for d in found], 0).round(2).tolist(),
        }
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", default="100,200,400,1000", help="spray-outs read")
    parser.add_argument("--at", default="0.5,0.8", help="where the changed shops changed")
    parser.add_argument("--repeats", type=int, default=5, help="draws of each shop's cases")
    parser.add_argument("--seed", type=int, default=100, help="seed of the first draw")
    parser.add_argument("--tin-sprayouts", type=int, default=1, help="spray-outs a tin serves")
    parser.add_argument("--tins", choices=TIN_KNOWLEDGE, default="none", help="cases record")
    parser.add_argument("--at-tins", action="store_true", help="read at the standard tins")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    sizes = seeds_from(args.cases)
    positions = [float(a) for a in args.at.split(",")]
    start = time.perf_counter()
    library = read_library(None)
    forward = forward_for(shipped_model("five-angle"), library)

    def draws(habits: dict) -> list[CaseArrays]:
        settings = WorldSettings(**habits, tins=args.tins, tin_sprayouts=args.tin_sprayouts)
        world = World(library, "five-angle", settings, exclude=forward.novel)
        made = [
            generated_case_arrays(world, max(sizes), args.seed + r) for r in range(args.repeats)
        ]
        return [at_standard_tins(d, library) if args.at_tins else d.without_tins() for d in made]

    plain, with_habits = draws({}), draws(SHOP_WITH_HABITS)
    rows = []
    for n in sizes:
        row: dict = {"cases": n}
        for way in WAYS:
            steady = [
                drift(forward, library, c.x[:n], c.R[:n], way) for c in (*plain, *with_habits)
            ]
            changed = {
                at: [
                    drift(forward, library, *joined(a, b, n, round(at * n)), way)
                    for a, b in zip(plain, with_habits, strict=True)
                ]
                for at in positions
            }
            row[way] = summary(steady, changed, n)
        rows.append(row)
        if not args.json:
            print_row(row, positions)
    report = {
        "drift_z": DRIFT_Z,
        "repeats": args.repeats,
        "tin_sprayouts": args.tin_sprayouts,
        "tins": args.tins,
        "at_tins": args.at_tins,
        "rows": rows,
    }
    report["seconds"] = time.perf_counter() - start
    report["peak_rss_gb"] = peak_rss_mb() / 1024
    if args.json:
        print(json.dumps(report, indent=2))
        return
    print(f"threshold |z| > {DRIFT_Z:g}; {report['seconds']:.0f} s, {report['peak_rss_gb']:.2f} GB")


def print_row(row: dict, positions: list[float]) -> None:
    for way in WAYS:
        r = row[way]
        line = (
            f"{row['cases']:5d} cases {way:6s}  steady: max |z| {r['steady_max_abs_z']:.2f} "
            f"(90 % under {r['steady_p90_abs_z']:.2f}), "
            f"flagged {r['steady_flagged']:.0%}"
        )
        for at in positions:
            c = r[f"changed_at_{at:g}"]
            line += (
                f"  changed at {at:g}: flagged {c['flagged']:.0%}, split off by "
                f"{c['split_error_cases']:.0f} (90 % within {c['split_error_p90_cases']:.0f}), "
                f"z {c['mean_z']}"
            )
        print(line, flush=True)


if __name__ == "__main__":
    main()
