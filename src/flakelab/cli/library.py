"""``flakelab library``: what a toner library holds, and how the model knows each toner."""

from __future__ import annotations

from dataclasses import replace
from enum import StrEnum
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich import box
from rich.markup import escape
from rich.table import Table

from flakelab.cli.common import (
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


class CharacterisedKind(StrEnum):
    """The kinds of toner ``library characterise`` reads
    (:data:`~flakelab.physics.characterisation.CHARACTERISED`)."""

    pigment = "pigment"
    aluminium = "aluminium"
    pearl = "pearl"


class Substrate(StrEnum):
    """A pearl's platelet (:data:`~flakelab.library.optics.SUBSTRATE_INDEX`)."""

    mica = "mica"
    alumina = "alumina"
    silica = "silica"


@library_app.command("characterise")
@reports_errors
def characterise(
    toner: Annotated[str, typer.Argument(help="The toner's name, as recipes name it.")],
    sprayed: Annotated[
        list[Path],
        typer.Argument(
            help="Measurement of each calibration panel (a masstone, tints in the library's "
            "white, the toner with an aluminium or a pigment of the library …), each with "
            "its --recipe in the same order."
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
            help="The library written: --library's toners and the toner read (JSON). It may "
            "be --library itself, which then gains the toner.",
        ),
    ],
    library: LibraryOption = None,
    kind: Annotated[
        CharacterisedKind | None,
        typer.Option(
            "--kind",
            help="What a new toner is: a pigment (its absorption and scattering are read), "
            "an aluminium flake (its orientation spread, surface quality and volume fraction; "
            "--thickness from its datasheet) or a pearl (its coating's thickness, orientation "
            "spread and volume fraction; --substrate from its datasheet); a flake's or a "
            "pearl's radius too, where the panels were read with texture. A toner read anew "
            "keeps its kind.",
            show_default="pigment",
        ),
    ] = None,
    family: Annotated[
        str | None,
        typer.Option(
            help="A new pigment's chemical family (phthalocyanine, iron oxide …); one read "
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
            help="A pigment's Henyey–Greenstein asymmetry: 0.3 for a scattering inorganic (the "
            "demo's white and oxides), 0 for an organic; one read anew keeps its own.",
            show_default="0",
        ),
    ] = None,
    radius: Annotated[
        float | None,
        typer.Option(
            "--radius",
            help="An aluminium flake's or a pearl's radius [µm], half its D50 (from its "
            "datasheet), kept as given; without it, read from the panels' texture (sparkle "
            "and graininess) where they were read with it.",
        ),
    ] = None,
    thickness: Annotated[
        float | None,
        typer.Option(
            "--thickness",
            help="An aluminium flake's thickness [µm], from its datasheet: the panels show it "
            "only with its volume fraction.",
        ),
    ] = None,
    density: Annotated[
        float | None, typer.Option("--density", help="Its density as sold [g/mL].")
    ] = None,
    anew: Annotated[
        bool,
        typer.Option(
            "--replace",
            help="Read a toner the library already holds anew, in its place (a new "
            "supplier's grade under the old name).",
        ),
    ] = False,
    substrate: Annotated[
        Substrate | None,
        typer.Option(
            "--substrate",
            help="A new pearl's platelet, from its datasheet: natural or synthetic mica, "
            "alumina (Xirallic-like) or silica.",
        ),
    ] = None,
    substrate_nm: Annotated[
        float | None,
        typer.Option(
            "--substrate-thickness",
            min=10,
            max=5000,
            help="A pearl's platelet thickness [nm], where its datasheet gives it; else "
            "that of the library's pearl on the same substrate nearest in radius (it sets "
            "only fine fringes, which the platelets' spread of thicknesses washes out).",
            show_default="a similar pearl's, or 400",
        ),
    ] = None,
    over: Annotated[
        list[str] | None,
        typer.Option(
            "--over",
            metavar="GROUND",
            help="What each panel was sprayed over, in order, one for each or none: primer "
            "(the library's), black or white (a hiding chart's), or a grey-shade primer "
            "G1–G7. A pigment's masstone over a chart's black reads its scattering where it "
            "hardly absorbs, which tints in the white leave unsure.",
            show_default="every panel over the library's primer",
        ),
    ] = None,
    sample: SampleOption = None,
    average: Annotated[
        bool,
        typer.Option(
            "--average",
            help="Average every reading in each panel's file (the panel read at a few spots) "
            "and use their mean.",
        ),
    ] = False,
    plot: Annotated[
        Path | None,
        typer.Option(
            "--plot",
            help="Also draw what was read (a pigment's absorption and scattering with their "
            "uncertainty; each panel's L* flop, read and fitted, for a flake) and each panel's "
            "misfit per geometry (PNG, PDF or SVG).",
        ),
    ] = None,
    json_output: JsonOption = False,
) -> None:
    """Read a new toner's optics from calibration panels of known recipes, and write the
    library with it.

    The library's physics, with the toner in it, is fitted to the panels at every geometry
    they were read at, each panel's film build and flake alignment allowed for: a pigment's
    absorption and scattering (from a Kubelka–Munk start at 45as45), an aluminium flake's
    orientation spread, surface quality and volume fraction, or a pearl's coating (its
    interference colour), orientation spread and volume fraction. A pigment's masstone alone
    tells its K/S, not K and S: give a tint in the white too, and for its scattering where it
    hardly absorbs its masstone over a hiding chart's black (--over) or a panel in an
    aluminium base. A pearl shows its interference colour best over black: spray it alone
    and with a little carbon black. The toner is then 'added' to the library: the matcher
    predicts it by the hybrid path until cases teach the model."""
    from datetime import date

    from flakelab.cli.common import (
        check_figure_file,
        check_one_for_each,
        check_output_file,
        read_readings,
    )
    from flakelab.cli.sources import recipe_fractions
    from flakelab.core.measurement import stacked_readings
    from flakelab.errors import FlakelabError
    from flakelab.io import read_library, read_recipe
    from flakelab.io.library_file import write_library
    from flakelab.physics.characterisation import (
        characterise_flake,
        characterise_pigment,
        with_toner,
    )

    check_one_for_each("--recipe", recipe, sprayed, "panel")
    check_one_for_each("--over", over or [], sprayed, "panel", optional=True)
    grounds = _grounds(over, len(sprayed))
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
    readings = [read_readings(path, sample, average)[0] for path in sprayed]
    geometries, measured, texture = stacked_readings(readings)
    options = {"--family": family, "--g": asymmetry, "--radius": radius, "--thickness": thickness,
               "--substrate": substrate, "--substrate-thickness": substrate_nm}  # fmt: skip
    start = _starting_toner(lib, toner, kind, options, density, np.isfinite(texture).any())
    lib = with_toner(lib, start)
    grams = [read_recipe(path) for path in recipe]
    x = np.array([recipe_fractions(lib, g, path) for g, path in zip(grams, recipe, strict=True)])
    names = [g.name for g in geometries]
    panels = [str(path) for path in sprayed]
    if start.kind == "pigment":
        found = characterise_pigment(lib, toner, x, geometries, measured, panels, grounds)
    else:  # an aluminium or a pearl: its radius read from the texture, where there is one
        found = characterise_flake(lib, toner, x, geometries, measured, panels,
                                   None if radius is not None else texture, grounds)  # fmt: skip
    made = f"read by flakelab from {len(sprayed)} calibration panels on {date.today()}"
    read = found.toner if found.toner.description else replace(found.toner, description=made)
    write_library(with_toner(lib, read), out)
    report = _characterisation_report(found, read, sprayed, x, lib.names.index(toner), names,
                                      grounds)  # fmt: skip
    report |= {"library": lib.name, "out": str(out), "replaced": held,
               "spectra_recovered": [str(p) for p, r in zip(sprayed, readings, strict=True)
                                     if r.spectra_recovered]}  # fmt: skip
    if plot is not None:
        _draw_characterisation(found, geometries, measured, sprayed, plot)
        report["plot"] = str(plot)
    if json_output:
        print_report(report)
        return
    _print_characterisation(report)


POORLY_READ_LOG_SD = float(np.log(2))
"""Standard deviation of a fitted quantity's log past which it is reported as poorly read:
the panels leave it unsure by more than a factor of two either way."""
MATTERS = 0.01
"""Share of a pigment's most absorption (or scattering) below which how well it is read is
not reported: a yellow's absorption in the red, a factor of two of nothing."""
PANEL_MISFIT_NOTED = 1.0
"""Worst ΔE00 between a panel and the fit past which the panel is named: a recipe weighed
otherwise, a mislabelled file, or a paint the physics does not reproduce."""
_KIND_OPTIONS = {
    "pigment": ("--family", "--g"),
    "aluminium": ("--radius", "--thickness"),
    "pearl": ("--radius", "--substrate", "--substrate-thickness"),
}
"""The options that describe a new toner of each kind (a flake or a pearl read anew takes
--radius, its datasheet's, in place of reading it from the texture)."""
_DATASHEET = {"aluminium": ("--thickness", "[µm] from its datasheet: the panels show it only "
                            "with its volume fraction"),
              "pearl": ("--substrate", "(mica, alumina or silica) from its datasheet: its "
                        "platelet, beneath the coating")}  # fmt: skip
"""What a new effect toner must be given, and why."""


def _starting_toner(lib, name: str, kind, options: dict, density, textured: bool):
    """The toner the panels are read for: the library's toner of that name (its kind kept),
    or a new one of ``kind`` described by ``options`` (a new flake or pearl starts from the
    library's of its kind nearest in radius; where the panels were read with texture,
    ``textured``, its radius may be left to them, from the median of the library's)."""
    from flakelab.core.wording import with_article
    from flakelab.errors import FlakelabError
    from flakelab.physics.characterisation import check_kind

    held = lib[name] if name in lib.names else None
    if held is not None:
        check_kind(held)
        if kind is not None and kind.value != held.kind:
            raise FlakelabError(f"--kind {kind.value}: {lib.name!r} holds {name!r} as "
                                f"{with_article(held.kind)}, and a toner read anew keeps its "
                                "kind")  # fmt: skip
    kind = held.kind if held is not None else (kind or CharacterisedKind.pigment).value
    if held is None and kind in _DATASHEET and options[_DATASHEET[kind][0]] is None:
        option, why = _DATASHEET[kind]
        raise FlakelabError(f"a new {kind}: {option} {why}")
    if held is None and kind != "pigment" and options["--radius"] is None and not textured:
        raise FlakelabError(f"a new {kind}: --radius (half its D50, from its datasheet), or "
                            "panels read with texture (sparkle and graininess), from which "
                            "it is read")  # fmt: skip
    for option, value in options.items():
        if value is not None and option not in _KIND_OPTIONS[kind]:
            takes = " and ".join(_KIND_OPTIONS[kind])
            raise FlakelabError(f"{option}: not for {kind} toner {name!r} (it takes {takes})")
    density = density or (held.density_g_ml if held is not None else None)
    if kind == "pigment":
        return _starting_pigment(held, name, options, density)
    if held is not None:
        given = {"radius_um": options["--radius"]}
        if kind == "aluminium":
            given["thickness_um"] = options["--thickness"]
        else:
            given |= {"substrate": options["--substrate"] and str(options["--substrate"]),
                      "substrate_nm": options["--substrate-thickness"]}  # fmt: skip
        given = {k: v for k, v in given.items() if v is not None}
        return replace(held, **given, density_g_ml=density, description="")
    return replace(_new_effect_toner(lib, name, kind, options), density_g_ml=density)


def _starting_pigment(held, name: str, options: dict, density):
    """A pigment read anew, or a new one (flat constants: the Kubelka–Munk start replaces
    them), of ``options``' family and asymmetry."""
    from flakelab.core.spectra import WAVELENGTHS
    from flakelab.library.toners import Pigment

    flat = np.ones(WAVELENGTHS.size)
    base = held or Pigment(name, "unknown", flat, flat)
    return replace(base, family=options["--family"] or base.family,
                   g=base.g if options["--g"] is None else options["--g"],
                   density_g_ml=density, description="")  # fmt: skip


def _new_effect_toner(lib, name: str, kind: str, options: dict):
    """A new aluminium or pearl from its datasheet's ``options``, where its fit starts."""
    from flakelab.physics.characterisation import (
        FLAKE_START_RADIUS_UM,
        similar_flake,
        similar_pearl,
    )

    radii = [t.radius_um for t in lib.of_kind(kind)] or [FLAKE_START_RADIUS_UM]
    radius = options["--radius"] or float(np.median(radii))
    if kind == "aluminium":
        return similar_flake(lib, name, radius, options["--thickness"])
    return similar_pearl(lib, name, str(options["--substrate"]), radius,
                         options["--substrate-thickness"])  # fmt: skip


def _grounds(over: list[str] | None, panels: int) -> list[str]:
    """``--over``'s grounds, one for each panel (the library's primer where none is given);
    one flakelab does not know is refused."""
    from flakelab.errors import FlakelabError
    from flakelab.physics.hiding import GROUNDS

    for ground in over or []:
        if ground not in GROUNDS:
            raise FlakelabError(f"--over: {ground!r}: expected one of {', '.join(GROUNDS)}")
    return list(over) if over else ["primer"] * panels


def _characterisation_report(found, toner, sprayed, x, k: int, geometries, grounds) -> dict:
    """``library characterise``'s report: the toner, each panel's misfit and the notes."""
    from flakelab.physics.characterisation import FIT_ITERATIONS

    panels = []
    for path, ground, share, film, spread, de00, start in zip(
        sprayed, grounds, x[:, k], found.film, found.spread, found.de00, found.start_de00,
        strict=True,
    ):  # fmt: skip
        worst = int(np.nanargmax(de00))
        panels.append({"panel": str(path), "over": ground, "share": float(share),
                       "film_build": float(film),
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
    if not found.converged:
        notes.append(f"the fit stopped after {FIT_ITERATIONS} iterations, still creeping along "
                     "what the panels hardly tell (each step a little closer to their noise): "
                     "what it predicts no longer moves by then")  # fmt: skip
    report = {"toner": toner.name, "kind": toner.kind}
    if toner.kind == "pigment":
        report |= _pigment_read(found, toner, notes)
    else:
        report |= _flake_read(found, toner, notes)
    return report | {"panels": panels, "chi2_per_dof": found.chi2_per_dof,
                     "evaluations": found.evaluations, "converged": found.converged,
                     "notes": notes}  # fmt: skip


def _pigment_read(found, pigment, notes: list[str]) -> dict:
    """A pigment's part of the report; a note where the panels leave it unsure."""
    from flakelab.core.spectra import WAVELENGTHS

    for key, what in (("absorption", "a tint in the white"),
                      ("scattering", "a masstone over a hiding chart's black, --over black, "
                       "or the pigment in an aluminium base")):  # fmt: skip
        sd, values = found.uncertainty[key], getattr(pigment, key)
        unsure = WAVELENGTHS[(sd > POORLY_READ_LOG_SD) & (values >= MATTERS * values.max())]
        if unsure.size:
            notes.append(
                f"its {key} is read to no better than a factor of two at "
                f"{_wavelength_ranges(unsure)}: add a panel that shows it ({what})"
            )
    return {
        "family": pigment.family,
        "g": pigment.g,
        "transparent": pigment.transparent,
        "hides": pigment.hides,
        "wavelengths_nm": WAVELENGTHS.tolist(),
        "absorption": pigment.absorption.tolist(),
        "scattering": pigment.scattering.tolist(),
        "absorption_log_sd": found.uncertainty["absorption"].tolist(),
        "scattering_log_sd": found.uncertainty["scattering"].tolist(),
        "start_absorption": found.start.absorption.tolist(),
        "start_scattering": found.start.scattering.tolist(),
    }


def _flake_read(found, flake, notes: list[str]) -> dict:
    """An aluminium flake's or a pearl's part of the report; a note where the panels leave it
    unsure."""
    from flakelab.physics.characterisation import EFFECT_FITTED

    fitted = EFFECT_FITTED[flake.kind]
    unsure = [f for f, sd in found.uncertainty.items() if sd > POORLY_READ_LOG_SD]
    if unsure:
        over = "over black (a little carbon black)" if flake.kind == "pearl" else "tinted"
        notes.append(f"its {', '.join(unsure)}: read to no better than a factor of two: add a "
                     f"panel that shows it (the {flake.kind} {over})")  # fmt: skip
    made = ("thickness_um",) if flake.kind == "aluminium" else ("substrate", "substrate_nm")
    return {f: getattr(flake, f) for f in (*fitted, "radius_um", *made)} | {
        "radius_read": "radius_um" in found.uncertainty,  # from the texture, else as given
        "relative_sd": dict(found.uncertainty),
        "start": {f: getattr(found.start, f) for f in (*fitted, "radius_um")},
    }


def _draw_characterisation(found, geometries, measured, sprayed, plot) -> None:
    """``library characterise --plot``: what was read beside each panel's misfit."""
    from flakelab.core.colorimetry import reflectance_to_Lab
    from flakelab.core.spectra import WAVELENGTHS
    from flakelab.render.plots import plot_flake_read, plot_pigment_read

    names = [g.name for g in geometries]
    labels = [p.name for p in sprayed]
    if len(set(labels)) < len(labels):  # panels of one name in several folders
        labels = [str(p) for p in sprayed]
    misfit = dict(zip(labels, found.de00, strict=True))
    title = (
        f"{found.toner.name}, read from {len(sprayed)} panels: worst ΔE00 "
        f"{np.nanmax(found.de00):.2f} (from the start: {np.nanmax(found.start_de00):.2f})"
    )
    if found.toner.kind == "pigment":
        spectra = {k: getattr(found.toner, k) for k in ("absorption", "scattering")}
        start = {k: getattr(found.start, k) for k in ("absorption", "scattering")}
        plot_pigment_read(WAVELENGTHS, spectra, start, found.uncertainty, names, misfit, plot,
                          title=title)  # fmt: skip
        return
    Lab = {"read": reflectance_to_Lab(np.nan_to_num(measured)),
           "fitted": reflectance_to_Lab(found.fitted)}  # fmt: skip
    Lab["read"][~np.isfinite(measured).all(axis=-1)] = np.nan
    plot_flake_read(
        names, list(misfit), Lab, misfit, plot, title=title, travel=found.toner.kind == "pearl"
    )  # its interference colour travels


def _relative(sd: float | None) -> str:
    """A relative standard deviation as the report words it."""
    if sd is None or not np.isfinite(sd):
        return "at the end of its range"
    if sd < 0.001:
        return "± less than 0.1%"
    return f"± {sd:.1%}" if sd < 0.1 else f"± {sd:.0%}"


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
    start = "Kubelka–Munk" if report["kind"] == "pigment" else "from the start"
    grounds = any(p["over"] != "primer" for p in report["panels"])
    for column in ("panel", *(["over"] if grounds else []), "its share", "film build",
                   "worst ΔE00, fit", start):  # fmt: skip
        table.add_column(column, justify="left" if column in ("panel", "over") else "right")
    for p in report["panels"]:
        table.add_row(escape(p["panel"]), *([p["over"]] if grounds else []), f"{p['share']:.1%}",
                      f"{p['film_build']:.2f}", f"{p['de00_max']:.2f} {p['de00_max_at']}",
                      f"{p['start_de00_max']:.2f}")  # fmt: skip
    console.print(table)
    console.print(f"{escape(report['toner'])} {_what_was_read(report)}.", highlight=False)
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


def _what_was_read(report: dict) -> str:
    """What the panels told of the toner, in a few words."""
    if report["kind"] in ("aluminium", "pearl"):
        return _effect_read(report)
    absorption = np.asarray(report["absorption"])
    peak = int(np.argmax(absorption))
    scatters = (
        "scatters nothing the panels tell from none (transparent)"
        if report["transparent"]
        else f"scatters σ {np.mean(report['scattering']):.3g} /µm on average"
    )
    hides = "; it hides the primer" if report["hides"] else ""
    return (
        f"({escape(report['family'])}): absorbs most at {report['wavelengths_nm'][peak]:g} nm "
        f"(κ {absorption[peak]:.3g} /µm), {scatters}{hides}"
    )


_READ_WORDS = {
    "coating_nm": ("TiO2 coating", " nm"),
    "orientation_sd_deg": ("orientation spread", "°"),
    "surface_quality": ("surface quality", ""),
    "volume_fraction": ("volume fraction", ""),
}
"""How the report names each value read of a flake or a pearl, and its unit."""


def _effect_read(report: dict) -> str:
    """What the panels told of an aluminium flake or a pearl, in a few words."""
    sd = report["relative_sd"]
    read = ", ".join(f"{_READ_WORDS[key][0]} {report[key]:.3g}{_READ_WORDS[key][1]} "
                     f"({_relative(sd[key])})" for key in sd if key in _READ_WORDS)  # fmt: skip
    if report["kind"] == "pearl":
        made = f"on {report['substrate']} {report['substrate_nm']:g} nm thick, as given"
        size = f"{report['radius_um']:g} µm"
    else:
        made = f"{report['thickness_um']:g} µm thick as given"
        size = f"{report['radius_um']:g} × {report['thickness_um']:g} µm"
    if report["radius_read"]:
        radius = (f"radius {report['radius_um']:.3g} µm read from the texture "
                  f"({_relative(sd['radius_um'])}), ")  # fmt: skip
        return f"({report['kind']}, {made}): {radius}{read}"
    if report["kind"] == "pearl":
        return f"(pearl, {size} {made}): {read}"
    return f"(aluminium, {size} as given): {read}"
