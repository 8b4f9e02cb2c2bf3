"""Whether a change of a shop's habits is seen: false alarms in steady shops, and changes found.

For each number of spray-outs (``--cases``) and ``--repeats`` draws, the cases of a steady
shop (without habits, and with ``SHOP_WITH_HABITS``) and of a shop that changed half-way
(its first half without habits, its second with them: 5 % more film, flakes 4 % flatter,
instrument 0.5 % high) are split in time order and read apart
(:func:`flakelab.match.habits.habits_drift`, against the shipped model). Printed per size:
the largest |z| of any habit in the steady shops and the share of them flagged (false
alarms, at |z| > ``DRIFT_Z``), and for the changed shop the share flagged and the mean z
of each habit.

    python benchmarks/habits_drift.py [--cases 100,200,400,1000] [--repeats 5] [--json]

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
from flakelab.match.habits import DRIFT_Z, MIN_HABIT_CASES, habits_drift
from flakelab.match.models import forward_for
from flakelab.models.registry import shipped_model
from flakelab.models.training import CaseArrays, generated_case_arrays

LEAST = 2 * MIN_HABIT_CASES
"""Sizes below the command's own floor (``MIN_DRIFT_CASES``) may be tried: each half must
still be readable."""


def joined(first: CaseArrays, second: CaseArrays, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Recipes and spray-outs of ``n`` cases: the first half from ``first``, the rest from
    ``second``."""
    half = n // 2
    return (
        np.concatenate([first.x[:half], second.x[: n - half]]),
        np.concatenate([first.R[:half], second.R[: n - half]]),
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", default="100,200,400,1000", help="spray-outs read")
    parser.add_argument("--repeats", type=int, default=5, help="draws of each shop's cases")
    parser.add_argument("--seed", type=int, default=100, help="seed of the first draw")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    sizes = seeds_from(args.cases)
    start = time.perf_counter()
    library = read_library(None)
    forward = forward_for(shipped_model("five-angle"), library)

    def draws(habits: dict) -> list[CaseArrays]:
        world = World(library, "five-angle", WorldSettings(**habits), exclude=forward.novel)
        n = max(sizes)
        return [generated_case_arrays(world, n, args.seed + r) for r in range(args.repeats)]

    plain, with_habits = draws({}), draws(SHOP_WITH_HABITS)
    rows = []
    for n in sizes:
        steady = [
            habits_drift(forward, library, c.x[:n], c.R[:n], minimum=LEAST)
            for c in (*plain, *with_habits)
        ]
        changed = [
            habits_drift(forward, library, *joined(a, b, n), minimum=LEAST)
            for a, b in zip(plain, with_habits, strict=True)
        ]
        rows.append(
            {
                "cases": n,
                "steady_max_abs_z": float(max(np.abs(d["z"]).max() for d in steady)),
                "steady_flagged": float(np.mean([d["changed"].any() for d in steady])),
                "changed_flagged": float(np.mean([d["changed"].any() for d in changed])),
                "changed_mean_z": np.mean([d["z"] for d in changed], 0).round(2).tolist(),
            }
        )
        if not args.json:
            r = rows[-1]
            print(
                f"{n:5d} cases  steady shops: max |z| {r['steady_max_abs_z']:.2f}, flagged "
                f"{r['steady_flagged']:.0%}  changed shop: flagged {r['changed_flagged']:.0%}, "
                f"mean z film/spread/gain {r['changed_mean_z']}",
                flush=True,
            )
    report = {"drift_z": DRIFT_Z, "repeats": args.repeats, "rows": rows}
    report["seconds"] = time.perf_counter() - start
    if args.json:
        print(json.dumps(report, indent=2))
        return
    print(f"threshold |z| > {DRIFT_Z:g}; {report['seconds']:.0f} s")


if __name__ == "__main__":
    main()
