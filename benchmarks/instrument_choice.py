"""Matcher: an MA-T12 reading matched with the MA-T12 model, or with the five-angle model.

An MA-T12 export reads every five-angle geometry too, so either shipped model can match it;
`flakelab match` takes the five-angle one unless `--instrument` says otherwise. This measures
which matches such a target better. Hidden
formulations of the shop's harness world are read on the car at the MA-T12's twelve
geometries; each target is matched twice, once with each shipped model (the five-angle model
sees five of the twelve readings: the baseline of the same run), and each best recipe is
sprayed with the *same* random stream (the shop's batches, one application, one reading)
and judged at all twelve geometries, as the colorist's instrument judges it, and at the five.
The recipes are also made by the world's nominal physics without batches, application or
instrument noise: the model's and the search's share alone. Last, what `flakelab match` shows
under the five-angle model's candidates, the MA-T12 model's prediction at the seven geometries
the search left out (`flakelab.match.crosscheck`), is set against those seven as sprayed: how
often a recipe it flags fails there, and how often one it passes does. The targets are the
harness's, drawn on the toners both models know; ``--new-toner-targets`` adds the harness's
targets that hold one of their new toners, reported apart (``new_toner``). Each group's
paired difference of the first shot at twelve geometries (MA-T12 model less five-angle) comes
with its standard error over targets.

    python benchmarks/instrument_choice.py [--targets 100] [--new-toner-targets 0]
        [--seed 4242] [--json]
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
import time

import numpy as np
from scipy import stats

from flakelab.cli.common import progress_bar
from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E
from flakelab.core.geometry import INSTRUMENT_GEOMETRIES
from flakelab.core.measurement import Measurement
from flakelab.core.spectra import WAVELENGTHS
from flakelab.core.tolerance import tolerance_preset
from flakelab.io import read_library
from flakelab.match.crosscheck import predict_left_out
from flakelab.match.evaluate import SUCCESS_DE00, harness_trials, harness_world
from flakelab.match.forward import PhysicsForward
from flakelab.match.judging import recipe_vector
from flakelab.match.models import effect_mask, forward_for
from flakelab.match.search import match
from flakelab.models.registry import shipped_model

MODELS = ("ma-t12", "five-angle")
FIVE = [INSTRUMENT_GEOMETRIES["ma-t12"].index(g) for g in INSTRUMENT_GEOMETRIES["five-angle"]]
OTHERS = [i for i in range(len(INSTRUMENT_GEOMETRIES["ma-t12"])) if i not in FIVE]


def worst(target: np.ndarray, reading: np.ndarray) -> tuple[float, float, float]:
    """The largest ΔE00 over the twelve geometries, the five-angle ones and the other seven."""
    de = delta_E(reflectance_to_Lab(target), reflectance_to_Lab(reading))
    return float(de.max()), float(de[FIVE].max()), float(de[OTHERS].max())


def rates(a: np.ndarray) -> dict[str, float]:
    """First-shot pass rates and median worst ΔE00 of rows ``a`` (:func:`worst` of the spray,
    then of the nominal recipe, per target)."""
    return {
        "first_shot_success_12": float(np.mean(a[:, 0] <= SUCCESS_DE00)),
        "first_shot_success_5": float(np.mean(a[:, 1] <= SUCCESS_DE00)),
        "sprayed_de00_median_12": float(np.median(a[:, 0])),
        "nominal_de00_median_12": float(np.median(a[:, 3])),
        "nominal_de00_median_5": float(np.median(a[:, 4])),
        "nominal_success_12": float(np.mean(a[:, 3] <= SUCCESS_DE00)),
    }


def paired_difference(rows: dict[str, list], which: slice) -> dict[str, float]:
    """The MA-T12 model's first shot at twelve geometries less the five-angle model's, paired
    per target (the same spray), and its standard error over the targets ``which``."""
    passed = {name: np.array(rows[name])[which, 0] <= SUCCESS_DE00 for name in MODELS}
    d = passed["ma-t12"].astype(float) - passed["five-angle"]
    return {"mean": float(d.mean()), "se": float(d.std(ddof=1) / np.sqrt(d.size))}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--targets", type=int, default=100)
    parser.add_argument("--new-toner-targets", type=int, default=0)
    parser.add_argument("--seed", type=int, default=4242)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)

    library = read_library(None)
    world = harness_world(library, "ma-t12")
    physics = PhysicsForward(library, world.geometries)
    forwards = {name: forward_for(shipped_model(name), library) for name in MODELS}
    rows: dict[str, list[tuple[float, ...]]] = {name: [] for name in MODELS}
    flagged = []  # the five-angle best recipe: the MA-T12 model's worst at the other seven
    start = time.perf_counter()
    with progress_bar(args.json) as bar:
        total = args.targets + args.new_toner_targets
        task = bar.add_task("matching MA-T12 targets with both models", total=total)
        novel = forwards["ma-t12"].novel
        for _, t in harness_trials(world, args.targets, args.seed, novel, args.new_toner_targets):
            target = Measurement("target", world.geometries, WAVELENGTHS, t.target)
            stream = t.streams[0]
            for name, forward in forwards.items():
                best = match(target, forward, effect_mask(library, forward.toners))
                best = best.candidates[0]
                if name == "five-angle":
                    shown = predict_left_out(
                        [best], target, forward, forwards["ma-t12"], tolerance_preset("refinish")
                    )
                    flagged.append(float(shown[0].de00.max()))
                x = recipe_vector(forward, best.fractions)
                sprayed = t.spray(x, copy.deepcopy(stream))  # the same spray for both
                nominal = physics.reflectance(x[None])[0]
                rows[name].append((*worst(t.target, sprayed), *worst(t.target, nominal)))
            bar.advance(task)
    report = {
        "targets": args.targets,
        "new_toner_targets": args.new_toner_targets,
        "seed": args.seed,
        "wall_s": time.perf_counter() - start,
    }
    known = slice(None, args.targets)
    for name, values in rows.items():
        a = np.array(values)
        report[name] = rates(a[known])
        if args.new_toner_targets:
            report[name]["new_toner"] = rates(a[args.targets :])
    report["paired_difference_12"] = paired_difference(rows, known)
    if args.new_toner_targets:
        report["paired_difference_12_new_toner"] = paired_difference(
            rows, slice(args.targets, None)
        )
    predicted = np.array(flagged)[known]
    sprayed_others = np.array(rows["five-angle"])[known, 2]
    fails = sprayed_others > SUCCESS_DE00
    said_fail = predicted > SUCCESS_DE00
    report["left_out_check"] = {
        "predicted_fail_share": float(said_fail.mean()),
        "sprayed_fail_share": float(fails.mean()),
        "sprayed_fail_when_predicted_fail": float(fails[said_fail].mean())
        if said_fail.any()
        else None,
        "sprayed_fail_when_predicted_pass": float(fails[~said_fail].mean())
        if (~said_fail).any()
        else None,
        "correlation": float(np.corrcoef(predicted, sprayed_others)[0, 1]),
        # Pearson's follows the few largest ΔE00; the ranks say how well the order holds
        "rank_correlation": float(stats.spearmanr(predicted, sprayed_others)[0]),
        "predicted_worst_de00": np.round(predicted, 3).tolist(),
        "sprayed_worst_de00": np.round(sprayed_others, 3).tolist(),
    }
    base, chosen = report["five-angle"], report["ma-t12"]
    report["ratio_first_shot_12"] = (
        chosen["first_shot_success_12"] / base["first_shot_success_12"]
        if base["first_shot_success_12"]
        else None
    )
    if args.json:
        print(json.dumps(report, indent=2))
        return 0
    print(f"{args.targets} MA-T12 targets, seed {args.seed}, {report['wall_s']:.0f} s")
    print(f"{'matched with':<14}{'pass@12':>9}{'pass@5':>8}{'sprayed@12':>12}"
          f"{'nominal@12':>12}{'nominal@5':>11}")  # fmt: skip
    for name in MODELS:
        r = report[name]
        print(f"{name:<14}{r['first_shot_success_12']:>9.3f}{r['first_shot_success_5']:>8.3f}"
              f"{r['sprayed_de00_median_12']:>12.2f}{r['nominal_de00_median_12']:>12.2f}"
              f"{r['nominal_de00_median_5']:>11.2f}")  # fmt: skip
    d = report["paired_difference_12"]
    print(f"first shot at twelve geometries, MA-T12 model / five-angle model: "
          f"{report['ratio_first_shot_12']:.2f}, paired difference {d['mean']:+.3f} ± "
          f"{d['se']:.3f}")  # fmt: skip
    if args.new_toner_targets:
        d = report["paired_difference_12_new_toner"]
        print(f"{args.new_toner_targets} targets with a new toner: first shot at twelve "
              f"{report['ma-t12']['new_toner']['first_shot_success_12']:.3f} / "
              f"{report['five-angle']['new_toner']['first_shot_success_12']:.3f}, paired "
              f"difference {d['mean']:+.3f} ± {d['se']:.3f}")  # fmt: skip
    check = report["left_out_check"]
    print(f"five-angle recipes at the other seven geometries: the MA-T12 model flags "
          f"{check['predicted_fail_share']:.3f} (worst ΔE00 > {SUCCESS_DE00}); sprayed, "
          f"{check['sprayed_fail_share']:.3f} fail there: "
          f"{check['sprayed_fail_when_predicted_fail']} of those flagged, "
          f"{check['sprayed_fail_when_predicted_pass']} of the others; "
          f"correlation {check['correlation']:.2f}, of ranks "
          f"{check['rank_correlation']:.2f}")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
