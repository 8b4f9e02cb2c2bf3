"""Matcher: how much of the harness's shortfall is the learned model's, and how much the world's.

Runs the evaluation harness (``flakelab match evaluate``) twice on the same hidden targets
and the same sprays: once with the shipped five-angle model (or ``--model FILE``, in its own
instrument's world), the baseline of the same run, and once with the *exact* model, the
generated world's own nominal physics (:class:`flakelab.match.forward.PhysicsForward`: the
library's fast model, which the world sprays with batches and application varied about it).
The search, the correction and the judging are the same; only the model differs. What the
exact model still fails is the world's: the shop's toner batches, which no model of the
library can know before a spray-out, and each spray's film build, flake alignment and
instrument reading. Its derivatives come from finite differences, so a match takes tens of
times longer than with the learned model.

    python benchmarks/exact_model.py [--targets 200] [--novel-targets 50] [--seed 4242]
        [--world shop] [--model FILE] [--resprays K] [--json]
"""

from __future__ import annotations

import argparse
import json
import sys

from _matcher import add_harness_arguments, shipped_matcher, timed_harness
from flakelab.match.forward import PhysicsForward

FIGURES = (
    "first_shot_success",
    "after_one_correction",
    "novel_toner_first_shot",
    "novel_oracle_success",
    "oracle_success",
    "first_shot_chance",
    "after_one_correction_chance",
    "oracle_chance",
    "respray_success",
    "after_one_perfect_correction",
    "predicted_de00_median",
    "first_shot_de00_median",
    "latency_p50_s",
    "latency_p95_s",
)
RATIOS = ("first_shot_success", "after_one_correction", "novel_toner_first_shot")


def run(world, forward, effect, args, novel, label: str) -> dict:
    """The harness's figures for ``forward`` and the command's wall time."""
    report, seconds = timed_harness(world, forward, effect, args, novel, label)
    return {"model": forward.name, **{k: report[k] for k in FIGURES}, "wall_s": seconds}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_harness_arguments(parser, targets=200, novel_targets=50)
    args = parser.parse_args()
    world, learned, effect = shipped_matcher(
        args.world, args.model, args.kinds, white_pearls=args.white_pearls
    )
    exact = PhysicsForward(world.library, world.geometries)
    # the new-toner targets are drawn as for the learned model; the exact model knows them all
    rows = {
        "learned": run(world, learned, effect, args, learned.novel, "learned model"),
        "exact": run(world, exact, effect, args, learned.novel, "exact model (physics)"),
    }
    ratios = {
        f"{k}_learned_vs_exact": rows["learned"][k] / rows["exact"][k]
        for k in RATIOS
        if rows["learned"][k] is not None and rows["exact"][k]
    }
    if args.json:
        print(json.dumps({"rows": rows, **ratios}, indent=2))
        return
    width = max(map(len, FIGURES)) + 2
    print(f"{'':{width}}{'learned':>10}{'exact':>10}")
    for k in (*FIGURES, "wall_s"):
        values = [rows[m][k] for m in ("learned", "exact")]
        cells = "".join(f"{'—' if v is None else f'{v:.3f}':>10}" for v in values)
        print(f"{k:{width}}{cells}")
    for k, v in ratios.items():
        print(f"{k}: {v:.3f}")
    print(f"learned: {rows['learned']['model']}", file=sys.stderr)


if __name__ == "__main__":
    main()
