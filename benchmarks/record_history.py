"""A shop's history brought in from its instrument files: how fast, and at what memory.

Writes ``--cases`` generated MA-T12 cases as a shop keeps them: the day's cars and the
day's spray-outs as multi-sample CxF3 exports (``--per-file`` samples each), one recipe
file in grams per spray-out, and a manifest naming them. Then times ``flakelab cases
record-all``'s library path (:func:`~flakelab.cases.manifest.cases_from_manifest`, then
one transaction into a fresh SQLite file) against the baseline of the same run: the same
cases imported from flakelab's own case CSV (``flakelab cases import``). Checks that what
was recorded is what was measured, and times the check 'cases record-all' makes of each
spray-out against its recipe's prediction (:func:`~flakelab.match.mixups.recorded_checks`),
with how many of the shop's own it would take for mix-ups: the first check, as a command
makes it, pays torch's import and the model's load (``check_s``); a second, in the same
process, the check alone (``check_again_s``).

    python benchmarks/record_history.py [--cases 500] [--per-file 10] [--seed 3] [--json]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from flakelab.cases.database import add_cases, count_cases, open_database
from flakelab.cases.exchange import read_cases, write_cases
from flakelab.cases.generator import World
from flakelab.cases.manifest import cases_from_manifest
from flakelab.core.measurement import Measurement
from flakelab.core.spectra import WAVELENGTHS
from flakelab.core.tolerance import tolerance_preset
from flakelab.io import read_library, write_measurements, write_recipe
from flakelab.match.mixups import is_mismatched, recorded_checks
from timing import peak_rss_mb, print_report


def write_history(cases, folder: Path, per_file: int) -> Path:
    """The cases as a shop's files (CxF3 exports, recipes in grams) and their manifest."""
    rows = ["target,recipe,sprayed,sample,sprayed_sample,shop,outcome"]
    for start in range(0, len(cases), per_file):
        day = cases[start : start + per_file]
        cars, sprays = folder / f"cars-{start:05d}.cxf", folder / f"sprays-{start:05d}.cxf"
        for path, role in ((cars, "target"), (sprays, "sprayout")):
            write_measurements([_reading(c, role) for c in day], path)
        for case in day:
            recipe = folder / f"{case.case_id}.json"
            write_recipe({k: 250.0 * v for k, v in case.recipe.items()}, recipe)
            rows.append(
                f"{cars.name},{recipe.name},{sprays.name},{case.case_id} car,"
                f"{case.case_id} spray,{case.shop},{case.outcome}"
            )
    manifest = folder / "manifest.csv"
    manifest.write_text("\n".join(rows) + "\n")
    return manifest


def _reading(case, role: str) -> Measurement:
    return Measurement(
        sample=f"{case.case_id} {'car' if role == 'target' else 'spray'}",
        geometries=case.geometries,
        wavelengths=WAVELENGTHS,
        reflectance=getattr(case, role),
        texture=getattr(case, f"{role}_texture"),
        instrument="X-Rite MA-T12",
        measured_at=case.created_at.replace(tzinfo=None),
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=500)
    parser.add_argument("--per-file", type=int, default=10, help="samples per CxF3 export")
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()

    library = read_library(None)
    world = World(library, "ma-t12")
    cases = [c for batch in world.cases(args.cases, seed=args.seed, shop="Dupont") for c in batch]
    with tempfile.TemporaryDirectory() as temporary:
        folder = Path(temporary)
        manifest = write_history(cases, folder, args.per_file)
        write_cases(cases, folder / "cases.csv")

        start = time.perf_counter()
        numbered = cases_from_manifest(manifest, library, tolerance=tolerance_preset("refinish"))
        engine = open_database(folder / "recorded.db")
        add_cases(engine, [c for _, c in numbered])
        record_s = time.perf_counter() - start

        start = time.perf_counter()
        add_cases(open_database(folder / "imported.db"), read_cases(folder / "cases.csv"))
        import_s = time.perf_counter() - start
        stored = count_cases(engine)

        start = time.perf_counter()
        checks, _ = recorded_checks([c for _, c in numbered], library, engine)
        check_s = time.perf_counter() - start
        start = time.perf_counter()
        recorded_checks([c for _, c in numbered], library, engine)
        check_again_s = time.perf_counter() - start

    recorded = [c for _, c in numbered]
    spectra_error = max(
        float(np.abs(r.sprayout - c.sprayout).max()) for r, c in zip(recorded, cases, strict=True)
    )
    report = {
        "cases": len(cases),
        "samples_per_file": args.per_file,
        "stored": stored,
        "record_all_s": round(record_s, 2),
        "record_all_cases_per_s": round(len(cases) / record_s, 1),
        "import_csv_s": round(import_s, 2),
        "record_all_vs_import_csv": round(record_s / import_s, 2),
        "check_s": round(check_s, 2),
        "check_vs_record_all": round(check_s / record_s, 3),
        "check_again_s": round(check_again_s, 3),
        "from_prediction_de00_median": round(float(np.median([c["de00"] for c in checks])), 3),
        "from_prediction_de00_max": max(c["de00"] for c in checks),
        "taken_for_mix_ups": sum(map(is_mismatched, checks)),
        "max_spectra_difference": spectra_error,
        "outcomes_as_given": all(
            r.outcome == c.outcome for r, c in zip(recorded, cases, strict=True)
        ),
        "peak_rss_mb": round(peak_rss_mb(), 1),
    }
    print_report(report, args.json)


if __name__ == "__main__":
    main()
