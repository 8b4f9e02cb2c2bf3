"""What toners added to a library since the model was trained cost a match: the demo
library (the baseline, measured in the same run) against it with ADDED variants of its own
toners (a pigment's K and S shifted along the grid and scaled, a flake resized, a pearl's
coating thickened or thinned), which the shipped model never saw and the matcher predicts as
new toners. Each target is the physics' reflectance of a recipe of a variant and two known
toners, matched with every library; the search's seconds and the best candidate's worst
ΔE00 (the model's prediction against the target) per library.

    python benchmarks/added_toners.py [--added 3 35] [--targets 8] [--seed 8] [--json]
"""

from __future__ import annotations

import argparse
import warnings
from dataclasses import replace

import numpy as np

from flakelab.core.geometry import DEFAULT_INSTRUMENT, parse_geometries
from flakelab.core.measurement import Measurement
from flakelab.core.spectra import WAVELENGTHS
from flakelab.errors import Note
from flakelab.io import read_library
from flakelab.library.toners import Library
from flakelab.match.forward import PhysicsForward
from flakelab.match.models import effect_mask, forward_for
from flakelab.match.search import match
from flakelab.models.registry import shipped_model
from timing import matmul_gflops, print_report


def variant(toner, generation: int, rng: np.random.Generator):
    """A toner like ``toner``, named as its ``generation``-th variant."""
    name = f"{toner.name} v{generation}"
    if toner.kind == "pigment":
        shift, scale = int(rng.integers(-2, 3)), rng.uniform(0.7, 1.4)
        return replace(toner, name=name, absorption=np.roll(toner.absorption, shift) * scale,
                       scattering=np.roll(toner.scattering, shift) * scale)  # fmt: skip
    if toner.kind == "aluminium":
        radius, spread = rng.uniform(0.8, 1.25), rng.uniform(0.85, 1.2)
        return replace(toner, name=name, radius_um=toner.radius_um * radius,
                       orientation_sd_deg=toner.orientation_sd_deg * spread)  # fmt: skip
    return replace(toner, name=name, coating_nm=toner.coating_nm * rng.uniform(0.9, 1.1))


def with_added(library: Library, added: int, seed: int) -> Library:
    """``library`` and ``added`` variants of its toners, the pigments' first."""
    rng = np.random.default_rng(seed)
    order = sorted(library.toners, key=lambda t: t.kind != "pigment")
    extra = [variant(order[k % len(order)], 2 + k // len(order), rng) for k in range(added)]
    return replace(
        library, name=f"{library.name} + {added} added", toners=(*library.toners, *extra)
    )


def targets(
    library: Library, base: Library, count: int, seed: int, among: int
) -> list[Measurement]:
    """Targets that need a variant of a pigment, one of the first ``among`` added to
    ``base`` (those every library of the run holds): an aluminium, the variant and a known
    pigment, in the physics at the shipped model's geometries."""
    rng = np.random.default_rng(seed)
    geometries = shipped_model(DEFAULT_INSTRUMENT).geometries
    physics, at = PhysicsForward(library, geometries), parse_geometries(geometries)
    names = library.names
    aluminiums = [t.name for t in base.of_kind("aluminium")]
    known = [t.name for t in base.of_kind("pigment")]
    added = [t for t in library.toners if t.name not in base.names][:among]
    variants = [t.name for t in added if t.kind == "pigment"]
    made = []
    for k in range(count):
        recipe = {rng.choice(aluminiums): 0.65, rng.choice(variants): 0.2, rng.choice(known): 0.15}
        x = np.zeros((1, len(names)))
        for name, share in recipe.items():
            x[0, names.index(name)] += share
        R = physics.reflectance(x)[0]
        made.append(Measurement(f"target {k}: {recipe}", at, WAVELENGTHS, R))
    return made


def timed_matches(library: Library, chosen: list[Measurement], base: Library) -> dict:
    with warnings.catch_warnings():  # the note naming the added toners: this run's point
        warnings.simplefilter("ignore", Note)
        forward = forward_for(shipped_model(DEFAULT_INSTRUMENT), library)
    effect = effect_mask(library, forward.toners)
    results = [match(target, forward, effect, library=library) for target in chosen]
    return {
        "toners": len(library.names),
        "seconds_median": round(float(np.median([r.seconds for r in results])), 2),
        "seconds_max": round(max(r.seconds for r in results), 2),
        "worst_de00_median": round(
            float(np.median([r.candidates[0].de00.max() for r in results])), 3
        ),
        "uses_an_added_toner": sum(
            any(name not in base.names for name in r.candidates[0].fractions) for r in results
        ),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--added", type=int, nargs="+", default=[3, 35], help="toners added")
    parser.add_argument("--targets", type=int, default=8)
    parser.add_argument("--seed", type=int, default=8)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()

    demo = read_library()
    widest = with_added(demo, max(args.added), args.seed)
    chosen = targets(widest, demo, args.targets, args.seed, min(args.added))
    report = {"gflops": round(matmul_gflops(), 1), "targets": args.targets, "seed": args.seed}
    report["demo"] = timed_matches(demo, chosen, demo)
    for added in args.added:
        report[f"added_{added}"] = timed_matches(with_added(demo, added, args.seed), chosen, demo)
    print_report(report, args.json)


if __name__ == "__main__":
    main()
