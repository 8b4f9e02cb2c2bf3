"""Texture limits against what varies by itself: where the refinish tolerance's sit.

A texture limit should fail a recipe for its flakes, not for the spray gun or the model. For
each bounded reading (G, SG, Si and Sa under every light) this prints, in the generated
world of the demo library:

* ``remeasure``: one spray-out read twice (the instrument's texture noise: the glints and
  grain of one spot of its camera, ``World.measure_texture``);
* ``respray``: the same cans sprayed twice (application, and each read once);
* ``factory_vs_shop``: one formulation sprayed by the factory and by a shop, each with its own
  batches and application, each read once (what a perfect recipe meets);
* ``model_error``: the shipped model's mean absolute texture error on generated cases it
  never saw, through the matcher's forward (the hybrid, for toners new to the model): what
  a candidate's predicted texture is off by from a spray-out's reading (the reading's own
  noise included);

and ``new_toner_error``: the matcher's (hybrid) texture error at the world's nominal
application for effect paints with and without one of the model's new toners (1–8 %, added
as the harness adds it);

as 50th / 95th / 99th percentiles of |Δ| (largest over the lights for Si and Sa) and each
limit as a multiple of the 99th percentile and of the model's error (a baseline measured in
the same run).

    python benchmarks/texture_tolerance.py [--formulations 2000] [--cases 500] [--seed 1]
        [--tolerance refinish] [--json]
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from flakelab.cases.generator import Variation, World
from flakelab.core.measurement import TEXTURE_FAMILIES, TEXTURE_READINGS
from flakelab.io import read_library, read_tolerance
from flakelab.match.judging import evaluate_recipes
from flakelab.match.models import forward_for
from flakelab.models.registry import shipped_model
from flakelab.models.training import evaluate_model, generated_case_arrays


def spread(a, b, effect: np.ndarray) -> dict[str, dict[str, float]]:
    """Percentiles of |Δ| per reading family over the effect paints (solids read none)."""
    difference = np.abs(a - b)[effect]
    out = {}
    for name, columns in TEXTURE_FAMILIES.items():
        worst = difference[:, columns].max(1)
        out[name] = {f"p{q}": float(np.percentile(worst, q)) for q in (50, 95, 99)}
    return out


def with_new_toner(world, x, novel, rng) -> np.ndarray:
    """``x`` with one of the ``novel`` toners added at 1–8 % and renormalised, as the
    harness makes its new-toner targets."""
    names, out = list(world.library.names), x.copy()
    for row in out:
        row[names.index(novel[int(rng.integers(len(novel)))])] = np.exp(
            rng.uniform(np.log(0.01), np.log(0.08))
        )
    return out / out.sum(1, keepdims=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--formulations", type=int, default=2000)
    parser.add_argument("--cases", type=int, default=500)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--tolerance", default="refinish")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    tolerance = read_tolerance(args.tolerance)
    if tolerance.texture is None:
        raise SystemExit(f"{args.tolerance}: bounds no texture reading")
    model = shipped_model("five-angle")
    world = World(read_library(None), model.instrument)
    rng = np.random.default_rng(args.seed)
    x = world.formulations(args.formulations, rng)
    effect = world.library.paint_families(x) != "solid"
    batch = world.variation(len(x), rng)

    def same_cans() -> Variation:
        return Variation(batch.strength, batch.hue_shift, *world.application(len(x), rng))

    texture_rng = rng.spawn(1)[0]  # the instrument's texture noise, apart from the sprays

    def read(variation: Variation) -> np.ndarray:  # one spray, read by the instrument
        return world.measure_texture(world.appearance(x, variation)[1], texture_rng)

    respray = spread(read(same_cans()), read(same_cans()), effect)
    remeasure = spread(*[world.measure_texture(world.appearance(x, batch)[1], texture_rng)
                         for _ in range(2)], effect)  # fmt: skip
    factory = read(world.variation(len(x), rng, at_shop=False))
    shop = read(world.variation(len(x), rng))
    factory_vs_shop = spread(factory, shop, effect)
    cases = generated_case_arrays(world, args.cases, args.seed + 1000)
    matcher = forward_for(model, world.library)
    predict = lambda x: evaluate_recipes(matcher, x)  # noqa: E731 as `model evaluate` does
    mae = evaluate_model(model, cases, predict)["texture_mae"]
    known = world.without(matcher.novel)
    without = known.formulations(len(x), rng)
    with_new = with_new_toner(world, without, matcher.novel, rng)
    flakes = world.library.paint_families(without) != "solid"
    nominal = world.nominal(len(x), at_shop=True)
    new_toner_error = {
        label: {
            name: float(np.abs(predict(xs)[1] - world.appearance(xs, nominal)[1])[flakes][
                :, columns].mean())
            for name, columns in TEXTURE_FAMILIES.items()
        }
        for label, xs in (("without", without), ("with", with_new))
    }  # fmt: skip
    limits = tolerance.texture.to_dict()
    model_error = {
        name: max(mae[TEXTURE_READINGS[i]] for i in TEXTURE_FAMILIES[name]) for name in limits
    }
    report = {
        "tolerance": tolerance.name,
        "formulations": args.formulations,
        "cases": args.cases,
        "seed": args.seed,
        "limits": limits,
        "remeasure": {k: remeasure[k] for k in limits},
        "respray": {k: respray[k] for k in limits},
        "factory_vs_shop": {k: factory_vs_shop[k] for k in limits},
        "model_error": model_error,
        "limit_over_factory_vs_shop_p99": {
            k: limits[k] / factory_vs_shop[k]["p99"] for k in limits
        },
        "limit_over_model_error": {k: limits[k] / model_error[k] for k in limits},
        "new_toner_error": new_toner_error,
    }
    if args.json:
        print(json.dumps(report, indent=1))
        return
    print(
        f"{tolerance.name}: {args.formulations} formulations, {args.cases} cases, seed {args.seed}"
    )
    for k, limit in limits.items():
        fs, rs, ms = factory_vs_shop[k], respray[k], remeasure[k]
        print(
            f"  |Δ{k}| ≤ {limit:g}: remeasure p99 {ms['p99']:.3f}; respray p99 {rs['p99']:.3f}; "
            f"factory vs shop p50 / p95 / p99 "
            f"{fs['p50']:.3f} / {fs['p95']:.3f} / {fs['p99']:.3f}; model error "
            f"{model_error[k]:.3f}; limit = {report['limit_over_factory_vs_shop_p99'][k]:.1f} × "
            f"p99, {report['limit_over_model_error'][k]:.0f} × model error"
        )
    for label, errors in new_toner_error.items():
        shown = ", ".join(f"|Δ{k}| {v:.3f}" for k, v in errors.items())
        print(f"  hybrid's mean error, effect paints {label} a new toner: {shown}")


if __name__ == "__main__":
    main()
