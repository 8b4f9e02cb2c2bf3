"""``flakelab library``: what a toner library holds, and how the model knows each toner."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich import box
from rich.markup import escape
from rich.table import Table

from flakelab.cli.common import (
    AverageOption,
    JsonOption,
    SampleOption,
    command_group,
    console,
    errors,
    print_report,
    reports_errors,
)
from flakelab.cli.matcher import ModelOption
from flakelab.cli.sources import DatabaseOption, InstrumentOption, LibraryOption, shop_spelled
from flakelab.core.geometry import DEFAULT_INSTRUMENT

library_app = command_group("The toner library: its toners, and how the current model knows each.")


@library_app.command("show")
@reports_errors
def show_library(
    library: Annotated[
        Path | None, typer.Argument(help="Toner library file (default: the demo library).")
    ] = None,
    instrument: InstrumentOption = DEFAULT_INSTRUMENT,
    model: ModelOption = None,
    database: DatabaseOption = None,
    shop: Annotated[
        str | None,
        typer.Option(
            callback=shop_spelled,
            help="The model current for this shop, where one was adapted to its cases.",
        ),
    ] = None,
    json_output: JsonOption = False,
) -> None:
    """Each toner of a library: its make-up (its kind and density too, with --json), and how
    the model the matcher would use knows it: learned, with the cases it learned it from;
    new, with too few of them; or added to the library since the model was trained. A new
    or added toner is predicted by the hybrid path, standing in as the known toner named."""
    from flakelab.cli.sources import chosen_model
    from flakelab.io import read_library
    from flakelab.match.models import toner_standing, unused_toners

    lib = read_library(library)
    chosen = chosen_model(model, instrument, database, shop)
    rows = toner_standing(lib, chosen)
    by_name = {t.name: t for t in lib.toners}
    for row in rows:
        toner = by_name[row["toner"]]
        row["make_up"] = _make_up(toner)
        row["density_g_ml"] = toner.density_g_ml
    unused = unused_toners(lib, chosen)
    model_name = chosen.info.get("name", chosen.instrument)
    if json_output:
        print_report(
            {
                "library": lib.name,
                "synthetic": lib.synthetic,
                "model": model_name,
                "toners": rows,
                "model_toners_not_in_library": unused,
            }
        )
        return
    synthetic = " (synthetic)" if lib.synthetic else ""
    table = Table(
        title=f"The {len(rows)} toners of {lib.name}{synthetic}, as model {model_name} knows them",
        box=box.SIMPLE_HEAD,
        collapse_padding=True,
    )
    for column in ("toner", "make-up", "cases", "model"):  # kind and density: in --json
        table.add_column(column, justify="right" if column == "cases" else "left")
    for row in rows:
        table.add_row(
            row["toner"],
            row["make_up"],
            "" if row["cases"] is None else f"{row['cases']:,}",
            _standing_text(row),
        )
    console.print(table)
    if unused:
        errors.print(
            f"the model's toners the library lacks (never used): {', '.join(unused)}",
            highlight=False,
        )


def _make_up(toner) -> str:
    """A toner's make-up in a few words: a flake's size and alignment, a pigment's family, a
    pearl's coating."""
    if toner.kind == "aluminium":
        return (
            f"{toner.radius_um:.3g} × {toner.thickness_um:.3g} µm, "
            f"σ {toner.orientation_sd_deg:.3g}°"
        )
    if toner.kind == "pearl":
        return f"{toner.coating_nm:.3g} nm on {toner.substrate}, {toner.radius_um:.3g} µm"
    return toner.family


def _standing_text(row: dict) -> str:
    if row["standing"] == "learned":
        return "learned"
    stand_in = f": as {row['stands_in_as']}" if row["stands_in_as"] else ""
    return f"[yellow]{row['standing']}[/]{stand_in}"


@library_app.command("characterise")
@reports_errors
def characterise(
    toner: Annotated[str, typer.Argument(help="The pigment's name, as recipes name it.")],
    sprayed: Annotated[
        list[Path],
        typer.Argument(
            help="Measurement of each calibration panel (a masstone, tints of the pigment in "
            "the library's white, the pigment in an aluminium base …), each with its --recipe "
            "in the same order."
        ),
    ],
    recipe: Annotated[
        list[Path],
        typer.Option(
            "--recipe",
            "-r",
            help="The panel's recipe {toner: grams}, as weighed (one for each panel).",
        ),
    ],
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            "-o",
            help="The library written: --library's toners and the pigment read (JSON). It may "
            "be --library itself, which then gains the pigment.",
        ),
    ],
    library: LibraryOption = None,
    family: Annotated[
        str | None,
        typer.Option(
            help="The pigment's chemical family (phthalocyanine, iron oxide …); a pigment read "
            "anew keeps its own.",
            show_default="unknown",
        ),
    ] = None,
    asymmetry: Annotated[
        float | None,
        typer.Option(
            "--g",
            min=-0.99,
            max=0.99,
            help="Henyey–Greenstein asymmetry of its scattering: 0.3 for a scattering "
            "inorganic (the demo's white and oxides), 0 for an organic; a pigment read anew "
            "keeps its own.",
            show_default="0",
        ),
    ] = None,
    density: Annotated[
        float | None, typer.Option("--density", help="Its density as sold [g/mL].")
    ] = None,
    anew: Annotated[
        bool,
        typer.Option(
            "--replace",
            help="Read a pigment the library already holds anew, in its place (a new "
            "supplier's grade under the old name).",
        ),
    ] = False,
    sample: SampleOption = None,
    average: AverageOption = False,
    plot: Annotated[
        Path | None,
        typer.Option(
            "--plot",
            help="Also draw the pigment's absorption and scattering with their uncertainty "
            "and each panel's misfit per geometry (PNG, PDF or SVG).",
        ),
    ] = None,
    json_output: JsonOption = False,
) -> None:
    """Read a new pigment's absorption and scattering from calibration panels of known
    recipes, and write the library with it.

    The library's physics, with the pigment in it, is fitted to the panels at every geometry
    they were read at (each panel's film build and flake alignment allowed for), from a
    Kubelka–Munk start at 45as45. A masstone alone tells the pigment's K/S, not K and S: give
    a tint in the white too, and a panel in an aluminium base for its scattering among
    flakes. The pigment is then 'added' to the library: the matcher predicts it by the
    hybrid path until cases teach the model."""
    from datetime import date

    from flakelab.cli.common import check_figure_file, check_output_file, read_readings
    from flakelab.cli.sources import recipe_fractions
    from flakelab.core.spectra import WAVELENGTHS
    from flakelab.errors import FlakelabError
    from flakelab.io import read_library, read_recipe
    from flakelab.io.library_file import write_library
    from flakelab.library.toners import Pigment
    from flakelab.physics.characterisation import characterise_pigment, with_pigment

    if len(recipe) != len(sprayed):
        raise FlakelabError(
            f"--recipe: expected one for each panel ({len(sprayed)}), got {len(recipe)}"
        )
    if out.suffix.lower() != ".json":
        raise FlakelabError(f"--out: {out}: a library is written as JSON: name a .json file")
    check_output_file(out, "--out", reads={"SPRAYED": sprayed, "--recipe": recipe})
    check_figure_file(plot, "--plot", reads={"SPRAYED": sprayed, "--recipe": recipe},
                      writes={"--out": out})  # fmt: skip
    lib = read_library(library)
    held = toner in lib.names
    if held and not anew:
        raise FlakelabError(f"{toner!r} is already a toner of {lib.name!r}: --replace reads it "
                            "anew, in its place")  # fmt: skip
    if anew and not held:
        raise FlakelabError(f"--replace: {lib.name!r} holds no toner {toner!r}")
    blank = _blank_pigment(lib[toner] if held else None, toner, family, asymmetry, density)
    lib = with_pigment(lib, blank) if isinstance(blank, Pigment) else lib
    grams = [read_recipe(path) for path in recipe]
    x = np.array([recipe_fractions(lib, g, path) for g, path in zip(grams, recipe, strict=True)])
    readings = [read_readings(path, sample, average)[0] for path in sprayed]
    geometries = tuple(sorted({g for r in readings for g in r.geometries}))  # every panel's
    names = [g.name for g in geometries]
    measured = np.full((len(readings), len(names), WAVELENGTHS.size), np.nan)
    for row, reading in zip(measured, readings, strict=True):
        row[[names.index(g) for g in reading.geometry_names]] = reading.storage_spectra(
            reading.geometry_names
        )
    found = characterise_pigment(lib, toner, x, geometries, measured,
                                 [str(path) for path in sprayed])  # fmt: skip
    made = f"read by flakelab from {len(sprayed)} calibration panels on {date.today()}"
    pigment = found.pigment
    if not pigment.description:
        pigment = replace(pigment, description=made)
    write_library(with_pigment(lib, pigment), out)
    report = _characterisation_report(found, pigment, sprayed, x, lib.names.index(toner), names)
    report |= {"library": lib.name, "out": str(out), "replaced": held,
               "spectra_recovered": [str(p) for p, r in zip(sprayed, readings, strict=True)
                                     if r.spectra_recovered]}  # fmt: skip
    if plot is not None:
        from flakelab.render.plots import plot_characterisation

        plot_characterisation(
            WAVELENGTHS,
            {"absorption": pigment.absorption, "scattering": pigment.scattering},
            {"absorption": found.start.absorption, "scattering": found.start.scattering},
            {"absorption": found.absorption_sd, "scattering": found.scattering_sd},
            names,
            {str(p.name): d for p, d in zip(sprayed, found.de00, strict=True)},
            plot,
            title=f"{toner}, read from {len(sprayed)} panels: worst ΔE00 "
            f"{np.nanmax(found.de00):.2f} (Kubelka–Munk start: {np.nanmax(found.start_de00):.2f})",
        )
        report["plot"] = str(plot)
    if json_output:
        print_report(report)
        return
    _print_characterisation(report)


POORLY_READ_LOG_SD = float(np.log(2))
"""Standard deviation of a fitted coefficient's log past which it is reported as poorly read:
the panels leave it unsure by more than a factor of two either way."""
MATTERS = 0.01
"""Share of a pigment's most absorption (or scattering) below which how well it is read is
not reported: a yellow's absorption in the red, a factor of two of nothing."""
PANEL_MISFIT_NOTED = 1.0
"""Worst ΔE00 between a panel and the fit past which the panel is named: a recipe weighed
otherwise, a mislabelled file, or a paint the physics does not reproduce."""


def _blank_pigment(held, name: str, family, asymmetry, density):
    """The pigment whose constants the panels will give: the library's ``held`` toner of that
    name, or a new one, with the options given."""
    from flakelab.core.spectra import WAVELENGTHS
    from flakelab.library.toners import Pigment
    from flakelab.physics.characterisation import check_pigment

    flat = np.ones(WAVELENGTHS.size)
    if held is None:
        return Pigment(name, family or "unknown", flat, flat, g=asymmetry or 0.0,
                       density_g_ml=density)  # fmt: skip
    check_pigment(held)
    return replace(held, family=family or held.family,
                   g=held.g if asymmetry is None else asymmetry,
                   density_g_ml=density or held.density_g_ml, description="")  # fmt: skip


def _characterisation_report(found, pigment, sprayed, x, k: int, geometries) -> dict:
    """``library characterise``'s report: the pigment, each panel's misfit and the notes."""
    from flakelab.core.spectra import WAVELENGTHS

    panels = []
    for path, share, film, spread, de00, start in zip(
        sprayed, x[:, k], found.film, found.spread, found.de00, found.start_de00, strict=True
    ):
        worst = int(np.nanargmax(de00))
        panels.append({"panel": str(path), "share": float(share), "film_build": float(film),
                       "flake_spread": float(spread), "de00_max": float(de00[worst]),
                       "de00_max_at": geometries[worst],
                       "start_de00_max": float(np.nanmax(start))})  # fmt: skip
    notes = [
        f"{p['panel']} lies {p['de00_max']:.2f} ΔE00 from the fit at {p['de00_max_at']}: a "
        "recipe weighed otherwise, a mislabelled file, or a paint the physics does not "
        "reproduce"
        for p in panels
        if p["de00_max"] > PANEL_MISFIT_NOTED
    ]
    for key, what in (("absorption", "a tint in the white"),
                      ("scattering", "the pigment in an aluminium base, or a masstone "
                       "thin enough to show the primer")):  # fmt: skip
        sd, values = getattr(found, f"{key}_sd"), getattr(pigment, key)
        unsure = WAVELENGTHS[(sd > POORLY_READ_LOG_SD) & (values >= MATTERS * values.max())]
        if unsure.size:
            notes.append(
                f"its {key} is read to no better than a factor of two at "
                f"{_wavelength_ranges(unsure)}: add a panel that shows it ({what})"
            )
    transparent = not np.any(pigment.scattering > 0)
    return {
        "toner": pigment.name,
        "family": pigment.family,
        "g": pigment.g,
        "transparent": transparent,
        "hides": pigment.hides,
        "wavelengths_nm": WAVELENGTHS.tolist(),
        "absorption": pigment.absorption.tolist(),
        "scattering": pigment.scattering.tolist(),
        "absorption_log_sd": found.absorption_sd.tolist(),
        "scattering_log_sd": found.scattering_sd.tolist(),
        "start_absorption": found.start.absorption.tolist(),
        "start_scattering": found.start.scattering.tolist(),
        "panels": panels,
        "chi2_per_dof": found.chi2_per_dof,
        "evaluations": found.evaluations,
        "notes": notes,
    }


def _wavelength_ranges(wavelengths) -> str:
    """``400–430, 600 nm``: wavelengths of the 10 nm grid as runs."""
    runs: list[list[float]] = []
    for w in wavelengths:
        if runs and w - runs[-1][-1] <= 10:
            runs[-1].append(w)
        else:
            runs.append([w])
    return ", ".join(f"{r[0]:g}–{r[-1]:g}" if len(r) > 1 else f"{r[0]:g}" for r in runs) + " nm"


def _print_characterisation(report: dict) -> None:
    table = Table(title=f"{report['toner']} read from {len(report['panels'])} panels",
                  box=box.SIMPLE_HEAD, collapse_padding=True)  # fmt: skip
    for column in ("panel", "its share", "film build", "worst ΔE00, fit", "Kubelka–Munk"):
        table.add_column(column, justify="left" if column == "panel" else "right")
    for p in report["panels"]:
        table.add_row(escape(p["panel"]), f"{p['share']:.1%}", f"{p['film_build']:.2f}",
                      f"{p['de00_max']:.2f} {p['de00_max_at']}",
                      f"{p['start_de00_max']:.2f}")  # fmt: skip
    console.print(table)
    absorption = np.asarray(report["absorption"])
    peak = int(np.argmax(absorption))
    scatters = (
        "scatters nothing the panels tell from none (transparent)"
        if report["transparent"]
        else f"scatters σ {np.mean(report['scattering']):.3g} /µm on average"
    )
    console.print(
        f"{escape(report['toner'])} ({escape(report['family'])}): absorbs most at "
        f"{report['wavelengths_nm'][peak]:g} nm (κ {absorption[peak]:.3g} /µm), {scatters}"
        f"{'; it hides the primer' if report['hides'] else ''}.",
        highlight=False,
    )
    verb = "read anew in" if report["replaced"] else "added to"
    console.print(
        f"{escape(report['toner'])} {verb} {escape(report['library'])}, written to "
        f"{escape(report['out'])}: the matcher predicts it by the hybrid path until cases "
        "teach the model.",
        highlight=False,
    )
    for path in report["spectra_recovered"]:
        errors.print(f"[yellow]note:[/] {escape(path)} gives colour alone: its spectra were "
                     "recovered from it, one metamer of many", highlight=False)  # fmt: skip
    for note in report["notes"]:
        errors.print(f"[yellow]note:[/] {escape(note)}", highlight=False)
