"""Spectra → CIELAB throughput: flakelab's ASTM E308 weight matrix against colour-science's
``msds_to_XYZ`` on the same spectra, in the same run (the baseline).

    python benchmarks/colorimetry.py [--n 100000] [--json]
"""

from __future__ import annotations

import argparse

import colour
import numpy as np

from flakelab.core.colorimetry import D65_10, OBSERVERS, reflectance_to_Lab, white_point
from flakelab.core.spectra import SHAPE_STORE
from timing import best_time, measure_peak, print_report


def baseline_lab(R: np.ndarray) -> np.ndarray:
    msds = colour.MultiSpectralDistributions(R.T, SHAPE_STORE.wavelengths)
    XYZ = colour.msds_to_XYZ(
        msds, colour.MSDS_CMFS[OBSERVERS["10"]], colour.SDS_ILLUMINANTS["D65"],
        method="ASTM E308", shape=SHAPE_STORE,
    ) / 100  # fmt: skip
    return colour.XYZ_to_Lab(XYZ, colour.XYZ_to_xy(white_point()))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=100_000, help="spectra per run")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()

    R = np.random.default_rng(args.seed).uniform(0, 1.2, (args.n, 31))
    reflectance_to_Lab(R[:10], conditions=D65_10)  # build the weight table once
    ours = best_time(reflectance_to_Lab, R)
    base_n = min(args.n, 20_000)
    base = best_time(baseline_lab, R[:base_n], repeat=1) * args.n / base_n
    lab, _, peak_mb = measure_peak(reflectance_to_Lab, R)
    agreement = float(np.abs(lab[:base_n] - baseline_lab(R[:base_n])).max())
    report = {
        "spectra": args.n,
        "flakelab_spectra_per_s": args.n / ours,
        "colour_msds_to_XYZ_spectra_per_s": args.n / base,
        "speedup": base / ours,
        "max_abs_Lab_difference": agreement,
        "peak_memory_mb": peak_mb,
    }
    print_report(report, args.json, ",.6g")


if __name__ == "__main__":
    main()
