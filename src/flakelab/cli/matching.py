"""CLI: the main job — match a target, weigh the recipe, correct after a spray-out."""

from __future__ import annotations

import json
from dataclasses import asdict
from datetime import datetime
from pathlib import Path
from typing import Annotated

import typer
from rich import box
from rich.table import Table

from flakelab.cli.common import (
    JsonOption,
    LightsOption,
    PlotOption,
    SampleOption,
    SprayedSampleOption,
    ToleranceOption,
    check_figure_file,
    check_output_file,
    console,
    draw_differences,
    draw_side_by_side,
    errors,
    lights_option,
    progress_bar,
    read_sample,
    texture_table,
)
from flakelab.cli.sources import (
    DatabaseOption,
    InstrumentOption,
    LibraryOption,
    current_forward,
    learned_forward,
    recipe_fractions,
    since_option,
)
from flakelab.core.geometry import DEFAULT_INSTRUMENT
from flakelab.core.tolerance import failing_geometries, failures
from flakelab.errors import FlakelabError
from flakelab.match.settings import EXTRA_TONERS_TRIED, MODEL_SD, MatchSettings

MetamerismOption = Annotated[
    float,
    typer.Option(
        min=0.0,
        help="Weight of the metamerism index against the target (ΔE00 after ISO 18314-4's "
        "correction, under the test lights) in the objective: steers recipes to the car's own "
        "pigments (0: colour under D65/10 alone).",
    ),
]

RecipeOutOption = Annotated[
    Path | None,
    typer.Option(
        "--recipe-out",
        help="Write the recipe as a file {toner: grams}, as 'correct --recipe' and "
        "'cases record --recipe' read it.",
    ),
]
QuantityOption = Annotated[
    str,
    typer.Option(help="Can size to weigh, e.g. 250g, 0.5kg, 1lb (to the scale's nearest step)."),
]
ResolutionOption = Annotated[float, typer.Option(help="Scale resolution in grams.")]
ModelOption = Annotated[
    Path | None,
    typer.Option(
        "--model",
        "-m",
        help="Model file, or a registered version NAME:VERSION (default: current for the "
        "instrument).",
    ),
]
PhysicsOption = Annotated[
    bool,
    typer.Option(
        "--physics",
        help="Predict with the library's physics model alone (colour and texture), not a "
        "learned model: no cases needed and every toner known, but a match takes ten to twenty "
        "times as long.",
    ),
]
HabitsOption = Annotated[
    Path | None,
    typer.Option(
        "--habits",
        help="The shop's habits file ('flakelab cases habits --out'): recipes are aimed off "
        "for its film build, flake alignment and instrument.",
    ),
]
HabitsShopOption = Annotated[
    str | None,
    typer.Option(
        "--shop",
        help="Aim recipes off for this shop's habits as stored in the database "
        "('flakelab cases habits --shop NAME --save').",
    ),
]


def _setup(
    library: Path | None,
    instrument: str,
    model: Path | None,
    database: str | None,
    physics: bool = False,
):
    """The library, the matcher's forward model (learned, or with ``physics`` the library's
    physics alone) and the library's effect-toner mask."""
    from flakelab.match.models import effect_mask

    if physics:
        from flakelab.core.geometry import instrument_geometries
        from flakelab.io import read_library
        from flakelab.match.forward import PhysicsForward

        if model is not None:
            raise FlakelabError("--physics and --model: expected one of them, not both")
        lib = read_library(library)
        forward = PhysicsForward(lib, instrument_geometries(instrument))
    else:
        lib, forward = learned_forward(library, instrument, model, database)
    return lib, forward, effect_mask(lib, forward.toners)


def habits_for(path: Path | None, shop: str | None, database: str | None, forward):
    """The shop's habits from the file ``path`` or stored in the database for ``shop`` (None:
    none), with a warning when they were measured against another model than ``forward``, or
    over a change of the shop's habits."""
    if path is None and shop is None:
        return None
    if path is not None and shop is not None:
        raise FlakelabError("--habits and --shop: expected one of them, not both")
    from flakelab.cases.database import open_database
    from flakelab.match.habits import read_habits, stored_habits

    found = (
        read_habits(path)
        if path
        else stored_habits(open_database(database, must_exist=True), shop, forward.model_id)
    )
    if found.model != forward.model_id:
        errors.print(
            f"[yellow]warning:[/] {path or shop}: habits measured against "
            f"{found.model or 'an unnamed model'}, not {forward.model_id}: read them again "
            "against this model",
            highlight=False,
        )
    if found.changed_since:
        since = datetime.fromisoformat(found.changed_since)
        errors.print(
            f"[yellow]warning:[/] {path or shop}: habits read over a change of the shop's "
            f"habits, from about {since:%Y-%m-%d %H:%M}: read them again from the recent "
            f"cases (flakelab cases habits {since_option(since)})",
            highlight=False,
        )
    return found


def spectra_for_model(path, reading, forward):
    """A reading's spectra at the model's geometries (:func:`~flakelab.match.search.
    target_spectra`); a reading that lacks some is named with its file."""
    from flakelab.match.search import MatchError, target_spectra

    try:
        return target_spectra(reading, forward)
    except MatchError as error:
        raise FlakelabError(f"{path}: sample {error}") from None


def match_command(
    target: Annotated[
        str | None,
        typer.Argument(help="Target measurement file, or 'evaluate' for the evaluation harness."),
    ] = None,
    example: Annotated[
        bool, typer.Option("--example", help="Match the shipped example target.")
    ] = False,
    sample: SampleOption = None,
    library: LibraryOption = None,
    quantity: QuantityOption = "250g",
    resolution: ResolutionOption = 0.1,
    tolerance: Annotated[
        str | None,
        typer.Option(
            "--tolerance",
            "-t",
            help="Preset (refinish, de00-1.0, components) or TOML/JSON file; the search aims at "
            "it (default: refinish; evaluate: de00-1.0, ΔE00 ≤ 1.0 at every geometry).",
        ),
    ] = None,
    candidates: Annotated[int, typer.Option(min=1, max=20, help="Candidates to show.")] = 3,
    instrument: InstrumentOption = DEFAULT_INSTRUMENT,
    model: ModelOption = None,
    physics: PhysicsOption = False,
    database: DatabaseOption = None,
    targets: Annotated[int, typer.Option(min=1, help="evaluate: hidden targets.")] = 200,
    novel_targets: Annotated[
        int, typer.Option(min=0, help="evaluate: targets with a new toner.")
    ] = 50,
    world: Annotated[
        str,
        typer.Option(
            help="evaluate: shop (batches and application vary), standard-pigments (no batch "
            "differs) or controlled (only the instrument's reading varies)."
        ),
    ] = "shop",
    seed: Annotated[
        int, typer.Option(min=0, help="Seed (search restarts; evaluate: the world).")
    ] = 0,
    model_risk: Annotated[
        float,
        typer.Option(
            min=0.0,
            help="Weight of the model ensemble's disagreement (ΔE94) in the search's objective: "
            "steers recipes to where the learned model's networks agree (0: the closest "
            "predicted match, wherever the model is unsure).",
        ),
    ] = MatchSettings.model_risk,
    metamerism: MetamerismOption = MatchSettings.metamerism,
    lights: LightsOption = None,
    solid_travel: Annotated[
        float,
        typer.Option(
            min=0.0,
            help="A target without texture readings whose colour travels less than this "
            "(ΔE00, the largest between two of its geometries) is a solid, matched with "
            "pigments alone (0: never).",
        ),
    ] = MatchSettings.solid_travel,
    target_texture: Annotated[
        bool,
        typer.Option(
            "--target-texture/--no-target-texture",
            help="evaluate: the matcher reads each target's texture readings (--no-target-"
            "texture: as from a file without them; the sprays are judged as ever).",
        ),
    ] = True,
    resprays: Annotated[
        int,
        typer.Option(
            min=0,
            max=1000,
            help="evaluate: spray each first recipe and hidden formula this many times more, "
            "and report the chance a spray passes (first_shot_chance, oracle_chance): the "
            "one spray's luck averaged out.",
        ),
    ] = 0,
    weighed: Annotated[
        bool,
        typer.Option(
            "--weighed",
            help="evaluate: spray each recipe as weighed for --quantity on a scale of "
            "--resolution, as a shop mixes it (default: as computed).",
        ),
    ] = False,
    habits: HabitsOption = None,
    shop: HabitsShopOption = None,
    render: Annotated[
        Path | None,
        typer.Option(
            help="Also draw the target and each candidate as curved panels side by side, as "
            "predicted (PNG, PDF or SVG).",
        ),
    ] = None,
    plot: PlotOption = None,
    recipe_out: RecipeOutOption = None,
    pick: Annotated[
        int, typer.Option(min=1, max=20, help="The candidate --recipe-out writes.")
    ] = 1,
    json_output: JsonOption = False,
) -> None:
    """Match a target: ranked recipes, grams for the can, pass/fail at every angle.

    Each candidate comes with its predicted ΔL*, ΔC*, ΔH* and ΔE00 per geometry
    and the model that produced them.
    'flakelab match evaluate' runs the evaluation harness."""
    from flakelab.data import example_path
    from flakelab.io import read_tolerance
    from flakelab.match.search import match

    if target == "evaluate":
        if render is not None or plot is not None or recipe_out is not None:
            raise FlakelabError(
                "--render, --plot, --recipe-out: for the candidates of one target, not the harness"
            )
        _evaluate(
            library=library,
            instrument=instrument,
            model=model,
            physics=physics,
            database=database,
            targets=targets,
            novel_targets=novel_targets,
            seed=seed,
            world_name=world,
            habits_file=habits,
            shop=shop,
            # the harness's own candidates and seeds
            settings=MatchSettings(
                model_risk=model_risk,
                metamerism=metamerism,
                lights=lights_option(lights),
                solid_travel=solid_travel,
            ),
            tolerance=tolerance,
            scale=_scale(quantity, resolution) if weighed else None,
            target_texture=target_texture,
            resprays=resprays,
            json_output=json_output,
        )
        return
    if weighed or not target_texture or resprays:
        raise FlakelabError(
            "--weighed, --no-target-texture, --resprays: for the harness (flakelab match evaluate)"
        )
    if target is not None and example:
        # "--quantity 250 g" leaves its "g" here as the target
        raise FlakelabError(
            f"expected a target file or --example, not both (got --example and {target!r})"
        )
    if target is None and not example:
        raise FlakelabError("expected a target file or --example")
    grams = _scale(quantity, resolution)[0]
    check_figure_file(render)
    check_figure_file(plot, "--plot")
    check_output_file(recipe_out, "--recipe-out")
    if pick > candidates:
        raise FlakelabError(f"--pick: expected one of the {candidates} candidates, got {pick}")
    lib, forward, effect = _setup(library, instrument, model, database, physics)
    path = example_path("target") if example else Path(target)
    measurement = read_sample(path, sample)
    spectra_for_model(path, measurement, forward)  # a reading the model cannot read: named
    tol = read_tolerance(tolerance or "refinish")
    result = match(
        measurement,
        forward,
        effect,
        tolerance=tol,
        settings=MatchSettings(
            candidates=candidates,
            seed=seed,
            model_risk=model_risk,
            metamerism=metamerism,
            lights=lights_option(lights),
            solid_travel=solid_travel,
        ),
        habits=habits_for(habits, shop, database, forward),
        library=lib,
    )
    report = result.to_dict()
    extra = []
    if habits is None and shop is None:  # aimed-off candidates: their offsets are per geometry
        other = _left_out_model(measurement, forward, lib, database, physics)
        if other is not None:
            from flakelab.match.crosscheck import predict_left_out

            extra = predict_left_out(result.candidates, measurement, forward, other, tol)
            for entry, left_out in zip(report["candidates"], extra, strict=True):
                entry["left_out"] = left_out.to_dict()
    for candidate, entry in zip(result.candidates, report["candidates"], strict=True):
        entry.update(_weighed(forward, candidate.fractions, grams, resolution))
    report["quantity_g"] = grams
    report["resolution_g"] = resolution
    if recipe_out is not None:
        _write_candidate(report, pick, recipe_out)
    if render is not None:
        _render_match(measurement.select(forward.geometries), result, render)
        report["rendering"] = str(render)
    if plot is not None:
        _plot_match(measurement, result, extra, tol, plot)
        report["plot"] = str(plot)
    if json_output:
        print(json.dumps(report, indent=2))
        return
    _print_match(report)


def _write_candidate(report: dict, pick: int, path: Path) -> None:
    """``--recipe-out``: candidate ``pick``'s weighed grams as a recipe file."""
    from flakelab.io import write_recipe

    if pick > len(report["candidates"]):
        raise FlakelabError(f"--pick: the search found {len(report['candidates'])} candidates")
    lines = report["candidates"][pick - 1]["weights_g"]
    write_recipe({ln["toner"]: ln["grams"] for ln in lines if ln["grams"] > 0}, path)
    report["recipe_out"] = {"file": str(path), "candidate": pick}
    errors.print(f"wrote candidate #{pick}'s recipe to {path}", highlight=False)


def _left_out_model(measurement, forward, library, database: str | None, physics: bool):
    """A model that predicts geometries of ``measurement`` that ``forward`` left out: the
    current model (with ``physics``, the library's physics) of the largest geometry set the
    target reads in full. None when there is none."""
    from flakelab.core.geometry import INSTRUMENT_GEOMETRIES, instrument_geometries
    from flakelab.match.search import unused_geometries
    from flakelab.models.network import ModelError
    from flakelab.models.registry import SHIPPED

    unused = set(unused_geometries(measurement, forward))
    read = set(measurement.geometry_names)
    sets = [
        name
        for name in (INSTRUMENT_GEOMETRIES if physics else SHIPPED)
        if unused & set(INSTRUMENT_GEOMETRIES[name]) and read >= set(INSTRUMENT_GEOMETRIES[name])
    ]
    if not sets:
        return None
    fullest = max(sets, key=lambda name: len(INSTRUMENT_GEOMETRIES[name]))
    if physics:
        from flakelab.match.forward import PhysicsForward

        return PhysicsForward(library, instrument_geometries(fullest))
    try:
        return current_forward(library, fullest, None, database)
    except ModelError:  # the user's library is not the one that model knows: no cross-check
        return None


def _render_match(target, result, path: Path) -> None:
    """The target as measured (at the model's geometries, as the candidates) above each
    candidate as its model predicts it, curved panels in one texture draw."""
    readings = [target] + [c.as_measurement(f"#{k}") for k, c in enumerate(result.candidates, 1)]
    labels = ["target"] + [
        f"#{k}  {'PASS' if c.passes else 'FAIL'}  max ΔE00 {c.de00.max():.2f}"
        for k, c in enumerate(result.candidates, 1)
    ]
    draw_side_by_side(readings, labels, path, f"{result.target}: target and candidates (predicted)")


def _plot_match(target, result, left_out: list, tolerance, path: Path) -> None:
    """Each candidate's predicted difference from the target at the searched geometries, then
    at the target's others as the model that predicts them says (``left_out``)."""
    if not result.candidates:
        raise FlakelabError("--plot: the search found no candidate to draw")
    samples = {f"#{k}": c.lab for k, c in enumerate(result.candidates, 1)}
    chart = _with_left_out(
        target, list(result.candidates[0].geometries), result.candidates[0].target_lab, samples,
        left_out and left_out[0].geometries, [x.lab for x in left_out],
    )  # fmt: skip
    apart = f"not searched; predicted by {left_out[0].model_id}" if left_out else ""
    texture = {f"#{k}": c.texture_share for k, c in enumerate(result.candidates, 1)}
    draw_differences(*chart, tolerance, path, f"{result.target}: candidates as predicted",
                     apart=len(result.candidates[0].geometries), apart_label=apart,
                     texture=texture)  # fmt: skip


def _with_left_out(target, names: list, reference_lab, samples: dict, others, there: list):
    """A chart's geometries, reference and samples (label → CIELAB ``[G, 3]``), followed by
    the target's ``others`` geometries, where each sample has its CIELAB in ``there`` (in the
    samples' order) and the reference is the target as read."""
    import numpy as np

    from flakelab.core.colorimetry import reflectance_to_Lab

    if not others:
        return names, reference_lab, samples
    target_there = reflectance_to_Lab(target.storage_spectra(list(others)))
    extended = {
        label: np.concatenate([lab, more])
        for (label, lab), more in zip(samples.items(), there, strict=True)
    }
    return names + list(others), np.concatenate([reference_lab, target_there]), extended


def _print_match(report: dict) -> None:
    console.print(
        f"[bold]{report['target']}[/] — {len(report['candidates'])} candidates "
        f"({report['subsets_tried']} toner sets optimised in {report['seconds']:.2f} s, "
        f"tolerance {report['tolerance']})"
    )
    for rank, c in enumerate(report["candidates"], start=1):
        failing = failures(c["failing_geometries"], c["failing_texture"])
        verdict = "[green]PASS[/]" if c["passes"] else "[red]FAIL[/] at " + ", ".join(failing)
        header = (
            f"#{rank}  max ΔE00 {c['de00_max']:.2f}  mean {c['de00_mean']:.2f}  {verdict}"
            f"  (at worst {c['limit_share_max']:.0%} of the tolerance)"
            + ("  aimed off for the shop's habits" if c.get("aimed_off") else "")
        )
        table = _weights_table(None, c["weights_g"])
        geo = Table(box=box.SIMPLE, show_header=True)
        keys = ["L", "a", "b", "dL", "dC", "dH", "dE00"]
        columns = ["geometry", "L*", "a*", "b*", "ΔL*", "ΔC*", "ΔH*", "ΔE00"]
        if all("model_spread" in v for v in c["geometries"].values()):
            keys.append("model_spread")
            columns.append("± model")  # the ensemble's members' disagreement
        for column in columns:
            geo.add_column(column, justify="right")
        for g, v in c["geometries"].items():
            geo.add_row(g, *(f"{v[k]:.2f}" for k in keys))
        left_out = c.get("left_out")
        if left_out:  # predicted by another model, not searched: set apart, marked *
            geo.add_section()
            for g, v in left_out["geometries"].items():
                cells = [f"{v[k]:.2f}" for k in keys if k != "model_spread"]
                cells[-1] = cells[-1] if v["pass"] else f"[red]{cells[-1]}[/]"
                geo.add_row(f"{g} *", *cells, *([""] if "model_spread" in keys else []))
        console.print(header, highlight=False)
        console.print(table)
        console.print(geo)
        if left_out:
            verdict = (
                "pass"
                if left_out["passes"]
                else "fail at " + ", ".join(left_out["failing_geometries"])
            )
            console.print(
                f"* not searched: the target's other geometries, as the model "
                f"{left_out['model_id']} predicts them: {verdict}",
                highlight=False,
            )
        if c["texture_delta"]:
            limits = {k: report["texture_limits"][k] for k in c["texture_limit_share"]}
            console.print(
                texture_table(
                    "predicted − target", c["texture_delta"], limits, c["failing_texture"]
                )
            )
        extra = f"model: {c['model']}; {_rounding_text(c)}"
        if c["novel_toners"]:
            extra += f"; uses new toners {', '.join(c['novel_toners'])} (physics scaling)"
        console.print(extra, highlight=False)
        console.print(_metamerism_text(c["metamerism_index_max"], c["metamer"]), highlight=False)
    for note in report["notes"]:
        console.print(f"[yellow]note:[/] {note}", highlight=False)
    if any("model_spread" in v for c in report["candidates"] for v in c["geometries"].values()):
        console.print(
            "± model: how far the networks of the model's ensemble disagree (ΔE00 about their "
            "mean); where it is large, the prediction deserves less trust.",
            highlight=False,
        )


def _evaluate(
    *,
    library,
    instrument,
    model,
    physics,
    database,
    targets,
    novel_targets,
    seed,
    world_name,
    habits_file,
    shop,
    settings,
    tolerance,
    scale,
    target_texture,
    resprays,
    json_output,
):
    from flakelab.core.difference import METAMERISM_ILLUMINANTS
    from flakelab.io import read_tolerance
    from flakelab.match.evaluate import evaluate_matching, harness_world
    from flakelab.match.objective import OBJECTIVE_DEFAULT

    tol = read_tolerance(tolerance or OBJECTIVE_DEFAULT)

    lib, forward, effect = _setup(library, instrument, model, database, physics)
    world = harness_world(lib, instrument, world_name)
    habits = habits_for(habits_file, shop, database, forward)
    with progress_bar(json_output) as bar:
        task = bar.add_task("matching hidden targets", total=targets + novel_targets)
        report = evaluate_matching(
            world,
            forward,
            effect,
            targets=targets,
            seed=seed,
            novel=forward.novel,
            novel_targets=novel_targets if forward.novel else 0,
            habits=habits,
            settings=settings,
            tolerance=tol,
            scale=scale,
            target_texture=target_texture,
            resprays=resprays,
            progress=lambda: bar.advance(task),
        )
    report["model"] = forward.name
    report["model_risk"] = settings.model_risk
    report["metamerism_weight"] = settings.metamerism
    report["metamerism_lights"] = list(settings.lights or METAMERISM_ILLUMINANTS)
    report["solid_travel"] = settings.solid_travel
    report["world"] = world_name
    report["habits"] = habits and habits.report()
    if json_output:
        print(json.dumps(report, indent=2))
        return
    console.print_json(json.dumps(report))


def correct_command(
    target: Annotated[Path, typer.Argument(help="Target measurement file.")],
    recipe: Annotated[Path, typer.Option("--recipe", "-r", help="Recipe JSON {toner: grams}.")],
    sprayed: Annotated[Path, typer.Option("--sprayed", help="Measurement of the spray-out.")],
    sample: SampleOption = None,
    sprayed_sample: SprayedSampleOption = None,
    mode: Annotated[
        str, typer.Option(help="additions (can already mixed) or reformulate.")
    ] = "additions",
    library: LibraryOption = None,
    instrument: InstrumentOption = DEFAULT_INSTRUMENT,
    model: ModelOption = None,
    physics: PhysicsOption = False,
    database: DatabaseOption = None,
    resolution: ResolutionOption = 0.1,
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
        int, typer.Option(help="Toners outside the recipe tried as one addition (0: none).")
    ] = EXTRA_TONERS_TRIED,
    model_sd: Annotated[
        float,
        typer.Option(
            min=0.0,
            help="Widen the prior of the offset that persists by this many times the model "
            "ensemble's disagreement at each geometry (0: one prior everywhere).",
        ),
    ] = MODEL_SD,
    tolerance: ToleranceOption = "refinish",
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
    from flakelab.core.difference import is_metamer, metamerism_indices, worst_per_light
    from flakelab.io import read_recipe, read_tolerance, write_recipe
    from flakelab.match.correction import correct, metamerism_note, mismatch_note, unreached_note
    from flakelab.match.crosscheck import expected_left_out
    from flakelab.match.search import left_out_note, unused_geometries

    tol = read_tolerance(tolerance)
    test_lights = lights_option(lights)
    check_output_file(recipe_out, "--recipe-out")
    check_figure_file(plot, "--plot")
    grams = read_recipe(recipe)
    _can_size(grams, resolution)  # before the model: a can the scale cannot weigh is a typo
    lib, forward, _ = _setup(library, instrument, model, database, physics)
    x0 = recipe_fractions(lib, grams, recipe)
    target_reading = read_sample(target, sample)
    sprayed_reading = read_sample(sprayed, sprayed_sample, "--sprayed-sample")
    target_R, _, _ = spectra_for_model(target, target_reading, forward)
    sprayed_R, _, _ = spectra_for_model(sprayed, sprayed_reading, forward)
    fractions = {n: float(v) for n, v in zip(lib.names, x0, strict=True) if v > 0}
    if extra_toners < 0:
        raise FlakelabError(f"--extra-toners: expected 0 or more, got {extra_toners}")
    shop_habits = habits_for(habits, shop, database, forward)
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
    )
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
        "notes": left_out_note(unused_geometries(target_reading, forward), forward, "correction"),
    }
    if not failing:
        report["notes"].append(
            f"the spray-out already passes {tol.name} at every geometry: the correction is "
            "optional, a move toward the target's centre"
        )
    if note := mismatch_note(forward, fractions, sprayed_R, shop_habits, lib):
        report["notes"].append(note)
    if texture_failing:
        report["notes"].append(
            f"the spray-out's texture fails {tol.name} at {', '.join(texture_failing)}: the "
            "correction aims at colour alone; a texture this far off asks for other effect "
            "toners (match the target again)"
        )
    weighing = _weigh_correction(forward, correction, mode, grams, resolution)
    report["add_g" if mode == "additions" else "recipe_g"] = weighing.grams
    report.update(_rounding_costs(weighing))
    expected_lab = correction.expected_lab + weighing.lab_shift  # as weighed, not as computed
    if recipe_out is not None:  # what the can holds after the additions, or the new recipe
        corrected = report.get("recipe_g") or {
            name: round(grams.get(name, 0.0) + report["add_g"].get(name, 0.0), 6)
            for name in {**grams, **report["add_g"]}
        }
        write_recipe(corrected, recipe_out)
        report["recipe_out"] = str(recipe_out)
        errors.print(f"wrote the corrected recipe to {recipe_out}", highlight=False)
    report["new_toner"] = correction.new_toner
    report["offset_weight"] = offset_weight
    report["model_sd"] = model_sd
    report["spray_application"] = correction.application and {
        name: round(value, 4) for name, value in correction.application.items()
    }
    report["habits"] = shop_habits and shop_habits.report()
    expected, _, expected_passed = tol.judge(forward.geometries, target_lab, expected_lab)
    report["expected_de00"] = expected.round(3).tolist()
    report["expected_failing"] = failing_geometries(forward.geometries, expected_passed)
    if failing and (note := unreached_note(tol, report["expected_failing"], expected, mode)):
        report["notes"].append(note)
    report["metamerism_weight"] = metamerism
    sprayed_metamerism = metamerism_indices(target_R, sprayed_R, tests=test_lights)
    report["sprayout_metamerism_index_max"] = worst_per_light(sprayed_metamerism)
    report["sprayout_metamer"] = is_metamer(sprayed_metamerism)
    report["expected_metamerism_index_max"] = worst_per_light(correction.metamerism)
    if note := metamerism_note(sprayed_metamerism, correction.metamerism):
        report["notes"].append(note)
    report["geometries"] = list(forward.geometries)
    other = (
        None if shop_habits else _left_out_model(target_reading, forward, lib, database, physics)
    )
    found = other and expected_left_out(
        target_reading, sprayed_reading, fractions, correction.fractions, forward, other, tol
    )
    if found:
        sprayed_there, expected_there = found
        report["left_out"] = expected_there.to_dict() | {
            "sprayout_de00": sprayed_there.round(3).tolist()
        }
    if plot is not None:
        samples = {
            "spray-out (measured)": reflectance_to_Lab(sprayed_R),
            "expected after the correction": expected_lab,
        }
        _plot_correction(target_reading, sprayed_reading, target_lab, samples,
                         found and found[1], forward, tol, plot)  # fmt: skip
        report["plot"] = str(plot)
    if json_output:
        print(json.dumps(report, indent=2))
        return
    _print_correction(report)


def _weigh_correction(forward, correction, mode: str, can: dict[str, float], resolution: float):
    """The correction on the scale: additions to the mixed ``can``, or the new recipe for a
    can of its size (traces under one scale step left out), each toner rounded as the
    colour closest to the computed correction's asks."""
    from flakelab.match.recipe import weigh_additions, weigh_whole_can

    if mode == "additions":
        return weigh_additions(forward, can, correction.added, resolution)
    return weigh_whole_can(forward, correction.fractions, _can_size(can, resolution), resolution)


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
    chart = _with_left_out(target, list(forward.geometries), target_lab, samples, others, there)
    apart = f"not in the correction; expected by {left_out.model_id}" if left_out else ""
    title = f"{sprayed.sample} against {target.sample}: the correction"
    measured = {next(iter(samples)): tolerance.texture_share(target.texture, sprayed.texture)}
    draw_differences(*chart, tolerance, path, title, apart=len(forward.geometries),
                     apart_label=apart, texture=measured)  # fmt: skip


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

    grams = read_recipe(recipe)
    can = _scale(quantity, resolution)[0]
    check_output_file(recipe_out, "--recipe-out")
    lib, forward, _ = _setup(library, instrument, model, database, physics)
    fractions = recipe_fractions(lib, grams, recipe)
    shares = {n: float(v) for n, v in zip(lib.names, fractions, strict=True) if v > 0}
    report = {
        "recipe": str(recipe),
        "quantity_g": can,
        "resolution_g": resolution,
        **_weighed(forward, shares, can, resolution),
        "model": forward.name,
    }
    if recipe_out is not None:
        write_recipe({ln["toner"]: ln["grams"] for ln in report["weights_g"]}, recipe_out)
        report["recipe_out"] = str(recipe_out)
        errors.print(f"wrote the weighed recipe to {recipe_out}", highlight=False)
    if json_output:
        print(json.dumps(report, indent=2))
        return
    console.print(_weights_table(f"{recipe.name} for {can:g} g", report["weights_g"]))
    console.print(f"{_rounding_text(report)} ({forward.name})", highlight=False)


def _scale(quantity: str, resolution: float) -> tuple[float, float]:
    """The can in grams and the scale's resolution, checked that the scale can weigh it."""
    from flakelab.match.recipe import can_on_scale

    return can_on_scale(quantity, resolution), resolution


def _weighed(forward, fractions: dict[str, float], quantity_g: float, resolution: float) -> dict:
    """The report's weights for a can: grams in pouring order, rounded to the scale as the
    colour closest to the exact recipe's asks, and what that and the nearest grams cost."""
    from flakelab.match.recipe import weigh_for_colour

    weighing = weigh_for_colour(forward, fractions, quantity_g, resolution)
    return {"weights_g": [asdict(ln) for ln in weighing.lines], **_rounding_costs(weighing)}


def _rounding_costs(weighing) -> dict[str, float]:
    """What rounding to the scale costs, as weighed and as the nearest grams would."""
    return {
        "rounding_de00": weighing.rounding_de00,
        "rounding_de00_nearest": weighing.nearest_de00,
    }


def _metamerism_values(worst: dict[str, float]) -> str:
    return "  ".join(f"{light} {value:.2f}" for light, value in worst.items())


def _metamerism_text(worst: dict[str, float], metamer: bool, label: str = "") -> str:
    """The worst geometry's metamerism index under each test illuminant, on one line; a
    ``metamer`` (as the report judged it, :func:`~flakelab.core.difference.is_metamer`)
    called one."""
    return (
        "metamerism index against the target (ISO 18314-4, ΔE00, worst geometry): "
        f"{label}{_metamerism_values(worst)}{' (a metamer)' if metamer else ''}"
    )


def _rounding_text(report: dict) -> str:
    text = f"rounding to the scale costs ΔE00 {report['rounding_de00']:.3f}"
    if report["rounding_de00_nearest"] > report["rounding_de00"] + 5e-4:
        text += f" (the nearest grams: {report['rounding_de00_nearest']:.3f})"
    return text


def _weights_table(title: str | None, weights_g: list[dict]) -> Table:
    """What to pour: grams per toner and the cumulative weight on the scale."""
    table = Table(title=title, box=box.SIMPLE_HEAVY, title_justify="left")
    table.add_column("toner")
    table.add_column("g", justify="right")
    table.add_column("cumul. g", justify="right")
    for line in weights_g:
        table.add_row(line["toner"], f"{line['grams']:.1f}", f"{line['cumulative']:.1f}")
    return table


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
    console.print(f"expected ΔE00 assumes {assumed}", highlight=False)
    console.print(
        _metamerism_text(
            report["sprayout_metamerism_index_max"], report["sprayout_metamer"], "spray-out "
        )
        + f"; expected {_metamerism_values(report['expected_metamerism_index_max'])}",
        highlight=False,
    )
    for note in report["notes"]:
        console.print(f"[yellow]note:[/] {note}", highlight=False)
