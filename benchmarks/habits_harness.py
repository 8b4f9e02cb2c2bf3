"""Matcher: what a shop's habits file buys in the harness, on the same targets and sprays.

Runs the evaluation harness (``flakelab match evaluate``) twice in one shop's world: without
habits, then aimed off for the habits file ``--habits`` (``flakelab cases habits CASES --out
FILE``, read from that shop's cases). Both runs see the same hidden targets and the same
sprays (seeded), so the rows differ only by the habits; what the habits add to each target's
match time is paired too, and each row records the machine's pace before it. The first
``--latency-targets`` targets are matched again, without and with the habits in turn, for
what the habits add to a match's time free of the machine's drift between the two runs.
The shop is ``--world``'s, or one given its own habits with ``--world-habits`` (film build
and flake spread as factors on the factory's, instrument gain as a fraction): a shop with
mild habits is ``--world-habits 1.015,0.99,0.0015``.

    python benchmarks/habits_harness.py --habits FILE [--world-habits FILM,SPREAD,GAIN]
        [--world shop] [--targets 200] [--novel-targets 50] [--seed 4242] [--resprays K]
        [--latency-targets 40] [--json]
"""

from __future__ import annotations

import argparse
import json
from itertools import islice

import numpy as np

from _matcher import (
    WORLD_HABITS_HELP,
    add_harness_arguments,
    harness_tolerance,
    parse_world_habits,
    shipped_matcher,
    timed_harness,
    world_habits,
)
from flakelab.match.evaluate import CHANCES, FAMILY_FIGURES, harness_match, harness_trials
from flakelab.match.habits import read_habits
from timing import matmul_gflops, peak_rss_mb

FIGURES = (
    "first_shot_success",
    "after_one_correction",
    "novel_toner_first_shot",
    "oracle_success",
    "respray_success",
    "after_one_perfect_correction",
    "first_shot_de00_median",
    "first_shot_metamerism_median",
    "latency_p50_s",
    "latency_p95_s",
)
PAIRED = ("first_shot_success", "after_one_correction")
PAIRED_CHANCES = ("first_shot_chance", "after_one_correction_chance")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--habits", required=True, help="habits file (flakelab cases habits)")
    parser.add_argument(
        "--world-habits",
        type=parse_world_habits,
        help=WORLD_HABITS_HELP + " (default: those of --world)",
    )
    parser.add_argument(
        "--latency-targets",
        type=int,
        default=40,
        help="the first this many targets matched again without and with the habits, "
        "alternately, for their latency free of the machine's drift (0: none)",
    )
    add_harness_arguments(parser, targets=200, novel_targets=50)
    args = parser.parse_args()
    habits = read_habits(args.habits)
    world, forward, effect = shipped_matcher(
        args.world,
        args.model,
        args.kinds,
        shop_habits=args.world_habits,
        white_pearls=args.white_pearls,
    )
    rows, trials = [], []
    for label, shop_habits in (("without habits", None), ("with its habits", habits)):
        pace = matmul_gflops()
        report, wall = timed_harness(
            world, forward, effect, args, forward.novel, label, habits=shop_habits, per_target=True
        )
        figures = FIGURES + (tuple(CHANCES) if args.resprays else ())
        rows.append(
            {"run": label, **{k: report[k] for k in figures}, "wall_s": wall, "gflops": pace}
        )
        trials.append(report["per_target"])
    summary = {
        "world": world_habits(world),
        "habits": habits.report(),
        "rows": rows,
        "with_minus_without": paired_differences(
            *(t[: args.targets] for t in trials), chances=bool(args.resprays)
        ),
        "latency_interleaved_s": interleaved_latency(
            world, forward, effect, habits, args, args.latency_targets
        ),
        "latency_with_minus_without_s": {
            "all": paired_latency(*trials),
            "known_toners": paired_latency(*(t[: args.targets] for t in trials)),
            "new_toner": paired_latency(*(t[args.targets :] for t in trials)),
        },
        "peak_rss_gb": peak_rss_mb() / 1024,
    }
    if args.json:
        print(json.dumps(summary, indent=2))
        return
    print(f"world's shop {summary['world']}; habits read: {habits.describe()}")
    for row in rows:
        figures = "  ".join(
            f"{k} {'–' if v is None else format(v, '.3f')}" for k, v in row.items() if k != "run"
        )
        print(f"{row['run']:>16}  {figures}")
    for name, d in summary["with_minus_without"].items():
        print(f"with − without habits, {name}: {d['mean']:+.3f} ± {d['se']:.3f} (paired)")
    if d := summary["latency_interleaved_s"]:
        print(
            f"latency, {d['targets']} targets matched alternately: p50 {d['without_p50']:.3f} s "
            f"without habits, {d['with_p50']:.3f} s with; the habits add p50 "
            f"{d['added_p50']:+.3f} s, p95 {d['added_p95']:+.3f} s"
        )
    for targets, d in summary["latency_with_minus_without_s"].items():
        if d:
            print(
                f"with − without habits, latency per target ({targets.replace('_', ' ')}): "
                f"p50 {d['p50']:+.3f} s, p95 {d['p95']:+.3f} s"
            )


def interleaved_latency(world, forward, effect, habits, args, count: int) -> dict:
    """What the habits add to a match's time, free of the machine's drift: the harness's first
    ``count`` targets, each matched without, with, with and without the habits in turn (the
    harness's match, :func:`~flakelab.match.evaluate.harness_match`), each target's two times
    of a kind averaged."""
    if not count:
        return {}
    tolerance = harness_tolerance(args)
    times = []
    trials = harness_trials(world, args.targets, args.seed, forward.novel, args.novel_targets)
    for _, t in islice(trials, count):
        seconds = [
            harness_match(t, forward, effect, None, shop_habits, tolerance)[1]
            for shop_habits in (None, habits, habits, None)
        ]
        times.append(((seconds[0] + seconds[3]) / 2, (seconds[1] + seconds[2]) / 2))
    without, with_habits = np.array(times).T
    added = with_habits - without
    return {
        "targets": len(times),
        "without_p50": float(np.percentile(without, 50)),
        "with_p50": float(np.percentile(with_habits, 50)),
        "added_p50": float(np.percentile(added, 50)),
        "added_p95": float(np.percentile(added, 95)),
    }


def paired_latency(without: list[dict], with_habits: list[dict]) -> dict:
    """What the habits add to a match's time, trial by trial of the two runs: their p50
    latencies differ by the machine's pace between them as well, which on this machine moves
    by the hour (each row's ``gflops`` says how far)."""
    d = [b["latency_s"] - a["latency_s"] for a, b in zip(without, with_habits, strict=True)]
    if not d:
        return {}
    return {"p50": float(np.percentile(d, 50)), "p95": float(np.percentile(d, 95))}


def paired_differences(without: list[dict], with_habits: list[dict], chances: bool) -> dict:
    """Each paired figure's mean difference over the same targets (with the habits − without)
    and its standard error: the same targets and sprays, so the targets' own luck cancels."""
    # a trial's rate is its worst share of the tolerance (≤ 1 passes), a chance its mean
    figures = {name: lambda t, key=FAMILY_FIGURES[name]: float(t[key] <= 1.0) for name in PAIRED}
    if chances:
        figures |= {name: lambda t, key=CHANCES[name]: t[key] for name in PAIRED_CHANCES}
    differences = {}
    for name, figure in figures.items():
        d = np.array([figure(b) - figure(a) for a, b in zip(without, with_habits, strict=True)])
        differences[name] = {"mean": float(d.mean()), "se": float(d.std(ddof=1) / np.sqrt(len(d)))}
    return differences


if __name__ == "__main__":
    main()
