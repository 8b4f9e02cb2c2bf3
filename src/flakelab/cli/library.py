"""``flakelab library``: what a toner library holds, and how the model knows each toner."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich import box
from rich.table import Table

from flakelab.cli.common import (
    JsonOption,
    command_group,
    console,
    errors,
    print_report,
    reports_errors,
)
from flakelab.cli.matcher import ModelOption
from flakelab.cli.sources import DatabaseOption, InstrumentOption, shop_spelled
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
