"""A measurement CSV as a row per reading and as a row per sample: read alike, and as fast?

Reads the 230 real MA-T12 samples' spectra (2,760 readings,
``../shared/data/ma-t12/all_samples_spectra.csv``, a row per reading), writes them a row per
sample (``write_measurements(..., wide=True)``: 372 reflectance columns), and the
instrument's own L*a*b* (``all_samples_instrument_lab_d65_10.csv``) likewise (36 colour
columns), and reads each back. It prints, for spectra and for colour alone:

* the time to read each layout, best of three, and the row-per-sample file's time as a
  ratio of the row-per-reading file's (the baseline, measured in the same run);
* whether the two layouts read to the same readings, exactly (``*_same``: 1 or 0).

    python benchmarks/csv_layouts.py [--json]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

from flakelab.io import read_measurements, write_measurements
from timing import best_time, print_report

MA_T12 = Path(__file__).resolve().parents[2] / "shared" / "data" / "ma-t12"


def _same(a, b) -> bool:
    """Two lists of measurements hold the same readings, exactly."""
    return len(a) == len(b) and all(
        x.sample == y.sample
        and x.geometries == y.geometries
        and np.array_equal(x.reflectance, y.reflectance)
        and (x.stored_lab is None) == (y.stored_lab is None)
        and (x.stored_lab is None or np.array_equal(x.stored_lab, y.stored_lab))
        for x, y in zip(a, b, strict=True)
    )


def layouts_report(folder: Path = MA_T12) -> dict:
    """Read times of each layout, the ratio, and whether they agree, for the real spectra and
    the real instrument colours."""
    report: dict = {}
    with tempfile.TemporaryDirectory(prefix="flakelab-layouts-") as work:
        for name, source in (
            ("spectra", folder / "all_samples_spectra.csv"),
            ("colour", folder / "all_samples_instrument_lab_d65_10.csv"),
        ):
            long = read_measurements(source)
            wide = Path(work) / f"{name}-wide.csv"
            write_measurements(long, wide, wide=True)
            per_reading = best_time(read_measurements, source)
            per_sample = best_time(read_measurements, wide)
            report |= {
                f"{name}_readings": sum(len(m.geometries) for m in long),
                f"{name}_row_per_reading_s": per_reading,
                f"{name}_row_per_sample_s": per_sample,
                f"{name}_row_per_sample_ratio": per_sample / per_reading,
                f"{name}_same": int(_same(read_measurements(wide), long)),
            }
    return report


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = parser.parse_args()
    if not MA_T12.is_dir():
        print(f"the real MA-T12 data is not at {MA_T12} (../shared/data is absent)")
        return 1
    print_report(layouts_report(), args.json, ",.4g")
    return 0


if __name__ == "__main__":
    sys.exit(main())
