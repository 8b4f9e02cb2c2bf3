"""CLI: ``flakelab lots``: the shop's toner tins, read from calibration panels
(:mod:`flakelab.match.lots`), and ``--lots`` for the commands that predict with them."""

from __future__ import annotations

import functools
from datetime import UTC, datetime
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich import box
from rich.table import Table

from flakelab.cli.common import (
    COUNT_MAX,
    AverageOption,
    JsonOption,
    SampleOption,
    check_figure_file,
    check_one_for_each,
    check_output_file,
    command_group,
    console,
    errors,
    file_name_for,
    names_read_in,
    print_report,
    read_readings,
    reports_errors,
)
from flakelab.cli.matcher import (
    ModelOption,
    PhysicsOption,
    RecipeOutOption,
    ResolutionOption,
    matcher_setup,
    spectra_for_model,
)
from flakelab.cli.sources import (
    WORKPLACE_SHOP,
    DatabaseOption,
    InstrumentOption,
    LibraryOption,
    existing_engine,
    recipe_fractions,
    shop_spelled,
    workplace_shop,
)
from flakelab.core.geometry import DEFAULT_INSTRUMENT
from flakelab.core.times import shown_time
from flakelab.core.wording import database_label, shop_meant
from flakelab.errors import FlakelabError
from flakelab.match.settings import SCALE_RESOLUTION_G

lots_app = command_group(
    "The shop's toner tins: a calibration panel for a toner, its tin's strength read from "
    "the panel's spray-out, the tins read so far. 'match --lots' and 'correct --lots' then "
    "weigh for them."
)

LotsOption = Annotated[
    Path | None,
    typer.Option(
        "--lots",
        help="The shop's toner-lot file ('flakelab lots calibrate' writes it): each tin's "
        "strength and shade against the model's standard, which the recipe is weighed for.",
        show_default="the shop's tins stored in the database (--shop), else the standard",
    ),
]


ShopTinsOption = Annotated[
    str | None,
    typer.Option(
        "--shop",
        callback=shop_spelled,
        help="The shop whose tins are kept in the database (--database), shared by its "
        "workplaces, instead of in a lot file. Default: the workplace's shop, FLAKELAB_SHOP, "
        "where no lot file is named.",
    ),
]


def _check_not_a_harness_mode(path: Path) -> None:
    """``--lots`` names a file for one target, and what the harness's shop knows of its tins
    for 'match evaluate': a mode given for one target is named as such."""
    from flakelab.library.lots import TIN_KNOWLEDGE

    if str(path) in TIN_KNOWLEDGE and not path.exists():
        raise FlakelabError(
            f"--lots: {path}: no such toner-lot file; '{path}' says what the evaluation "
            f"harness's shop knows of its tins ('flakelab match evaluate --lots {path}')"
        )


def shop_lots(
    path: Path | None, library, forward, shop: str | None = None, database: str | None = None
):
    """The lots of ``path``, else those stored for ``shop`` in the database where it has
    any (else none), checked against ``library``; ``forward`` for them; and notes: where
    stored tins came from, and where they were read against another model than
    ``forward``'s."""
    from flakelab.io.lots_file import read_lots
    from flakelab.match.lots import with_lots

    notes = []
    if path is not None:
        _check_not_a_harness_mode(path)
        lots = read_lots(path, library.names)
    elif (kept := stored_tins(shop, database, library.names)) is not None:
        lots = kept.lots
        notes.append(f"weighed for {kept.describe()}")
    else:
        return None, forward, []
    others = sorted(
        {lot.model_id for lot in lots.lots.values() if lot.model_id} - {forward.model_id}
    )
    if others:
        notes.append(
            f"the tins of {path or shop} were read against model {', '.join(others)}, not this "
            f"one ({forward.model_id}): their readings carry that model's errors on the panels"
        )
    return lots, with_lots(forward, lots, library), notes


def stored_tins(shop: str | None, database: str | None, toners=None, version: int | None = None):
    """The latest tins stored for ``shop`` (or its ``version``) in the database named or
    configured (None: no shop, no database yet, or none stored), each of one of ``toners``
    where given (a library's names)."""
    from flakelab.cases.shop_lots import stored_lots

    if shop is None or (engine := existing_engine(database)) is None:
        return None
    return stored_lots(engine, shop, toners, version)


def lots_report(lots) -> dict[str, dict[str, float]]:
    """The tins off the standard, by toner, as a report shows them: strength and shade."""
    return {
        n: {"strength": round(lot.strength, 4), "shade_nm": round(lot.shade_nm, 2)}
        for n, lot in sorted(lots.lots.items())
        if lot.strength != 1 or lot.shade_nm != 0
    }


@lots_app.command("panel")
@reports_errors
def panel_command(
    toner: Annotated[
        list[str],
        typer.Argument(help="The toner whose tin is to be read (several: a panel for each)."),
    ],
    quantity: Annotated[
        str, typer.Option(help="How much of the panel's paint to mix, e.g. 100g or 0.1l.")
    ] = "100g",
    resolution: ResolutionOption = SCALE_RESOLUTION_G,
    library: LibraryOption = None,
    instrument: InstrumentOption = DEFAULT_INSTRUMENT,
    model: ModelOption = None,
    physics: PhysicsOption = False,
    database: DatabaseOption = None,
    recipe_out: RecipeOutOption = None,
    recipe_dir: Annotated[
        Path | None,
        typer.Option(help="Write each panel's recipe into this folder as TONER.json."),
    ] = None,
    json_output: JsonOption = False,
) -> None:
    """The calibration panel for a toner's tin: an OEM-like paint of the toner and one
    partner (an effect base, or the white of ISO 787-24's reduction), the pair and share
    whose colour depends most on the tin, weighed for the can. Spray it, read it, and
    'flakelab lots calibrate' reads the tin's strength and shade from it; several toners'
    panels, sprayed together, are read at once."""
    from flakelab.io import write_recipe
    from flakelab.library import check_toners
    from flakelab.match.lots import calibration_recipes
    from flakelab.match.recipe import order_can

    reads = {"--library": library, "--model": model, "--database": database}
    check_output_file(recipe_out, "--recipe-out", reads=reads)
    if recipe_out is not None and len(toner) > 1:
        raise FlakelabError("--recipe-out: for one toner's panel (--recipe-dir writes each)")
    if recipe_dir is not None and not recipe_dir.is_dir():
        raise FlakelabError(f"--recipe-dir: {recipe_dir}: not a folder")
    can = order_can(quantity, resolution)
    lib, forward, _ = matcher_setup(library, instrument, model, database, physics)
    check_toners(toner, forward.toners)
    toners = list(dict.fromkeys(toner))

    @functools.cache
    def panel_of(name: str):  # a partner among the toners asked for: its panel chosen once
        return calibration_recipes(forward, lib, (name,))[0]

    reports, names = [], names_read_in(recipe_dir, reads)
    for name in toners:
        report = _panel_report(name, panel_of, forward, lib, can, resolution)
        report["partner_in_set"] = report["partner"] in toners
        out = (
            recipe_out if recipe_dir is None else recipe_dir / f"{file_name_for(name, names)}.json"
        )
        if out is not None:
            write_recipe(report["recipe_g"], out)
            report["recipe_out"] = str(out)
            errors.print(f"wrote {name}'s panel recipe to {out}", highlight=False)
        reports.append(report)
    if json_output:
        print_report(reports[0] if len(reports) == 1 else {"panels": reports})
        return
    for report in reports:
        _print_panel(report)
    if len(reports) > 1:
        console.print(
            f"Spray the {len(reports)} panels together and read them at once: 'flakelab lots "
            "calibrate' takes each spray-out with its --recipe in the same order.",
            highlight=False,
        )


def _panel_report(toner: str, panel_of, forward, lib, can, resolution: float) -> dict:
    """``toner``'s calibration panel (``panel_of`` a toner gives its panel's fractions),
    weighed for ``can``, and what its reading tells."""
    from flakelab.match.forward import model_name_for
    from flakelab.match.lots import de00_per_nm, de00_per_percent
    from flakelab.match.recipe import weigh_whole_can

    x = panel_of(toner)
    fractions = {n: float(v) for n, v in zip(forward.toners, x, strict=True) if v > 0}
    grams_can = can.for_toners(lib, fractions).grams_for(fractions)
    weighing = weigh_whole_can(forward, fractions, grams_can, resolution)
    k = forward.toners.index(toner)
    partner = next(n for n in fractions if n != toner)
    partner_x = panel_of(partner)
    per_nm = None if lib[toner].kind != "pigment" else de00_per_nm(forward, lib, x, k)
    return {
        "toner": toner,
        "quantity_g": grams_can,
        "recipe_g": weighing.grams,
        "shares": {n: round(v, 4) for n, v in fractions.items()},
        "de00_per_percent": de00_per_percent(forward, x, k).round(3).tolist(),
        "de00_per_nm": None if per_nm is None else per_nm.round(3).tolist(),
        "geometries": list(forward.geometries),
        "partner": partner,
        "partners_panel_partner": next(
            n for n, v in zip(forward.toners, partner_x, strict=True) if v > 0 and n != partner
        ),
        "model": model_name_for(forward, fractions),
    }


def _print_panel(report: dict) -> None:
    toner = report["toner"]
    title = f"Calibration panel for {toner} ({report['quantity_g']:g} g)"
    table = Table(title=title, box=box.SIMPLE)
    table.add_column("toner")
    table.add_column("g", justify="right")
    for name, grams in report["recipe_g"].items():
        table.add_row(name, f"{grams:.1f}")
    console.print(table)
    for what, key in (("a tin 1 % stronger", "de00_per_percent"),
                      ("a tin 1 nm off in shade", "de00_per_nm")):  # fmt: skip
        if report[key] is not None:
            per = "  ".join(f"{g} {d:.2f}" for g, d in zip(report["geometries"], report[key],
                                                           strict=True))  # fmt: skip
            console.print(f"ΔE00 for {what}: {per}", highlight=False)
    console.print(_partner_advice(report), highlight=False)


def _partner_advice(report: dict) -> str:
    """What a panel of a toner with its partner reads, and how to read each tin alone."""
    toner, partner, partners_partner = (
        report["toner"], report["partner"], report["partners_panel_partner"]
    )  # fmt: skip
    advice = (
        f"The panel reads {toner}'s tin against {partner}'s: it tells how strong one is "
        f"against the other better than how strong either is. "
    )
    if report.get("partner_in_set"):
        return advice + f"{partner}'s own panel is among these: read them at once."
    if partners_partner != toner:
        return advice + (
            f"Read {partner}'s tin from its own panel too ('flakelab lots panel \"{partner}\"', "
            f"with {partners_partner}), or hold it at its reading with "
            f"'lots calibrate --toner \"{toner}\"'."
        )
    return advice + (
        f"{partner}'s own panel is the same pair: hold {partner}'s tin at its reading with "
        f"'lots calibrate --toner \"{toner}\"'."
    )


@lots_app.command("calibrate")
@reports_errors
def calibrate_command(
    sprayed: Annotated[
        list[Path],
        typer.Argument(
            help="Measurement of the panel's spray-out; several panels' are read at once, "
            "each with its --recipe in the same order."
        ),
    ],
    recipe: Annotated[
        list[Path],
        typer.Option(
            "--recipe",
            "-r",
            help="The panel's recipe {toner: grams}, as weighed (one for each spray-out).",
        ),
    ],
    lots: Annotated[
        Path | None,
        typer.Option(
            "--lots", help="The shop's toner-lot file: read where it exists, and updated."
        ),
    ] = None,
    shop: ShopTinsOption = None,
    toner: Annotated[
        list[str] | None,
        typer.Option(
            "--toner",
            metavar="TONER",
            help="A toner whose tin the panel reads (repeat for each; default: every toner of "
            "the recipe, each starting from its tin's last reading); a --lot's toner too.",
            show_default="every toner of the recipe",
        ),
    ] = None,
    lot: Annotated[
        list[str] | None,
        typer.Option(
            "--lot",
            metavar="TONER=NUMBER",
            help="TONER=NUMBER: the tin's lot number. A number other than the one on file is a "
            "new tin: it starts from the standard, not from the old tin's reading.",
        ),
    ] = None,
    standard: Annotated[
        list[Path] | None,
        typer.Option(
            "--standard",
            help="The paint maker's reading of the same panel sprayed from its standard tins: "
            "the tin is read against it, as ISO 787-24 reads a pigment against its "
            "standard's reduction, and the model's own error on the panel drops out (one for "
            "each spray-out, or none).",
            show_default="read against the model's prediction",
        ),
    ] = None,
    standard_sample: Annotated[
        str | None, typer.Option(help="Sample name in a multi-sample --standard file.")
    ] = None,
    shade: Annotated[
        bool,
        typer.Option(
            "--shade/--no-shade",
            help="Read the pigments' shades beside the strengths; with --no-shade each tin "
            "keeps the shade on file (a supplier's certificate, or the standard's).",
        ),
    ] = True,
    sample: SampleOption = None,
    average: AverageOption = False,
    library: LibraryOption = None,
    instrument: InstrumentOption = DEFAULT_INSTRUMENT,
    model: ModelOption = None,
    physics: PhysicsOption = False,
    database: DatabaseOption = None,
    dry_run: Annotated[
        bool, typer.Option("--dry-run", help="Show the reading; leave the lot file as it is.")
    ] = False,
    json_output: JsonOption = False,
) -> None:
    """Read the strength and shade of the shop's tins from a panel's spray-out of a known
    recipe, or from several panels' at once.

    The panels' colour at every geometry is fitted by the tins' strengths and the pigments'
    shades (their absorption a few nm off the standard's), each drawn towards its last
    reading (or the standard ± 3 %, ± 1.5 nm) as far as the panels leave it unsure; the
    spray's own film build and flake alignment are allowed for by the library's physics.
    Tins read together with these before move with them."""
    from flakelab.cases.database import open_database
    from flakelab.io import read_recipe
    from flakelab.library import check_toners
    from flakelab.match.lots import calibrate_lots, recorded

    shop = _tins_kept(lots, shop)
    if lots is not None:  # the lot file is read and updated; the panels' files only read
        check_output_file(lots, "--lots", reads={
            "SPRAYED": sprayed, "--recipe": recipe, "--standard": standard, "--library": library,
            "--model": model, "--database": database})  # fmt: skip
    numbers = _lot_numbers(lot or [])
    check_one_for_each("--recipe", recipe, sprayed, "spray-out")
    check_one_for_each("--standard", standard or [], sprayed, "spray-out", optional=True)
    grams = [read_recipe(path) for path in recipe]
    # a command that stores creates its database, as the others do: before the model is
    # looked for in it
    engine = open_database(database) if shop is not None and not dry_run else None
    lib, forward, _ = matcher_setup(library, instrument, model, database, physics)
    x = np.array([recipe_fractions(lib, g, path) for g, path in zip(grams, recipe, strict=True)])
    check_toners([*(toner or []), *numbers], forward.toners, "--toner, --lot: ")
    _check_in_the_panels([*(toner or []), *numbers], grams, recipe)
    as_read = _contents(lots)  # before it is read: a reading stored since is not written over
    kept, stored = _tins_on_file(engine, lots, shop, database, lib)
    new_tins = [
        n for n, number in numbers.items() if n in stored.lots and stored.lots[n].lot != number
    ]
    start = stored.without(new_tins)
    sprayed_R = _panel_spectra(sprayed, sample, average, forward)
    if standard_sample is not None and not standard:
        raise FlakelabError("--standard-sample: for a --standard file")
    standards = (
        _panel_spectra(standard, standard_sample, False, forward, "--standard-sample")
        if standard
        else None
    )
    fitted = tuple(dict.fromkeys([*toner, *numbers])) if toner else None  # a new tin is read
    found = calibrate_lots(forward, lib, x, sprayed_R, start, toners=fitted,
                           standards=standards, shades=shade)  # fmt: skip
    _check_the_panels_read(found, sprayed, recipe, standard)
    held = np.count_nonzero(x, axis=0)  # the panels that hold each toner
    counts = {name: int(held[forward.toners.index(name)]) for name in found.toners}
    when = datetime.now(UTC).isoformat(timespec="seconds")
    updated = recorded(start, found, when=when, model_id=forward.model_id, numbers=numbers,
                       panels=counts)  # fmt: skip
    version = None
    if not dry_run:
        version = _keep_tins(updated, lots, engine, shop, kept, as_read)
    report = {"lots": lots and str(lots), "shop": shop, "version": version, "written": not dry_run}
    report |= _calibration_report(found, start, updated, new_tins)
    report |= _panels_report(found, sprayed, recipe)
    report["model"], report["model_id"] = forward.name, forward.model_id
    if json_output:
        print_report(report)
        return
    _print_calibration(report)


def _check_in_the_panels(names: list[str], grams: list[dict], recipe: list[Path]) -> None:
    """A tin named to be read is in one of the panels' recipes at least."""
    for name in names:
        if all(g.get(name, 0) <= 0 for g in grams):
            where = recipe[0] if len(recipe) == 1 else ", ".join(map(str, recipe))
            raise FlakelabError(
                f"{where}: {name!r} is not in the panel's recipe: its tin cannot be read from it"
            )


def _tins_on_file(engine, lots: Path | None, shop: str | None, database, lib):
    """The shop's tins stored in the database (the version a reading starts from, or None),
    and the tins the reading starts from: the lot file's where one is named."""
    from flakelab.cases.shop_lots import stored_lots
    from flakelab.io.lots_file import read_lots
    from flakelab.library.lots import TonerLots

    kept = None
    if engine is not None:
        kept = stored_lots(engine, shop, lib.names)
    elif lots is None:
        kept = stored_tins(shop, database, lib.names)
    if lots is not None and lots.exists():
        return kept, read_lots(lots, lib.names)
    return kept, kept.lots if kept else TonerLots(library=lib.name)


def _panel_spectra(paths: list[Path], sample, average: bool, forward, option="--sample"):
    """Each panel file's reflectance at the model's geometries ``[N, G·31]``. A tin's strength
    and shade are read from its panels' colour in D65/10 (:func:`~flakelab.match.lots.
    calibrate_lots`), so a panel known by that colour alone serves as well as its spectra: its
    recovered spectrum gives that colour exactly. One known by its colour under other light is
    refused: its daylight colour would be an estimate, and the lot file keeps what is read."""
    from flakelab.core.colorimetry import D65_10
    from flakelab.core.measurement import colour_stated_elsewhere

    readings = [(path, read_readings(path, sample, average, option)[0]) for path in paths]
    for path, reading in readings:
        if stated := colour_stated_elsewhere(reading):
            raise FlakelabError(
                f"{path}: {reading.sample!r} gives L*a*b* under {stated} alone: a tin's strength "
                f"and shade are read from a panel's colour in {D65_10}, which its file does not "
                f"give; export the panel's spectra, or its colour in {D65_10}"
            )
    return np.array([spectra_for_model(path, reading, forward)[0] for path, reading in readings])


def _check_the_panels_read(found, sprayed: list[Path], recipe: list[Path], standard) -> None:
    """Panels that lie as far from their recipe as a mix-up, or read a tin beyond any a
    supplier delivers, are refused: the shop's tins stay as they were."""
    from flakelab.library.lots import MAX_SHADE_NM
    from flakelab.match.mixups import SPRAYOUT_MISMATCH

    for n, before in enumerate(found.de00_before):
        if before > SPRAYOUT_MISMATCH:
            against = f"{standard[n]}'s reading" if standard else "its recipe's prediction"
            raise FlakelabError(
                f"{sprayed[n]}: the panel lies {before:.1f} ΔE00 from {against} at worst, "
                f"beyond the {SPRAYOUT_MISMATCH:g} of a likely mix-up: is it a spray-out of "
                f"{recipe[n]}'s recipe? (the shop's tins are unchanged)"
            )
    where = sprayed[0] if len(sprayed) == 1 else ", ".join(map(str, sprayed))
    for name, strength, nm in zip(found.toners, found.strength, found.shade, strict=True):
        if not (0.5 <= strength <= 2.0 and abs(nm) <= MAX_SHADE_NM):
            raise FlakelabError(
                f"{where}: the panels read {name}'s tin at {strength:.2f} times the standard "
                f"and {nm:+.1f} nm off its shade: not spray-outs of their recipes, or not "
                "of this library's toners"
            )


def _keep_tins(updated, lots: Path | None, engine, shop: str | None, kept,
               as_read: bytes | None) -> int | None:  # fmt: skip
    """Write the tins as read to the lot file, unless another reading wrote it since it held
    ``as_read``, or store them as the shop's next version in the database (its number)."""
    from flakelab.cases.shop_lots import store_lots
    from flakelab.io.lots_file import write_lots

    if lots is None:
        return store_lots(engine, shop, updated, kept and kept.version).version
    if _contents(lots) != as_read:  # two workplaces sharing the file: the other's kept
        raise FlakelabError(
            f"--lots: {lots} was written by another reading while this one ran; nothing was "
            "written: run the calibration again, from the tins as they are now"
        )
    write_lots(updated, lots)
    return None


def _contents(path: Path | None) -> bytes | None:
    """A lot file's bytes (None where there is none yet)."""
    try:
        return None if path is None else path.read_bytes()
    except FileNotFoundError:
        return None
    except OSError as error:
        raise FlakelabError(f"--lots: {path}: cannot be read ({error.strerror})") from None


def _panels_report(found, sprayed: list[Path], recipe: list[Path]) -> dict:
    """Each panel's worst ΔE00 from what it was read against, with the tins as they stood
    and as read, and the worst of them."""
    return {
        "panels": [
            {
                "sprayed": str(path),
                "recipe": str(r),
                "de00_before": round(float(b), 3),
                "de00_after": round(float(a), 3),
            }
            for path, r, b, a in zip(
                sprayed, recipe, found.de00_before, found.de00_after, strict=True
            )
        ],
        "panel_de00_before": round(float(found.de00_before.max()), 3),
        "panel_de00_after": round(float(found.de00_after.max()), 3),
    }


def _calibration_report(found, start, updated, new_tins: list[str]) -> dict:
    """The tins a calibration read (before and as read), those it moved with them, the
    pairs it read together and the shop's misfit to the model."""
    from flakelab.match.lots import read_together

    read = [updated.lots[name] for name in found.toners]
    moved = [updated.lots[name] for name in found.moved]
    return {
        "tins": [
            {
                "toner": t.toner,
                "lot": t.lot,
                "before": round(float(found.prior_strength[i]), 4),
                "before_sd": round(float(found.prior_sd[i]), 4),
                "strength": round(t.strength, 4),
                "strength_sd": round(t.strength_sd, 4),
                "shade_before_nm": round(float(found.prior_shade[i]), 2),
                "shade_nm": round(t.shade_nm, 2),
                "shade_sd_nm": round(t.shade_sd_nm, 2),
                "shade_read": bool(found.shaded[i]),
                "new_tin": t.toner in new_tins,
            }
            for i, t in enumerate(read)
        ],
        "moved": [
            {
                "toner": t.toner,
                "lot": t.lot,
                "before": round(start.lots[t.toner].strength, 4),
                "strength": round(t.strength, 4),
                "strength_sd": round(t.strength_sd, 4),
                "shade_before_nm": round(start.lots[t.toner].shade_nm, 2),
                "shade_nm": round(t.shade_nm, 2),
                "shade_sd_nm": round(t.shade_sd_nm, 2),
                "shade_read": t.shade_read,
            }
            for t in moved
        ],
        "read_together": [
            {
                **pair,
                "correlation": round(pair["correlation"], 3),
                "ratio": round(pair["ratio"], 4),
                "ratio_sd": round(pair["ratio_sd"], 4),
            }
            for pair in read_together(found)
        ],
        "against": found.misfit[1],  # "model" or "standard"
        "misfit": _misfit_report(updated, found.misfit[:2]),
    }


def _tins_kept(lots: Path | None, shop: str | None) -> str | None:
    """The shop whose tins the database keeps, where no lot file ``lots`` is named: ``--shop``
    or the workplace's; one of the two places, not both."""
    shop, named = workplace_shop(shop)
    if lots is not None and named:
        raise FlakelabError("--lots and --shop: expected one place for the tins, not both")
    if lots is None and shop is None:
        raise FlakelabError(
            "--lots or --shop: expected where the shop's tins are kept: a toner-lot file, or "
            f"the database for a shop (--shop, or {WORKPLACE_SHOP})"
        )
    return None if lots is not None else shop


def _lot_numbers(given: list[str]) -> dict[str, str]:
    numbers = {}
    for text in given:
        name, sep, number = text.partition("=")
        if not sep or not name.strip() or not number.strip():
            raise FlakelabError(f"--lot: expected TONER=NUMBER, got {text!r}")
        numbers[name.strip()] = number.strip()
    return numbers


def _print_calibration(report: dict) -> None:
    several = len(report["panels"]) > 1
    source = f"the {len(report['panels'])} panels" if several else "the panel"
    table = _tins_table(f"The shop's tins, read from {source}")
    for t in report["tins"]:
        before = "standard" if t["new_tin"] else f"{t['before']:.3f} ± {t['before_sd']:.3f}"
        change = 100 * (t["strength"] - t["before"])
        shade = f"{t['shade_nm']:+.2f} ± {t['shade_sd_nm']:.2f} nm" if t["shade_read"] else "—"
        table.add_row(
            t["toner"],
            t["lot"],
            before,
            f"{t['strength']:.3f} ± {t['strength_sd']:.3f}",
            f"{change:+.1f} %",
            shade,
        )
    console.print(table)
    if report["moved"]:
        moved = _tins_table("Tins read together with these before, moved with them")
        for t in report["moved"]:
            moved.add_row(
                t["toner"],
                t["lot"],
                f"{t['before']:.3f}",
                f"{t['strength']:.3f} ± {t['strength_sd']:.3f}",
                f"{100 * (t['strength'] - t['before']):+.1f} %",
                _shade_text(t["shade_nm"], t["shade_sd_nm"], t["shade_read"]),
            )
        console.print(moved)
    against = "the model" if report["against"] == "model" else "the standard's panel"
    for panel in report["panels"]:
        name = f" {panel['sprayed']}" if several else ""
        console.print(
            f"the panel{name}'s worst ΔE00 from {against}: {panel['de00_before']:.2f} with the "
            f"tins as they stood, {panel['de00_after']:.2f} as read",
            highlight=False,
        )
    _print_read_together(report["read_together"], source, several)
    misfit = report["misfit"]
    console.print(
        f"the shop's panels read against {against} so far sit χ²/dof = "
        f"{misfit['chi2_per_dof']:.2f} from it over {misfit['dof']} degrees of freedom: "
        f"their covariance is scaled by {max(1.0, misfit['chi2_per_dof']):.2f}",
        highlight=False,
    )
    kept = report["lots"] or f"the tins of shop {report['shop']!r}"
    if not report["written"]:
        errors.print(f"--dry-run: {kept} unchanged", highlight=False)
    elif report["lots"]:
        errors.print(f"wrote {kept}", highlight=False)
    else:
        errors.print(f"stored {kept} as version {report['version']}", highlight=False)


def _tins_table(title: str) -> Table:
    """A calibration's table of tins: each one's lot, strength before and now, and shade."""
    table = Table(title=title, box=box.SIMPLE)
    for column in ("toner", "lot", "before", "now", "change", "shade"):
        table.add_column(column, justify="left" if column in ("toner", "lot") else "right")
    return table


def _misfit_report(lots, key: tuple[str, str]) -> dict:
    """The shop's pooled misfit to a model read against one thing (``key``), for a report."""
    chi2, dof = lots.misfit.get(key, (0.0, 0))
    return {"model_id": key[0], "against": key[1], "chi2_per_dof": round(chi2 / max(dof, 1), 3),
            "dof": dof}  # fmt: skip


MOST_PAIRS_PRINTED = 3
"""Beyond this many pairs of tins read together a report names the tins, not each pair."""


def _print_read_together(pairs: list[dict], source: str, several: bool) -> None:
    """Which tins ``source`` read together, and what that tells: their ratios."""
    if len(pairs) > MOST_PAIRS_PRINTED:
        tins = sorted({name for pair in pairs for name in pair["toners"]})
        console.print(
            f"{len(tins)} tins were read together ({', '.join(tins)}): {source} tell their "
            "strengths against each other (each pair's ratio in --json) better than against "
            "the standard, as tins all alike stronger look the same in every panel",
            highlight=False,
        )
        return
    for pair in pairs:
        a, b = pair["toners"]
        advice = "" if several else "; a panel of either with another partner tells them apart"
        console.print(
            f"{a} and {b} were read together (correlation {pair['correlation']:+.2f}): "
            f"{source} tell{'' if several else 's'} their ratio, {pair['ratio']:.3f} ± "
            f"{pair['ratio_sd']:.3f}, better than either's strength{advice}",
            highlight=False,
        )


READ_WITH_NAMED = 2
"""How many of the tins a tin was read with ``lots show`` names before it counts the rest."""


def _read_with_text(names: list[str]) -> str:
    if len(names) <= READ_WITH_NAMED + 1:
        return ", ".join(names)
    return f"{', '.join(names[:READ_WITH_NAMED])} and {len(names) - READ_WITH_NAMED} more"


@lots_app.command("show")
@reports_errors
def show_command(
    lots: Annotated[
        Path | None,
        typer.Argument(
            help="A toner-lot file.", show_default="the tins stored for --shop, or every shop's"
        ),
    ] = None,
    shop: ShopTinsOption = None,
    database: DatabaseOption = None,
    version: Annotated[
        int | None,
        typer.Option(
            min=1,
            max=COUNT_MAX,
            help="The version of the shop's tins ('lots history' lists them).",
            show_default="the latest",
        ),
    ] = None,
    out: Annotated[
        Path | None,
        typer.Option("--out", "-o", help="Also write the tins shown as a toner-lot file."),
    ] = None,
    library: LibraryOption = None,
    json_output: JsonOption = False,
) -> None:
    """The tins of a toner-lot file, or those stored for a shop: strength and shade against
    the standard, how sure, when read, and the tins each was read with. Without either, the
    shops whose tins the database keeps. The library (default: demo) tells an effect toner,
    which has no shade, from a pigment whose shade was not read."""
    from dataclasses import asdict

    from flakelab.io import read_library
    from flakelab.io.lots_file import read_lots, write_lots

    check_output_file(out, "--out", reads={"LOTS": lots, "--library": library,
                                           "--database": database})  # fmt: skip
    if lots is None and workplace_shop(shop)[0] is None:
        _show_shops(database, json_output)
        return
    lib = read_library(library)
    shop = _tins_kept(lots, shop)
    if version is not None and lots is not None:
        raise FlakelabError("--version: for the tins stored for a shop (--shop), not a file")
    kept = None if lots is not None else _stored_or_told(shop, database, version)
    found = read_lots(lots) if lots is not None else kept.lots
    if out is not None:
        write_lots(found, out)
    kinds = {t.name: t.kind for t in lib.toners}
    if json_output:
        print_report(
            {
                "library": found.library,
                "shop": shop,
                "version": kept and kept.version,
                "saved_at": kept and kept.saved_at.isoformat(),
                "lots": [
                    {**asdict(t), "read_with": found.read_with(t.toner)}
                    for t in found.lots.values()
                ],
                "misfit": [_misfit_report(found, key) for key in sorted(found.misfit)],
                "out": out and str(out),
            }
        )
        return
    title = f"Toner tins of {lots}" if kept is None else f"Toner {kept.describe()[4:]}"
    table = Table(title=title, box=box.SIMPLE)
    for column in ("toner", "lot", "strength", "shade", "panels", "read", "read with"):
        table.add_column(
            column, justify="right" if column in ("strength", "shade", "panels") else "left"
        )
    for name in sorted(found.lots):
        t = found.lots[name]
        table.add_row(
            name,
            t.lot,
            f"{t.strength:.3f} ± {t.strength_sd:.3f}",
            _shade_text(t.shade_nm, t.shade_sd_nm, t.shade_read, kinds.get(name)),
            str(t.panels),
            shown_time(t.calibrated, day=True),
            _read_with_text(found.read_with(name)),
        )
    console.print(table)
    for key in sorted(found.misfit):
        misfit = _misfit_report(found, key)
        console.print(
            f"panels read against the {key[1]} ({key[0]}): χ²/dof {misfit['chi2_per_dof']:.2f} "
            f"over {misfit['dof']} degrees of freedom",
            highlight=False,
        )
    if any(found.read_with(name) for name in found.lots):
        console.print(
            "read with: tins read together, whose strengths' ratio is surer than either; a "
            "panel of one moves the others with it",
            highlight=False,
        )
    if out is not None:
        errors.print(f"wrote {out}", highlight=False)


@lots_app.command("save")
@reports_errors
def save_command(
    lots: Annotated[Path, typer.Argument(help="A toner-lot file ('flakelab lots calibrate').")],
    shop: ShopTinsOption = None,
    database: DatabaseOption = None,
    library: LibraryOption = None,
    json_output: JsonOption = False,
) -> None:
    """Store a toner-lot file's tins in the database as the shop's latest, where each of its
    workplaces finds them ('match', 'correct' and 'cases record' for the shop, 'lots
    calibrate --shop'). The versions before are kept."""
    from flakelab.cases.database import open_database
    from flakelab.cases.shop_lots import store_lots, stored_lots
    from flakelab.io import read_library
    from flakelab.io.lots_file import read_lots

    shop = _tins_kept(None, shop)
    lib = read_library(library)
    found = read_lots(lots, lib.names)
    engine = open_database(database)
    before = stored_lots(engine, shop)
    saved = store_lots(engine, shop, found, before and before.version)
    report = {
        "lots": str(lots),
        "shop": shop,
        "version": saved.version,
        "tins": len(found.lots),
        "database": engine.url.render_as_string(hide_password=True),
    }
    if json_output:
        print_report(report)
        return
    errors.print(
        f"stored the {report['tins']} tins of {lots} for shop {shop!r} as version "
        f"{saved.version} in {database_label(engine)}",
        highlight=False,
    )


def _stored_or_told(shop: str, database: str | None, version: int | None = None):
    """The latest tins stored for ``shop`` (or its ``version``), as stored; where there are
    none, an error saying how to store them."""
    kept = stored_tins(shop, database, version=version)
    if kept:
        return kept
    if version is not None and stored_tins(shop, database):
        raise FlakelabError(f"--version: shop {shop!r} has no version {version} of its tins")
    raise _no_tins_stored(shop, database)


def _no_tins_stored(shop: str, database: str | None) -> FlakelabError:
    """The error for a shop with no tins stored, saying how to store them, or which shop
    with tins it likely means (:func:`~flakelab.core.wording.shop_meant`)."""
    from flakelab.cases.shop_lots import list_stored_lots

    engine = existing_engine(database)
    shops = [row["shop"] for row in list_stored_lots(engine)] if engine is not None else []
    return FlakelabError(
        f"no tins stored for shop {shop!r}{shop_meant(shop, shops)}: flakelab lots calibrate "
        f"SPRAYED --recipe R --shop {shop!r} reads them from panels, flakelab lots save FILE "
        f"--shop {shop!r} stores a lot file's"
    )


@lots_app.command("history")
@reports_errors
def history_command(
    shop: ShopTinsOption = None,
    database: DatabaseOption = None,
    plot: Annotated[
        Path | None,
        typer.Option(
            "--plot",
            help="Also draw each toner's strength and shade, version by version, a new tin "
            "marked (PNG, PDF or SVG).",
        ),
    ] = None,
    json_output: JsonOption = False,
) -> None:
    """Every version of a shop's tins stored in the database: when it was stored, and the
    tins it changed against the version before (read again, or a new tin opened); with
    --json, each toner's tins through the versions too (what --plot draws)."""
    from flakelab.cases.shop_lots import lots_history, tins_through

    check_figure_file(plot, "--plot")
    shop = _tins_kept(None, shop)
    engine = existing_engine(database)
    versions = lots_history(engine, shop) if engine is not None else []
    if not versions:
        raise _no_tins_stored(shop, database)
    tins = tins_through(versions)
    if plot is not None:
        from flakelab.render.plots import plot_tins_history

        plot_tins_history(tins, plot, title=f"The tins of shop {shop!r}")
        errors.print(f"wrote {plot}", highlight=False)
    report = [
        {
            "version": v.version,
            "saved_at": v.saved_at.isoformat(),
            "tins": len(v.lots.lots),
            "changed": _changed_tins(before and before.lots, v.lots),
        }
        for before, v in zip([None, *versions[:-1]], versions, strict=True)
    ]
    if json_output:
        print_report({"shop": shop, "versions": report, "tins": tins})
        return
    table = Table(title=f"Versions of the tins of shop {shop!r}", box=box.SIMPLE)
    for column in ("version", "saved", "tins", "changed"):
        table.add_column(column, justify="left" if column == "changed" else "right")
    for row in report:
        changed = "; ".join(_change_text(c) for c in row["changed"])
        saved = shown_time(row["saved_at"])
        table.add_row(str(row["version"]), saved, str(row["tins"]), changed)
    console.print(table)


def _changed_tins(before, after) -> list[dict]:
    """The tins of ``after`` (lots) that ``before`` lacks or held otherwise, and those it
    dropped: each with its lot, strength and shade, before and after (None: none)."""

    def fields(lot):
        return lot and {"lot": lot.lot, "strength": lot.strength, "shade_nm": lot.shade_nm}

    old = before.lots if before is not None else {}
    names = sorted({*old, *after.lots})
    pairs = [(n, fields(old.get(n)), fields(after.lots.get(n))) for n in names]
    return [{"toner": n, "before": b, "after": a} for n, b, a in pairs if b != a]


def _change_text(change: dict) -> str:
    before, after = change["before"], change["after"]
    if after is None:
        return f"{change['toner']} dropped"
    lot = f" ({after['lot']})" if after["lot"] else ""
    if before is None or before["lot"] != after["lot"]:
        return f"{change['toner']} new tin{lot} {after['strength']:.3f}"
    return f"{change['toner']}{lot} {before['strength']:.3f} → {after['strength']:.3f}"


def _show_shops(database: str | None, json_output: bool) -> None:
    """The shops whose tins the database keeps: each one's latest version."""
    from flakelab.cases.shop_lots import list_stored_lots

    engine = existing_engine(database)
    shops = list_stored_lots(engine) if engine is not None else []
    if json_output:
        print_report({"shops": shops})
        return
    if not shops:
        raise FlakelabError(
            "no shop has tins stored in the database: name a toner-lot file, or store a "
            "shop's tins ('flakelab lots calibrate --shop NAME', 'flakelab lots save FILE "
            "--shop NAME')"
        )
    table = Table(title="Shops' tins in the database", box=box.SIMPLE)
    for column in ("shop", "version", "tins", "saved"):
        table.add_column(column, justify="left" if column == "shop" else "right")
    for row in shops:
        table.add_row(
            row["shop"],
            str(row["version"]),
            str(row["tins"]),
            shown_time(row["saved_at"]),
        )
    console.print(table)


def _shade_text(shade_nm: float, shade_sd_nm: float, read: bool, kind: str | None = None) -> str:
    """A tin's shade as a table shows it: "—" for an effect toner (``kind`` not "pigment":
    it has none), "not read" while it stands at the standard's prior (``read`` False: a
    pigment's read --no-shade, or any toner's where the library does not know its kind)."""
    if kind is not None and kind != "pigment":
        return "—"
    if not read:
        return "not read"
    return f"{shade_nm:+.2f} ± {shade_sd_nm:.2f} nm"
