"""Matcher: does ``SOLID_TRAVEL`` still part the generated world's solids from its effect paints?

A target read without texture readings is matched as a solid when its colour travels less
than :data:`~flakelab.match.settings.SOLID_TRAVEL` (ΔE00) between any two of its geometries
at least :data:`~flakelab.match.settings.SOLID_TRAVEL_FROM` from specular. The threshold was
set on the generated world, so a change to the world's physics can move either family across
it. This draws formulations as the case generator does (the default family mix), sprays each
with the shop's variation, reads it with the instrument's noise, and prints, per instrument
and paint family, the least and the most colour travel and how many paints fall on the wrong
side of the threshold: as the rule reads it, and over all the geometries (the rule before
stop 94, in the same run).

Then the same for real paints, where ../shared/data/reference-brdf holds them: fits of
measured BRDFs (RGB taken as linear sRGB) read at each instrument's geometries. Günther et
al.'s three metallics and four solid car paints; the MERL database's 16 effect paints (by
their names) and its nine others, which their names do not call car paints' solids.

    python benchmarks/solid_travel.py [--n 20000] [--seed 11] [--white-pearls 0] [--json]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from _matcher import add_white_pearls_argument
from flakelab.cases.generator import World, WorldSettings
from flakelab.core.colorimetry import linear_sRGB_to_Lab, reflectance_to_Lab
from flakelab.core.difference import colour_travel, travel_off_specular
from flakelab.core.geometry import geometry_angles, instrument_geometries
from flakelab.io import read_library
from flakelab.library import PAINT_FAMILIES
from flakelab.match.settings import SOLID_TRAVEL, SOLID_TRAVEL_FROM
from flakelab.physics.reference_brdf import (
    GUNTHER_METALLICS,
    GUNTHER_SOLIDS,
    REFERENCE_FITS,
    is_merl_effect_paint,
    is_merl_paint,
)

REFERENCE_BRDF = Path(__file__).resolve().parents[2] / "shared" / "data" / "reference-brdf"

INSTRUMENTS = ("five-angle", "ma-t12")
BATCH = 2000


def measured_travel(world: World, fractions: np.ndarray, rng: np.random.Generator) -> dict:
    """Colour travel ``[N]`` of ``fractions`` sprayed with the shop's variation and read: as
    the rule reads it (``"rule"``) and over every geometry (``"all"``)."""
    names = [str(g) for g in instrument_geometries(world.instrument)]
    travel = {"rule": [], "all": []}
    for start in range(0, len(fractions), BATCH):
        x = fractions[start : start + BATCH]
        R, _ = world.appearance(x, world.variation(len(x), rng))
        Lab = reflectance_to_Lab(world.measure(R, rng))
        travel["rule"].append(travel_off_specular(Lab, names, SOLID_TRAVEL_FROM))
        travel["all"].append(colour_travel(Lab))
    return {k: np.concatenate(v) for k, v in travel.items()}


def family_travel(
    library,
    instrument: str,
    n: int,
    seed: int,
    white_pearls: float = WorldSettings.white_pearl_share,
) -> dict[str, dict]:
    world = World(library, instrument, WorldSettings(white_pearl_share=white_pearls))
    rng = np.random.default_rng(seed)
    x = world.formulations(n, rng)
    families = library.paint_families(x)
    travel = measured_travel(world, x, rng)
    rows = {}
    for family in PAINT_FAMILIES:
        rows[family] = {"paints": int((families == family).sum())}
        for read, values in travel.items():
            t = values[families == family]
            wrong = t >= SOLID_TRAVEL if family == "solid" else t < SOLID_TRAVEL
            # a family the draw left out (a small --n) has no travel: null, not a crash
            rows[family][read] = {"travel_min": float(t.min()) if t.size else None,
                                  "travel_max": float(t.max()) if t.size else None,
                                  "wrong_side": int(wrong.sum())}  # fmt: skip
    return rows


def reference_groups() -> dict[str, list] | None:
    """The real paints by what their sources say they are (module docstring)."""
    if not REFERENCE_BRDF.is_dir():
        return None
    fits = {fit: read(REFERENCE_BRDF / file) for fit, (file, read) in REFERENCE_FITS.items()}
    groups = {
        "Günther metallic": [p for p in fits["gunther"] if p.name in GUNTHER_METALLICS],
        "Günther solid": [p for p in fits["gunther"] if p.name in GUNTHER_SOLIDS],
    }
    for fit in ("ABC", "SGD"):
        paints = [p for p in fits[f"merl_{fit.lower()}"] if is_merl_paint(p.name)]
        groups[f"MERL {fit} effect"] = [p for p in paints if is_merl_effect_paint(p.name)]
        groups[f"MERL {fit} other"] = [p for p in paints if not is_merl_effect_paint(p.name)]
    return groups


def reference_travel(instrument: str, groups: dict[str, list]) -> dict[str, dict]:
    """Each real paint's colour travel at ``instrument``'s geometries, by group: as the rule
    reads it, and over every geometry."""
    names = [str(g) for g in instrument_geometries(instrument)]
    angles = geometry_angles(names)
    rows = {}
    for group, paints in groups.items():
        Lab = {p.name: linear_sRGB_to_Lab(p.reflectance_factor(*angles)) for p in paints}
        rows[group] = {"paints": len(paints)}
        for read in ("rule", "all"):
            travel = {name: float(travel_off_specular(lab, names, SOLID_TRAVEL_FROM)
                                  if read == "rule" else colour_travel(lab))
                      for name, lab in Lab.items()}  # fmt: skip
            rows[group][read] = {"travel": {k: round(v, 2) for k, v in travel.items()},
                                 "below_threshold": [k for k, v in travel.items()
                                                     if v < SOLID_TRAVEL]}  # fmt: skip
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=20_000)
    parser.add_argument("--seed", type=int, default=11)
    add_white_pearls_argument(parser, "the pearls", WorldSettings.white_pearl_share)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    if args.n < 1:
        parser.error(f"--n: {args.n} is not a positive number of formulations")
    library = read_library(None)
    result = {
        "solid_travel": SOLID_TRAVEL,
        "n": args.n,
        "seed": args.seed,
        "white_pearls": args.white_pearls,
        **{i: family_travel(library, i, args.n, args.seed, args.white_pearls) for i in INSTRUMENTS},
    }
    if (groups := reference_groups()) is not None:
        result["reference"] = {i: reference_travel(i, groups) for i in INSTRUMENTS}
    if args.json:
        print(json.dumps(result, indent=2))
        return
    print(f"SOLID_TRAVEL {SOLID_TRAVEL} ΔE00 at geometries {SOLID_TRAVEL_FROM:g}° or more from "
          f"specular [over all geometries]; {args.n} formulations, seed {args.seed}, "
          f"white pearls {args.white_pearls:g} of the pearls")  # fmt: skip
    for instrument in INSTRUMENTS:
        for family, row in result[instrument].items():
            rule, every = row["rule"], row["all"]
            if not row["paints"]:
                print(f"{instrument:>10} {family:>8}: no paints in this draw")
                continue
            print(f"{instrument:>10} {family:>8}: {row['paints']:>6} paints, travel "
                  f"{rule['travel_min']:.3f}–{rule['travel_max']:.3f} "
                  f"[{every['travel_min']:.3f}–{every['travel_max']:.3f}], "
                  f"{rule['wrong_side']} [{every['wrong_side']}] on the wrong side")  # fmt: skip
    for instrument, groups in result.get("reference", {}).items():
        print(f"real paints at the {instrument}'s geometries (below {SOLID_TRAVEL}: a solid)")
        for group, row in groups.items():
            for read in ("rule", "all"):
                travel = row[read]["travel"].values()
                label = group if read == "rule" else "[all geometries]"
                print(f"  {label:>18}: {row['paints']:>2} paints, travel "
                      f"{min(travel):.2f}–{max(travel):.2f}, below: "
                      f"{', '.join(row[read]['below_threshold']) or 'none'}")  # fmt: skip


if __name__ == "__main__":
    main()
