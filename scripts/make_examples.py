"""Regenerate the shipped example measurements (synthetic, labelled so in their metadata).

A blue metallic from the demo library, made in the case generator's world (physics fast
model, factory batches and application, instrument noise) and read at the MA-T12
geometries with texture, the texture as one spot of the camera's field reads it: the
*target*. The *spray-out* is a colorist's first recipe for it (amounts off by a few per
cent), mixed from the shop's batches and sprayed. The *panel* is the calibration panel of
a tin of phthalo blue GS 4 % stronger than the standard (``flakelab lots panel "Phthalo
blue GS"``: 10 % of it in Al coarse bright), sprayed in the shop; the *panel standard* is the same
recipe from the paint maker's standard tins, sprayed at the factory. Run:

    python scripts/make_examples.py
"""

from __future__ import annotations

import json
from datetime import datetime
from pathlib import Path

import numpy as np

from flakelab.cases.generator import World
from flakelab.core.measurement import TEXTURE_READINGS, Measurement
from flakelab.core.spectra import WAVELENGTHS
from flakelab.io import read_library, write_measurements

OUT = Path(__file__).resolve().parents[1] / "src" / "flakelab" / "data" / "examples"
FORMULATION = {
    "Al medium": 0.78,
    "Al fine bright": 0.10,
    "Phthalo blue GS": 0.07,
    "Indanthrone blue": 0.035,
    "Carbon black": 0.015,
}
"""The hidden paint of the example target (mass fractions)."""


def main() -> None:
    library = read_library(None)
    world = World(library, "ma-t12")
    rng = np.random.default_rng(20261122)
    texture_rng = rng.spawn(1)[0]  # a stream of its own: the colours stay as they were
    hidden = library.fractions(FORMULATION)[None]
    recipe = world.colorist_recipe(hidden, rng)
    OUT.mkdir(parents=True, exist_ok=True)
    for name, x in (("target", hidden), ("sprayout", recipe)):
        R, texture = world.appearance(x, world.variation(1, rng))
        measured = world.measure(R, rng)[0]
        texture = world.measure_texture(texture, texture_rng)
        used = {library.names[i]: round(float(x[0, i]), 5) for i in np.flatnonzero(x[0])}
        measurement = Measurement(
            sample=f"Blue metallic {name} (synthetic)",
            geometries=world.geometries,
            wavelengths=WAVELENGTHS,
            reflectance=measured,
            texture=dict(zip(TEXTURE_READINGS, np.round(texture[0], 2).tolist(), strict=True)),
            instrument="X-Rite MA-T12 (synthetic example)",
            measured_at=datetime(2026, 11, 22, 9, 30 if name == "target" else 45),
            metadata={
                "synthetic": "yes: scripts/make_examples.py",
                "paint": "blue metallic",
                "formulation": json.dumps(used),
            },
        )
        write_measurements([measurement], OUT / f"blue-metallic-{name}.cxf")
    grams = {k: round(v * 250, 1) for k, v in zip(library.names, recipe[0], strict=True) if v > 0}
    (OUT / "blue-metallic-recipe.json").write_text(json.dumps(grams, indent=1) + "\n")
    make_panel(library, world)


PANEL = {"Al coarse bright": 90.0, "Phthalo blue GS": 10.0}
"""The calibration panel of phthalo blue GS, grams (``flakelab lots panel``'s for the shipped
five-angle model)."""

PANEL_TIN = ("Phthalo blue GS", 1.04)
"""The example tin, and its strength against the standard."""


def make_panel(library, world: World) -> None:
    rng = np.random.default_rng(20261130)
    x = library.fractions(PANEL)[None]
    shop = world.variation(1, rng)
    shop.strength[0, library.names.index(PANEL_TIN[0])] = PANEL_TIN[1]
    factory = world.nominal(1)
    factory.film[:], factory.spread[:] = world.application(1, rng, at_shop=False)
    for name, tins, minute in (("panel", shop, 10), ("panel-standard", factory, 0)):
        measured = world.measure(world.appearance(x, tins)[0], rng)[0]
        measurement = Measurement(
            sample=f"Phthalo blue GS {name} (synthetic)",
            geometries=world.geometries,
            wavelengths=WAVELENGTHS,
            reflectance=measured,
            instrument="X-Rite MA-T12 (synthetic example)",
            measured_at=datetime(2026, 11, 30, 8, minute),
            metadata={
                "synthetic": "yes: scripts/make_examples.py",
                "tins": "the shop's, phthalo blue GS 4 % strong" if name == "panel" else "standard",
            },
        )
        write_measurements([measurement], OUT / f"phthalo-blue-{name}.cxf")
    (OUT / "phthalo-blue-panel-recipe.json").write_text(json.dumps(PANEL, indent=1) + "\n")


if __name__ == "__main__":
    main()
