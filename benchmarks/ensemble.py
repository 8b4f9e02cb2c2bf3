"""Learned model: an ensemble (``flakelab train --members K``) against its own members alone.

Each member is a network the protocol would have trained alone on the same cleaned cases,
so the members are the baseline, measured in the same run:

* ΔE00 on the 500 unseen cases of ``flakelab cases generate --n 500 --seed 987`` against the
  spray-outs and against the recipes' nominal physics (the model's own error), by family;
* how well the members' spread (the ``± model`` column of ``flakelab match``) tells where
  the ensemble's own error is large: rank correlation, own error by spread quintile;
* batched inference, formulations per second, ensemble against one member;
* with ``--matched``, the own error at the recipes the matcher proposes and at the hidden
  formulas (``benchmarks/matched_error.py``), ensemble against its first member.

    python benchmarks/ensemble.py --model FILE [--matched] [--targets 60] [--seed 81,82]
        [--json]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
from scipy.stats import spearmanr

from _matcher import shipped_matcher
from flakelab.cases.generator import World
from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E
from flakelab.io import read_library
from flakelab.match.judging import evaluate_recipes, model_spread
from flakelab.match.models import forward_for
from flakelab.models.registry import load_model_file
from flakelab.models.training import generated_case_arrays
from learning_variants import EVALUATION, judge
from matched_error import measure


def spread_calibration(library, forward) -> dict:
    """Does the members' spread point at the ensemble's own error? On the unseen cases, per
    case and geometry."""
    world = World(library, forward.model.instrument)
    n, seed = EVALUATION
    data = generated_case_arrays(world, n, seed)
    R, _ = evaluate_recipes(forward, data.x)
    lab = reflectance_to_Lab(R)
    nominal, _ = world.appearance(data.x, world.nominal(n))
    own = delta_E(reflectance_to_Lab(nominal), lab).ravel()
    spread = model_spread(forward, data.x, lab).ravel()
    quintile = np.searchsorted(np.quantile(spread, [0.2, 0.4, 0.6, 0.8]), spread)
    worst = own >= np.quantile(own, 0.95)
    return {
        "spread_mean": float(spread.mean()),
        "spread_own_error_spearman": float(spearmanr(spread, own).statistic),
        "own_error_by_spread_quintile": [float(own[quintile == q].mean()) for q in range(5)],
        "spread_by_quintile_upper": np.quantile(spread, [0.2, 0.4, 0.6, 0.8, 1.0]).tolist(),
        "worst_5pct_own_errors_in_top_spread_quintile": float(np.mean(quintile[worst] == 4)),
    }


def throughput(model, n: int = 200_000, repeats: int = 3) -> float:
    """Formulations per second through ``model.predict`` (best of ``repeats``)."""
    x = np.random.default_rng(0).dirichlet(np.full(len(model.toners), 0.3), n)
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        model.predict(x)
        best = min(best, time.perf_counter() - start)
    return n / best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", required=True, help="an ensemble model file")
    parser.add_argument("--matched", action="store_true", help="also the matched-recipe error")
    parser.add_argument("--targets", type=int, default=60, help="per seed, with --matched")
    parser.add_argument("--seed", default="81,82", help="target seeds, with --matched")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    library = read_library(None)
    model = load_model_file(args.model)
    if model.members < 2:
        raise SystemExit(f"{args.model}: a single network, not an ensemble (--members K)")
    members = model.split_members()
    report: dict = {"model": args.model, "members": model.members}
    report["ensemble"] = judge(library, model)
    report["member"] = [judge(library, m) for m in members]
    keys = report["ensemble"]
    report["member_mean"] = {k: float(np.mean([m[k] for m in report["member"]])) for k in keys}
    report["spread"] = spread_calibration(library, forward_for(model, library))
    report["formulations_per_s"] = {
        "ensemble": throughput(model),
        "member": throughput(members[0]),
    }
    if args.matched:
        world, forward, effect = shipped_matcher(model=args.model)
        report["matched_ensemble"] = measure(world, forward, effect, args)
        report["matched_member_1"] = measure(world, forward_for(members[0], library), effect, args)
    if args.json:
        print(json.dumps(report, indent=1))
        return
    print(f"{args.model}: {model.members} members")
    for key in keys:
        each = " ".join(f"{m[key]:.3f}" for m in report["member"])
        print(
            f"  {key:28s} ensemble {report['ensemble'][key]:.3f}  "
            f"members {each} (mean {report['member_mean'][key]:.3f})"
        )
    for key, value in report["spread"].items():
        print(f"  {key:44s} {np.round(value, 3).tolist()}")
    rates = report["formulations_per_s"]
    print(
        f"  inference: ensemble {rates['ensemble']:,.0f}/s, one member {rates['member']:,.0f}/s "
        f"(×{rates['ensemble'] / rates['member']:.2f})"
    )
    for name in ("matched_ensemble", "matched_member_1"):
        if name in report:
            m = report[name]
            print(
                f"  {name:18s} own error at matched recipes "
                f"{m['at_matched_recipes']['de00_mean']:.3f}, at hidden formulas "
                f"{m['at_hidden_formulas']['de00_mean']:.3f} (×{m['mean_ratio']:.2f})"
            )


if __name__ == "__main__":
    main()
