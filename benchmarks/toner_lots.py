"""What knowing the shop's tins buys: the harness run on the same targets and sprays with every
tin taken at the model's standard (the baseline, measured in the same run), with each tin's
strength and shade read from one calibration panel against the model's prediction of it
(``flakelab match evaluate --lots calibrated``) or against the paint maker's reading of it
from the standard tins (``--lots referenced``), and with the world's own strengths and shade
(``--lots known``, the limit calibration approaches); the differences paired target by
target.

    python benchmarks/toner_lots.py [--targets 200] [--seed 4242]
        [--modes calibrated,referenced,known] [--json]
"""

from __future__ import annotations

import argparse

import numpy as np

from _matcher import add_harness_arguments, shipped_matcher, timed_harness
from flakelab.library.lots import TIN_KNOWLEDGE
from timing import print_report


def paired(base: list[dict], other: list[dict], key: str) -> dict:
    """Pass rates of ``key`` (share ≤ 1) in both runs and their paired difference ± its
    standard error."""
    a = np.array([r[key] <= 1.0 for r in base], float)
    b = np.array([r[key] <= 1.0 for r in other], float)
    diff = b - a
    return {
        "standard": round(float(a.mean()), 3),
        "with_lots": round(float(b.mean()), 3),
        "difference": round(float(diff.mean()), 3),
        "difference_se": round(float(diff.std(ddof=1) / np.sqrt(diff.size)), 3),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--modes",
        default="calibrated,referenced,known",
        help="what the shop knows of its tins, each against none",
    )
    add_harness_arguments(parser, targets=200, novel_targets=0)
    args = parser.parse_args()
    modes = [m for m in args.modes.split(",") if m]
    if not set(modes) <= set(TIN_KNOWLEDGE) - {"none"}:
        raise SystemExit(
            f"--modes: expected some of {', '.join(TIN_KNOWLEDGE[1:])}, got {args.modes!r}"
        )

    world, forward, effect = shipped_matcher(
        args.world, args.model, args.kinds, white_pearls=args.white_pearls
    )
    runs = {}
    for mode in ["none", *modes]:
        runs[mode] = timed_harness(world, forward, effect, args, forward.novel, mode,
                                   per_target=True, lots=mode)  # fmt: skip
    base = runs["none"][0]["per_target"]
    report = {"targets": args.targets, "novel_targets": args.novel_targets, "seed": args.seed,
              "world": args.world}  # fmt: skip
    for mode, (run, seconds) in runs.items():
        report[mode] = {
            "first_shot_success": run["first_shot_success"],
            "after_one_correction": run["after_one_correction"],
            "oracle_success": run["oracle_success"],
            "lot_strength_error_rms": run["lot_strength_error_rms"],
            "lot_shade_error_rms_nm": run["lot_shade_error_rms_nm"],
            "latency_p50_s": round(run["latency_p50_s"], 3),
            "wall_s": round(seconds, 1),
        }
        if mode != "none":
            rows = run["per_target"]
            report[mode]["first_shot_paired"] = paired(base, rows, "first")
            report[mode]["after_one_correction_paired"] = paired(base, rows, "corrected")
    print_report(report, args.json)


if __name__ == "__main__":
    main()
