"""Matcher: targets read without texture readings, their solids found by how little their
colour travels over the geometries (``MatchSettings.solid_travel``) or left free.

Runs the evaluation harness (``flakelab match evaluate --no-target-texture``) twice on the
same hidden targets and sprays, the matcher reading each target's spectra alone, as from a
file without texture readings: once with solids found by colour travel (the default,
:data:`~flakelab.match.settings.SOLID_TRAVEL`), once with every toner free for every target
(``--solid-travel 0``), the baseline of the same run. The sprays are judged as ever.

    python benchmarks/textureless_targets.py [--targets 200] [--seed 4242] [--model FILE]
        [--json]
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace

from _matcher import add_harness_arguments, shipped_matcher, timed_harness
from flakelab.match.settings import SOLID_TRAVEL, MatchSettings

FIGURES = ("first_shot_success", "by_family", "after_one_correction", "oracle_success")


def run(world, forward, effect, args, settings: MatchSettings, label: str) -> dict:
    # the hidden targets keep to the toners the model knows (forward.novel), as the harness's
    report, seconds = timed_harness(
        world, forward, effect, args, forward.novel, label, settings, target_texture=False
    )
    return {k: report[k] for k in FIGURES} | {"wall_s": seconds}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_harness_arguments(parser, targets=200, novel_targets=0)
    args = parser.parse_args()
    world, forward, effect = shipped_matcher(
        args.world, args.model, args.kinds, white_pearls=args.white_pearls
    )
    settings = MatchSettings()
    rows = {
        f"solid_travel_{SOLID_TRAVEL:g}": run(
            world, forward, effect, args, settings, "solids found by colour travel"
        ),
        "free": run(
            world, forward, effect, args, replace(settings, solid_travel=0.0), "every toner free"
        ),
    }
    found, free = rows.values()
    report = {
        "targets": args.targets,
        "seed": args.seed,
        "rows": rows,
        "first_shot_gain": found["first_shot_success"] - free["first_shot_success"],
    }
    if args.json:
        print(json.dumps(report, indent=2))
        return
    for name, row in rows.items():
        families = ", ".join(
            f"{f} {v['first_shot_success']:.3f} of {v['targets']}"
            for f, v in row["by_family"].items()
        )
        print(
            f"{name:>18}: first shot {row['first_shot_success']:.3f} ({families}), after one "
            f"correction {row['after_one_correction']:.3f}, oracle {row['oracle_success']:.3f}, "
            f"{row['wall_s']:.0f} s"
        )
    print(f"first shot, found − free: {report['first_shot_gain']:+.3f}")


if __name__ == "__main__":
    main()
