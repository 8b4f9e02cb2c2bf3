"""Matcher: what buys first-shot success — the search's settings, on the same targets.

Runs the evaluation harness (``flakelab match evaluate``) with the shipped five-angle model
(or ``--model FILE``, in its own instrument's world) once per setting given, each a
comma-separated list of :class:`MatchSettings` fields. Every run sees the same hidden targets
and the same sprays (seeded), so rows differ only by the recipes the search proposed. The
first row is the defaults: the baseline of the same run.

    python benchmarks/match_variants.py [--targets 100] [--novel-targets 0] [--seed 4242]
        [--world shop] [--kinds pearl=1] [--model FILE] [--tolerance T] [--resprays K]
        [--json] "top_effects=2" "swap_above=inf" ...

``--kinds`` draws the hidden targets from these paint families' shares (``pearl=1``: pearls
alone), to compare settings on one family with all its targets.

With ``--resprays K`` each first recipe is sprayed K more times (paired with the hidden
formula's sprays): ``first_shot_chance`` tells settings apart that one spray each cannot.
"""

from __future__ import annotations

import argparse
import dataclasses
import json

from _matcher import add_harness_arguments, run_harness, shipped_matcher
from flakelab.match.search import MatchSettings

FIGURES = (
    "first_shot_success",
    "after_one_correction",
    "novel_toner_first_shot",
    "oracle_success",
    "first_shot_chance",
    "after_one_correction_chance",
    "oracle_chance",
    "respray_success",
    "after_one_perfect_correction",
    "predicted_de00_median",
    "first_shot_de00_median",
    "first_shot_metamerism_median",
    "first_shot_texture_within",
    "first_shot_texture_share_p95",
    "latency_p50_s",
    "latency_p95_s",
)


def parse_settings(spec: str) -> MatchSettings:
    """``"top_effects=2,sparsity=0.2"`` → MatchSettings (types from the dataclass)."""
    types = {
        f.name: float if f.default is None else type(f.default)
        for f in dataclasses.fields(MatchSettings)
    }
    values = {}
    for item in filter(None, (part.strip() for part in spec.split(","))):
        name, _, value = item.partition("=")
        if name not in types:
            raise SystemExit(f"setting {name!r}: not a MatchSettings field ({', '.join(types)})")
        values[name] = value in ("1", "true", "True") if types[name] is bool else types[name](value)
    return MatchSettings(**values)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("settings", nargs="*", help="e.g. top_effects=2,top_pigments=5")
    add_harness_arguments(parser, targets=100, novel_targets=0)
    args = parser.parse_args()
    world, forward, effect = shipped_matcher(
        args.world, args.model, args.kinds, white_pearls=args.white_pearls
    )
    rows = []
    for spec in ["", *args.settings]:
        report = run_harness(world, forward, effect, args, forward.novel, parse_settings(spec))
        figures = {k: report[k] for k in FIGURES}
        if args.resprays:
            figures["first_shot_chance_by_family"] = {
                f: v["first_shot_chance"] for f, v in report["by_family"].items()
            }
        rows.append({"settings": spec or "defaults", **figures})
        if not args.json:
            print(rows[-1]["settings"], figures, flush=True)
    if args.json:
        print(json.dumps(rows, indent=2))


if __name__ == "__main__":
    main()
