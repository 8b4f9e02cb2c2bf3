"""CLI: weigh a recipe for a can, and what rounding to the scale costs in colour."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path
from typing import Annotated

import typer
from rich import box
from rich.table import Table

from flakelab.cli.common import JsonOption, check_output_file, console, errors
from flakelab.cli.matcher import (
    ModelOption,
    PhysicsOption,
    QuantityOption,
    RecipeOutOption,
    ResolutionOption,
    matcher_setup,
)
from flakelab.cli.sources import DatabaseOption, InstrumentOption, LibraryOption, recipe_fractions
from flakelab.core.geometry import DEFAULT_INSTRUMENT


def weigh_command(
    recipe: Annotated[Path, typer.Argument(help="Recipe JSON {toner: grams} (any amount).")],
    quantity: QuantityOption = "250g",
    resolution: ResolutionOption = 0.1,
    library: LibraryOption = None,
    instrument: InstrumentOption = DEFAULT_INSTRUMENT,
    model: ModelOption = None,
    physics: PhysicsOption = False,
    database: DatabaseOption = None,
    recipe_out: RecipeOutOption = None,
    json_output: JsonOption = False,
) -> None:
    """Weigh a recipe for another can, and what rounding to the scale costs in colour.

    Grams per toner at the scale's resolution, cumulative weights in pouring order, and the
    ΔE00 between the exact and the weighed recipe, both predicted by the model."""
    from flakelab.io import read_recipe, write_recipe
    from flakelab.match.recipe import order_can

    grams = read_recipe(recipe)
    can = order_can(quantity, resolution)
    check_output_file(recipe_out, "--recipe-out")
    lib, forward, _ = matcher_setup(library, instrument, model, database, physics)
    fractions = recipe_fractions(lib, grams, recipe)
    shares = {n: float(v) for n, v in zip(lib.names, fractions, strict=True) if v > 0}
    can = can.for_toners(lib, shares)
    can_g = can.grams_for(shares)
    report = {
        "recipe": str(recipe),
        **can_size(can, can_g),
        **weighed_recipe(forward, shares, can_g, resolution),
        "model": forward.name,
    }
    if recipe_out is not None:
        write_recipe({ln["toner"]: ln["grams"] for ln in report["weights_g"]}, recipe_out)
        report["recipe_out"] = str(recipe_out)
        errors.print(f"wrote the weighed recipe to {recipe_out}", highlight=False)
    if json_output:
        print(json.dumps(report, indent=2))
        return
    console.print(f"{recipe.name} for {can_text(report)}", highlight=False)
    console.print(weights_table(None, report["weights_g"]))
    console.print(f"{rounding_text(report)} ({forward.name})", highlight=False)


def can_size(can, grams: float) -> dict:
    """The report's can: its ``grams`` for the recipe, and as ordered by volume."""
    volume = {} if can.millilitres is None else {
        "quantity": can.quantity, "quantity_ml": can.millilitres}  # fmt: skip
    return {"quantity_g": grams, **volume, "resolution_g": can.resolution_g}


def can_text(report: dict) -> str:
    """``250 g``, or ``1qt (927.3 g)`` for a can ordered by volume."""
    grams = f"{report['quantity_g']:g} g"
    return grams if "quantity_ml" not in report else f"{report['quantity']} ({grams})"


def weighed_recipe(
    forward, fractions: dict[str, float], quantity_g: float, resolution: float
) -> dict:
    """The report's weights for a can: grams in pouring order, rounded to the scale as the
    colour closest to the exact recipe's asks, and what that and the nearest grams cost."""
    from flakelab.match.recipe import weigh_for_colour

    weighing = weigh_for_colour(forward, fractions, quantity_g, resolution)
    return {"weights_g": [asdict(ln) for ln in weighing.lines], **rounding_costs(weighing)}


def rounding_costs(weighing) -> dict[str, float]:
    """What rounding to the scale costs, as weighed and as the nearest grams would."""
    return {
        "rounding_de00": weighing.rounding_de00,
        "rounding_de00_nearest": weighing.nearest_de00,
    }


def rounding_text(report: dict) -> str:
    text = f"rounding to the scale costs ΔE00 {report['rounding_de00']:.3f}"
    if report["rounding_de00_nearest"] > report["rounding_de00"] + 5e-4:
        text += f" (the nearest grams: {report['rounding_de00_nearest']:.3f})"
    return text


def weights_table(title: str | None, weights_g: list[dict]) -> Table:
    """What to pour: grams per toner and the cumulative weight on the scale."""
    table = Table(title=title, box=box.SIMPLE_HEAVY, title_justify="left")
    table.add_column("toner")
    table.add_column("g", justify="right")
    table.add_column("cumul. g", justify="right")
    for line in weights_g:
        table.add_row(line["toner"], f"{line['grams']:.1f}", f"{line['cumulative']:.1f}")
    return table
