"""``flakelab cases nearest`` on a shop's database the size of the paper's (61,000 cases):
how long a colorist waits, and at what memory.

Generates ``--cases`` five-angle cases (seed ``--seed``) into a fresh SQLite file, then
times what the command does, :func:`~flakelab.cases.nearest.nearest_stored_cases`, whole
(``command_s``) and in its steps: reading the spray-outs alone (``sprayouts_s``) and
ranking them in one colour computation (``rank_s``). Two baselines are measured in the same
run: reading every case whole, as the command did first (``cases_s``), and ranking the
cases one by one (``loop_s``, each spray-out's L*a*b* and the tolerance's judgement one at a
time). The car is one case's own spray-out read again with the instrument's noise, so the
case it came from should come first, by every path.

Each case carries one of 1,000 colour codes (ten makers', in turn: about 61 cases a code),
and the same search among the car's own code's cases alone (``match --colour-code``,
``cases nearest --colour-code``: the database picks them) is timed too (``code_command_s``),
against the search among all (``command_s``); so are the 20 newest cases, of that code
(``code_list_s``, ``cases list --colour-code``) and of any (``list_s``).

    python benchmarks/nearest_cases.py [--cases 61000] [--seed 5] [--json]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from flakelab.cases.case import cases_at
from flakelab.cases.database import (
    add_cases,
    iter_cases,
    latest_cases,
    open_database,
    stored_sprayouts,
)
from flakelab.cases.generator import World
from flakelab.cases.nearest import nearest_cases, nearest_stored_cases
from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.geometry import INSTRUMENT_GEOMETRIES
from flakelab.core.tolerance import tolerance_preset
from flakelab.io import read_library
from timing import peak_rss_mb, print_report

# relative reflectance noise of a second reading (docs/cases-and-model.md: repeatability)
NOISE = 0.003
MAKERS = ("Toyota", "VW", "Ford", "BMW", "Honda", "Nissan", "Renault", "Opel", "Fiat", "Kia")


def colour_code(k: int) -> str:
    """The colour code of case ``k``: one of 1,000, ten makers' in turn."""
    return f"{MAKERS[k % 1000 % len(MAKERS)]} {k % 1000:03d}"


def loop_ranking(car: np.ndarray, cases, tolerance, geometries) -> np.ndarray:
    """The baseline: each case judged on its own, the worst geometry's share of the limit."""
    car_lab = reflectance_to_Lab(car)
    shares = []
    for case in cases:
        de00, dLCH, _ = tolerance.judge(geometries, car_lab, reflectance_to_Lab(case.sprayout))
        shares.append(tolerance.share_of_limit(geometries, de00=de00, dLCH=dLCH).max())
    return np.argsort(shares, kind="stable")


def timed(function, *args, **kwargs):
    """``function``'s result and its wall time in seconds."""
    start = time.perf_counter()
    result = function(*args, **kwargs)
    return result, time.perf_counter() - start


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
        done = 0
        for batch in world.cases(args.cases, seed=args.seed, batch=2000):
            add_cases(engine, [replace(c, colour_code=colour_code(done + k))
                               for k, c in enumerate(batch)])  # fmt: skip
            done += len(batch)
        cases, cases_s = timed(lambda: cases_at(iter_cases(engine), geometries))
        (_, sprayouts), sprayouts_s = timed(stored_sprayouts, engine, geometries)
        chosen = int(rng.integers(len(cases)))
        car = cases[chosen].sprayout * (1 + rng.normal(0, NOISE, cases[chosen].sprayout.shape))
        (found, searched), command_s = timed(
            nearest_stored_cases, engine, car, geometries, tolerance, 5
        )
        code = colour_code(chosen)
        (of_code, code_searched), code_command_s = timed(
            nearest_stored_cases, engine, car, geometries, tolerance, 5, colour_code=code
        )
        _, list_s = timed(latest_cases, engine, 20)
        newest_of_code, code_list_s = timed(latest_cases, engine, 20, colour_code=code)
    in_memory, rank_s = timed(nearest_cases, car, cases, tolerance, 5)
    loop, loop_s = timed(loop_ranking, car, cases, tolerance, geometries)
    first_five = [n.case.case_id for n in found]
    report = {
        "cases": searched,
        "seed": args.seed,
        "command_s": round(command_s, 2),
        "sprayouts_s": round(sprayouts_s, 2),
        "rank_s": round(rank_s, 3),
        "cases_s": round(cases_s, 2),
        "loop_s": round(loop_s, 2),
        "read_speedup_vs_cases": round(cases_s / sprayouts_s, 1),
        "rank_speedup_vs_loop": round(loop_s / rank_s, 1),
        "same_five_by_every_path": first_five
        == [n.case.case_id for n in in_memory]
        == [cases[i].case_id for i in loop[:5]],
        "car_case_first": first_five[0] == cases[chosen].case_id,
        "nearest_de00_max": round(float(found[0].sprayout_de00.max()), 3),
        "colour_codes": len({colour_code(k) for k in range(searched)}),
        "code_cases_searched": code_searched,
        "code_command_s": round(code_command_s, 3),
        "code_speedup_vs_all": round(command_s / code_command_s, 1),
        "code_car_case_first": of_code[0].case.case_id == cases[chosen].case_id,
        "code_nearest_all_of_code": all(n.case.colour_code == code.upper() for n in of_code),
        "list_s": round(list_s, 3),
        "code_list_s": round(code_list_s, 3),
        "code_list_cases": len(newest_of_code),
        "code_list_all_of_code": all(c.colour_code == code.upper() for c in newest_of_code),
        "peak_rss_mb": round(peak_rss_mb()),
    }
    print_report(report, args.json)


if __name__ == "__main__":
    main()
