"""Matcher: does the model ensemble's disagreement on the best candidate foretell its spray?

``flakelab match`` shows, beside each candidate's predicted ΔE00, how far the networks of the
model's ensemble disagree (``± model``), and says so in a note where that disagreement exceeds
:data:`~flakelab.match.settings.MODEL_SPREAD_NOTICE` at some geometry. This runs the
evaluation harness (``flakelab match evaluate``) with each first recipe sprayed ``--resprays``
times more, and gives the first shot's chance to pass by the best candidate's disagreement
at its worst geometry, in bands, and over the notice against the rest of the same run (the
baseline), for every target and by paint family. The recipes are the model's own, as
``--no-physics-check`` leaves them (``benchmarks/physics_check.py`` measures the check).

    python benchmarks/model_spread.py [--targets 200] [--novel-targets 50] [--seed 4242]
        [--resprays 10] [--notice 0.5] [--notices 0.3,0.4,0.5,0.7,1.0] [--model FILE] [--json]

``--notices`` weighs where the note might stand: for each, the targets over it, their chance
and the rest's, and how much lower theirs is, with its standard error (over targets; each
target's chance is the share of its sprays that passed).
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from _matcher import (
    add_harness_arguments,
    column,
    families,
    mean_and_se,
    parse_with_chances,
    shipped_ensemble,
    thresholds_from,
    timed_harness,
)
from flakelab.match.settings import MODEL_SPREAD_NOTICE, MatchSettings

BANDS = (0.0, 0.2, 0.3, 0.4, 0.5, 0.7, 1.0, np.inf)
"""Edges of the disagreement bands [ΔE00]."""

NOTICES = "0.3,0.4,0.5,0.7,1.0"
"""Where the note might stand (``--notices``) [ΔE00]."""


def chance_by_notice(rows: list[dict], notices: list[float]) -> list[dict]:
    """For each of ``notices``: the harness's ``rows`` whose best candidate's disagreement
    exceeds it, their first shot's chance and the rest's, and the rest's lead over them with
    its standard error (the two groups' errors in quadrature)."""
    spread, chance = column(rows, "predicted_spread"), column(rows, "first_chance")
    figures = []
    for notice in notices:
        over = spread > notice
        mean_over, se_over = mean_and_se(chance[over])
        mean_under, se_under = mean_and_se(chance[~over])
        known = None not in (mean_over, mean_under)
        errors = None if None in (se_over, se_under) else float(np.hypot(se_over, se_under))
        figures.append({
            "notice": notice,
            "targets_over": int(over.sum()),
            "first_shot_chance_over": mean_over,
            "first_shot_chance_under": mean_under,
            "lead_of_the_rest": mean_under - mean_over if known else None,
            "lead_of_the_rest_se": errors,
        })  # fmt: skip
    return figures


def chance_by_spread(rows: list[dict], notice: float) -> dict:
    """The first shot's chance of the harness's ``rows`` in bands of the best candidate's
    disagreement, and over ``notice`` against under it, for all and by family."""
    spread, chance = column(rows, "predicted_spread"), column(rows, "first_chance")
    sprayed, predicted = column(rows, "first_de00"), column(rows, "predicted_de00")
    family = families(rows)

    def summary(mask: np.ndarray) -> dict:
        if not mask.any():
            return {"targets": 0, "first_shot_chance": None}
        return {
            "targets": int(mask.sum()),
            "first_shot_chance": float(chance[mask].mean()),
            "predicted_de00_median": float(np.median(predicted[mask])),
            "sprayed_de00_median": float(np.median(sprayed[mask])),
        }

    over = spread > notice
    return {
        "spread_percentiles": {
            k: float(v)
            for k, v in zip(
                ("p50", "p90", "p95", "max"), np.percentile(spread, [50, 90, 95, 100]), strict=True
            )
        },
        "bands": {
            f"{lo:g}-{hi:g}": summary((spread >= lo) & (spread < hi))
            for lo, hi in zip(BANDS[:-1], BANDS[1:], strict=True)
        },
        "over_notice": summary(over),
        "under_notice": summary(~over),
        "by_family": {
            str(f): {
                "over_notice": summary(over & (family == f)),
                "under_notice": summary(~over & (family == f)),
            }
            for f in np.unique(family)
        },  # fmt: skip
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_harness_arguments(parser, targets=200, novel_targets=50)
    parser.add_argument("--notice", type=float, default=MODEL_SPREAD_NOTICE,
                        help="the disagreement [ΔE00] the match's note names")  # fmt: skip
    parser.add_argument("--notices", type=thresholds_from, default=thresholds_from(NOTICES),
                        help=f"where the note might stand, e.g. {NOTICES} [ΔE00]")  # fmt: skip
    parser.set_defaults(resprays=10)
    args = parse_with_chances(parser)
    world, forward, effect = shipped_ensemble(parser, args)
    # the model's own recipes: the physics checks none (benchmarks/physics_check.py does)
    report, seconds = timed_harness(
        world, forward, effect, args, forward.novel, "harness",
        settings=MatchSettings(physics_check=0), per_target=True,
    )  # fmt: skip
    figures = chance_by_spread(report["per_target"], args.notice)
    figures["by_notice"] = chance_by_notice(report["per_target"], args.notices)
    summary = {
        "targets": args.targets,
        "novel_targets": args.novel_targets,
        "seed": args.seed,
        "resprays": args.resprays,
        "notice": args.notice,
        "first_shot_chance": report["first_shot_chance"],
        **figures,
        "wall_s": seconds,
    }
    if args.json:
        print(json.dumps(summary, indent=2))
        return
    p = figures["spread_percentiles"]
    print(f"{len(report['per_target'])} targets, each first recipe sprayed {args.resprays} times "
          f"more; the best candidate's disagreement p50 {p['p50']:.2f}, p95 {p['p95']:.2f}, "
          f"max {p['max']:.2f} ΔE00")  # fmt: skip
    for band, row in figures["bands"].items():
        if row["targets"]:
            print(f"  disagreement {band:>8}: {row['targets']:3d} targets, first-shot chance "
                  f"{row['first_shot_chance']:.3f}, predicted {row['predicted_de00_median']:.2f}, "
                  f"sprayed {row['sprayed_de00_median']:.2f} (medians)")  # fmt: skip
    for name, rows in [("all", figures), *figures["by_family"].items()]:
        over, under = rows["over_notice"], rows["under_notice"]
        shown = [f"{r['targets']} at {r['first_shot_chance']:.3f}" if r["targets"] else "none"
                 for r in (over, under)]  # fmt: skip
        print(f"{name:>9}: over {args.notice:g}: {shown[0]}; the rest: {shown[1]}")
    for row in figures["by_notice"]:
        if row["lead_of_the_rest"] is not None:
            se = row["lead_of_the_rest_se"]
            print(f"  note over {row['notice']:g}: {row['targets_over']:3d} targets at "
                  f"{row['first_shot_chance_over']:.3f}, the rest at "
                  f"{row['first_shot_chance_under']:.3f}: {row['lead_of_the_rest']:+.3f}"
                  + (f" ± {se:.3f}" if se is not None else ""))  # fmt: skip
    print(f"{seconds:.0f} s")


if __name__ == "__main__":
    main()
