"""Learned model: its own error where the matcher uses it, against where the cases lie.

The matcher optimises recipes through the learned model and so finds where the model is
wrong in its favour; the held-out error, measured at the formulas the generator makes,
does not see that. For hidden targets made as in ``flakelab match evaluate`` this measures
the model's ΔE00 against the nominal physics of the world (no batch, application or
instrument noise) twice: at the recipe the matcher proposes for each target, and at the
target's hidden formula. Their ratio says how much of the model's error the optimiser
finds. Beside them, the search's own fit: the best recipe's predicted worst-geometry ΔE00
to the target (per paint family too), which is what the search could reach through the
model; run with an older checkout's ``src`` first on ``PYTHONPATH`` (and its model) to tell
a world where targets are harder to reach from one where the model is further off.

    python benchmarks/matched_error.py [--targets 60] [--seed 81,82] [--model FILE] [--json]
        [--settings "model_risk=1"]
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from _matcher import MODEL_HELP, seeds_from, shipped_matcher
from flakelab.cases.generator import World
from flakelab.cli.common import tracked
from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E
from flakelab.match.evaluate import harness_trials, recipe_vector
from flakelab.match.judging import evaluate_recipes
from flakelab.match.search import MatchSettings, match
from match_variants import parse_settings


def own_error(world: World, forward, x: np.ndarray) -> np.ndarray:
    """ΔE00 ``[N, G]`` of the model's prediction for recipes ``x[N, T]`` against the world's
    nominal physics."""
    physics, _ = world.appearance(x, world.nominal(len(x)))
    predicted, _ = evaluate_recipes(forward, x)
    return delta_E(reflectance_to_Lab(physics), reflectance_to_Lab(predicted))


def statistics(de: np.ndarray) -> dict[str, float]:
    return {
        "de00_mean": float(de.mean()),
        "de00_p95": float(np.percentile(de, 95)),
        "worst_geometry_median": float(np.median(de.max(1))),
    }


def matched_and_hidden(
    world: World,
    forward,
    effect,
    seeds: list[int],
    targets: int,
    candidates: int = 1,
    settings: MatchSettings | None = None,
    fits: list[float] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """For ``targets`` hidden formulations per seed, made and measured as in the harness: the
    recipes ``[N·candidates, T]`` the matcher proposes (its best ``candidates``) and the hidden
    formulations ``[N, T]``; with a list ``fits``, each target's best recipe's predicted
    worst-geometry ΔE00 to it is appended there."""
    matched, hidden = [], []
    for seed in seeds:
        trials = harness_trials(world, targets, seed, forward.novel)
        for x_hidden, t in tracked(trials, f"targets (seed {seed})", total=targets):
            proposed = match(t.target, forward, effect, settings=settings).candidates[:candidates]
            matched += [recipe_vector(forward, c.fractions) for c in proposed]
            hidden.append(x_hidden)
            if fits is not None:
                fits.append(float(proposed[0].de00.max()))
    return np.array(matched), np.array(hidden)


def measure(world: World, forward, effect, args, settings: MatchSettings | None = None) -> dict:
    """The model's own error at matched recipes and at hidden formulas, their ratio, and the
    search's predicted fit (median worst-geometry ΔE00, over all and per paint family)."""
    fits: list[float] = []
    matched, hidden = matched_and_hidden(
        world, forward, effect, seeds_from(args.seed), args.targets, settings=settings, fits=fits
    )
    at_matches = statistics(own_error(world, forward, matched))
    at_hidden = statistics(own_error(world, forward, hidden))
    families, fit = world.library.paint_families(hidden), np.array(fits)
    return {
        "targets": len(hidden),
        "at_matched_recipes": at_matches,
        "at_hidden_formulas": at_hidden,
        "mean_ratio": at_matches["de00_mean"] / at_hidden["de00_mean"],
        "predicted_fit_median": float(np.median(fit)),
        "predicted_fit_median_by_family": {
            str(f): float(np.median(fit[families == f])) for f in np.unique(families)
        },
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--targets", type=int, default=60, help="per seed")
    parser.add_argument("--seed", default="81,82", help="one seed, a list or a range")
    parser.add_argument("--model", help=MODEL_HELP)
    parser.add_argument("--settings", default="", help="matcher settings, e.g. model_risk=0")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    world, forward, effect = shipped_matcher(model=args.model)
    settings = parse_settings(args.settings)
    report = {
        "model": args.model or "shipped",
        "settings": args.settings or "defaults",
        **measure(world, forward, effect, args, settings),
    }
    if args.json:
        print(json.dumps(report, indent=2))
        return
    print(f"{report['model']}: {report['targets']} targets, own ΔE00 against the nominal physics")
    for name in ("at_matched_recipes", "at_hidden_formulas"):
        s = report[name]
        print(
            f"  {name:20s} mean {s['de00_mean']:.3f}  p95 {s['de00_p95']:.3f}  "
            f"worst geometry median {s['worst_geometry_median']:.3f}"
        )
    print(f"  matched / hidden mean ×{report['mean_ratio']:.2f}")
    families = ", ".join(
        f"{f} {v:.3f}" for f, v in report["predicted_fit_median_by_family"].items()
    )
    fit = report["predicted_fit_median"]
    print(f"  the search's predicted worst-geometry ΔE00, median {fit:.3f} ({families})")


if __name__ == "__main__":
    main()
