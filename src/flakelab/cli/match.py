"""CLI: the main job — match a target (and the evaluation harness, ``match evaluate``)."""

from __future__ import annotations

from collections import Counter
from dataclasses import replace
from pathlib import Path
from typing import Annotated

import typer
from rich import box
from rich.markup import escape
from rich.table import Table

from flakelab.cli.common import (
    COUNT_MAX,
    MODEL_SPREAD_LEGEND,
    WEIGHT_MAX,
    AverageOption,
    JsonOption,
    LightsOption,
    RenderLampsOption,
    SampleOption,
    add_readings_spread,
    check_figure_file,
    check_output_file,
    console,
    draw_differences,
    draw_side_by_side,
    errors,
    file_name_for,
    lights_option,
    names_read_in,
    print_notes,
    print_report,
    progress_bar,
    read_readings,
    render_lamps,
    seed_option,
    shares_text,
    stop_interrupted,
    texture_table,
)
from flakelab.cli.hiding import PrimersOption, workplace_primers
from flakelab.cli.lots import lots_report, shop_lots
from flakelab.cli.matcher import (
    HabitsOption,
    HabitsShopOption,
    MetamerismOption,
    ModelOption,
    PhysicsOption,
    QuantityOption,
    RecipeOutOption,
    ResolutionOption,
    WithoutOption,
    habits_for,
    left_out_model,
    matcher_setup,
    metamerism_text,
    spectra_for_model,
    with_left_out,
)
from flakelab.cli.sources import (
    DatabaseOption,
    InstrumentOption,
    LibraryOption,
    cases_hint_in,
    colour_code_spelled,
    database_option,
    workplace_shop,
)
from flakelab.cli.weigh import can_size, can_text, rounding_text, weighed_recipe, weights_table
from flakelab.core.defaults import DEFAULT_TOLERANCE
from flakelab.core.geometry import DEFAULT_INSTRUMENT
from flakelab.core.wording import counted, database_label, hidden_passwords
from flakelab.errors import FlakelabError
from flakelab.match.settings import (
    CAN_QUANTITY,
    PHYSICS_CHECK,
    SCALE_RESOLUTION_G,
    SOLID_TRAVEL_FROM,
    MatchSettings,
    physics_check_words,
)

NEAREST_OF_A_CODE = 5
"""The recorded cases ``match --colour-code`` shows where ``--nearest`` names no number (as
many as ``cases nearest`` shows)."""

VARIANT_CARS = 500
"""The newest cars of a code that ``match --colour-code`` groups into variants to name the
car's: bounds the pairwise comparison (500 cars of one code: 0.6-1.0 s,
``benchmarks/code_variants.py``)."""


def match_command(
    target: Annotated[
        str | None,
        typer.Argument(
            help="Target measurement file (- reads stdin), or 'evaluate' for the evaluation "
            "harness."
        ),
    ] = None,
    example: Annotated[
        bool, typer.Option("--example", help="Match the shipped example target.")
    ] = False,
    sample: SampleOption = None,
    average: AverageOption = False,
    all_samples: Annotated[
        bool,
        typer.Option(
            "--all",
            help="Match every sample of the file (a colour collection, a day's cars), shared "
            "out over --jobs processes: a table of each one's best recipe and verdict; --json "
            "gives each one's report.",
        ),
    ] = False,
    jobs: Annotated[
        int | None,
        typer.Option(
            "--jobs",
            "-j",
            max=COUNT_MAX,
            help="With --all: how many processes match the samples (each the same recipes as "
            "one process gives).",
            show_default="one per 4 samples, up to the cores",
        ),
    ] = None,
    recipe_dir: Annotated[
        Path | None,
        typer.Option(
            help="With --all: write each sample's best recipe, weighed for --quantity, into "
            "this folder as SAMPLE.json.",
        ),
    ] = None,
    library: LibraryOption = None,
    quantity: QuantityOption = CAN_QUANTITY,
    resolution: ResolutionOption = SCALE_RESOLUTION_G,
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
    targets: Annotated[
        int,
        typer.Option(
            min=0, max=COUNT_MAX, help="evaluate: hidden targets (0: those with a new toner alone)."
        ),
    ] = 200,
    novel_targets: Annotated[
        int, typer.Option(min=0, max=COUNT_MAX, help="evaluate: targets with a new toner.")
    ] = 50,
    world: Annotated[
        str,
        typer.Option(
            help="evaluate: shop (batches and application vary), standard-pigments (no batch "
            "differs) or controlled (only the instrument's reading varies)."
        ),
    ] = "shop",
    seed: Annotated[int, seed_option("Seed (search restarts; evaluate: the world).")] = 0,
    model_risk: Annotated[
        float,
        typer.Option(
            min=0.0,
            max=WEIGHT_MAX,
            help="Weight of the model ensemble's disagreement (ΔE94) in the search's objective: "
            "steers recipes to where the learned model's networks agree (0: the closest "
            "predicted match, wherever the model is unsure).",
        ),
    ] = MatchSettings.model_risk,
    physics_check: Annotated[
        bool,
        typer.Option(
            "--physics-check/--no-physics-check",
            help="Where the model's networks disagree on the best recipe by over "
            f"{physics_check_words()} (its cases too few), the library's physics refines "
            "the best recipes and predicts every candidate (--no-physics-check: the learned "
            "model's recipes and numbers throughout).",
        ),
    ] = True,
    metamerism: MetamerismOption = MatchSettings.metamerism,
    lights: LightsOption = None,
    without: WithoutOption = None,
    lots: Annotated[
        str | None,
        typer.Option(
            "--lots",
            help="The shop's toner-lot file ('flakelab lots calibrate' writes it): recipes are "
            "weighed for its tins' strengths and shades. evaluate: what the harness's shop "
            "knows of its tins: none (every tin taken at the standard), calibrated (each read "
            "from one panel against the model), referenced (against the paint maker's standard "
            "panel) or known.",
            show_default="the shop's tins stored in the database (--shop), else the standard",
        ),
    ] = None,
    nearest: Annotated[
        int,
        typer.Option(
            min=0,
            max=20,
            help="Also show the N recorded cases of --database (the shop's, with --shop) whose "
            "spray-outs lie closest to the target: panels measured, beside the candidates "
            "predicted ('cases nearest').",
        ),
    ] = 0,
    colour_code: Annotated[
        str | None,
        typer.Option(
            callback=colour_code_spelled,
            help="The car's colour code, as on its plate ('Toyota 1G3'): --nearest shows the "
            "recorded cases of this code alone (5 of them where --nearest is not given).",
        ),
    ] = None,
    max_pigments: Annotated[
        int,
        typer.Option(
            min=1,
            max=5,
            help="The most coloured toners (pigments) a recipe may hold, besides its effect "
            "toners: fewer are quicker to weigh and to correct.",
        ),
    ] = MatchSettings.max_pigments,
    solid_travel: Annotated[
        float,
        typer.Option(
            min=0.0,
            help="A target without texture readings whose colour travels less than this "
            f"(ΔE00, the largest between two of its geometries {SOLID_TRAVEL_FROM:g}° or more "
            "from specular, "
            "where a clearcoat's haze no longer lifts a solid's lightness) is a solid, "
            "matched with pigments alone (0: never).",
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
    colour_alone: Annotated[
        bool,
        typer.Option(
            "--colour-alone",
            help="evaluate: the shop's instrument exports L*a*b* alone: the matcher and the "
            "correction read each target and spray-out by its colour (D65/10), their spectra "
            "recovered from it, as from such a file; the sprays are judged as ever.",
        ),
    ] = False,
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
    lamps: RenderLampsOption = None,
    plot: Annotated[
        Path | None,
        typer.Option(
            "--plot",
            help="Also draw the candidates' multi-angle difference chart: ΔL*, ΔC*, ΔH* and the "
            "share of the tolerance used at every geometry. evaluate: each spray's worst share "
            "of the tolerance over the targets, and the first shots sprayed against predicted "
            "(PNG, PDF or SVG).",
        ),
    ] = None,
    recipe_out: RecipeOutOption = None,
    pick: Annotated[
        int, typer.Option(min=1, max=20, help="The candidate --recipe-out writes.")
    ] = 1,
    primers: PrimersOption = None,
    json_output: JsonOption = False,
) -> None:
    """Match a target: ranked recipes, grams for the can, pass/fail at every angle.

    Each candidate comes with its predicted ΔL*, ΔC*, ΔH* and ΔE00 per geometry
    and the model that produced them.
    'flakelab match evaluate' runs the evaluation harness."""
    from flakelab.cases.database import default_url
    from flakelab.data import example_path
    from flakelab.io import read_tolerance
    from flakelab.match.recipe import order_can
    from flakelab.match.search import match
    from flakelab.match.stock import toners_allowed

    search = MatchSettings(
        model_risk=model_risk,
        physics_check=PHYSICS_CHECK if physics_check else 0,
        metamerism=metamerism,
        lights=lights_option(lights),
        solid_travel=solid_travel,
        max_pigments=max_pigments,
        without=tuple(without or ()),
    )
    if target == "evaluate":
        if render or lamps or recipe_out or average or nearest or colour_code or primers:
            raise FlakelabError(
                "--render, --render-lamps, --recipe-out, --average, --nearest, --colour-code, "
                "--primers: for the candidates of one target, not the harness"
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
            settings=search,  # the harness's own candidates and seeds
            tolerance=tolerance,
            scale=order_can(quantity, resolution) if weighed else None,
            target_texture=target_texture,
            colour_alone=colour_alone,
            resprays=resprays,
            lots=lots or "none",
            plot=plot,
            json_output=json_output,
        )
        return
    if weighed or not target_texture or colour_alone or resprays:
        raise FlakelabError(
            "--weighed, --no-target-texture, --colour-alone, --resprays: for the harness "
            "(flakelab match evaluate)"
        )
    _check_target_options(target, example, all_samples, jobs, recipe_dir,
                          for_one=(sample, average, render, plot, recipe_out, nearest,
                                   colour_code))  # fmt: skip
    can = order_can(quantity, resolution)
    reads = {"TARGET": None if example else target, "--library": library, "--model": model,
             "--database": database, "--habits": habits, "--lots": lots,
             "--tolerance": tolerance, "--primers": primers}  # fmt: skip
    _check_output_options(render, plot, recipe_out, pick, candidates, reads)
    shop_primers, primer_notes, primers = workplace_primers(primers)  # before the wait
    over = {"primers": shop_primers, "primers_file": primers}
    lamps = render_lamps(lamps, render)
    shop, named = workplace_shop(shop)
    lib, forward, effect = matcher_setup(library, instrument, model, database, physics, shop)
    tins, forward, lot_notes = shop_lots(lots and Path(lots), lib, forward, shop, database)
    allowed = toners_allowed(forward.toners, without or ())
    can = can.for_toners(lib, [n for n, ok in zip(forward.toners, allowed, strict=True) if ok])
    path = example_path("target") if example else Path(target)
    tol = read_tolerance(tolerance or DEFAULT_TOLERANCE)
    shop_habits = habits_for(
        habits, shop, database, forward, named=named, with_tins=tins is not None
    )
    settings = replace(search, candidates=candidates, seed=seed)
    if all_samples:
        from flakelab.io import read_measurements

        keywords = dict(tolerance=tol, settings=settings, habits=shop_habits, library=lib)
        shop_tins = {"lots": tins and lots_report(tins), "notes": lot_notes + primer_notes}
        _match_every_sample(read_measurements(path), path, forward, effect, keywords, can,
                            recipe_dir, json_output, jobs, shop_tins,
                            taken=names_read_in(recipe_dir, reads), over=over)  # fmt: skip
        return
    measurement, readings = read_readings(path, sample, average)
    spectra = spectra_for_model(path, measurement, forward)[0]  # one it cannot read: named
    nearest = nearest or (NEAREST_OF_A_CODE if colour_code else 0)
    recorded = {}
    coded = None  # a code's cases, read whole once: its nearest recipes and its variants
    if nearest:  # before the search: a database that is not there is refused before the wait
        from flakelab.cases.nearest import recorded_recipes
        from flakelab.cli.cases import recorded_cases, recorded_nearest

        source = database or default_url()
        if colour_code:
            coded = recorded_cases(source, shop, forward.geometries, colour_code)
        found, searched = recorded_nearest(source, shop, forward.geometries, spectra, tol,
                                           nearest, measurement.texture, colour_code,
                                           cases=coded)  # fmt: skip
        recorded = recorded_recipes(found, forward.toners)
    result = match(
        measurement,
        forward,
        effect,
        tolerance=tol,
        settings=settings,
        habits=shop_habits,
        library=lib,
        starts=list(recorded.values()) or None,
    )
    report = result.to_dict()
    report["without"] = list(without or ())
    report["lots"] = tins and lots_report(tins)
    report["notes"] += lot_notes + primer_notes
    if nearest:
        _add_recorded_nearest(report, found, searched, database or default_url(), shop, forward,
                              colour_code)  # fmt: skip
        _mark_recorded(report, recorded, forward.toners)
    if coded:
        _add_car_variant(report, database or default_url(), coded, spectra, tol)
    if average:
        add_readings_spread(report, "target_readings", readings, measurement, tol)
    extra = []
    if shop_habits is None:  # aimed-off candidates: their offsets are per geometry
        other = left_out_model(measurement, forward, lib, database, physics, shop)
        extra = _add_predicted_left_out(report, result, measurement, forward, other, tol)
    _weigh_candidates(report, result.candidates, forward, can)
    _add_hiding(report, result.candidates, lib, forward.geometries, **over)
    if recipe_out is not None:
        _write_candidate(report, pick, recipe_out)
    if render is not None:
        _render_match(measurement.select(forward.geometries), result, render, lamps)
        report["rendering"] = str(render)
    if plot is not None:
        _plot_match(measurement, result, extra, tol, plot)
        report["plot"] = str(plot)
    if json_output:
        print_report(report)
        return
    _print_match(report, database_option(database))


def _check_target_options(target, example, all_samples, jobs, recipe_dir, for_one) -> None:
    """The target (a file or ``--example``) and the options of ``--all`` (``jobs``,
    ``recipe_dir``), refused before any file is read where they do not fit together;
    ``for_one`` holds the options of one target's match (--sample, --average, --render,
    --plot, --recipe-out, --nearest, --colour-code), which ``--all`` refuses."""
    if target is not None and example:
        # "--quantity 250 g" leaves its "g" here as the target
        raise FlakelabError(
            f"expected a target file or --example, not both (got --example and {target!r})"
        )
    if target is None and not example:
        raise FlakelabError("expected a target file or --example")
    if all_samples and any(for_one):
        raise FlakelabError(
            "--sample, --average, --render, --plot, --recipe-out, --nearest, --colour-code: for "
            "one target, not --all (--recipe-dir writes every sample's best recipe)"
        )
    if jobs is not None and not all_samples:
        raise FlakelabError("--jobs: for --all (one target is matched in one process)")
    if recipe_dir is not None and not all_samples:
        raise FlakelabError("--recipe-dir: for --all (--recipe-out writes one target's)")
    if recipe_dir is not None and not recipe_dir.is_dir():
        raise FlakelabError(f"--recipe-dir: {recipe_dir}: not a folder")


def _check_output_options(render, plot, recipe_out, pick: int, candidates: int,
                          reads: dict) -> None:  # fmt: skip
    """The files a match writes, refused before the search where they cannot be written or
    would replace a file it ``reads`` or another it writes, and ``--pick`` beyond the
    candidates shown."""
    check_figure_file(render, reads=reads)
    check_figure_file(plot, "--plot", reads=reads, writes={"--render": render})
    check_output_file(recipe_out, "--recipe-out", reads=reads,
                      writes={"--render": render, "--plot": plot})  # fmt: skip
    if pick > candidates:
        shown = counted(candidates, "candidate")
        raise FlakelabError(f"--pick: {pick} is more than the {shown} shown (--candidates)")


def _add_recorded_nearest(
    report: dict, found, searched: bool, database: str, shop, forward, colour_code
):
    """``--nearest``: the recorded cases ``found`` closest to the target, into ``report``, and a
    note where no case of the ``database`` (of ``shop``, of ``colour_code``) was read at the
    model's geometries."""
    from flakelab.cases.database import url_for

    report["recorded_nearest"] = [near.to_dict() for near in found]
    report["colour_code"] = colour_code
    if not searched:
        whose = (f" of shop {shop!r}" if shop else "") + (
            f" of colour code {colour_code!r}" if colour_code else ""
        )
        whose += cases_hint_in(database, shop, colour_code)
        report["notes"].append(
            f"--nearest: no recorded cases{whose} in {database_label(url_for(database))} read "
            f"at the model's geometries ({', '.join(forward.geometries)})"
        )


def _add_car_variant(report: dict, source: str, cases: list, spectra, tolerance) -> None:
    """``--colour-code``: the variant of the code among the shop's cars (``cases`` of the
    code read in ``source``, at the model's geometries; their newest :data:`VARIANT_CARS`,
    as ``cases variants`` groups them) whose centre car the target lies nearest, into
    ``report``."""
    from flakelab.cases.variants import colour_variants
    from flakelab.cli.codes import car_from_variants

    grouped = sorted(cases, key=lambda case: case.created_at)[-VARIANT_CARS:]
    found = colour_variants(grouped, tolerance)
    rows, k = car_from_variants(found, spectra, tolerance)
    report["colour_variant"] = {
        "cases": hidden_passwords(source),
        "variant": k + 1,
        "variants": len(found),
        "cars": len(found[k].cases),
        "cars_grouped": len(grouped),
        "cars_of_code": len(cases),
        "centre_case_id": found[k].centre.case_id,
        **rows[k],
    }


def _mark_recorded(report: dict, recorded: dict, toners) -> None:
    """Each candidate's ``recorded_case``: the case whose recipe (``recorded``, fractions over
    ``toners`` by case id) it is, as recorded (the search judges the nearest cases' recipes as
    they are, and refines each), else None; and a note that the search started from them."""
    recipes = {
        case_id: dict(zip(toners, x.tolist(), strict=True)) for case_id, x in recorded.items()
    }
    for c in report["candidates"]:
        c["recorded_case"] = next(
            (case_id for case_id, r in recipes.items() if _same_recipe(c["recipe"], r)), None
        )
    if recorded:
        report["notes"].append(
            f"the search also started from the recipes of the {counted(len(recorded), 'case')} "
            "recorded nearest the target, each judged as it is and refined"
        )


def _as_recorded(case_id: str | None) -> str:
    """A candidate's header's word on the recorded case whose recipe it is, if any."""
    if case_id is None:
        return ""
    from flakelab.cases.database import short_id

    return f"  as recorded in case {short_id(case_id)}"


def _same_recipe(shown: dict[str, float], recorded: dict[str, float]) -> bool:
    """Whether a candidate's ``shown`` recipe (fractions to 6 decimals) is ``recorded``."""
    toners = set(shown) | {t for t, v in recorded.items() if v > 0}
    return all(abs(shown.get(t, 0.0) - recorded.get(t, 0.0)) < 2e-6 for t in toners)


def _add_predicted_left_out(report: dict, result, measurement, forward, other, tolerance) -> list:
    """Each candidate as the ``other`` model predicts it at the target's geometries that
    ``forward`` leaves out, into its entry of ``report``; the predictions (none without
    such a model)."""
    if other is None:
        return []
    from flakelab.match.crosscheck import predict_left_out

    extra = predict_left_out(result.candidates, measurement, forward, other, tolerance)
    for entry, left_out in zip(report["candidates"], extra, strict=True):
        entry["left_out"] = left_out.to_dict()
    return extra


def _weigh_candidates(report: dict, candidates, forward, can) -> None:
    """Each candidate's grams for the ``can``, rounded for colour (by volume, each weighs its
    own), into its entry of ``report``, and the can into ``report``."""
    for candidate, entry in zip(candidates, report["candidates"], strict=True):
        grams = can.grams_for(candidate.fractions)
        entry.update(weighed_recipe(forward, candidate.fractions, grams, can.resolution_g))
        entry["quantity_g"] = grams
    report |= can_size(can, can.grams)


def _add_hiding(report: dict, candidates, library, geometries, primers=None,
                primers_file=None) -> None:  # fmt: skip
    """Each candidate's hiding and the primer to spray it over (``flakelab hiding``'s, by the
    physics) into its entry of ``report``: of the grey shades, or of ``primers`` (read from
    ``primers_file``)."""
    import numpy as np

    from flakelab.cli.hiding import hiding_report
    from flakelab.core.colorimetry import reflectance_to_Lab
    from flakelab.core.geometry import Geometry
    from flakelab.physics.hiding import hiding, read_bare

    binder = library.binder  # what the cases, and so the predictions, were sprayed over
    own = reflectance_to_Lab(read_bare(binder.primer_reflectance, binder.refractive_index))
    x = np.array([library.fractions(c.fractions) for c in candidates])
    at = tuple(Geometry.parse(g) for g in geometries)  # the names the model reads
    found = hiding_report(hiding(library, x, at, primers=primers), [""] * len(x), "",
                          primers_file)  # fmt: skip
    for entry, paint in zip(report["candidates"], found["paints"], strict=True):
        over = next((g for g in paint["primers"] if g["primer"] == paint["best_primer"]), None)
        entry["hiding"] = {
            "hiding_um": paint["hiding_um"],
            "coats": paint["coats"],
            "contrast_ratio": paint["contrast_ratio"],
            "best_primer": paint["best_primer"],
            "best_primer_lightness": over and over["lightness"],
            "best_primer_coats": over and over["coats"],
            "film_um_range": found["film_um_range"],
            "primers_file": found["primers_file"],
            "nominal_um": found["nominal_um"],
            "library_primer_lightness": round(float(own[0]), 2),
        }


def _hiding_text(hiding: dict) -> str:
    """A candidate's primer line: the grey (or the shop's primer) to spray it over, and the
    coats; for a paint that hides none, the primer and build its colour was predicted at."""
    if hiding["best_primer"] is None:  # predicted as the cases were sprayed: keep to that
        return (f"primer: it hides none within {hiding['film_um_range'][1]:.0f} µm (a "
                "transparent colour): its colour is predicted over the library's primer (L* "
                f"{hiding['library_primer_lightness']:.0f}) at {hiding['nominal_um']:g} µm; spray "
                "it over that primer, to that build")  # fmt: skip
    primer, L = hiding["best_primer"], hiding["best_primer_lightness"]
    shop = hiding["primers_file"]
    named = f"{primer!r} of {shop}" if shop else f"grey {primer}"
    return (
        f"primer: spray over {named} (L* {L:.0f}), its full colour in "
        f"{counted(hiding['best_primer_coats'], 'coat')} (black and white hidden in "
        f"{counted(hiding['coats'], 'coat')}; flakelab hiding)"
    )


def _match_every_sample(readings, path, forward, effect, search: dict, can, recipe_dir,
                        json_output: bool, jobs: int | None = None,
                        shop_tins: dict | None = None, taken: set[str] = frozenset(),
                        over: dict | None = None) -> None:  # fmt: skip
    """``match --all``: each reading of the file matched as ``match`` matches one (the
    ``search``'s keywords), by ``jobs`` processes (default: one per core,
    :func:`~flakelab.match.batch.workers_for`), its best candidate weighed for the ``can``
    (and written into ``recipe_dir``, under no name ``taken``); a reading the model cannot
    read is named in its row, and the rest go on. ``shop_tins`` (the tins weighed for, and
    their notes) head the report; each best recipe's primer is of ``over``'s primers
    (:func:`_add_hiding`; default the grey shades)."""
    shop_tins = shop_tins or {"lots": None, "notes": []}
    from flakelab.io import write_recipe
    from flakelab.match.batch import match_readings, usable_cores, workers_for

    readable, refused = [], {}
    for i, reading in enumerate(readings):
        try:
            spectra_for_model(path, reading, forward)
            readable.append(i)
        except FlakelabError as error:  # this sample's: named in its row
            refused[i] = error
    workers = workers_for(len(readable), jobs)
    if jobs is not None and jobs > workers == usable_cores():
        shop_tins["notes"].append(f"--jobs {jobs}: {counted(workers, 'process', 'processes')}, "
                                  "one per core this machine lets it use; more would match no "
                                  "faster")  # fmt: skip
    with progress_bar(json_output) as bar:
        task = bar.add_task("matching every sample", total=len(readable))
        matched = match_readings([readings[i] for i in readable], forward, effect,
                                 jobs=workers, progress=lambda: bar.advance(task),
                                 **search)  # fmt: skip
    results = refused | dict(zip(readable, matched, strict=True))
    reports, names = [], set(taken)
    for i, reading in enumerate(readings):
        result = results[i]
        if isinstance(result, FlakelabError):
            reports.append({"target": reading.sample, "error": str(result)})
            continue
        report = result.to_dict()
        _weigh_candidates(report, result.candidates, forward, can)
        _add_hiding(report, result.candidates, search["library"], forward.geometries,
                    **(over or {}))  # fmt: skip
        if recipe_dir is not None:
            best = recipe_dir / f"{file_name_for(reading.sample, names)}.json"
            write_recipe({w["toner"]: w["grams"] for w in report["candidates"][0]["weights_g"]},
                         best)  # fmt: skip
            report["recipe_out"] = str(best)
        reports.append(report)
    if json_output:
        print_report({"file": str(path), **shop_tins, "targets": reports})
        return
    _print_every_sample(path, reports)
    if shop_tins["lots"]:
        console.print(f"weighed for the shop's tins: {len(shop_tins['lots'])} read off the "
                      "standard", highlight=False)  # fmt: skip
    print_notes(shop_tins["notes"])


def _print_every_sample(path, reports: list[dict]) -> None:
    """``match --all``'s table: each sample's best recipe, its worst predicted ΔE00 and
    verdict."""
    table = Table(title=f"The best recipe for each sample of {path}", box=box.SIMPLE_HEAD,
                  collapse_padding=True)  # fmt: skip
    for column in ("sample", "max ΔE00", "verdict", "spray over", "best recipe (share)"):
        table.add_column(column, justify="right" if "ΔE" in column else "left",
                         no_wrap=column != "best recipe (share)")  # fmt: skip
    for report in reports:
        if "error" in report:
            table.add_row(report["target"], "", "[red]not read[/]", "", report["error"])
            continue
        best = report["candidates"][0]
        verdict = (
            "[green]PASS[/]" if best["passes"] else "[red]FAIL[/] at " + _failing_in_short(best)
        )
        recipe = shares_text(best["recipe"])
        if best["novel_toners"]:  # predicted by the physics scaling for them
            recipe += f" [yellow](new: {', '.join(best['novel_toners'])})[/]"
        grey = best["hiding"]["best_primer"] or "none"  # the primer: flakelab hiding
        table.add_row(report["target"], f"{best['de00_max']:.2f}", verdict, escape(grey), recipe)
    console.print(table)
    passing = sum(1 for r in reports if "error" not in r and r["candidates"][0]["passes"])
    samples = counted(len(reports), "sample")
    console.print(f"{passing} of {samples} matched within the tolerance, as predicted",
                  highlight=False)  # fmt: skip


SHORT_FAILURES = 3
"""Failures ``match --all``'s table names one by one; beyond, it counts them and names the
worst geometry (the sample's own report names every one)."""


def _failing_in_short(candidate: dict) -> str:
    """What fails ``candidate`` (its report), for one cell of a table: ``45as15, texture G``,
    or ``10 geometries (worst 45as15), texture G``."""
    from flakelab.core.tolerance import failures

    geometries = candidate["failing_geometries"]
    if len(geometries) > SHORT_FAILURES:
        worst = max(geometries, key=lambda g: candidate["geometries"][g]["dE00"])
        geometries = [f"{len(geometries)} geometries (worst {worst})"]
    return ", ".join(failures(geometries, candidate["failing_texture"]))


def _write_candidate(report: dict, pick: int, path: Path) -> None:
    """``--recipe-out``: candidate ``pick``'s weighed grams as a recipe file."""
    from flakelab.io import write_recipe

    if pick > len(report["candidates"]):
        found = counted(len(report["candidates"]), "candidate")
        raise FlakelabError(f"--pick: the search found {found}")
    lines = report["candidates"][pick - 1]["weights_g"]
    write_recipe({ln["toner"]: ln["grams"] for ln in lines if ln["grams"] > 0}, path)
    report["recipe_out"] = {"file": str(path), "candidate": pick}
    errors.print(f"wrote candidate #{pick}'s recipe to {path}", highlight=False)


def _render_match(target, result, path: Path, lamps) -> None:
    """The target as measured (at the model's geometries, as the candidates) above each
    candidate as its model predicts it, curved panels in one texture draw, under ``lamps``
    (None: each the target was read under)."""
    readings = [target] + [c.as_measurement(f"#{k}") for k, c in enumerate(result.candidates, 1)]
    labels = ["target"] + [
        f"#{k}  {'PASS' if c.passes else 'FAIL'}  max ΔE00 {c.de00.max():.2f}"
        for k, c in enumerate(result.candidates, 1)
    ]
    draw_side_by_side(readings, labels, path, f"{result.target}: target and candidates (predicted)",
                      lamps=lamps)  # fmt: skip


def _plot_match(target, result, left_out: list, tolerance, path: Path) -> None:
    """Each candidate's predicted difference from the target at the searched geometries, then
    at the target's others as the model that predicts them says (``left_out``)."""
    if not result.candidates:
        raise FlakelabError("--plot: the search found no candidate to draw")
    samples = {f"#{k}": c.lab for k, c in enumerate(result.candidates, 1)}
    chart = with_left_out(
        target, list(result.candidates[0].geometries), result.candidates[0].target_lab, samples,
        left_out and left_out[0].geometries, [x.lab for x in left_out],
    )  # fmt: skip
    apart = f"not searched; predicted by {left_out[0].model_id}" if left_out else ""
    texture = {f"#{k}": c.texture_share for k, c in enumerate(result.candidates, 1)}
    title = f"{result.target}: candidates as predicted by {result.model_id}"
    draw_differences(*chart, tolerance, path, title,
                     apart=len(result.candidates[0].geometries), apart_label=apart,
                     texture=texture)  # fmt: skip


def _print_match(report: dict, where: str = "") -> None:
    """The candidates as a colorist reads them; the commands suggested read the cases
    ``where`` (:func:`~flakelab.cli.sources.database_option`)."""
    from flakelab.core.tolerance import failures

    console.print(
        f"[bold]{report['target']}[/] — {counted(len(report['candidates']), 'candidate')} "
        f"({report['subsets_tried']} toner sets optimised in {report['seconds']:.2f} s, "
        f"tolerance {report['tolerance']}, model {report['model_id']})",
        highlight=False,
    )
    if report.get("lots"):
        tins = ", ".join(
            f"{n} {100 * (t['strength'] - 1):+.1f} %"
            + (f" {t['shade_nm']:+.1f} nm" if t["shade_nm"] else "")
            for n, t in report["lots"].items()
        )
        console.print(f"weighed for the shop's tins: {tins}", highlight=False)
    for rank, c in enumerate(report["candidates"], start=1):
        failing = failures(c["failing_geometries"], c["failing_texture"])
        verdict = "[green]PASS[/]" if c["passes"] else "[red]FAIL[/] at " + ", ".join(failing)
        header = (
            f"#{rank}  max ΔE00 {c['de00_max']:.2f}  mean {c['de00_mean']:.2f}  {verdict}"
            f"  (at worst {c['limit_share_max']:.0%} of the tolerance)"
            + ("  aimed off for the shop's habits" if c.get("aimed_off") else "")
            + _as_recorded(c.get("recorded_case"))
        )
        table = weights_table(can_text(report | c) if "quantity_ml" in report else None,
                              c["weights_g"])  # fmt: skip
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
        # a recipe with new toners is flagged by its model, which names their physics scaling
        console.print(f"model: {c['model']}; {rounding_text(c)}", highlight=False)
        if c.get("hiding"):
            console.print(_hiding_text(c["hiding"]), highlight=False, markup=False)
        if c["metamerism_index_max"]:  # none against spectra recovered from L*a*b*
            console.print(metamerism_text(c["metamerism_index_max"], c["metamer"]), highlight=False)
    if report.get("recorded_nearest"):
        from flakelab.cli.cases import nearest_table

        code = f" of colour code {report['colour_code']!r}" if report["colour_code"] else ""
        title = f"Recorded spray-outs{code} nearest the target (measured, not predicted)"
        console.print(nearest_table(report["recorded_nearest"], title))
    if report.get("colour_variant"):
        _print_car_variant(report, where)
    print_notes(report["notes"])
    if any("model_spread" in v for c in report["candidates"] for v in c["geometries"].values()):
        console.print(MODEL_SPREAD_LEGEND, highlight=False)


def _print_car_variant(report: dict, where: str) -> None:
    """Which of its code's variants the car lies nearest, and what to do next."""
    v, code = report["colour_variant"], report["colour_code"]
    newest = f"newest {v['cars_grouped']} of its " if v["cars_grouped"] < v["cars_of_code"] else ""
    said = (
        f"The car lies nearest variant #{v['variant']} of the {v['variants']} of {code!r} among "
        f"the shop's {newest}{counted(v['cars_of_code'], 'car')} ({v['cars']} in it): worst "
        f"ΔE00 {v['de00_max']:.2f} at {v['geometry']} from its centre car"
    )
    if v["passes"]:
        shown = f"flakelab cases variants {code!r}{where}"
        console.print(f"{said}, within {report['tolerance']} ({shown})", highlight=False)
    else:
        console.print(
            f"[yellow]note:[/] {said}, outside {report['tolerance']}: no variant of the code "
            "the shop has painted is this car's colour",
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
    colour_alone,
    resprays,
    lots,
    plot,
    json_output,
):
    from flakelab.core.difference import METAMERISM_ILLUMINANTS
    from flakelab.io import read_tolerance
    from flakelab.library.lots import TIN_KNOWLEDGE
    from flakelab.match.evaluate import evaluate_matching, harness_world
    from flakelab.match.objective import OBJECTIVE_DEFAULT
    from flakelab.match.physics_check import check_over
    from flakelab.match.stock import toners_allowed

    tol = read_tolerance(tolerance or OBJECTIVE_DEFAULT)
    if not targets + novel_targets:
        raise FlakelabError("--targets 0 --novel-targets 0: no target to judge")
    check_figure_file(plot, "--plot")
    if lots not in TIN_KNOWLEDGE:  # before the model: a file is for one target's match
        raise FlakelabError(
            f"--lots: evaluate: expected one of {', '.join(TIN_KNOWLEDGE)}, got {lots!r}"
        )
    lib, forward, effect = matcher_setup(library, instrument, model, database, physics, shop)
    world = harness_world(lib, instrument, world_name)
    toners_allowed(forward.toners, settings.without)  # a toner misspelt: before the targets
    scale = scale and scale.for_toners(lib, forward.toners)
    habits = habits_for(habits_file, shop, database, forward, with_tins=lots != "none")
    novel_targets = novel_targets if forward.novel else 0  # no new toner, none of its targets
    if not targets + novel_targets:
        raise FlakelabError(
            f"--targets 0: judges the targets with a new toner alone, and {forward.name} has "
            "no new toner"
        )
    with progress_bar(json_output) as bar:
        task = bar.add_task("matching hidden targets", total=targets + novel_targets)
        report = evaluate_matching(
            world,
            forward,
            effect,
            targets=targets,
            seed=seed,
            novel=forward.novel,
            novel_targets=novel_targets,
            habits=habits,
            settings=settings,
            tolerance=tol,
            scale=scale,
            target_texture=target_texture,
            colour_alone=colour_alone,
            resprays=resprays,
            lots=lots,
            progress=lambda: bar.advance(task),
            per_target=plot is not None,
        )
    if plot is not None:
        from flakelab.render.plots import plot_harness

        trials = report.pop("per_target")
        judged = report["targets"]  # fewer than asked where a Ctrl-C ended the run
        read = ", read by L*a*b* alone" if colour_alone else ""
        words = _targets_words(judged, report["novel_targets"])
        title = f"{forward.model_id}, {words} (seed {seed}){read}"
        plot_harness(trials[:judged], trials[judged:], plot, tolerance=tol.name, title=title)
        report["plot"] = str(plot)
    report["model"] = forward.name
    report["model_id"] = forward.model_id
    report["model_risk"] = settings.model_risk
    report["physics_check"] = settings.physics_check
    report["physics_check_over"] = check_over(forward.geometries)
    report["metamerism_weight"] = settings.metamerism
    report["metamerism_lights"] = list(settings.lights or METAMERISM_ILLUMINANTS)
    report["solid_travel"] = settings.solid_travel
    report["solid_travel_from"] = settings.solid_travel_from
    report["max_pigments"] = settings.max_pigments
    report["world"] = world_name
    report["habits"] = habits and habits.report()
    if json_output:
        print_report(report)
    else:
        _print_harness(report)
    if "targets_asked" in report:  # a Ctrl-C ended the run early
        judged = _targets_words(report["targets"], report["novel_targets"])
        asked = report["targets_asked"] + report["novel_targets_asked"]
        stop_interrupted(f"{judged} of the {asked} asked for were judged; the figures are theirs")


def _targets_words(targets: int, novel: int, noun: str = "target") -> str:
    """The harness's targets in words: ``2 targets and 1 with a new toner``, or
    ``3 targets with a new toner`` where it judged those alone (``--targets 0``)."""
    if not targets:
        return f"{counted(novel, noun)} with a new toner"
    return counted(targets, noun) + (f" and {novel} with a new toner" if novel else "")


def _share(value: float | None) -> str:
    """A rate as the harness's tables show it: to the thousandth, where 200 targets count in
    steps of 0.005 (0.595 is not rounded to 0.59 or 0.60)."""
    return "–" if value is None else f"{value:.3f}"


def _print_harness(report: dict) -> None:
    """The harness's figures as tables (``--json`` gives them all, and each target's): each
    rate, of how many targets, and against the oracle's, the limit that spray and
    measurement set; the rates of each paint family; the errors and the latency. It printed
    the JSON report itself, 60 lines of it."""
    from flakelab.render.plots import HARNESS_CURVES

    targets, novel = report["targets"], report["novel_targets"]
    rows = [
        (HARNESS_CURVES["first"], "first_shot_success", "first_shot_vs_oracle", targets),
        (HARNESS_CURVES["corrected"], "after_one_correction", "after_one_correction_vs_oracle",
         targets),
        ("new toner, first shot", "novel_toner_first_shot", "novel_toner_first_shot_vs_oracle",
         novel),
        ("new toner, after one correction", "novel_toner_after_one_correction",
         "novel_toner_after_one_correction_vs_oracle", novel),
        (HARNESS_CURVES["first_unsprayed"], "first_shot_unsprayed", None, targets),
        ("… with a new toner", "novel_toner_first_shot_unsprayed", None, novel),
        (f"oracle: {HARNESS_CURVES['oracle']}", "oracle_success", None, targets),
        ("oracle, new toner", "novel_oracle_success", None, novel),
        (HARNESS_CURVES["respray"], "respray_success", None, targets),
        ("after one perfect correction", "after_one_perfect_correction", None, targets),
    ]  # fmt: skip
    table = Table(
        title=f"The harness: {_targets_words(targets, novel, 'hidden target')}"
        + f" (seed {report['seed']}, tolerance {report['tolerance']}, world {report['world']})",
        box=box.SIMPLE_HEAD,
    )
    for column in ("sprayed and judged", "passed", "÷ oracle", "targets"):
        table.add_column(column, justify="left" if column.startswith("sprayed") else "right")
    for name, key, versus, count in rows:
        if count:
            ratio = _share(report[versus]) if versus else ""
            table.add_row(name, _share(report[key]), ratio, str(count))
    console.print(table)
    console.print(_families_table(report))
    lines = [
        *(_errors_lines(report) if targets else []),
        *_harness_options(report),
        _matched_as_line(report),
        _physics_checked_line(report),
        f"latency per target: p50 {report['latency_p50_s']:.2f} s, p95 "
        f"{report['latency_p95_s']:.2f} s",
        f"model: {report['model']} ({report['model_id']}); --json gives every figure and "
        "--plot draws each target's",
    ]
    for line in lines:
        console.print(line, highlight=False)


def _families_table(report: dict) -> Table:
    """The harness's rates by paint family, as its first table names them: the known toners'
    targets, then a new toner's (each family against its own oracle)."""
    from flakelab.match.evaluate import FAMILY_FIGURES
    from flakelab.render.plots import HARNESS_CURVES

    families = Table(title="By paint family", box=box.SIMPLE_HEAD)
    families.add_column("family")
    families.add_column("targets", justify="right")
    short = {"oracle": "oracle", "respray": "sprayed again"}  # as the rows above name them
    for trial in FAMILY_FIGURES.values():
        families.add_column(short.get(trial, HARNESS_CURVES[trial]), justify="right")
    for part, which in (("by_family", ""), ("novel_by_family", ", new toner")):
        for family, figures in report[part].items():
            families.add_row(family + which, str(figures["targets"]),
                             *(_share(figures[key]) for key in FAMILY_FIGURES))  # fmt: skip
    return families


def _matched_as_line(report: dict) -> str:
    """How many targets' first recipes are of another paint family than the target's paint
    (a pearl matched with aluminium alone, a solid with an effect toner, …), and which."""
    moves: Counter[str] = Counter()
    for part in ("by_family", "novel_by_family"):
        for family, figures in report[part].items():
            for matched, count in figures["matched_as"].items():
                if matched != family:
                    moves[f"{family} as {matched}"] += count
    if not moves:
        return "every first recipe is of its target's paint family"
    targets = report["targets"] + report["novel_targets"]
    which = ", ".join(f"{move} {count}" for move, count in moves.most_common())
    return (
        f"first recipes of another paint family than their target's: {moves.total()} of "
        f"{counted(targets, 'target')} ({which})"
    )


def _errors_lines(report: dict) -> list[str]:
    """The known targets' median errors, texture and metamerism, in words."""
    return [
        f"worst-geometry ΔE00, median: predicted {report['predicted_de00_median']:.2f}, first "
        f"shot sprayed {report['first_shot_de00_median']:.2f}, the hidden formula sprayed "
        f"{report['oracle_de00_median']:.2f}",
        f"first shots within the texture limits {_share(report['first_shot_texture_within'])} "
        f"(the hidden formula's {_share(report['oracle_texture_within'])}); metamerism index "
        f"median {report['first_shot_metamerism_median']:.2f} "
        f"({report['oracle_metamerism_median']:.2f})",
    ]


def _physics_checked_line(report: dict) -> str:
    """How many targets' best recipes the physics refined, and how many failed first shots it
    corrected, the model's networks disagreeing on them (``--physics-check``)."""
    if not report["physics_check"]:
        return "the physics checked no recipe (--no-physics-check)"
    checked = report["physics_checked_targets"] + report["novel_physics_checked_targets"]
    corrected = (
        report["correction_physics_checked_targets"]
        + report["novel_correction_physics_checked_targets"]
    )
    return (
        f"the physics refined the recipes of {counted(checked, 'target')} and corrected "
        f"{counted(corrected, 'failed first shot')}, where the model's networks disagreed by "
        f"over {report['physics_check_over']:.1f} ΔE00 (--physics-check)"
    )


def _harness_options(report: dict) -> list[str]:
    """What the harness's options add to its report, in words: the targets that needed a
    toner out of stock (``--without``), the chances over the resprays (``--resprays``), how
    the targets were read (``--colour-alone``, ``--no-target-texture``), and how far the tins
    the shop matched with were from the true ones (``--lots``)."""
    lines = []
    if report["without"]:
        novel_needing = report["novel_needing_missing_targets"]
        lines.append(
            f"{counted(report['needing_missing_targets'], 'target')} needed "
            f"{', '.join(report['without'])}, out of stock: first shot "
            f"{_share(report['needing_missing_first_shot'])}, after one correction "
            f"{_share(report['needing_missing_after_one_correction'])}"
            + (
                f"; {counted(novel_needing, 'target')} with a new toner, first shot "
                f"{_share(report['novel_needing_missing_first_shot'])}"
                if novel_needing
                else ""
            )
        )
    if report["resprays"]:
        novel = report["novel_toner_after_one_correction_chance"], report["novel_oracle_chance"]
        lines.append(
            f"the chance a spray passes, over {report['resprays']} resprays each: first shot "
            f"{_share(report['first_shot_chance'])}, after one correction "
            f"{_share(report['after_one_correction_chance'])}, oracle "
            f"{_share(report['oracle_chance'])}, new toner "
            f"{_share(report['novel_toner_first_shot_chance'])}"
            + (
                f" (after one correction {_share(novel[0])}, its oracle {_share(novel[1])})"
                if report["novel_targets"]
                else ""
            )
        )
    if report["targets_read_colour_alone"]:
        lines.append(
            "targets and spray-outs read by their L*a*b* alone, their spectra recovered from "
            "it: the metamerism index above is the sprays' against the car's measured spectra"
        )
    if not report["targets_read_texture"]:
        lines.append("targets read without their texture readings")
    if report["lots"] != "none" and report["lot_strength_error_rms"] is not None:
        shade = report["lot_shade_error_rms_nm"]
        lines.append(
            f"the shop's tins ({report['lots']}) against the true ones: strength RMS "
            f"{report['lot_strength_error_rms']:.3f}"
            + (f", shade RMS {shade:.2f} nm" if shade is not None else "")
        )
    return lines
