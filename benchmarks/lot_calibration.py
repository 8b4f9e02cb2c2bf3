"""How well the shop's tins are read when its calibration panels are read one at a time, as
a shop sprays them (``flakelab lots calibrate`` once per panel, the lot file carried between),
against reading every panel at once (the harness's ``--lots calibrated``): as the lot file
carries them now (the tins' correlations and the shop's misfit to the model pooled over its
panels), without the pooled misfit, and with each tin's own spread alone (the lot file
before stop 75).
Each trial is a harness target's shop (its tins drawn by the world), every toner's D-optimal
panel sprayed once from them and read against the model; the figures are the RMS error of
the tins' strengths and of the pigments' shades, averaged over the trials, with each mode's
ratio to reading at once (the baseline, in the same run).

    python benchmarks/lot_calibration.py [--trials 20] [--seed 4242] [--json]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from _matcher import shipped_matcher
from flakelab.cli.common import progress_bar
from flakelab.library.lots import TonerLots
from flakelab.match.evaluate import harness_trials
from flakelab.match.lots import calibrate_lots, calibration_recipes, recorded
from timing import print_report

MODES = {
    # mode: (the correlations kept, the misfit pooled) between panels read one at a time
    "at once": None,
    "one at a time": (True, True),
    "one at a time, misfit not pooled": (True, False),
    "one at a time, own spreads alone": (False, False),
}


def read_tins(forward, library, panels, readings, mode: str) -> TonerLots:
    """The tins read from ``readings`` of ``panels`` in ``mode`` (:data:`MODES`)."""
    if MODES[mode] is None:
        return recorded(TonerLots(), calibrate_lots(forward, library, panels, readings))
    correlated, pooled = MODES[mode]
    lots = TonerLots()
    for panel, reading in zip(panels, readings, strict=True):
        found = calibrate_lots(forward, library, panel[None], reading[None], lots)
        lots = recorded(lots, found)
        lots = TonerLots(lots.lots, lots.library, lots.correlations if correlated else {},
                         lots.misfit if pooled else {})  # fmt: skip
    return lots


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=20)
    parser.add_argument("--seed", type=int, default=4242)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()

    world, forward, _ = shipped_matcher()
    library = world.library
    panels = calibration_recipes(forward, library)
    names = list(forward.toners)
    order = [list(library.names).index(n) for n in names]
    pigments = ~library.effect[order]
    errors = {mode: [] for mode in MODES}
    seconds = dict.fromkeys(MODES, 0.0)
    with progress_bar(args.json) as bar:
        task = bar.add_task("trials", total=args.trials)
        for _, t in harness_trials(world, args.trials, args.seed):
            strength = t.shop.strength[0][order]
            shade = np.where(pigments, t.shop.hue_shift[0], 0.0)
            readings = t.panels(panels)
            for mode in MODES:
                start = time.perf_counter()
                lots = read_tins(forward, library, panels, readings, mode)
                seconds[mode] += time.perf_counter() - start
                errors[mode].append((
                    np.sqrt(np.mean((lots.strengths(names) - strength) ** 2)),
                    np.sqrt(np.mean((lots.shades(names) - shade)[pigments] ** 2)),
                ))  # fmt: skip
            bar.advance(task)
    report = {"trials": args.trials, "seed": args.seed, "panels": len(panels)}
    base = np.mean(errors["at once"], axis=0)
    for mode in MODES:
        rms = np.mean(errors[mode], axis=0)
        report[mode] = {
            "strength_rms": round(float(rms[0]), 5),
            "shade_rms_nm": round(float(rms[1]), 4),
            "strength_ratio_to_at_once": round(float(rms[0] / base[0]), 3),
            "shade_ratio_to_at_once": round(float(rms[1] / base[1]), 3),
            "seconds_per_trial": round(seconds[mode] / args.trials, 2),
        }
    print_report(report, args.json)


if __name__ == "__main__":
    main()
