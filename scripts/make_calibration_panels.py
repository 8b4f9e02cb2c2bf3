"""Write calibration panels of three toners new to the demo library, for trying
``flakelab library characterise`` (synthetic, labelled so in their metadata).

* ``DPP red 2027``, a new grade of the demo's DPP red (its absorption band 10 nm to the red,
  15 % stronger): a masstone, tints of 1:4 and 1:19 in the white and a tenth of it in Al
  medium (``dpp-*.cxf``, ``dpp-*.json``);
* ``Al sparkle 2027``, a coarse paste (15 µm radius, 0.4 µm thick, normals spread 8.5°,
  surface quality 0.92, volume fraction 0.12): its masstone, a tenth of phthalo blue GS in it
  and a fifth of iron oxide red (``al-*.cxf``, ``al-*.json``);
* ``Pearl gold 2027``, an interference gold (TiO2 80 nm thick on mica 400 nm, 12 µm radius,
  normals spread 9°, volume fraction 0.09): alone, over a twentieth of carbon black and half
  and half with Al medium (``pearl-*.cxf``, ``pearl-*.json``).

Each set is sprayed in the generated world from one set of tins at the factory, each panel
with its own film build and flake spread, and read at the MA-T12's geometries with its noise
and texture (sparkle and graininess, as one spot of the camera's field reads them); each
panel's recipe is written beside it in grams for a 50 g can. Run:

    python scripts/make_calibration_panels.py FOLDER [--seed 2027]

and read them (docs/toner-library.md, "A new toner read from panels"):

    flakelab library characterise "DPP red 2027" FOLDER/dpp-*.cxf -r FOLDER/dpp-masstone.json …
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from flakelab.cases.generator import World
from flakelab.core.measurement import TEXTURE_READINGS, Measurement
from flakelab.core.spectra import WAVELENGTHS, shift_spectra
from flakelab.io import read_library, write_measurements
from flakelab.library.toners import AluminiumFlake, Pearl
from flakelab.physics.characterisation import with_toner

CAN_G = 50.0
PIGMENT, FLAKE, PEARL = "DPP red 2027", "Al sparkle 2027", "Pearl gold 2027"
PANELS = {
    "dpp": {
        "masstone": {PIGMENT: 1.0},
        "tint-1-4": {PIGMENT: 0.2, "Titanium dioxide white": 0.8},
        "tint-1-19": {PIGMENT: 0.05, "Titanium dioxide white": 0.95},
        "in-al-medium": {PIGMENT: 0.1, "Al medium": 0.9},
    },
    "al": {
        "masstone": {FLAKE: 1.0},
        "phthalo-blue": {FLAKE: 0.9, "Phthalo blue GS": 0.1},
        "iron-oxide-red": {FLAKE: 0.8, "Iron oxide red": 0.2},
    },
    "pearl": {
        "alone": {PEARL: 1.0},
        "over-black": {PEARL: 0.95, "Carbon black": 0.05},
        "with-al-medium": {PEARL: 0.5, "Al medium": 0.5},
    },
}
"""Each set's panels: their names and recipes (mass fractions)."""
DELIVERIES = (("dpp", "al"), ("pearl",))
"""The sets in the order their toners arrived: each delivery is sprayed in a world that holds
the toners delivered so far, so that a later delivery leaves an earlier one's panels as they
were (the world draws a batch for every toner it holds)."""


def new_toners(library):
    """The three toners, as the world sprays them (the library never holds them)."""
    dpp = library["DPP red"]
    pigment = replace(dpp, name=PIGMENT, absorption=1.15 * shift_spectra(
        dpp.absorption[None], np.array([10.0]))[0])  # fmt: skip
    flake = AluminiumFlake(FLAKE, radius_um=15.0, thickness_um=0.4, orientation_sd_deg=8.5,
                           surface_quality=0.92, volume_fraction=0.12)  # fmt: skip
    pearl = Pearl(PEARL, coating_nm=80.0, substrate="mica", substrate_nm=400.0, radius_um=12.0,
                  orientation_sd_deg=9.0, volume_fraction=0.09)  # fmt: skip
    return pigment, flake, pearl


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder", type=Path, help="where the panels and recipes are written")
    parser.add_argument("--seed", type=int, default=2027, help="seed of tins, sprays, noise")
    args = parser.parse_args()
    args.folder.mkdir(parents=True, exist_ok=True)
    library = read_library()
    new = iter(new_toners(library))
    rng = np.random.default_rng(args.seed)
    for delivery in DELIVERIES:
        for _ in delivery:
            library = with_toner(library, next(new))
        world = World(library, "ma-t12")
        for prefix in delivery:
            spray_and_read(world, prefix, rng, args.folder)
    print(f"wrote {sum(map(len, PANELS.values()))} panels and their recipes to {args.folder}")


def spray_and_read(world: World, prefix: str, rng: np.random.Generator, folder: Path) -> None:
    """Spray one set's panels from one set of tins, read them, and write each with its
    recipe."""
    panels = PANELS[prefix]
    x = np.array([world.library.fractions(recipe) for recipe in panels.values()])
    sprayed = world.one_set_of_tins(len(x), rng)
    R, texture = world.appearance(x, sprayed)
    measured, read = world.measure(R, rng), world.measure_texture(texture, rng)
    for (name, recipe), spectra, spot in zip(panels.items(), measured, read, strict=True):
        panel = Measurement(
            f"{prefix} {name}", world.geometries, WAVELENGTHS, spectra,
            texture=dict(zip(TEXTURE_READINGS, spot.round(2).tolist(), strict=True)),
            instrument="X-Rite MA-T12 (synthetic example)",
            metadata={"synthetic": "yes: scripts/make_calibration_panels.py"},
        )  # fmt: skip
        write_measurements([panel], folder / f"{prefix}-{name}.cxf")
        grams = {toner: round(CAN_G * share, 1) for toner, share in recipe.items()}
        (folder / f"{prefix}-{name}.json").write_text(json.dumps(grams) + "\n")


if __name__ == "__main__":
    main()
