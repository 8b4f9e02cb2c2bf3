"""``flakelab cases nearest`` on a shop's database the size of the paper's (61,000 cases):
how long a colorist waits, and at what memory.

Generates ``--cases`` five-angle cases (seed ``--seed``) into a fresh SQLite file, then
times, as the command runs them: reading every case of the database at the instrument's
geometries (``load_s``), and ranking them against a car (``rank_s``,
:func:`~flakelab.cases.nearest.nearest_cases`: every spray-out in one colour computation),
against the baseline of the same run: the same ranking case by case (``loop_s``, each
spray-out's L*a*b* and the tolerance's judgement one at a time). The car is one case's own
spray-out read again with the instrument's noise, so the case it came from should come
first.

    python benchmarks/nearest_cases.py [--cases 61000] [--seed 5] [--json]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from flakelab.cases.case import cases_at
from flakelab.cases.database import add_cases, iter_cases, open_database
from flakelab.cases.generator import World
from flakelab.cases.nearest import nearest_cases
from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.geometry import INSTRUMENT_GEOMETRIES
from flakelab.core.tolerance import tolerance_preset
from flakelab.io import read_library
from timing import peak_rss_mb, print_report

NOISE = 0.003  # relative reflectance noise of a second reading (README: repeatability)


def loop_ranking(car: np.ndarray, cases, tolerance, geometries) -> np.ndarray:
    """The baseline: each case judged on its own, the worst geometry's share of the limit."""
    car_lab = reflectance_to_Lab(car)
    shares = []
    for case in cases:
        de00, dLCH, _ = tolerance.judge(geometries, car_lab, reflectance_to_Lab(case.sprayout))
        shares.append(tolerance.share_of_limit(geometries, de00=de00, dLCH=dLCH).max())
    return np.argsort(shares, kind="stable")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=61000)
    parser.add_argument("--seed", type=int, default=5)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()

    geometries = INSTRUMENT_GEOMETRIES["five-angle"]
    tolerance = tolerance_preset("refinish")
    world = World(read_library(None), "five-angle")
    rng = np.random.default_rng(args.seed)
    with tempfile.TemporaryDirectory() as folder:
        engine = open_database(Path(folder) / "shop.db")
        for batch in world.cases(args.cases, seed=args.seed, batch=2000):
            add_cases(engine, batch)
        start = time.perf_counter()
        cases = cases_at(iter_cases(engine), geometries)
        load_s = time.perf_counter() - start
    chosen = int(rng.integers(len(cases)))
    car = cases[chosen].sprayout * (1 + rng.normal(0, NOISE, cases[chosen].sprayout.shape))
    start = time.perf_counter()
    found = nearest_cases(car, cases, tolerance, 5)
    rank_s = time.perf_counter() - start
    start = time.perf_counter()
    loop = loop_ranking(car, cases, tolerance, geometries)
    loop_s = time.perf_counter() - start
    report = {
        "cases": len(cases),
        "seed": args.seed,
        "load_s": round(load_s, 2),
        "rank_s": round(rank_s, 3),
        "loop_s": round(loop_s, 2),
        "rank_speedup_vs_loop": round(loop_s / rank_s, 1),
        "same_order_as_loop": [n.case.case_id for n in found]
        == [cases[i].case_id for i in loop[:5]],
        "car_case_first": found[0].case.case_id == cases[chosen].case_id,
        "nearest_de00_max": round(float(found[0].sprayout_de00.max()), 3),
        "peak_rss_mb": round(peak_rss_mb()),
    }
    print_report(report, args.json)


if __name__ == "__main__":
    main()
