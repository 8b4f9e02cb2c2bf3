"""Texture repeatability: the spot-to-spot spread of rendered flake images, and the
generated world's texture reading noise fitted to it.

For effect paints of the demo library (nominal application), each coating's flakes are
rendered at ``--spots`` places by flakelab's texture camera (256 × 256 pixels of 15 µm,
a 3.84 mm field; :mod:`flakelab.texture.images`) and read (:mod:`flakelab.texture.metrics`).
The spread between spots fits the counting model of
:func:`flakelab.texture.readings.counted_readings`: Var(Sa) = glint_share·Sa,
sd(Si)/Si = glint_sd/√N with N = Sa/glint_share glints, sd(G)/G = grain_sd. The script prints
the fitted constants, the world's (``WorldSettings``) and their ratio, and how well the model
predicts each coating's spread (median |log ratio| of predicted to rendered sd); the rise of
Si with the light's angle (slope k of :func:`flakelab.texture.readings.light_factor`) fitted
to the rendered means against the world's, with both Si15 : Si45 : Si75; then what
the world's noise gives: |Δ| between two readings of one panel (50th / 95th / 99th
percentiles over the effect paints, the largest over the lights for Sa and Si, each paint read
50 times over) and the share of those pairs more than 1.0 apart.

    python benchmarks/texture_repeatability.py [--coatings 24] [--spots 16] [--seed 5] [--json]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from flakelab.cases.generator import World
from flakelab.core.measurement import TEXTURE_FAMILIES
from flakelab.io import read_library
from flakelab.texture.images import flake_populations
from flakelab.texture.readings import SPARKLE_LIGHT_SLOPE
from flakelab.texture.repeatability import (
    counting_sd,
    fit_counting_noise,
    fit_light_slope,
    spot_readings,
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--coatings", type=int, default=24)
    parser.add_argument("--spots", type=int, default=16)
    parser.add_argument("--seed", type=int, default=5)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()

    world = World(read_library(None))
    rng = np.random.default_rng(args.seed)
    x = world.formulations(8 * args.coatings, rng)
    x = x[world.library.paint_families(x) != "solid"][: args.coatings]
    layer = world.layer(x, world.nominal(len(x)))
    start = time.perf_counter()
    spots = [
        spot_readings(p, args.spots, seed=1000 * i)
        for i, p in enumerate(flake_populations(layer, world.library.flake_radii_um))
    ]
    render_s = time.perf_counter() - start
    fitted = fit_counting_noise(spots)
    settings = {k: getattr(world.settings, k) for k in fitted}
    stack = np.stack(spots)
    mean, sd = stack.mean(1), stack.std(1, ddof=1)
    predicted = counting_sd(settings, mean)
    # Sa, Si and G where the coating shows them (SG has no closed form)
    seen = np.isfinite(predicted) & (mean > 0)
    log_ratio = np.abs(np.log(predicted[seen] / sd[seen]))

    _, texture = world.appearance(x, world.nominal(len(x)))
    si = TEXTURE_FAMILIES["Si"]
    rendered_si = mean[:, si] / mean[:, si[:1]]
    world_si = texture[:, si] / texture[:, si[:1]]
    light_slope = {
        "fitted": fit_light_slope(spots),
        "world": SPARKLE_LIGHT_SLOPE,
        "rendered_si_over_si15_median": np.median(rendered_si, 0).round(3).tolist(),
        "world_si_over_si15_median": np.median(world_si, 0).round(3).tolist(),
    }
    many = np.repeat(texture, 50, axis=0)
    first, second = world.measure_texture(many, rng), world.measure_texture(many, rng)
    difference = np.abs(first - second)
    remeasure = {
        name: {f"p{q}": float(np.percentile(difference[:, cols].max(1), q)) for q in (50, 95, 99)}
        | {"over_1": float(np.mean(difference[:, cols].max(1) > 1.0))}
        for name, cols in TEXTURE_FAMILIES.items()
    }
    report = {
        "coatings": len(x),
        "spots": args.spots,
        "seed": args.seed,
        "fitted": fitted,
        "world": settings,
        "world_over_fitted": {k: settings[k] / fitted[k] for k in fitted},
        "model_sd_median_abs_log_ratio": float(np.median(log_ratio)),
        "model_sd_within_factor_1_5": float(np.mean(log_ratio < np.log(1.5))),
        "light_slope": light_slope,
        "remeasure_abs_difference": remeasure,
        "render_s": render_s,
    }
    if args.json:
        print(json.dumps(report, indent=2))
        return
    print(f"{len(x)} effect coatings × {args.spots} spots rendered in {render_s:.0f} s")
    for k in fitted:
        print(f"  {k:12s} fitted {fitted[k]:.4f}   world {settings[k]:.4f}   "
              f"ratio {settings[k] / fitted[k]:.2f}")  # fmt: skip
    print(f"  the world's model predicts each coating's rendered sd within ×1.5 for "
          f"{report['model_sd_within_factor_1_5']:.0%} (median |log ratio| "
          f"{report['model_sd_median_abs_log_ratio']:.2f})")  # fmt: skip
    print(f"  Si's rise with the light's angle, k of 1 + k·log10(1/cos θ): fitted "
          f"{light_slope['fitted']:.3f}, world {SPARKLE_LIGHT_SLOPE:.3f}; Si15 : Si45 : Si75 "
          f"rendered {light_slope['rendered_si_over_si15_median']}, "
          f"world {light_slope['world_si_over_si15_median']}")  # fmt: skip
    print("the same panel read twice by the world's instrument, |Δ| p50 / p95 / p99, and the "
          "share of panels whose two readings differ by more than 1.0:")  # fmt: skip
    for name, q in remeasure.items():
        print(f"  {name:3s} {q['p50']:.3f} / {q['p95']:.3f} / {q['p99']:.3f}   "
              f"{q['over_1']:.1%}")  # fmt: skip


if __name__ == "__main__":
    main()
