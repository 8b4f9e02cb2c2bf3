"""CLI: how thick a recipe must be sprayed to hide the primer, and over which grey."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich import box
from rich.markup import escape
from rich.table import Table

from flakelab.cli.common import (
    JsonOption,
    check_figure_file,
    console,
    print_notes,
    print_report,
)
from flakelab.cli.sources import (
    WORKPLACE_PRIMERS,
    InstrumentOption,
    LibraryOption,
    recipe_fractions,
)
from flakelab.core.defaults import HIDING_DE00
from flakelab.core.geometry import DEFAULT_INSTRUMENT
from flakelab.errors import FlakelabError


def hiding_command(
    recipes: Annotated[
        list[Path],
        typer.Argument(help="Recipe JSON files {toner: grams} (any amount), one or more."),
    ],
    library: LibraryOption = None,
    instrument: InstrumentOption = DEFAULT_INSTRUMENT,
    threshold: Annotated[
        float,
        typer.Option(
            "--threshold",
            min=0.1,
            max=10.0,
            help="ΔE00, at every geometry, between the film over black and over white (or over "
            "a grey and built up) at which it hides.",
        ),
    ] = HIDING_DE00,
    primers: PrimersOption = None,
    plot: Annotated[
        Path | None,
        typer.Option(
            "--plot",
            help="Also draw each recipe's ΔE00 over black against white, and over each primer "
            "against built up, versus film build (PNG, PDF or SVG).",
        ),
    ] = None,
    json_output: JsonOption = False,
) -> None:
    """How thick a recipe must be sprayed to hide the primer, and the grey-shade primer to
    spray it over.

    By the physics, each recipe is sprayed at film builds from a hundredth of the library's
    basecoat to eight times it over a contrast chart's black and white and over seven
    neutral greys (G1 white to G7 black) or the shop's own primers (--primers): it hides where
    the film over black and over white differ by --threshold ΔE00 at every geometry at most
    (a colorimetric criterion, as DIN 55987 reads hiding), and over a primer where it comes
    that near the colour it tends to. The primer to spray it over is, of those it hides over
    in the fewest coats, the one nearest its own colour (for greys, its lightness)."""
    from flakelab.core.geometry import instrument_geometries
    from flakelab.io import read_library, read_recipe
    from flakelab.physics.hiding import hiding

    reads = {"RECIPES": recipes, "--library": library, "--primers": primers}
    check_figure_file(plot, "--plot", reads=reads)
    lib = read_library(library)
    grams = [read_recipe(path) for path in recipes]
    x = np.array([recipe_fractions(lib, g, path) for g, path in zip(grams, recipes, strict=True)])
    shop_primers, notes, primers = workplace_primers(primers)
    geometries = instrument_geometries(instrument)
    found = hiding(lib, x, geometries, threshold, shop_primers)
    report = hiding_report(found, [str(p) for p in recipes], instrument, primers)
    report["notes"] = notes
    if plot is not None:
        from flakelab.render.plots import plot_hiding

        labels = [p.name for p in recipes]
        plot_hiding(found, labels if len(set(labels)) == len(labels) else report["recipes"],
                    plot)  # fmt: skip
        report["plot"] = str(plot)
    if json_output:
        print_report(report)
        return
    _print_hiding(report)
    print_notes(notes)


PrimersOption = Annotated[
    Path | None,
    typer.Option(
        "--primers",
        help="The shop's own primers, measured: a measurement file (CxF, CSV, MA-T12 export) "
        "of one sample a primer, its reading at 45as45 taken as its colour; a workplace sets "
        f"its own with {WORKPLACE_PRIMERS}.",
        show_default=f"{WORKPLACE_PRIMERS}'s file, else seven neutral greys, G1 (L* 93) to G7 "
        "(L* 27)",
    ),
]


MATTE_SPREAD_DE00 = 2.0
"""ΔE00 between a primer's 45°:0° reading and its others away from the gloss (45° lamp, 25°
or more from the specular) beyond which it is said to read like no matte primer: a dull
surface reads nearly alike there, an effect or glossy panel does not."""


def workplace_primers(primers: Path | None) -> tuple[dict | None, list[str], Path | None]:
    """The primers ``--primers`` names, else the workplace's (:data:`WORKPLACE_PRIMERS`), read
    (:func:`read_primers`), their notes and their file; (None, [], None): the grey shades. A
    workplace's file that cannot be read is refused naming the variable."""
    if primers is not None:
        return *read_primers(primers), primers
    workplace = os.environ.get(WORKPLACE_PRIMERS, "").strip()
    if not workplace:
        return None, [], None
    try:
        return *read_primers(Path(workplace)), Path(workplace)
    except FlakelabError as error:
        raise FlakelabError(f"{WORKPLACE_PRIMERS}: {error}") from None


def read_primers(path: Path) -> tuple[dict[str, np.ndarray], list[str]]:
    """The primers of a measurement file ``{sample: reflectance [W] at 45°:0°}`` and notes on
    those that read like no matte primer, or are known by their colour alone. A sample
    without a 45°:0° reading is refused with the file's name (one named twice, by the
    file's reader)."""
    from flakelab.core.colorimetry import reflectance_to_Lab
    from flakelab.core.difference import delta_E_CIE2000
    from flakelab.core.geometry import FACE_GEOMETRY
    from flakelab.core.measurement import recovered_note
    from flakelab.errors import MeasurementFileError
    from flakelab.io import read_measurements

    primers, notes = {}, []
    for reading in read_measurements(path):
        where = f"sample {reading.sample!r}"
        if FACE_GEOMETRY not in reading.geometry_names:
            raise MeasurementFileError(path, f"no reading at {FACE_GEOMETRY} (45°:0°), where a "
                                       "primer's colour is taken", field=where)  # fmt: skip
        face = reading.storage_spectra([FACE_GEOMETRY])
        dull = [g for g in reading.geometries if g.illumination == 45 and g.aspecular >= 25]
        spread = delta_E_CIE2000(reflectance_to_Lab(face), reflectance_to_Lab(
            reading.storage_spectra(dull))).max()  # fmt: skip
        if spread > MATTE_SPREAD_DE00:
            notes.append(
                f"{path}: {where} reads like no matte primer ({spread:.1f} ΔE00 between "
                f"its readings away from the gloss): its {FACE_GEOMETRY} reading taken"
            )
        notes += [f"{path}: {note}" for note in [recovered_note(reading)] if note]
        primers[reading.sample] = face[0]
    return primers, notes


def hiding_report(found, names: list[str], instrument: str, primers: Path | None = None) -> dict:
    """``flakelab hiding``'s report (JSON: inf as null); ``primers``: the file the primers were
    read from (None: the grey shades)."""

    def um(value: float) -> float | None:
        return float(value) if np.isfinite(value) else None

    def coats(film_um: float) -> int | None:
        return int(found.coats(film_um)) if np.isfinite(film_um) else None

    paints = []
    for f, (name, best) in enumerate(zip(names, found.best_primer, strict=True)):
        greys = []
        for i, (primer, lab) in enumerate(zip(found.primers, found.primer_lab, strict=True)):
            hides = found.primer_hiding_um[f, i]
            greys.append({"primer": primer, "lightness": float(lab[0]),
                          "lab": [round(float(v), 2) for v in lab],
                          "de00_at_nominal": um(found.primer_de00[f, i]), "hiding_um": um(hides),
                          "coats": coats(hides)})  # fmt: skip
        paints.append({
            "recipe": name,
            "hiding_um": um(found.hiding_um[f]),
            "coats": coats(found.hiding_um[f]),
            "contrast_ratio": um(found.contrast_ratio[f]),
            "lightness": um(found.lightness[f]),
            "best_primer": best,
            "primers": greys,
        })  # fmt: skip
    return {
        "instrument": instrument,
        "threshold_de00": found.threshold,
        "nominal_um": found.nominal_um,
        "coat_um": found.coat_um,
        "film_um_range": [float(found.film_um[0]), float(found.film_um[-1])],
        "primers_file": primers and str(primers),
        "recipes": names,
        "paints": paints,
    }


def _print_hiding(report: dict) -> None:
    top = report["film_um_range"][1]
    table = Table(title=f"Hiding (ΔE00 ≤ {report['threshold_de00']:g} at every geometry; a coat "
                  f"{report['coat_um']:g} µm, {report['nominal_um']:g} µm nominal)",
                  box=box.SIMPLE_HEAD, collapse_padding=True)  # fmt: skip
    for column in ("recipe", "hides black/white", "contrast ratio", "spray over",
                   "hides over it", "ΔE00 at nominal"):  # fmt: skip
        table.add_column(column, justify="left" if column == "recipe" else "right")
    for paint in report["paints"]:
        best = next((g for g in paint["primers"] if g["primer"] == paint["best_primer"]), None)
        table.add_row(
            escape(Path(paint["recipe"]).name),
            _build_text(paint["hiding_um"], paint["coats"], top),
            "–" if paint["contrast_ratio"] is None else f"{paint['contrast_ratio']:.3f}",
            "none" if best is None else f"{escape(best['primer'])} (L* {best['lightness']:.0f})",
            "–" if best is None else _build_text(best["hiding_um"], best["coats"], top),
            "–" if best is None else f"{best['de00_at_nominal']:.2f}",
        )
    console.print(table)
    for paint in report["paints"]:
        if paint["hiding_um"] is None:
            console.print(
                f"{escape(Path(paint['recipe']).name)} does not hide within {top:.0f} µm: a "
                "transparent colour, sprayed over a ground of its own colour or with a pigment "
                "that hides",
                highlight=False,
            )
    if len(report["paints"]) == 1:
        console.print(_primers_table(report["paints"][0], top, report["primers_file"]))


def _primers_table(paint: dict, top: float, primers_file: str | None) -> Table:
    """One recipe over each primer: how far from its full colour at the nominal build, and
    the build at which it reaches it."""
    title = f"over each primer of {escape(primers_file)}" if primers_file else "over each grey"
    table = Table(title=title, box=box.SIMPLE_HEAD, collapse_padding=True)
    for column in ("primer" if primers_file else "grey", "L*", "a*", "b*", "ΔE00 at nominal",
                   "hides over it"):  # fmt: skip
        table.add_column(column, justify="right")
    for primer in paint["primers"]:
        mark = " ←" if primer["primer"] == paint["best_primer"] else ""
        de = primer["de00_at_nominal"]
        table.add_row(escape(primer["primer"]) + mark,
                      *(str(round(v)) for v in primer["lab"]),
                      "–" if de is None else f"{de:.2f}",
                      _build_text(primer["hiding_um"], primer["coats"], top))  # fmt: skip
    return table


def _build_text(film_um: float | None, coats: float | None, top: float) -> str:
    if film_um is None:
        return f"not within {top:.0f} µm"
    return f"{film_um:.1f} µm, {int(coats)} coat{'s' if coats != 1 else ''}"
