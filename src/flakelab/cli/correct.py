"""CLI: correct a recipe from its measured spray-out."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich import box
from rich.table import Table

from flakelab.cli.common import (
    COUNT_MAX,
    MODEL_SPREAD_LEGEND,
    WEIGHT_MAX,
    AverageOption,
    AverageSprayedOption,
    JsonOption,
    LightsOption,
    PlotOption,
    SampleOption,
    SprayedSampleOption,
    ToleranceOption,
    add_readings_spread,
    check_figure_file,
    check_output_file,
    console,
    draw_differences,
    errors,
    lights_option,
    print_notes,
    print_report,
    read_readings,
)
from flakelab.cli.lots import LotsOption, lots_report, shop_lots
from flakelab.cli.matcher import (
    HabitsOption,
    HabitsShopOption,
    MetamerismOption,
    ModelOption,
    PhysicsOption,
    RecipeOutOption,
    ResolutionOption,
    WithoutOption,
    habits_for,
    left_out_model,
    matcher_setup,
    metamerism_text,
    metamerism_values,
    spectra_for_model,
    with_left_out,
)
from flakelab.cli.sources import (
    DatabaseOption,
    InstrumentOption,
    LibraryOption,
    recipe_fractions,
    workplace_shop,
)
from flakelab.cli.weigh import rounding_costs, rounding_text
from flakelab.core.defaults import DEFAULT_TOLERANCE
from flakelab.core.geometry import DEFAULT_INSTRUMENT
from flakelab.errors import FlakelabError
from flakelab.match.settings import (
    EXTRA_TONERS_TRIED,
    MODEL_SD,
    SCALE_RESOLUTION_G,
    MatchSettings,
    physics_check_words,
)


def correct_command(
    target: Annotated[Path, typer.Argument(help="Target measurement file.")],
    recipe: Annotated[Path, typer.Option("--recipe", "-r", help="Recipe JSON {toner: grams}.")],
    sprayed: Annotated[Path, typer.Option("--sprayed", help="Measurement of the spray-out.")],
    sample: SampleOption = None,
    sprayed_sample: SprayedSampleOption = None,
    average: AverageOption = False,
    average_sprayed: AverageSprayedOption = False,
    mode: Annotated[
        str, typer.Option(help="additions (can already mixed) or reformulate.")
    ] = "additions",
    library: LibraryOption = None,
    instrument: InstrumentOption = DEFAULT_INSTRUMENT,
    model: ModelOption = None,
    physics: PhysicsOption = False,
    database: DatabaseOption = None,
    resolution: ResolutionOption = SCALE_RESOLUTION_G,
    left: Annotated[
        str | None,
        typer.Option(
            help="What is left in the mixed can after the spray-out, e.g. 180g (or by volume, "
            "0.2l): the additions are for it. Default: the whole recipe.",
            show_default="the whole recipe",
        ),
    ] = None,
    most: Annotated[
        str | None,
        typer.Option(
            help="The most the can may hold after the additions, e.g. 300g (or by volume, "
            "0.35l, at the recipe's density): they are scaled down together to fit.",
            show_default="no bound",
        ),
    ] = None,
    offset_weight: Annotated[
        float | None,
        typer.Option(
            help="Weight the whole of the spray-out's offset from the model by this share "
            "(0 to 1) instead of splitting off this spray's film build and flake alignment "
            "by the library's physics.",
            show_default="physics split",
        ),
    ] = None,
    extra_toners: Annotated[
        int,
        typer.Option(
            min=0, max=COUNT_MAX, help="Toners outside the recipe tried as one addition (0: none)."
        ),
    ] = EXTRA_TONERS_TRIED,
    without: WithoutOption = None,
    lots: LotsOption = None,
    model_sd: Annotated[
        float,
        typer.Option(
            min=0.0,
            max=WEIGHT_MAX,
            help="Widen the prior of the offset that persists by this many times the model "
            "ensemble's disagreement at each geometry (0: one prior everywhere).",
        ),
    ] = MODEL_SD,
    physics_check: Annotated[
        bool,
        typer.Option(
            "--physics-check/--no-physics-check",
            help="Where the model's networks disagree on the sprayed recipe by over "
            f"{physics_check_words()} (its cases too few), the library's physics "
            "corrects in the model's place (--no-physics-check: the learned model's).",
        ),
    ] = True,
    tolerance: ToleranceOption = DEFAULT_TOLERANCE,
    metamerism: MetamerismOption = MatchSettings.metamerism,
    lights: LightsOption = None,
    habits: HabitsOption = None,
    shop: HabitsShopOption = None,
    recipe_out: RecipeOutOption = None,
    plot: PlotOption = None,
    json_output: JsonOption = False,
) -> None:
    """Correct a recipe from its measured spray-out.

    The model's local behaviour around the recipe, applied to the part of the
    spray-out's offset from the prediction that persists: the library's physics
    splits off what the spray's own film build and flake alignment did."""
    from flakelab.core.colorimetry import reflectance_to_Lab
    from flakelab.core.measurement import daylight_estimate_note, recovered_note
    from flakelab.core.tolerance import failing_geometries, failures
    from flakelab.io import read_recipe, read_tolerance
    from flakelab.match.correction import correct, mismatch_note, physics_checked_note
    from flakelab.match.search import left_out_note, unused_geometries

    _check_correction_options(mode, left, most)
    tol = read_tolerance(tolerance)
    test_lights = lights_option(lights)
    reads = {"TARGET": target, "--recipe": recipe, "--sprayed": sprayed, "--library": library,
             "--model": model, "--database": database, "--lots": lots, "--habits": habits,
             "--tolerance": tolerance}  # fmt: skip
    check_output_file(recipe_out, "--recipe-out", reads=reads, writes={"--plot": plot})
    check_figure_file(plot, "--plot", reads=reads)
    grams = read_recipe(recipe)
    _can_size(grams, resolution)  # before the model: a can the scale cannot weigh is a typo
    shop, named = workplace_shop(shop)
    lib, forward, _ = matcher_setup(library, instrument, model, database, physics, shop)
    tins, forward, lot_notes = shop_lots(lots, lib, forward, shop, database)
    x0 = recipe_fractions(lib, grams, recipe)
    can = grams if left is None else _what_is_left(grams, left, resolution, lib, recipe)
    most_g = None if most is None else _most_g(most, can, resolution, lib)
    room = None if most_g is None else _room_in_can(most_g, can, resolution, extra_toners)
    target_reading, target_readings = read_readings(target, sample, average)
    sprayed_reading, sprayed_readings = read_readings(
        sprayed, sprayed_sample, average_sprayed, "--sprayed-sample", "--average-sprayed"
    )
    target_R, _, _ = spectra_for_model(target, target_reading, forward)
    sprayed_R, _, _ = spectra_for_model(sprayed, sprayed_reading, forward)
    readings = (target_reading, sprayed_reading)
    recovered = [note for r in readings if (note := recovered_note(r))]
    estimates = [n for r in readings if (n := daylight_estimate_note(r, "the correction"))]
    if recovered:  # a metamer of many: neither weighed nor reported
        metamerism, test_lights = 0.0, ()
    fractions = {n: float(v) for n, v in zip(lib.names, x0, strict=True) if v > 0}
    shop_habits = habits_for(
        habits, shop, database, forward, named=named, with_tins=tins is not None
    )
    correction = correct(
        forward,
        target_R,
        fractions,
        sprayed_R,
        mode=mode,
        library=lib,
        offset_weight=offset_weight,
        extra_toners=extra_toners,
        habits=shop_habits,
        model_sd=model_sd,
        tolerance=tol,
        metamerism=metamerism,
        lights=test_lights,
        max_total=room,
        without=without or (),
        physics_check=physics_check,
    )
    forward = correction.predicted_by  # the library's physics, where the model was unsure
    target_lab = reflectance_to_Lab(target_R)
    before, _, passed = tol.judge(forward.geometries, target_lab, reflectance_to_Lab(sprayed_R))
    texture_failing = tol.failing_texture(target_reading.texture, sprayed_reading.texture)
    failing = failing_geometries(forward.geometries, passed)
    report = {
        "mode": mode,
        "before_de00": before.round(3).tolist(),
        "tolerance": tol.name,
        "sprayout_passes": not failing and not texture_failing,
        "sprayout_failing": failures(failing, texture_failing),
        "notes": left_out_note(unused_geometries(target_reading, forward), forward, "correction")
        + [f"{note}: no metamerism index is weighed or taken" for note in recovered]
        + estimates
        + lot_notes,
        "lots": tins and lots_report(tins),
    }
    if average:
        add_readings_spread(report, "target_readings", target_readings, target_reading, tol)
    if average_sprayed:
        add_readings_spread(report, "sprayout_readings", sprayed_readings, sprayed_reading, tol,
                            "spray-out")  # fmt: skip
    mismatch = mismatch_note(forward, fractions, sprayed_R, shop_habits, lib)
    report["notes"] += _sprayout_notes(tol, failing, texture_failing, mismatch)
    report["notes"] += [note] if (note := physics_checked_note(correction)) else []
    weighing = _weigh_correction(forward, correction, mode, can, resolution)
    report |= _weighing_report(weighing, forward, mode, fractions)
    expected_lab = correction.expected_lab + weighing.lab_shift  # as weighed, not as computed
    _add_can_limits(report, can if left is not None else None, most_g, room, correction)
    if recipe_out is not None:
        _write_corrected(report, can, recipe_out)
    report |= {
        "new_toner": correction.new_toner,
        "without": list(without or ()),
        "offset_weight": offset_weight,
        "model_sd": model_sd,
        "spray_application": correction.application
        and {name: round(value, 4) for name, value in correction.application.items()},
        "habits": shop_habits and shop_habits.report(),
        # how far the ensemble that corrected disagrees on the corrected recipe, per geometry
        "expected_model_spread": None
        if correction.expected_spread is None
        else correction.expected_spread.round(3).tolist(),
    }
    _add_expected(report, tol, forward.geometries, target_lab, expected_lab, failing, mode)
    _add_metamerism(report, target_R, sprayed_R, correction, metamerism, test_lights)
    report["geometries"] = list(forward.geometries)
    other = (
        None
        if shop_habits
        else left_out_model(target_reading, forward, lib, database, physics, shop)
    )
    found = other and _add_expected_left_out(
        report, target_reading, sprayed_reading, fractions, correction, forward, other, tol
    )
    if plot is not None:
        samples = {
            "spray-out (measured)": reflectance_to_Lab(sprayed_R),
            "expected after the correction": expected_lab,
        }
        _plot_correction(target_reading, sprayed_reading, target_lab, samples,
                         found and found[1], forward, tol, plot)  # fmt: skip
        report["plot"] = str(plot)
    if json_output:
        print_report(report)
        return
    _print_correction(report)


def _add_can_limits(report: dict, left: dict | None, most_g, room, correction) -> None:
    """``--left`` (the grams ``left`` in the can) and ``--most`` (``most_g``, ``room`` for the
    additions) into ``report``, with a note where the additions fill the can."""
    if left is not None:
        report["left_g"] = round(sum(left.values()), 6)
    if most_g is not None:
        report["most_g"] = most_g
        if sum(correction.added.values()) >= room * 0.99:  # traces under 1e-4 left out
            report["notes"].append(
                f"the additions fill the can to --most {most_g:g} g: the correction is cut "
                "short there, as far as the can allows"
            )


def _add_expected_left_out(
    report, target, sprayed, fractions, correction, forward, other, tolerance
):
    """The spray-out and the corrected recipe at the target's geometries that ``forward``
    leaves out, as the ``other`` model predicts them, into ``report``; the two comparisons
    (None where the target has no such geometries)."""
    from flakelab.match.crosscheck import expected_left_out

    found = expected_left_out(
        target, sprayed, fractions, correction.fractions, forward, other, tolerance
    )
    if found:
        sprayed_there, expected_there = found
        report["left_out"] = expected_there.to_dict() | {
            "sprayout_de00": sprayed_there.round(3).tolist()
        }
    return found


def _check_correction_options(mode: str, left, most) -> None:
    """Options that do not fit the correction's ``mode``, refused before any file is read."""
    for option, given in (("--left", left), ("--most", most)):
        if given is not None and mode != "additions":
            raise FlakelabError(f"{option}: for --mode additions (a reformulation is mixed afresh)")


def _add_expected(report: dict, tol, geometries, target_lab, expected_lab, failing, mode) -> None:
    """What the corrected recipe is expected to give against the target, into ``report``, and
    a note where it still fails where the spray-out did (``failing``)."""
    from flakelab.core.tolerance import failing_geometries
    from flakelab.match.correction import unreached_note

    expected, _, expected_passed = tol.judge(geometries, target_lab, expected_lab)
    report["expected_de00"] = expected.round(3).tolist()
    report["expected_failing"] = failing_geometries(geometries, expected_passed)
    if failing and (note := unreached_note(tol, report["expected_failing"], expected, mode)):
        report["notes"].append(note)


def _add_metamerism(report: dict, target_R, sprayed_R, correction, weight, lights) -> None:
    """The spray-out's and the corrected recipe's metamerism against the target under the
    test ``lights`` (ISO 18314-4), into ``report``, with a note where the correction changes
    it."""
    from flakelab.core.difference import is_metamer, metamerism_indices, worst_per_light
    from flakelab.match.correction import metamerism_note

    sprayed_metamerism = metamerism_indices(target_R, sprayed_R, tests=lights)
    report |= {
        "metamerism_weight": weight,
        "sprayout_metamerism_index_max": worst_per_light(sprayed_metamerism),
        "sprayout_metamer": is_metamer(sprayed_metamerism),
        "expected_metamerism_index_max": worst_per_light(correction.metamerism),
    }
    if note := metamerism_note(sprayed_metamerism, correction.metamerism):
        report["notes"].append(note)


def _sprayout_notes(tol, failing: list[str], texture_failing: list[str], mismatch) -> list[str]:
    """What the spray-out's verdict says of the correction: optional where it passes, a
    likely mix-up (``mismatch``), colour alone where its texture fails."""
    notes = []
    if not failing:
        notes.append(
            f"the spray-out already passes {tol.name} at every geometry: the correction is "
            "optional, a move toward the target's centre"
        )
    if mismatch:
        notes.append(mismatch)
    if texture_failing:
        notes.append(
            f"the spray-out's texture fails {tol.name} at {', '.join(texture_failing)}: the "
            "correction aims at colour alone; a texture this far off asks for other effect "
            "toners (match the target again)"
        )
    return notes


def _weighing_report(weighing, forward, mode: str, fractions: dict[str, float]) -> dict:
    """The correction's grams on the scale, what rounding them costs, and the model behind
    the figures (named for the toners the can holds after it)."""
    from flakelab.match.forward import model_name_for

    held = weighing.grams if mode != "additions" else {*fractions, *weighing.grams}
    return {
        "add_g" if mode == "additions" else "recipe_g": weighing.grams,
        **rounding_costs(weighing),
        "model": model_name_for(forward, held),
        "model_id": forward.model_id,
    }


def _write_corrected(report: dict, can: dict[str, float], path: Path) -> None:
    """Write what the can holds after the additions, or the new recipe, as a recipe file."""
    from flakelab.io import write_recipe

    corrected = report.get("recipe_g") or {
        name: round(can.get(name, 0.0) + report["add_g"].get(name, 0.0), 6)
        for name in {**can, **report["add_g"]}
    }
    write_recipe(corrected, path)
    report["recipe_out"] = str(path)
    errors.print(f"wrote the corrected recipe to {path}", highlight=False)


def _weigh_correction(forward, correction, mode: str, can: dict[str, float], resolution: float):
    """The correction on the scale: additions to the mixed ``can``, or the new recipe for a
    can of its size (traces under one scale step left out), each toner rounded as the
    colour closest to the computed correction's asks."""
    from flakelab.match.recipe import weigh_additions, weigh_whole_can

    if mode == "additions":
        return weigh_additions(forward, can, correction.added, resolution)
    return weigh_whole_can(forward, correction.fractions, _can_size(can, resolution), resolution)


def _what_is_left(
    grams: dict[str, float], left: str, resolution: float, library, recipe: Path
) -> dict[str, float]:
    """The mixed can after the spray-out took some of it: the recipe's toners in its
    proportions, ``left`` grams (or millilitres, by its toners' densities) in all."""
    from flakelab.match.recipe import recipe_grams

    mixed = sum(grams.values())
    shares = {name: g / mixed for name, g in grams.items() if g > 0}
    remaining = recipe_grams(left, resolution, library, shares, "--left")
    if remaining > mixed:
        raise FlakelabError(
            f"--left: {remaining:g} g is more than the {mixed:g} g the recipe mixed ({recipe})"
        )
    return {name: share * remaining for name, share in shares.items()}


def _most_g(most: str, can: dict[str, float], resolution: float, library) -> float:
    """``--most`` in grams: by volume, at the density of the ``can``'s recipe."""
    from flakelab.match.recipe import recipe_grams

    return recipe_grams(
        most, resolution, library, {n: g for n, g in can.items() if g > 0}, "--most"
    )


def _room_in_can(most_g: float, can: dict[str, float], resolution: float, extra: int) -> float:
    """The share of the mixed ``can`` its additions may come to together under ``--most``: a
    step of the scale kept for each toner's rounding (the recipe's and the one that may join
    it, with ``extra`` toners tried)."""
    from flakelab.match.recipe import room_for_additions

    toners = sum(g > 0 for g in can.values()) + (extra > 0)
    return room_for_additions(most_g, sum(can.values()), toners, resolution)


def _can_size(can: dict[str, float], resolution: float) -> float:
    """The mixed ``can``'s size in grams, to the scale's resolution, checked that the scale
    weighs it."""
    from flakelab.match.recipe import check_scale, to_scale

    quantity = to_scale(sum(can.values()), resolution)
    check_scale(quantity, resolution)
    return quantity


def _plot_correction(target, sprayed, target_lab, samples: dict, left_out, forward, tolerance,
                     path: Path) -> None:  # fmt: skip
    """The spray-out as measured and as the correction expects it (``samples``, CIELAB at the
    model's geometries), against the target; then at the target's other geometries, where
    ``left_out`` expects it. The measured spray-out's texture shares join the share panel
    (the correction aims at colour alone)."""
    from flakelab.core.colorimetry import reflectance_to_Lab

    others = left_out.geometries if left_out else ()
    there = (
        [reflectance_to_Lab(sprayed.storage_spectra(list(others))), left_out.lab] if others else []
    )
    chart = with_left_out(target, list(forward.geometries), target_lab, samples, others, there)
    apart = f"not in the correction; expected by {left_out.model_id}" if left_out else ""
    # the model that made the correction: the library's physics, where the ensemble was unsure
    title = f"{sprayed.sample} against {target.sample}: the correction by {forward.model_id}"
    measured = {next(iter(samples)): tolerance.texture_share(target.texture, sprayed.texture)}
    draw_differences(*chart, tolerance, path, title, apart=len(forward.geometries),
                     apart_label=apart, texture=measured)  # fmt: skip


def _left_out_correction_table(left_out: dict) -> Table:
    """The spray-out and the correction's expected result at the geometries it left out."""
    names = list(left_out["geometries"])
    table = Table(box=box.SIMPLE, show_header=True)
    table.add_column("ΔE00")
    for name in names:
        table.add_column(name, justify="right")
    table.add_row("spray-out*", *(f"{v:.2f}" for v in left_out["sprayout_de00"]))
    table.add_row(
        "expected*",
        *(
            f"{row['dE00']:.2f}" if row["pass"] else f"[red]{row['dE00']:.2f}[/]"
            for row in left_out["geometries"].values()
        ),
    )
    return table


def _print_correction(report: dict) -> None:
    """The correction as a colorist reads it: what to weigh, then the colour before/after."""
    grams = report.get("add_g", report.get("recipe_g", {}))
    title = "add to the mixed can" if report["mode"] == "additions" else "mix afresh"
    if "left_g" in report:
        title += f" ({report['left_g']:g} g left in it)"
    table = Table(title=f"Correction: {title}", box=box.SIMPLE_HEAD)
    table.add_column("toner")
    table.add_column("g", justify="right")
    for toner, g in grams.items():
        label = f"{toner} [yellow](new to the recipe)[/]" if toner == report["new_toner"] else toner
        table.add_row(label, f"{g:.1f}")
    if not grams:
        table.add_row("[dim]nothing to add on this scale[/]", "")
    geo = Table(box=box.SIMPLE, show_header=True)
    geo.add_column("ΔE00")
    for name in report["geometries"]:
        geo.add_column(name, justify="right")
    failing = set(report["sprayout_failing"])
    geo.add_row(
        "spray-out",
        *(
            f"[red]{v:.2f}[/]" if g in failing else f"{v:.2f}"
            for g, v in zip(report["geometries"], report["before_de00"], strict=True)
        ),
    )
    still = set(report["expected_failing"])
    geo.add_row(
        "expected",
        *(
            f"[red]{v:.2f}[/]" if g in still else f"{v:.2f}"
            for g, v in zip(report["geometries"], report["expected_de00"], strict=True)
        ),
    )
    if spread := report["expected_model_spread"]:
        geo.add_row("± model", *(f"{v:.2f}" for v in spread))
    console.print(table)
    console.print(geo)
    if left_out := report.get("left_out"):
        console.print(_left_out_correction_table(left_out))
        console.print(
            "* not corrected for: the target's other geometries; expected there: the spray-out "
            f"as measured, moved by what the model {left_out['model_id']} predicts the "
            "correction does",
            highlight=False,
        )
    application = report["spray_application"]
    if application is None:
        assumed = f"{report['offset_weight']:.0%} of the spray-out's offset from the model persists"
    else:
        film, spread = application.values()
        assumed = (
            "the spray-out's offset from the model persists, except what this spray's "
            f"application explains (film build {film:+.1%}, flake spread {spread:+.1%})"
        )
        if report["habits"]:
            assumed += " beyond the shop's habits, which persist"
    console.print(f"model: {report['model']}; {rounding_text(report)}", highlight=False)
    console.print(f"expected ΔE00 assumes {assumed}", highlight=False)
    if report["sprayout_metamerism_index_max"]:  # none against spectra recovered from L*a*b*
        console.print(
            metamerism_text(
                report["sprayout_metamerism_index_max"], report["sprayout_metamer"], "spray-out "
            )
            + f"; expected {metamerism_values(report['expected_metamerism_index_max'])}",
            highlight=False,
        )
    print_notes(report["notes"])
    if report["expected_model_spread"]:
        console.print(MODEL_SPREAD_LEGEND, highlight=False)
