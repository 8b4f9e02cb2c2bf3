"""What weighing metamerism costs the search, in time.

Two figures, each against a baseline measured in the same run:

* one optimiser step of the objective alone (forward and backward, no model), for ``N``
  recipes at the five-angle instrument's geometries: daylight colour alone (the baseline),
  then daylight colour plus the smooth metamerism index
  (:meth:`~flakelab.match.objective.MatchObjective.recipe_loss`);
* whole matches of the harness's hidden targets (``flakelab match evaluate``'s world, seed
  ``--seed``) by the shipped model, with metamerism weight 0 (the baseline) and the default.

    python benchmarks/metamerism_cost.py [--targets 15] [--seed 4242] [--model FILE] [--json]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from _matcher import MODEL_HELP, shipped_matcher
from flakelab.match.evaluate import trial
from flakelab.match.objective import MatchObjective
from flakelab.match.search import match
from flakelab.match.settings import MatchSettings
from timing import best_time, print_report

STEPS = 200


def step_seconds(objective: MatchObjective, target_lab, R0: torch.Tensor) -> float:
    """Seconds per step of the objective's forward and backward pass at ``R0``."""

    def steps() -> None:
        for _ in range(STEPS):
            R = R0.clone().requires_grad_(True)
            objective.recipe_loss(target_lab, R).sum().backward()

    return best_time(steps) / STEPS


def objective_steps(forward, spectra: np.ndarray, rows: int, rng) -> dict[str, float]:
    R0 = torch.as_tensor(
        rng.uniform(0.05, 0.8, (rows, *spectra.shape)), dtype=forward.dtype
    )  # fmt: skip
    seconds = {}
    for weight in (0.0, MatchSettings.metamerism):
        objective = MatchObjective(forward.geometries, None, forward.dtype, spectra, weight)
        target_lab = objective.lab(torch.as_tensor(spectra, dtype=forward.dtype))
        seconds[weight] = step_seconds(objective, target_lab, R0)
    daylight, weighed = seconds[0.0], seconds[MatchSettings.metamerism]
    return {
        f"step_ms_daylight_{rows}_rows": 1e3 * daylight,
        f"step_ms_with_metamerism_{rows}_rows": 1e3 * weighed,
        f"step_ratio_{rows}_rows": weighed / daylight,
    }


def match_seconds(targets, forward, effect, weight: float) -> np.ndarray:
    settings = MatchSettings(metamerism=weight)
    match(targets[0], forward, effect, settings=settings)  # warm the caches
    seconds = []
    for target in targets:
        start = time.perf_counter()
        match(target, forward, effect, settings=settings)
        seconds.append(time.perf_counter() - start)
    return np.array(seconds)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--targets", type=int, default=15)
    parser.add_argument("--seed", type=int, default=4242)
    parser.add_argument("--model", help=MODEL_HELP)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()

    torch.set_num_threads(1)  # as match runs
    world, forward, effect = shipped_matcher(model=args.model)
    rng = np.random.default_rng(args.seed)
    targets = [trial(world, x, rng).target for x in world.formulations(args.targets, rng)]
    report: dict = {"model": forward.name, "geometries": len(forward.geometries)}
    report |= {"targets": args.targets, "seed": args.seed}
    for rows in (20, 140):
        report |= objective_steps(forward, targets[0], rows, np.random.default_rng(0))
    daylight = match_seconds(targets, forward, effect, 0.0)
    weighed = match_seconds(targets, forward, effect, MatchSettings.metamerism)
    report |= {
        "match_s_daylight_median": float(np.median(daylight)),
        "match_s_with_metamerism_median": float(np.median(weighed)),
        "match_ratio_of_means": float(weighed.mean() / daylight.mean()),
    }
    print_report(report, args.json, ",.4g")


if __name__ == "__main__":
    main()
