"""What weighing metamerism costs the search, in time.

Two figures, each against a baseline measured in the same run:

* one optimiser step of the objective alone (forward and backward, no model), for ``N``
  recipes at the model's geometries: daylight colour alone (the baseline), then daylight
  colour plus the smooth metamerism index at every step
  (:meth:`~flakelab.match.objective.MatchObjective.recipe_loss`), then with the index
  along its tangent, as the search takes it;
* whole matches of the harness's hidden targets (``flakelab match evaluate``'s world, seed
  ``--seed``) by the shipped model, with metamerism weight 0 (the baseline), the default
  (the term followed along its tangent between retakes every ``metamerism_every`` steps:
  :class:`~flakelab.match.objective.MetamerismTangent`) and the exact term at every step
  (``metamerism_every=1``).

    python benchmarks/metamerism_cost.py [--targets 15] [--seed 4242] [--model FILE] [--json]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from _matcher import MODEL_HELP, shipped_matcher
from flakelab.match.evaluate import trial
from flakelab.match.objective import MatchObjective, MetamerismTangent
from flakelab.match.search import match
from flakelab.match.settings import MatchSettings
from timing import best_time, print_report

STEPS = 200


def step_seconds(loss, R0: torch.Tensor) -> float:
    """Seconds per step of ``loss``'s forward and backward pass at ``R0``."""

    def steps() -> None:
        for _ in range(STEPS):
            R = R0.clone().requires_grad_(True)
            loss(R).sum().backward()

    return best_time(steps) / STEPS


def tangent_loss(objective: MatchObjective, target_lab):
    """The search's loss with the metamerism term along its tangent, retaken as it is."""
    tangent = MetamerismTangent(objective, MatchSettings.metamerism_every)
    return lambda R: objective.colour_loss(target_lab, R) + tangent(R)


def objective_steps(forward, spectra: np.ndarray, rows: int, rng) -> dict[str, float]:
    R0 = torch.as_tensor(
        rng.uniform(0.05, 0.8, (rows, *spectra.shape)), dtype=forward.dtype
    )  # fmt: skip
    objective = MatchObjective(
        forward.geometries, None, forward.dtype, spectra, MatchSettings.metamerism
    )
    target_lab = objective.lab(torch.as_tensor(spectra, dtype=forward.dtype))
    daylight = step_seconds(lambda R: objective.colour_loss(target_lab, R), R0)
    weighed = step_seconds(lambda R: objective.recipe_loss(target_lab, R), R0)
    tangent = step_seconds(tangent_loss(objective, target_lab), R0)
    return {
        f"step_ms_daylight_{rows}_rows": 1e3 * daylight,
        f"step_ms_with_metamerism_{rows}_rows": 1e3 * weighed,
        f"step_ms_with_tangent_{rows}_rows": 1e3 * tangent,
        f"step_ratio_{rows}_rows": weighed / daylight,
        f"step_ratio_tangent_{rows}_rows": tangent / daylight,
    }


def match_seconds(targets, forward, effect, settings: MatchSettings) -> np.ndarray:
    match(targets[0], forward, effect, settings=settings)  # warm the caches
    seconds = []
    for target in targets:
        start = time.perf_counter()
        match(target, forward, effect, settings=settings)
        seconds.append(time.perf_counter() - start)
    return np.array(seconds)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
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
    daylight = match_seconds(targets, forward, effect, MatchSettings(metamerism=0.0))
    weighed = match_seconds(targets, forward, effect, MatchSettings())
    exact = match_seconds(targets, forward, effect, MatchSettings(metamerism_every=1))
    report |= {
        "match_s_daylight_median": float(np.median(daylight)),
        "match_s_with_metamerism_median": float(np.median(weighed)),
        "match_s_exact_metamerism_median": float(np.median(exact)),
        "match_ratio_of_means": float(weighed.mean() / daylight.mean()),
        "match_ratio_of_means_exact": float(exact.mean() / daylight.mean()),
    }
    print_report(report, args.json, ",.4g")


if __name__ == "__main__":
    main()
