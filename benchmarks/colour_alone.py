"""A car known by its L*a*b* alone: what the spectra recovered from it cost and keep.

Reads the instrument's own L*a*b* of the 230 real MA-T12 samples (2,760 readings,
``../shared/data/ma-t12/all_samples_instrument_lab_d65_10.csv``) as a file of colour alone,
each reading's spectrum recovered from its colour
(:func:`~flakelab.core.colorimetry.reflectance_from_Lab`), and the same samples' measured
spectra (``all_samples_spectra.csv``). It prints:

* the time to read the colour file (the recovery within it), best of three, and readings/s;
* the largest ΔE00 between a recovered and a measured reading in D65/10, where the file's
  colour was stated: the recovery's error added to the instrument's own rounding;
* per other light (A, F11, LED-B3, D50/2°) the median, 95th percentile and largest ΔE00
  between the recovered and the measured reading: how far a colour under another light
  read from recovered spectra is an estimate (the metamerism that colour alone hides).

    python benchmarks/colour_alone.py [--json]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from flakelab.core.colorimetry import Conditions, reflectance_to_Lab
from flakelab.core.difference import delta_E
from flakelab.io import read_measurements
from timing import best_time, print_report

MA_T12 = Path(__file__).resolve().parents[2] / "shared" / "data" / "ma-t12"

OTHER_LIGHTS = ("A/10", "FL11/10", "LED-B3/10", "D50/2")
"""The lights under which a recovered reading's colour is an estimate."""


def colour_alone_report(folder: Path = MA_T12) -> dict:
    colour_file = folder / "all_samples_instrument_lab_d65_10.csv"
    seconds = best_time(read_measurements, colour_file)
    recovered = read_measurements(colour_file)
    measured = read_measurements(folder / "all_samples_spectra.csv")
    readings = sum(len(m.geometries) for m in recovered)

    assert [m.sample for m in recovered] == [m.sample for m in measured]
    R_recovered, R_measured = (
        np.stack([m.reflectance for m in ms]) for ms in (recovered, measured)
    )

    def apart(conditions: Conditions) -> np.ndarray:
        lab = (reflectance_to_Lab(R, conditions=conditions) for R in (R_recovered, R_measured))
        return delta_E(*lab).ravel()

    report = {
        "samples": len(recovered),
        "readings": readings,
        "read_seconds": seconds,
        "readings_per_s": readings / seconds,
        "de00_d65_10_max": float(apart(Conditions("D65", "10")).max()),
    }
    for light in OTHER_LIGHTS:
        found = apart(Conditions.parse(light))
        name = light.replace("/", "_").replace("-", "_").lower()
        report |= {
            f"de00_{name}_median": float(np.median(found)),
            f"de00_{name}_p95": float(np.percentile(found, 95)),
            f"de00_{name}_max": float(found.max()),
        }
    return report


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    if not MA_T12.is_dir():
        print(f"{MA_T12}: absent (the real MA-T12 data beside the checkout)", file=sys.stderr)
        return 1
    print_report(colour_alone_report(), args.json, ".4g")
    return 0


if __name__ == "__main__":
    sys.exit(main())
