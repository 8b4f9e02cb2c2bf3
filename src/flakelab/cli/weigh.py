"""CLI: weigh a recipe for a can, and what rounding to the scale costs in colour."""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path
from typing import Annotated

import typer
from rich import box
from rich.table import Table

from flakelab.cli.common import (
    JsonOption,
    check_output_file,
    console,
    errors,
    print_notes,
    print_report,
)
from flakelab.cli.lots import ShopTinsOption
from flakelab.cli.matcher import (
    ModelOption,
    PhysicsOption,
    QuantityOption,
    RecipeOutOption,
    ResolutionOption,
    matcher_setup,
)
from flakelab.cli.sources import (
    DatabaseOption,
    InstrumentOption,
    LibraryOption,
    recipe_fractions,
    workplace_shop,
)
from flakelab.core.geometry import DEFAULT_INSTRUMENT
from flakelab.errors import FlakelabError
from flakelab.match.settings import CAN_QUANTITY, SCALE_RESOLUTION_G, physics_check_words


def weigh_command(
    recipe: Annotated[
        Path, typer.Argument(help="Recipe JSON {toner: grams} (any amount; - reads stdin).")
    ],
    quantity: QuantityOption = CAN_QUANTITY,
    resolution: ResolutionOption = SCALE_RESOLUTION_G,
    library: LibraryOption = None,
    instrument: InstrumentOption = DEFAULT_INSTRUMENT,
    model: ModelOption = None,
    physics: PhysicsOption = False,
    database: DatabaseOption = None,
    recipe_out: RecipeOutOption = None,
    poured: Annotated[
        list[str] | None,
        typer.Option(
            metavar="NAME=GRAMS",
            help="A toner already poured, as the scale read it: 'NAME=GRAMS' (repeat for "
            "each). Prints what is still to pour; where one ran over, for the least larger "
            "can that keeps the recipe's proportions.",
        ),
    ] = None,
    most: Annotated[
        str | None,
        typer.Option(
            help="With --poured: the most the can may hold once the rest is poured, e.g. 300g "
            "(or by volume, 0.35l, at the recipe's density). A can that would grow past it "
            "is brought as near the recipe's colour as it allows.",
            show_default="no bound",
        ),
    ] = None,
    lots: Annotated[
        Path | None,
        typer.Option(
            "--lots",
            help="The shop's toner-lot file: the rounding's colour cost (and, with --poured, "
            "the dilution) predicted for its tins.",
            show_default="the shop's tins stored in the database (--shop), else the standard",
        ),
    ] = None,
    shop: ShopTinsOption = None,
    physics_check: Annotated[
        bool,
        typer.Option(
            "--physics-check/--no-physics-check",
            help="With --poured: where the model's networks disagree on the can or its recipe "
            f"by over {physics_check_words()} (its cases too few), the library's physics "
            "dilutes in the model's place (--no-physics-check: the learned model's).",
        ),
    ] = True,
    json_output: JsonOption = False,
) -> None:
    """Weigh a recipe for another can, and what rounding to the scale costs in colour.

    Grams per toner at the scale's resolution, cumulative weights in pouring order, and the
    ΔE00 between the exact and the weighed recipe, both predicted by the model."""
    from flakelab.cli.lots import lots_report, shop_lots
    from flakelab.io import read_recipe, write_recipe
    from flakelab.match.forward import model_name_for
    from flakelab.match.recipe import order_can

    grams = read_recipe(recipe)
    can = order_can(quantity, resolution)
    check_output_file(recipe_out, "--recipe-out", reads={
        "RECIPE": recipe, "--library": library, "--model": model, "--database": database,
        "--lots": lots})  # fmt: skip
    lib, forward, _ = matcher_setup(library, instrument, model, database, physics)
    tins, forward, lot_notes = shop_lots(lots, lib, forward, workplace_shop(shop)[0], database)
    for_tins = {"lots": tins and lots_report(tins), "notes": lot_notes}
    fractions = recipe_fractions(lib, grams, recipe)
    shares = {n: float(v) for n, v in zip(lib.names, fractions, strict=True) if v > 0}
    can = can.for_toners(lib, shares)
    can_g = can.grams_for(shares)
    if most is not None and not poured:
        raise FlakelabError("--most: for --poured (how far a can may grow once poured)")
    if not physics_check and not poured:
        raise FlakelabError("--no-physics-check: for --poured (what dilutes a stray toner)")
    if poured:
        most_g = None if most is None else _most_the_can_holds(most, can, can_g, lib, shares)
        _weigh_the_rest(forward, recipe, shares, can, can_g, poured_grams(poured), most_g,
                        recipe_out, json_output, for_tins, lib, physics_check)  # fmt: skip
        return
    report = {
        "recipe": str(recipe),
        **can_size(can, can_g),
        **weighed_recipe(forward, shares, can_g, resolution),
        "model": model_name_for(forward, shares),
        **for_tins,
    }
    if recipe_out is not None:
        write_recipe({ln["toner"]: ln["grams"] for ln in report["weights_g"]}, recipe_out)
        report["recipe_out"] = str(recipe_out)
        errors.print(f"wrote the weighed recipe to {recipe_out}", highlight=False)
    if json_output:
        print_report(report)
        return
    console.print(f"{recipe.name} for {can_text(report)}", highlight=False)
    console.print(weights_table(None, report["weights_g"]))
    console.print(f"{rounding_text(report)} ({report['model']})", highlight=False)
    print_notes(report["notes"])


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


def _most_the_can_holds(most: str, can, can_g: float, library, shares) -> float:
    """``--most`` in grams (by volume, at the recipe's density), checked that it holds the
    recipe's own can."""
    from flakelab.match.recipe import is_volume, recipe_grams

    most_g = recipe_grams(most, can.resolution_g, library, shares, "--most")
    if most_g < can_g:
        amount = f"{most} ({most_g:g} g)" if is_volume(most) else most
        raise FlakelabError(f"--most: {amount} is less than the can, {can_g:g} g")
    return most_g


def _weigh_the_rest(
    forward, recipe: Path, shares, can, can_g: float, poured: dict, most_g, recipe_out,
    json_output, for_tins: dict, library, physics_check: bool,
) -> None:  # fmt: skip
    """``weigh --poured``: what is still to pour, and the can's size, once some is poured;
    where a toner outside the recipe was poured, what brings the can back to its colour
    (``for_tins``: the report's entries for the shop's tins), with ``physics_check`` by the
    ``library``'s physics where the model is unsure of the can."""
    from flakelab.io import write_recipe
    from flakelab.library import did_you_mean
    from flakelab.match.correction import physics_checked_note
    from flakelab.match.forward import model_name_for

    if unknown := [n for n in poured if n not in forward.toners]:
        raise FlakelabError(
            f"--poured: {', '.join(unknown)}: not a toner the model knows"
            f"{did_you_mean(unknown[0], forward.toners)} ({recipe}'s toners: "
            f"{', '.join(shares)})"
        )
    total = sum(shares.values())
    planned = {n: shares.get(n, 0.0) / total * can_g for n in poured}
    strays = [n for n in poured if n not in shares]
    weighing, found, diluted = _what_to_pour(
        forward, shares, can, can_g, poured, strays, most_g, library, physics_check
    )
    predicted_by = forward if diluted is None else diluted.predicted_by
    grown = round(sum(poured.values()) + sum(weighing.grams.values()), 6)
    report = {
        "recipe": str(recipe),
        **can_size(can, can_g),
        "most_g": most_g,
        "poured_g": poured,
        "grown_g": grown,
        "ran_over": [
            n for n, g in poured.items() if n in shares and g > planned[n] + can.resolution_g / 2
        ],
        "not_in_recipe": strays,
        **found,
        "to_pour_g": [asdict(ln) for ln in weighing.lines],
        **rounding_costs(weighing),
        "model": model_name_for(predicted_by, {*shares, *poured}),  # strays poured in too
        **for_tins,
    }
    if note := diluted and physics_checked_note(diluted, "the can as poured or its recipe"):
        report["notes"] = [*report["notes"], note]
    if recipe_out is not None:  # what the can holds once the rest is poured
        held = {n: poured.get(n, 0.0) + weighing.grams.get(n, 0.0) for n in {*poured, *shares}}
        write_recipe({n: g for n, g in held.items() if g > 0}, recipe_out)
        report["recipe_out"] = str(recipe_out)
        errors.print(f"wrote what the can holds to {recipe_out}", highlight=False)
    if json_output:
        print_report(report)
        return
    _print_the_rest(report, recipe, planned)


def _what_to_pour(
    forward, shares, can, can_g: float, poured: dict, strays, most_g, library, physics_check
):
    """The weighing of what is still to pour, what the report adds for it, and the dilution
    (None: none was needed): nothing on plan or where a recipe's toner ran over and the can
    may grow to keep the proportions; where ``strays`` outside the recipe were poured, or the
    can may not grow to more than ``most_g``, the ΔE00 by which it is then expected to miss
    the recipe, with ``physics_check`` by ``library``'s physics where the model is unsure of
    the can."""
    from flakelab.core.tolerance import failing_geometries, tolerance_preset
    from flakelab.match.correction import correct_what_was_poured
    from flakelab.match.objective import OBJECTIVE_DEFAULT
    from flakelab.match.recipe import weigh_after_pouring

    found = {}
    if not strays:
        weighing = weigh_after_pouring(forward, shares, can_g, poured, can.resolution_g)[1]
        proportional = round(sum(poured.values()) + sum(weighing.grams.values()), 6)
        if most_g is None or proportional <= most_g:
            return weighing, found, None
        found["proportional_g"] = proportional  # more than --most: diluted as far as it allows
    tolerance = tolerance_preset(OBJECTIVE_DEFAULT)
    poured_right = correct_what_was_poured(
        forward, shares, can_g, poured, can.resolution_g, tolerance, most_g, library,
        physics_check,
    )  # fmt: skip
    return (
        poured_right.weighing,
        found
        | {
            "tolerance": tolerance.name,
            "geometries": list(forward.geometries),
            "as_planned_de00": poured_right.as_planned_de00.round(3).tolist(),
            "expected_de00": poured_right.expected_de00.round(3).tolist(),
            "expected_failing": failing_geometries(forward.geometries, poured_right.passes),
            # predicted by the library's physics, the model unsure of the can (or its recipe)
            "physics_checked": poured_right.model_spread is not None,
        },
        poured_right,
    )


def _print_the_rest(report: dict, recipe: Path, planned: dict) -> None:
    poured, grown = report["poured_g"], report["grown_g"]
    over = report["ran_over"]
    by = "by the library's physics" if report.get("physics_checked") else "by the model"
    ran = ", ".join(f"{n} ({poured[n]:g} g of {planned[n]:.1f} g)" for n in over)
    if report["not_in_recipe"]:
        state = (
            f"{', '.join(report['not_in_recipe'])} is not in the recipe: the rest of the recipe "
            f"and what brings the can back to its colour {by}; the can grows to "
            f"{grown:g} g" + (f" (--most {report['most_g']:g} g)" if report["most_g"] else "")
        )
    elif over and "proportional_g" in report:
        state = (
            f"{ran} ran over; at the recipe's proportions the can would grow to "
            f"{report['proportional_g']:g} g, more than --most {report['most_g']:g} g: the "
            f"rest and what brings the can nearest its colour {by}, in {grown:g} g"
        )
    elif over:
        state = f"{ran} ran over; the can grows to {grown:g} g"
    else:
        state = "on plan"
    console.print(
        f"{recipe.name} for {can_text(report)}: {state}; {sum(poured.values()):g} g poured, "
        "still to pour:",
        highlight=False,
    )
    if report["to_pour_g"]:
        console.print(weights_table(None, report["to_pour_g"]))
    else:
        console.print("nothing: the can is complete on this scale", highlight=False)
    console.print(f"{rounding_text(report)} ({report['model']})", highlight=False)
    if "expected_de00" in report:
        worst, planned_worst = max(report["expected_de00"]), max(report["as_planned_de00"])
        text = (
            f"expected to miss the recipe by ΔE00 {worst:.2f} at worst ({by}; "
            f"{planned_worst:.2f} with the rest poured as planned)"
        )
        if report["expected_failing"]:
            text = (
                f"[yellow]note:[/] even so {text}, failing {report['tolerance']} at "
                f"{', '.join(report['expected_failing'])}: mix afresh"
            )
        console.print(text, highlight=False)
    print_notes(report["notes"])


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
