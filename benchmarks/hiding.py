"""How thick a paint must be to hide the primer (``flakelab hiding``): the fast model against
the reference Monte Carlo, and what it costs beside the search it joins.

**Accuracy.** For a few paints of the demo library (a transparent-pigment metallic, a tint
in the white, bismuth vanadate, an iron oxide red in the white), the build at which the
film over a contrast chart's black and white differ by 1 ΔE00 at 45as45 is read by the fast
model (:func:`flakelab.physics.hiding.hiding` at that one geometry) and by the reference
Monte Carlo (:func:`flakelab.physics.montecarlo.simulate`, seeded), which traces the same
layer over each ground at builds from a third to three times the fast model's and crosses
1 ΔE00 between them (log build, as the fast model does). The Monte Carlo's own noise on the
contrast is printed with it (its standard errors carried through by perturbing both
readings by one each).

**Cost.** ``hiding`` for three candidates at the five-angle and the MA-T12 geometries (best
of five), against the search of ``match --example`` in the same run (the baseline: what the
colorist waits for anyway).

    python benchmarks/hiding.py [--photons 40000] [--seed 3] [--json]
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace

import numpy as np

from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E_CIE2000
from flakelab.core.geometry import FACE_GEOMETRY, Geometry, instrument_geometries
from flakelab.io import read_library
from flakelab.physics.application import sprayed_layer
from flakelab.physics.hiding import HIDING_DE00, ground_reflectance, hiding
from flakelab.physics.layer import layer_from_fractions
from flakelab.physics.montecarlo import simulate
from timing import best_time, print_report

PAINTS = {
    "blue metallic": {"Al medium": 0.7, "Phthalo blue GS": 0.3},
    "quinacridone 1:4 in white": {"Quinacridone red": 0.8, "Titanium dioxide white": 0.2},
    "bismuth vanadate": {"Bismuth vanadate yellow": 1.0},
    "iron oxide 1:9 in white": {"Iron oxide red": 0.1, "Titanium dioxide white": 0.9},
}
"""The paints whose hiding is read both ways."""
FACE = (Geometry.parse(FACE_GEOMETRY),)
BUILDS = np.geomspace(1 / 3, 3, 9)
"""Where the Monte Carlo reads each paint, relative to the fast model's hiding build."""


def monte_carlo_contrast(library, x, build: float, photons: int, seed: int):
    """ΔE00 at 45as45 between the paint over the chart's black and white at relative ``build``
    by the Monte Carlo, and its noise (both readings moved by one standard error apart)."""
    layer = sprayed_layer(layer_from_fractions(library, x[None]), library, [build], [1.0])
    Lab, moved = {}, {}
    for sign, ground in ((1, "black"), (-1, "white")):
        over = replace(layer, primer=ground_reflectance(library, ground))
        run = simulate(over, FACE, photons, seed=seed)
        Lab[ground] = reflectance_to_Lab(np.pi * run.brdf)
        moved[ground] = reflectance_to_Lab(np.pi * (run.brdf + sign * run.stderr))
    de = float(delta_E_CIE2000(Lab["black"], Lab["white"])[0])
    return de, abs(float(delta_E_CIE2000(moved["black"], moved["white"])[0]) - de)


def crossing(builds: np.ndarray, de: np.ndarray, threshold: float) -> float:
    """Where ``de`` falls to ``threshold`` for good, in log build (NaN where it does not)."""
    above = np.flatnonzero(de > threshold)
    if above.size == 0 or above[-1] == len(de) - 1:
        return float("nan")
    i = above[-1]
    share = (de[i] - threshold) / (de[i] - de[i + 1])
    return float(np.exp(np.log(builds[i]) + share * np.log(builds[i + 1] / builds[i])))


def accuracy_report(photons: int, seed: int) -> dict:
    """Each paint's hiding build at 45as45, fast and Monte Carlo."""
    library = read_library()
    nominal = library.binder.thickness_um
    report: dict = {"photons": photons}
    ratios = []
    for name, recipe in PAINTS.items():
        x = library.fractions(recipe)
        fast = float(hiding(library, x[None], FACE).hiding_um[0]) / nominal
        builds = fast * BUILDS
        runs = [monte_carlo_contrast(library, x, b, photons, seed) for b in builds]
        de, noise = np.array(runs).T
        mc = crossing(builds, de, HIDING_DE00)
        key = name.replace(" ", "_").replace(":", "_")
        report |= {f"{key}_fast_um": fast * nominal, f"{key}_monte_carlo_um": mc * nominal,
                   f"{key}_monte_carlo_noise_de00_at_crossing": float(np.interp(
                       HIDING_DE00, de[::-1], noise[::-1]))}  # fmt: skip
        ratios.append(mc / fast)
    report["monte_carlo_over_fast_median"] = float(np.nanmedian(ratios))
    report["monte_carlo_over_fast_worst"] = float(ratios[int(np.nanargmax(np.abs(np.log(
        ratios))))])  # fmt: skip
    return report


def cost_report() -> dict:
    """``hiding`` for three candidates, against the search of ``match --example``."""
    from flakelab.data import example_path
    from flakelab.io import read_measurement
    from flakelab.match.models import effect_mask, forward_for
    from flakelab.match.search import match
    from flakelab.models.registry import shipped_model

    library = read_library()
    forward = forward_for(shipped_model("five-angle"), library)
    target = read_measurement(example_path("target")).select(list(forward.geometries))
    started = time.perf_counter()
    result = match(target, forward, effect_mask(library, forward.toners), library=library)
    search = time.perf_counter() - started
    x = np.array([library.fractions(c.fractions) for c in result.candidates])
    report = {"match_search_s": search}
    for instrument in ("five-angle", "ma-t12"):
        geometries = instrument_geometries(instrument)
        seconds = best_time(hiding, library, x, geometries, repeat=5)
        report[f"hiding_{instrument}_s"] = seconds
        report[f"hiding_{instrument}_over_search"] = seconds / search
    return report


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--photons", type=int, default=40_000, help="photons a Monte Carlo run")
    parser.add_argument("--seed", type=int, default=3, help="the Monte Carlo's seed")
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = parser.parse_args()
    print_report(accuracy_report(args.photons, args.seed) | cost_report(), args.json, ".3g")
    return 0


if __name__ == "__main__":
    sys.exit(main())
