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
from flakelab.errors import FlakelabError


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
    poured: Annotated[
        list[str] | None,
        typer.Option(
            help="A toner already poured, as the scale read it: 'NAME=GRAMS' (repeat for "
            "each). Prints what is still to pour; where one ran over, for the least larger "
            "can that keeps the recipe's proportions.",
        ),
    ] = None,
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
    if poured:
        _weigh_the_rest(forward, recipe, shares, can, can_g, poured_grams(poured), recipe_out,
                        json_output)  # fmt: skip
        return
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


def poured_grams(pairs: list[str]) -> dict[str, float]:
    """``--poured 'NAME=GRAMS'`` options → grams per toner."""
    import math

    grams = {}
    for pair in pairs:
        name, sep, amount = pair.rpartition("=")
        try:
            value = float(amount)
        except ValueError:
            value = math.nan
        if not sep or not name.strip() or not (math.isfinite(value) and value >= 0):
            raise FlakelabError(f"--poured: expected NAME=GRAMS (grams ≥ 0), got {pair!r}")
        if name.strip() in grams:
            raise FlakelabError(f"--poured: {name.strip()} given twice")
        grams[name.strip()] = value
    return grams


def _weigh_the_rest(
    forward, recipe: Path, shares, can, can_g: float, poured: dict, recipe_out, json_output
) -> None:
    """``weigh --poured``: what is still to pour, and the can's size, once some is poured."""
    from flakelab.io import write_recipe
    from flakelab.match.recipe import weigh_after_pouring

    grown, weighing = weigh_after_pouring(forward, shares, can_g, poured, can.resolution_g)
    total = sum(shares.values())
    planned = {n: shares[n] / total * can_g for n in poured}
    report = {
        "recipe": str(recipe),
        **can_size(can, can_g),
        "poured_g": poured,
        "grown_g": grown,
        "ran_over": [n for n, g in poured.items() if g > planned[n] + can.resolution_g / 2],
        "to_pour_g": [asdict(ln) for ln in weighing.lines],
        **rounding_costs(weighing),
        "model": forward.name,
    }
    if recipe_out is not None:  # what the can holds once the rest is poured
        held = {n: poured.get(n, 0.0) + weighing.grams.get(n, 0.0) for n in {*poured, *shares}}
        write_recipe({n: g for n, g in held.items() if g > 0}, recipe_out)
        report["recipe_out"] = str(recipe_out)
        errors.print(f"wrote what the can holds to {recipe_out}", highlight=False)
    if json_output:
        print(json.dumps(report, indent=2))
        return
    over = ", ".join(f"{n} ({poured[n]:g} g of {planned[n]:.1f} g)" for n in report["ran_over"])
    console.print(
        f"{recipe.name} for {can_text(report)}: "
        + (f"{over} ran over; the can grows to {grown:g} g" if over else "on plan")
        + f"; {sum(poured.values()):g} g poured, still to pour:",
        highlight=False,
    )
    if report["to_pour_g"]:
        console.print(weights_table(None, report["to_pour_g"]))
    else:
        console.print("nothing: the can is complete on this scale", highlight=False)
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
