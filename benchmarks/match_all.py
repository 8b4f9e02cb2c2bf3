"""``match --all`` shared out over processes (:mod:`flakelab.match.batch`): the wall time to
match a file of harness targets in this process alone (the baseline, measured in the same
run) and shared out over ``--jobs`` processes, this one among them, the workers' start
included; and whether every recipe came out the same.

    python benchmarks/match_all.py [--targets 24] [--jobs N] [--seed 4242] [--json]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from _matcher import shipped_matcher
from flakelab.match.batch import match_readings, workers_for
from flakelab.match.evaluate import harness_trials
from flakelab.match.settings import MatchSettings
from timing import matmul_gflops, print_report


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--targets", type=int, default=24)
    parser.add_argument("--jobs", type=int, default=None, help="default: one per core")
    parser.add_argument("--seed", type=int, default=4242)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()

    world, forward, effect = shipped_matcher()
    readings = [t.measurement() for _, t in harness_trials(world, args.targets, args.seed)]
    jobs = workers_for(len(readings), args.jobs)
    settings = MatchSettings()
    match_readings(readings[:1], forward, effect, settings=settings)  # compiled, warm
    report = {"targets": len(readings), "jobs": jobs, "gflops": round(matmul_gflops())}
    runs = {}
    for label, n in (("alone", 1), ("shared", jobs)):
        start = time.perf_counter()
        runs[label] = match_readings(readings, forward, effect, jobs=n, settings=settings)
        report[f"{label}_s"] = round(time.perf_counter() - start, 2)
    report["speedup"] = round(report["alone_s"] / report["shared_s"], 2)
    report["same_recipes"] = all(
        a.candidates[0].fractions == b.candidates[0].fractions
        and np.array_equal(a.candidates[0].reflectance, b.candidates[0].reflectance)
        for a, b in zip(runs["alone"], runs["shared"], strict=True)
    )
    print_report(report, args.json)


if __name__ == "__main__":
    main()
