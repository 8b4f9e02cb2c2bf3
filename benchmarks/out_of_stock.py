"""What a toner out of stock costs the shop: the harness run twice on the same targets, with
every toner (the baseline, measured in the same run) and without ``--without`` (``flakelab
match evaluate --without NAME``), compared target by target on those whose paint holds the
missing toner, where it can cost; on the others the two runs differ only by the search's
own path.

    python benchmarks/out_of_stock.py --without "Perylene maroon" [--targets 200]
        [--seed 4242] [--json]
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np

from _matcher import add_harness_arguments, mean_and_se, shipped_matcher, timed_harness
from flakelab.match.settings import MatchSettings
from timing import print_report


def paired(rows_all: list[dict], rows_without: list[dict], key: str, chosen) -> dict:
    """The pass rate of ``key`` (share ≤ 1) on the ``chosen`` targets, both runs, and the
    paired difference with its standard error."""
    a = np.array([r[key] <= 1.0 for r, c in zip(rows_all, chosen, strict=True) if c], float)
    b = np.array([r[key] <= 1.0 for r, c in zip(rows_without, chosen, strict=True) if c], float)
    diff = b - a
    se = mean_and_se(diff)[1]
    return {
        "with_every_toner": round(float(a.mean()), 3) if a.size else None,
        "without": round(float(b.mean()), 3) if b.size else None,
        "difference": round(float(diff.mean()), 3) if diff.size else None,
        "difference_se": se and round(se, 3),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--without", action="append", required=True, help="toner out of stock")
    add_harness_arguments(parser, targets=200, novel_targets=0)
    args = parser.parse_args()

    world, forward, effect = shipped_matcher(
        args.world, args.model, args.kinds, white_pearls=args.white_pearls
    )
    novel = forward.novel  # as the harness: the hidden targets hold only toners it knows
    every, seconds_all = timed_harness(world, forward, effect, args, novel, "every toner",
                                       per_target=True)  # fmt: skip
    settings = replace(MatchSettings(), without=tuple(args.without))
    lacking, seconds_without = timed_harness(world, forward, effect, args, novel, "without",
                                             settings=settings, per_target=True)  # fmt: skip
    rows_all = every["per_target"][: args.targets]  # the targets with a new toner apart
    rows_without = lacking["per_target"][: args.targets]
    needing = [r["needs_missing"] for r in rows_without]
    report = {"without": args.without, "targets": args.targets, "seed": args.seed}
    report["targets_needing_it"] = int(sum(needing))
    for key, label in (("first", "first_shot"), ("corrected", "after_one_correction")):
        report[f"{label}_needing_it"] = paired(rows_all, rows_without, key, needing)
        others = [not n for n in needing]
        report[f"{label}_others"] = paired(rows_all, rows_without, key, others)
    report["oracle_needing_it"] = paired(rows_all, rows_without, "oracle", needing)["without"]
    report["wall_s"] = round(seconds_all + seconds_without, 1)
    print_report(report, args.json)


if __name__ == "__main__":
    main()
