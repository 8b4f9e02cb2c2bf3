"""Near-black solids: how many of the generated cases they are, and what the model errs on them.

Until 2026-11-27 (stop 51) the generator drew a solid's one to four pigments from the whole
library, so a third of its solids held no pigment that hides the primer, and 90 % of those
were transparent organics whose absorption bands cover the spectrum between them
(quinacridone red with a little phthalo blue): they read black, with reflectance factors
down to 1e-29 and L* below 1 at every geometry, 7.75 % of ``cases realism``'s cases (seed
0), and no real paint reads that. A solid is now built on a pigment that hides
(:attr:`~flakelab.library.toners.Pigment.hides`: the white, an opaque iron oxide, BiVO4 or
carbon black) with up to three tints; the near-black paints left are the blacks a shop
sees. The learned model learns the logarithm of the reflectance above a floor
(``flakelab.models.network.LOG_FLOOR``, 1e-3), so it predicts a paint darker than that at
about L* 0.8. This prints, on the cases of ``flakelab cases generate --n 500 --seed 987``
(issue 4's evaluation, the shipped model) or any others:

* the share of the cases that are near-black (nominal L* below ``--black`` at every
  geometry), the measured spray-outs' reflectance there;
* the model's ΔE00 against the measured spray-outs (issue 4's ``de00_mean``) and the noise
  floor (the nominal paint against them) with and without the near-black cases;
* the solids' nominal L* quartiles, how many hold a pigment that hides, and how many of
  the near-black hold a black;
* for the solids, the mean ΔL* of the nominal paint minus the model's prediction per band
  of nominal L*: the model's bias.

    python benchmarks/near_black.py [--instrument five-angle] [--cases 500] [--seed 987]
        [--black 1.0] [--json]
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from flakelab.cases.generator import NEAR_BLACK_L, World, near_black
from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E
from flakelab.io import read_library
from flakelab.match.judging import evaluate_recipes
from flakelab.match.models import forward_for
from flakelab.models.registry import shipped_model
from flakelab.models.training import generated_case_arrays

BANDS = (0.0, 0.1, 1.0, 10.0, 30.0, 100.0)
"""Bands of a solid's nominal L* (mean over geometries) for its bias."""


def near_black_report(instrument: str, cases: int, seed: int, black: float) -> dict:
    library = read_library(None)
    model = shipped_model(instrument)
    world = World(library, instrument)
    data = generated_case_arrays(world, cases, seed)
    predicted = evaluate_recipes(forward_for(model, library), data.x)[0]
    nominal, _ = world.appearance(data.x, world.nominal(cases))
    measured_lab, model_lab = reflectance_to_Lab(data.R), reflectance_to_Lab(predicted)
    nominal_lab = reflectance_to_Lab(nominal)
    error, floor = delta_E(measured_lab, model_lab), delta_E(measured_lab, nominal_lab)
    solid = library.paint_families(data.x) == "solid"
    lightness = nominal_lab[..., 0]
    dark = solid & near_black(nominal_lab, black)

    def split(values: np.ndarray) -> dict[str, float]:
        return {
            "all": round(float(values.mean()), 3),
            "without_near_black": round(float(values[~dark].mean()), 3),
            "near_black": round(float(values[dark].mean()), 3) if dark.any() else None,
        }

    def holding(kind: str) -> np.ndarray:  # which solids hold a pigment that hides, or a black
        pigments = np.array([t.kind == "pigment" and getattr(t, kind) for t in library.toners])
        return (data.x[solid][:, pigments] > 0).any(axis=1)

    with_hiding, with_black = holding("hides"), holding("black")
    dark_solids = dark[solid]
    solid_lightness = lightness[solid].mean(axis=1)
    bias = (nominal_lab - model_lab)[solid, :, 0].mean(axis=1)
    band = np.digitize(solid_lightness, BANDS[1:-1])
    return {
        "instrument": instrument,
        "cases": cases,
        "seed": seed,
        "model": model.info.get("name", instrument),
        "solids": int(solid.sum()),
        "near_black": int(dark.sum()),
        "near_black_share": round(float(dark.mean()), 4),
        "near_black_measured_R_median": float(np.median(data.R[dark])) if dark.any() else None,
        # what makes them: a black, or (the generator before 2026-11-27) no hiding pigment
        "solid_nominal_L_quartiles": np.percentile(solid_lightness, [25, 50, 75]).round(1).tolist(),
        "solids_with_a_hiding_pigment": round(float(with_hiding.mean()), 3),
        "near_black_share_of_solids": {
            "with_a_hiding_pigment": _share(dark_solids[with_hiding]),
            "without": _share(dark_solids[~with_hiding]),
        },
        "near_black_holding_a_black": _share(with_black[dark_solids]),
        "de00_mean": split(error),
        "noise_floor_de00_mean": split(floor),
        "solid_bias_dL_by_nominal_L": {
            f"{BANDS[k]:g}-{BANDS[k + 1]:g}": {
                "solids": int((band == k).sum()),
                "mean_dL": round(float(bias[band == k].mean()), 3) if (band == k).any() else None,
            }
            for k in range(len(BANDS) - 1)
        },
    }


def _share(flags: np.ndarray) -> float | None:
    return round(float(flags.mean()), 3) if flags.size else None


def _percent(share: float | None) -> str:
    return "none" if share is None else f"{share:.0%}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--instrument", default="five-angle", choices=("five-angle", "ma-t12"))
    parser.add_argument("--cases", type=int, default=500)
    parser.add_argument("--seed", type=int, default=987)
    parser.add_argument(
        "--black", type=float, default=NEAR_BLACK_L, help="nominal L* below: near-black"
    )
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    report = near_black_report(args.instrument, args.cases, args.seed, args.black)
    if args.json:
        print(json.dumps(report, indent=2))
        return
    print(
        f"{report['model']}, {args.cases} cases of seed {args.seed}: {report['solids']} solids, "
        f"{report['near_black']} near-black (nominal L* < {args.black:g} at every geometry, "
        f"{report['near_black_share']:.1%} of the cases; measured R median "
        f"{report['near_black_measured_R_median'] or 0:.1e})"
    )
    shares = report["near_black_share_of_solids"]
    print(
        f"solids' nominal L* (mean over geometries) quartiles "
        f"{report['solid_nominal_L_quartiles']}; {report['solids_with_a_hiding_pigment']:.0%} "
        f"hold a pigment that hides, of which {_percent(shares['with_a_hiding_pigment'])} "
        f"are near-black, against {_percent(shares['without'])} of the others; "
        f"{_percent(report['near_black_holding_a_black'])} of the near-black hold a black"
    )
    for name in ("de00_mean", "noise_floor_de00_mean"):
        row = report[name]
        print(
            f"{name:>22}: all {row['all']:.3f}, without the near-black "
            f"{row['without_near_black']:.3f}, near-black alone {row['near_black']}"
        )
    print("solids' mean ΔL* (nominal − model) by nominal L*:")
    for band, row in report["solid_bias_dL_by_nominal_L"].items():
        print(f"  L* {band:>8}: {row['solids']:4d} solids, ΔL* {row['mean_dL']}")


if __name__ == "__main__":
    main()
