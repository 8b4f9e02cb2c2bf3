"""A new pigment or aluminium flake read from calibration panels: how well what was read
predicts paints the panels never showed.

For each of the demo library's pigments in turn, the generated world sprays panels from one
set of tins, each with its own film build and flake spread, and reads them with the MA-T12's
noise (``World.measure``): a masstone and tints of 1:4 and 1:19 in the white (the white
itself in carbon black), ``tints``; those and a tenth of the pigment in Al medium,
``tints_and_metallic``; and those and the masstone sprayed over a hiding chart's black,
``tints_and_black``. ``flakelab.physics.characterisation`` fits the pigment's absorption
and scattering to the readings, its library constants unseen. Three held-out paints of the
same tins are then predicted by the physics at the nominal application, and compared, worst
geometry, with what those tins give (ΔE00, D65/10):

* a 1:9 tint in the white, a fifth of the pigment in Al coarse bright, and a fifth of it with
  another pigment of the library;
* by the constants fitted (``fitted``), by the Kubelka–Munk start at 45as45 alone (Allen's
  two-constant method, ``km``: the baseline, measured in the same run) and by the tin's own
  constants (``oracle``: what the other tins' batch strengths leave, the floor).

It prints the median, p95 and max over pigments × held-out paints of each, the ratio of
the fitted's median to the baseline's, and the seconds a characterisation takes.

Each of the library's ten aluminium flakes likewise (``flakes_*``): a masstone, a tenth of
phthalo blue in it and a fifth of iron oxide red, its orientation spread, surface quality
and volume fraction fitted from the next flake's values (the baseline: a similar paste taken
for it), the held-out paints three tenths of perylene maroon in it and a twentieth of carbon
black; and how far each fitted value lies from the tin's (``flakes_parameter_error_*``: the
volume fraction times the tin's batch strength), its radius read from the panels' texture
readings (the camera's glint counts), started from the library's median radius. The floor
(``oracle``) is the tin's own flake.

Each of its five pearls likewise (``pearls_*``): alone, over a twentieth of carbon black and
half and half with Al medium, its coating, orientation spread and volume fraction fitted
from the next pearl's values, the held-out paints three tenths of phthalo blue in it and
four tenths of Al fine with a fifth of quinacridone magenta; its radius from the texture
started from half the library's median (its pearls are all of about the median's).

    python benchmarks/toner_characterisation.py [--seed 7] [--json]
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace

import numpy as np

from flakelab.cases.generator import World
from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E_CIE2000
from flakelab.core.spectra import shift_spectra
from flakelab.io import read_library
from flakelab.physics.application import sprayed_reflectance
from flakelab.physics.characterisation import (
    EFFECT_FITTED,
    characterise_flake,
    characterise_pigment,
    with_toner,
)
from flakelab.physics.hiding import reflectance_over
from timing import print_report

WHITE, BLACK = "Titanium dioxide white", "Carbon black"
PANEL_BASE, HELD_OUT_BASE = "Al medium", "Al coarse bright"
PANEL_SHARES = (1.0, 0.2, 0.05)
PANEL_SETS = ("tints", "tints_and_metallic", "tints_and_black")
"""The panels sprayed: a masstone and two tints in the white; those and a tenth of the
pigment in Al medium; and those and the masstone over a hiding chart's black."""


def recipes(names: tuple[str, ...], pigment: str, partner: str, shares) -> np.ndarray:
    """Recipes ``[len(shares), T]``: the pigment at each share, the partner the rest."""
    return np.array([blended(names, pigment, {partner: 1 - share}) for share in shares])


def tins_pigment(pigment, strength: float, shade_nm: float):
    """The pigment as its tin holds it: the batch's strength and shade."""
    absorption = shift_spectra(pigment.absorption[None], np.array([shade_nm]))[0]
    return replace(pigment, absorption=absorption * strength,
                   scattering=pigment.scattering * strength)  # fmt: skip


def worst_de00(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return delta_E_CIE2000(reflectance_to_Lab(a), reflectance_to_Lab(b)).max(axis=-1)


def one_pigment(world: World, name: str, rng: np.random.Generator, panel_set: str) -> dict:
    """Spray and read one pigment's panels, characterise it, and judge the held-out paints."""
    library, names = world.library, world.library.names
    partner = BLACK if name == WHITE else WHITE
    x = recipes(names, name, partner, PANEL_SHARES)
    labels = ["masstone", "1:4", "1:19"]
    grounds = ["primer"] * len(x)
    if panel_set == "tints_and_metallic":
        x, labels = np.concatenate([x, recipes(names, name, PANEL_BASE, (0.1,))]), [*labels, "Al"]
        grounds.append("primer")
    if panel_set == "tints_and_black":
        x, labels = np.concatenate([x, x[:1]]), [*labels, "masstone over black"]
        grounds.append("black")
    sprayed = world.one_set_of_tins(len(x), rng)
    R = reflectance_over(world.layer(x, sprayed), library, grounds, world.geometries)
    measured = world.measure(R, rng)
    blank = replace(library[name], absorption=np.ones(31), scattering=np.ones(31))
    started = time.perf_counter()
    found = characterise_pigment(with_toner(library, blank), name, x, world.geometries,
                                 measured, labels, grounds)  # fmt: skip
    seconds = time.perf_counter() - started
    other = next(p.name for p in library.of_kind("pigment") if p.name not in (name, partner))
    held = np.concatenate([
        recipes(names, name, partner, (0.1,)),
        recipes(names, name, HELD_OUT_BASE, (0.2,)),
        recipes(names, name, other, (0.2,)),
    ])  # fmt: skip
    n = len(held)
    truth = world.appearance(held, sprayed.tins_at_nominal(n))[0]
    k = names.index(name)
    tin = tins_pigment(library[name], sprayed.strength[0, k], sprayed.hue_shift[0])
    judged = {}
    for label, pigment in (("fitted", found.toner), ("km", found.start), ("oracle", tin)):
        predicted = sprayed_reflectance(with_toner(library, pigment), held, world.geometries,
                                        np.ones(n), np.ones(n))  # fmt: skip
        judged[label] = worst_de00(predicted, truth)
    return {"seconds": seconds, "panels_de00_max": float(np.nanmax(found.de00)), **judged}


def blended(names: tuple[str, ...], toner: str, others: dict[str, float]) -> np.ndarray:
    """A recipe of ``toner`` with ``others`` at their shares, the toner the rest."""
    x = np.zeros(len(names))
    x[names.index(toner)] = 1 - sum(others.values())
    for name, share in others.items():
        x[names.index(name)] = share
    return x


EFFECT_PANELS = {
    "aluminium": ({}, {"Phthalo blue GS": 0.1}, {"Iron oxide red": 0.2}),
    "pearl": ({}, {BLACK: 0.05}, {PANEL_BASE: 0.5}),
}
"""Each effect kind's panels: what else each holds (the toner the rest)."""
EFFECT_HELD_OUT = {
    "aluminium": ({"Perylene maroon": 0.3}, {BLACK: 0.05}),
    "pearl": ({"Phthalo blue GS": 0.3}, {"Al fine": 0.4, "Quinacridone magenta": 0.2}),
}
"""Each effect kind's held-out paints."""
EFFECT_REPORTED = {"aluminium": "flakes", "pearl": "pearls"}
"""The report's prefix for each effect kind."""


def one_effect(world: World, kind: str, k: int, rng: np.random.Generator) -> dict:
    """Spray and read the library's ``k``-th toner of ``kind`` (aluminium or pearl), read it
    starting from the next one's values, and judge the held-out paints; read it again with
    the panels' texture, its radius from the library's median (a pearl's from half of it:
    the demo's pearls are all of about the median's)."""
    library, names = world.library, world.library.names
    toners, fitted = library.of_kind(kind), EFFECT_FITTED[kind]
    toner, similar = toners[k], toners[(k + 1) % len(toners)]
    start = replace(toner, **{f: getattr(similar, f) for f in fitted})
    x = np.array([blended(names, toner.name, parts) for parts in EFFECT_PANELS[kind]])
    labels = [", ".join(parts) or "alone" for parts in EFFECT_PANELS[kind]]
    sprayed = world.one_set_of_tins(len(x), rng)
    R, texture = world.appearance(x, sprayed)
    measured = world.measure(R, rng)
    started = time.perf_counter()
    found = characterise_flake(with_toner(library, start), toner.name, x, world.geometries,
                               measured, labels)  # fmt: skip
    seconds = time.perf_counter() - started
    radius = float(np.median([t.radius_um for t in toners])) * (0.5 if kind == "pearl" else 1)
    textured = characterise_flake(with_toner(library, replace(start, radius_um=radius)),
                                  toner.name, x, world.geometries, measured, labels,
                                  texture=world.measure_texture(texture, rng))  # fmt: skip
    held = np.array([blended(names, toner.name, parts) for parts in EFFECT_HELD_OUT[kind]])
    n = len(held)
    truth = world.appearance(held, sprayed.tins_at_nominal(n))[0]
    tin = replace(toner, volume_fraction=toner.volume_fraction * sprayed.strength[0, names.index(
        toner.name)])  # fmt: skip
    judged = {}
    for label, read in (("fitted", found.toner), ("similar", start), ("oracle", tin)):
        predicted = sprayed_reflectance(with_toner(library, read), held, world.geometries,
                                        np.ones(n), np.ones(n))  # fmt: skip
        judged[label] = worst_de00(predicted, truth)
    errors = {f: abs(getattr(found.toner, f) / getattr(tin, f) - 1) for f in fitted}
    errors["radius_um"] = abs(textured.toner.radius_um / toner.radius_um - 1)
    return {"seconds": seconds, "panels_de00_max": float(np.nanmax(found.de00)), **judged,
            "errors": errors}  # fmt: skip


def effect_report(world: World, kind: str, seed: int) -> dict:
    """Every aluminium flake or pearl of the library read from its panels
    (:func:`one_effect`)."""
    rng = np.random.default_rng(seed)
    results = [one_effect(world, kind, k, rng) for k in range(len(world.library.of_kind(kind)))]
    prefix = EFFECT_REPORTED[kind]
    report: dict = {prefix: len(results)}
    for label in ("fitted", "similar", "oracle"):
        values = np.concatenate([r[label] for r in results])
        report |= {f"{prefix}_{label}_de00_median": float(np.median(values)),
                   f"{prefix}_{label}_de00_max": float(values.max())}  # fmt: skip
    report[f"{prefix}_fitted_over_similar_median"] = (
        report[f"{prefix}_fitted_de00_median"] / report[f"{prefix}_similar_de00_median"]
    )
    for f in (*EFFECT_FITTED[kind], "radius_um"):
        report[f"{prefix}_parameter_error_{f}_max"] = max(r["errors"][f] for r in results)
    report[f"{prefix}_parameter_error_radius_um_median"] = float(
        np.median([r["errors"]["radius_um"] for r in results])
    )
    report[f"{prefix}_panels_de00_max"] = max(r["panels_de00_max"] for r in results)
    report[f"{prefix}_seconds_max"] = max(r["seconds"] for r in results)
    return report


def characterisation_report(seed: int) -> dict:
    """Every demo pigment characterised from each set of panels (the same tins, sprays and
    noise for both), the held-out paints judged."""
    library = read_library()
    world = World(library, "ma-t12")
    pigments = [p.name for p in library.of_kind("pigment")]
    report: dict = {"pigments": len(pigments), "held_out_paints": 3 * len(pigments)}
    for panel_set in PANEL_SETS:
        rng = np.random.default_rng(seed)
        results = [one_pigment(world, name, rng, panel_set) for name in pigments]
        for label in ("fitted", "km", "oracle"):
            values = np.concatenate([r[label] for r in results])
            report |= {
                f"{panel_set}_{label}_de00_median": float(np.median(values)),
                f"{panel_set}_{label}_de00_p95": float(np.percentile(values, 95)),
                f"{panel_set}_{label}_de00_max": float(values.max()),
            }
        report[f"{panel_set}_worst"] = pigments[
            int(np.argmax([r["fitted"].max() for r in results]))
        ]
        report[f"{panel_set}_fitted_over_km_median"] = (
            report[f"{panel_set}_fitted_de00_median"] / report[f"{panel_set}_km_de00_median"]
        )
        report[f"{panel_set}_panels_de00_max"] = max(r["panels_de00_max"] for r in results)
        seconds = [r["seconds"] for r in results]
        report[f"{panel_set}_seconds_median"] = float(np.median(seconds))
        report[f"{panel_set}_seconds_max"] = max(seconds)
    return report | effect_report(world, "aluminium", seed) | effect_report(world, "pearl", seed)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seed", type=int, default=7, help="seed of the tins, sprays, noise")
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = parser.parse_args()
    print_report(characterisation_report(args.seed), args.json, ".3g")
    return 0


if __name__ == "__main__":
    sys.exit(main())
