"""CLI: ``flakelab cases``: the case database, the case generator and a shop's habits."""

from __future__ import annotations

from dataclasses import replace
from datetime import datetime
from operator import attrgetter
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich import box
from rich.table import Table

from flakelab.cli.common import (
    COUNT_MAX,
    AverageOption,
    AverageSprayedOption,
    JsonOption,
    SampleOption,
    SprayedSampleOption,
    ToleranceOption,
    check_figure_file,
    check_output_file,
    command_group,
    console,
    errors,
    interrupted,
    print_report,
    progress_bar,
    read_reading_at,
    read_readings,
    reports_errors,
    seed_option,
    shares_text,
    tracked,
)
from flakelab.cli.matcher import ResolutionOption
from flakelab.cli.sources import (
    WORKPLACE_SHOP,
    CasesArgument,
    CaseSourceOption,
    ColourCodeOption,
    DatabaseOption,
    InstrumentOption,
    KeptGeometriesOption,
    LibraryOption,
    ModelFileOption,
    NoTinsOption,
    ShopModelOption,
    ShopOption,
    SinceOption,
    StartOption,
    cases_hint_in,
    colour_code_spelled,
    existing_engine,
    instrument_key,
    instrument_spelled,
    learned_forward,
    recipe_fractions,
    recorded_tins_used,
    shop_cases,
    shop_spelled,
    since_option,
    source_arrays,
    time_option,
    which_cases,
)
from flakelab.core.defaults import DEFAULT_TOLERANCE
from flakelab.core.geometry import (
    DEFAULT_INSTRUMENT,
    INSTRUMENT_GEOMETRIES,
    instruments_reading,
)
from flakelab.core.times import shown_time
from flakelab.core.wording import counted, database_label, hidden_passwords
from flakelab.errors import FlakelabError
from flakelab.match.settings import CAN_QUANTITY, SCALE_RESOLUTION_G

CheckOption = Annotated[
    bool,
    typer.Option(
        "--check/--no-check",
        help="Check each spray-out against its recipe's prediction by the current model (with "
        "the shop's stored habits) and name the likely mix-ups; it loads the model (about 2 s).",
    ),
]

cases_app = command_group(
    "Refinish cases: generate, record, record-all, list, nearest, remove, import, export; "
    "realism, habits, shops; colour codes and their variants."
)


@cases_app.command("generate")
@reports_errors
def generate(
    n: Annotated[int, typer.Option("--n", min=1, max=COUNT_MAX, help="Number of cases.")] = 1000,
    seed: Annotated[int, seed_option("Seed of the generated world.")] = 0,
    out: Annotated[
        Path | None, typer.Option("--out", "-o", help="CSV/CxF file or SQLite .db to write.")
    ] = None,
    database: DatabaseOption = None,
    instrument: InstrumentOption = DEFAULT_INSTRUMENT,
    library: LibraryOption = None,
    shop: Annotated[
        str, typer.Option(callback=shop_spelled, help="Shop name recorded with the cases.")
    ] = "synthetic shop",
    shop_film_build: Annotated[
        float,
        typer.Option(min=0.8, max=1.2, help="The shop's mean film build against the factory's."),
    ] = 1.0,
    shop_spread: Annotated[
        float,
        typer.Option(
            min=0.8,
            max=1.2,
            help="The shop's mean flake spread against the factory's (<1: "
            "flakes lie flatter, brighter face, darker flop).",
        ),
    ] = 1.0,
    shop_gain: Annotated[
        float,
        typer.Option(
            min=-0.05, max=0.05, help="The shop instrument's gain against the reference's."
        ),
    ] = 0.0,
    start: StartOption = None,
    tins: Annotated[
        str,
        typer.Option(
            help="What each case records of the tins its recipe was poured from: none (as "
            "most shops), calibrated (the shop read every tin from a panel against the model, "
            "to the error that reading has, as 'lots calibrate' does), referenced (against the "
            "paint maker's panel of the toner, 'lots calibrate --standard') or known (the "
            "world's own strengths and shades).",
        ),
    ] = "none",
    tin_sprayouts: Annotated[
        int,
        typer.Option(
            min=1,
            max=COUNT_MAX,
            help="Spray-outs each of the shop's tins serves before the next is opened: the "
            "cases of a stretch share their tins (1: every spray-out from batches of its own).",
        ),
    ] = 1,
    colour_codes: Annotated[
        int,
        typer.Option(
            min=0,
            max=COUNT_MAX,
            help="The car makers' colours the shop meets: every car painted in one of this many "
            "OEM colours, coded GEN 001 … (synthetic), the r-th met as often as 1/r; its case "
            "records the code (0: every car a colour of its own, no code).",
        ),
    ] = 0,
) -> None:
    """Generate synthetic refinish cases (labelled synthetic) and store them. A database
    takes them in batches of 500: the same command again, after a Ctrl-C, stores the rest."""
    from flakelab.cases.database import open_database
    from flakelab.cases.exchange import check_cases_or_database_name, is_case_file, write_cases
    from flakelab.cases.generator import World, WorldSettings
    from flakelab.io import read_library
    from flakelab.library.lots import TIN_KNOWLEDGE

    if out is not None:
        check_cases_or_database_name(out, "--out")
    if tins not in TIN_KNOWLEDGE:
        raise FlakelabError(f"--tins: expected one of {', '.join(TIN_KNOWLEDGE)}, got {tins!r}")
    settings = WorldSettings(
        shop_film_build=shop_film_build,
        shop_spread=shop_spread,
        shop_gain=shop_gain,
        tins=tins,
        tin_sprayouts=tin_sprayouts,
        colour_codes=colour_codes,
    )
    world = World(read_library(library), instrument_key(instrument), settings)
    to_file = out is not None and is_case_file(out)
    if to_file:
        # before the cases are generated, not after
        check_output_file(out, "--out", reads={"--library": library})
    batches = world.cases(n, seed, shop=shop, start=start)
    if to_file:
        with interrupted(f"nothing was written to {out}"), progress_bar() as bar:
            task = bar.add_task("generating cases", total=n)

            def generated():  # written as they come (a CSV): none held
                for batch in batches:
                    yield from batch
                    bar.advance(task, len(batch))

            columns = tuple(g.name for g in world.geometries)
            write_cases(generated(), out, geometries=columns, tins=tins != "none",
                        codes=colour_codes > 0)  # fmt: skip
        errors.print(
            f"wrote {n} synthetic cases ({instrument}, seed {seed}) to {out}",
            highlight=False,
            soft_wrap=True,
        )
        return
    storing = _GeneratedStore(open_database(out if out is not None else database), n)
    with interrupted(storing.interrupted), progress_bar() as bar:
        task = bar.add_task("generating cases", total=n)
        for batch in batches:
            storing.store(batch)
            bar.advance(task, len(batch))
    errors.print(storing.summary(instrument, seed), highlight=False, soft_wrap=True)
    _note_recorded_cases(storing.engine)


def _note_recorded_cases(engine) -> None:
    """Where a generation went into a database that holds a shop's recorded cases: how the
    synthetic ones are told apart and taken out again."""
    from flakelab.cases.database import synthetic_cases

    if recorded := synthetic_cases(engine, recorded=True):
        shops = ", ".join(recorded)
        errors.print(
            f"[yellow]note:[/] {database_label(engine)} also holds "
            f"{counted(sum(recorded.values()), 'recorded case')} ({shops}): the generated ones "
            "are labelled synthetic, which 'flakelab cases remove --synthetic' takes out again",
            highlight=False,
            soft_wrap=True,
        )


class _GeneratedStore:
    """``cases generate``'s batches stored one transaction each. A case stored already, as
    generated (a run of the same command cut short, or one with a smaller ``--n``), is kept
    as it is: running the command again goes on where it stopped."""

    def __init__(self, engine, n: int):
        self.engine, self.n = engine, n
        self.added = self.found = 0
        self.batch: list = []

    def store(self, batch: list) -> None:
        from flakelab.cases.case import CaseError
        from flakelab.cases.database import add_new_cases

        self.batch = batch
        try:
            added, found = add_new_cases(self.engine, batch)
        except CaseError as error:
            raise FlakelabError(
                f"{error}{self._before()}; a seed generates the same case ids every time: choose "
                "another --seed or another database"
            ) from None
        self.added, self.found, self.batch = self.added + added, self.found + found, []

    def _before(self) -> str:
        stored = self.added + self.found
        return f"; the {counted(stored, 'case')} generated before it stay stored" if stored else ""

    def interrupted(self) -> str:
        """What a Ctrl-C left: the batches stored, and those of the batch being stored that
        are there (all, where its transaction landed; else those stored before)."""
        from flakelab.cases.database import existing_case_ids

        landed = existing_case_ids(self.engine, [case.case_id for case in self.batch])
        stored = self.added + self.found + len(landed)
        return (
            f"{stored} of the {counted(self.n, 'case')} are stored in "
            f"{database_label(self.engine)}; the same command again stores the rest"
        )

    def summary(self, instrument: str, seed: int) -> str:
        made = f"synthetic cases ({instrument}, seed {seed})"
        if not self.found:
            return f"wrote {self.added} {made} to {database_label(self.engine)}"
        if not self.added:
            return (
                f"all {self.n} {made} were stored in {database_label(self.engine)} already; "
                "nothing added"
            )
        return (
            f"wrote {self.added} {made} to {database_label(self.engine)}; the other "
            f"{self.found} were stored already (by an earlier run of the same generation)"
        )


@cases_app.command("import")
@reports_errors
def import_cases(
    source: Annotated[Path, typer.Argument(help="CSV or CxF3 case history.")],
    database: DatabaseOption = None,
    library: LibraryOption = None,
    check: CheckOption = True,
    new_only: Annotated[
        bool,
        typer.Option(
            "--new-only",
            help="Store the cases not stored yet and pass over those stored already, as a "
            "history exported again with a month more holds them (each must be stored as the "
            "file has it). Without it, one case stored already refuses the file.",
        ),
    ] = False,
) -> None:
    """Import a shop's case history into the database (all cases or none)."""
    from flakelab.cases.case import CaseError
    from flakelab.cases.database import add_cases, open_database, store_new_cases
    from flakelab.cases.exchange import count_lines, read_cases
    from flakelab.io import read_library
    from flakelab.match.mixups import is_mismatched, recorded_checks

    # a library given is read, and refused if malformed, even where --no-check leaves it unused
    lib = read_library(library) if check or library is not None else None
    # a shop's history of 30,000 cases: 7 s to read
    with interrupted("nothing was imported"), progress_bar() as bar:
        task = bar.add_task(f"reading the lines of {source.name}", total=count_lines(source))
        cases = read_cases(source, lambda: bar.advance(task))
    engine = open_database(database)
    left = _left_by_storing(engine, cases, "imported", new_only)
    try:  # one transaction: all of them or none
        with interrupted(left):
            if new_only:
                stored = store_new_cases(engine, cases)
            else:
                add_cases(engine, cases)
                stored = cases
    except CaseError as error:  # it names the case stored already, or stored otherwise
        again = " (--new-only passes over those stored already)" if not new_only else ""
        raise FlakelabError(f"{source}: {error}{again}") from None
    imported = (
        f"imported {counted(len(stored), 'case')} from {source} into {database_label(engine)}"
    )
    there = f"; {len(cases) - len(stored)} stored already" if new_only else ""
    for flag, role in (("target_recovered", "target"), ("sprayout_recovered", "spray-out")):
        if alone := sum(getattr(c, flag) for c in stored):
            there += f"; {alone} of them know their {role} by their L*a*b* in D65/10 alone"
    errors.print(imported + there, highlight=False)
    if not check:
        return
    # the cases stored now: those stored already were checked then
    with interrupted(left):
        checks, unchecked = recorded_checks(stored, lib, existing_engine(database))
    mismatched = [c.case_id for c, k in zip(stored, checks, strict=True) if is_mismatched(k)]
    shown = ", ".join(mismatched[:5]) + (" …" if len(mismatched) > 5 else "")
    _tell_mix_ups(len(mismatched), shown, unchecked)


@cases_app.command("record")
@reports_errors
def record_case(
    target: Annotated[Path, typer.Argument(help="Target measurement file (the car).")],
    recipe: Annotated[
        Path, typer.Option("--recipe", "-r", help="Recipe JSON {toner: grams} that was sprayed.")
    ],
    sprayed: Annotated[Path, typer.Option("--sprayed", help="Measurement of the spray-out.")],
    sample: SampleOption = None,
    sprayed_sample: SprayedSampleOption = None,
    average: AverageOption = False,
    average_sprayed: AverageSprayedOption = False,
    outcome: Annotated[
        str,
        typer.Option(
            help="auto (judged against --tolerance: accepted when the spray-out passes, "
            "corrected when it goes to a correction), accepted, corrected or rejected."
        ),
    ] = "auto",
    shop: Annotated[
        str,
        typer.Option(
            envvar=WORKPLACE_SHOP, callback=shop_spelled, help="Shop name recorded with the case."
        ),
    ] = "unknown",
    instrument: KeptGeometriesOption = None,
    library: LibraryOption = None,
    tolerance: ToleranceOption = DEFAULT_TOLERANCE,
    at: Annotated[
        datetime | None,
        time_option(
            "When the spray-out was made (local time).",
            show_default="the spray-out file's date, else now",
        ),
    ] = None,
    case_id: Annotated[
        str | None,
        typer.Option(help="Case id.", show_default="made from the readings and the recipe"),
    ] = None,
    colour_code: Annotated[
        str | None,
        typer.Option(
            callback=colour_code_spelled,
            help="The car maker's code for the car's colour, as on its plate ('Toyota 1G3', "
            "'LY9B'): 'cases list', 'nearest', 'export' and 'match' find the case by it.",
            show_default="none",
        ),
    ] = None,
    database: DatabaseOption = None,
    check: CheckOption = True,
    lots: Annotated[
        Path | None,
        typer.Option(
            "--lots",
            help="The shop's toner-lot file ('flakelab lots calibrate'): the case records "
            "the tins the recipe was poured from (lot, strength, shade), and a model is "
            "judged on it for them.",
            show_default="the tins stored for --shop in the database, where there are any",
        ),
    ] = None,
    json_output: JsonOption = False,
) -> None:
    """Record a spray-out as the shop's own case: target, recipe, spray-out and outcome.

    The case joins the database, where 'cases habits', 'model adapt' and 'train' read it.
    It keeps every geometry both readings share, so each model whose geometries are among
    them learns from it; the same spray-out recorded twice is refused."""
    from flakelab.cases.case import tin_fields
    from flakelab.cases.database import add_cases, case_exists, count_cases, open_database
    from flakelab.cases.record import case_from_readings, judged_outcome
    from flakelab.cases.shop_lots import stored_lots
    from flakelab.io import read_library, read_recipe, read_tolerance
    from flakelab.io.lots_file import read_lots
    from flakelab.match.mixups import recorded_checks

    instrument = instrument and instrument_key(instrument)
    tol = read_tolerance(tolerance)
    lib = read_library(library)
    tins = read_lots(lots, lib.names).lots if lots else None
    grams = read_recipe(recipe)
    fractions = recipe_fractions(lib, grams, recipe)
    target_reading = read_readings(target, sample, average)[0]
    sprayed_reading = read_readings(
        sprayed, sprayed_sample, average_sprayed, "--sprayed-sample", "--average-sprayed"
    )[0]
    engine = open_database(database)
    kept = None if lots else stored_lots(engine, shop, lib.names)  # the shop's, where stored
    tins = kept.lots.lots if kept else tins
    case = case_from_readings(
        target_reading,
        sprayed_reading,
        {name: share for name, share in zip(lib.names, fractions.tolist(), strict=True) if share},
        instrument,
        shop=shop,
        outcome=outcome,
        tolerance=tol,
        created_at=at,
        case_id=case_id,
        tins=tins,
        colour_code=colour_code or "",
    )
    textures = (case.target_texture, case.sprayout_texture)
    _, failing = judged_outcome(case.target, case.sprayout, case.geometries, tol, textures)
    if case_exists(engine, case.case_id):
        raise FlakelabError(
            f"{database_label(engine)}: case {case.case_id} is already recorded (the same "
            "readings, recipe and shop); nothing was stored"
        )
    left = _left_by_storing(engine, [case], "recorded")
    with interrupted(left):  # a writer between the check and here is refused by the database
        add_cases(engine, [case])
    left_out = [g for g in target_reading.geometry_names if g not in case.geometry_names]
    models = instruments_reading(case.geometry_names)
    found, unchecked = None, None
    if check:
        with interrupted(left):
            (found,), unchecked = recorded_checks([case], lib, existing_engine(database))
    report = {
        "case_id": case.case_id,
        "shop": case.shop,
        "colour_code": case.colour_code,
        "instrument": case.instrument,
        "geometries": list(case.geometry_names),
        "read_by_models_of": list(models),
        "outcome": case.outcome,
        "target_recovered": case.target_recovered,
        "sprayout_recovered": case.sprayout_recovered,
        "tins": {name: tin_fields(tin) for name, tin in sorted(case.tins.items())},
        "tins_from": str(lots) if lots else kept and kept.describe(),
        "created_at": case.created_at.isoformat(),
        "tolerance": tol.name,
        "sprayout_passes": not failing,
        "sprayout_failing": failing,
        "recipe": {k: round(v, 6) for k, v in case.recipe.items()},
        "left_out": left_out,
        "from_prediction": found,
        "from_prediction_unchecked": unchecked,
        "database": str(engine.url),
        "cases_in_database": count_cases(engine),
    }
    if json_output:
        print_report(report)
        return
    _print_recorded(report, chosen=instrument is not None)


def _print_recorded(report: dict, chosen: bool) -> None:
    """A recorded case as the shop reads it: its verdict, the models that learn from it, its
    tins, how far the spray-out lies from its recipe's prediction, what was not kept
    (``chosen``: the geometries were chosen by ``--instrument``), the cases now in its
    database."""
    from flakelab.cases.case import recovered_note
    from flakelab.match.mixups import is_mismatched, mismatch_message

    failing, found, left_out = (
        report[k] for k in ("sprayout_failing", "from_prediction", "left_out")
    )
    verdict = "passes" if not failing else f"fails {report['tolerance']} at {', '.join(failing)}"
    case_id, at = report["case_id"], datetime.fromisoformat(report["created_at"])
    code = f" (colour code {report['colour_code']})" if report["colour_code"] else ""
    console.print(
        f"recorded case [bold]{case_id}[/] for {report['shop']!r}{code}: {report['outcome']} "
        f"(the spray-out {verdict}), {report['instrument']} at {shown_time(at)}",
        highlight=False,
    )
    if models := report["read_by_models_of"]:
        console.print(f"models that learn from it: {', '.join(models)}", highlight=False)
    else:
        console.print(
            f"[yellow]warning:[/] no instrument's model learns from it: its geometries "
            f"{', '.join(report['geometries'])} hold no instrument's whole set",
            highlight=False,
        )
    if note := recovered_note(report["target_recovered"], report["sprayout_recovered"]):
        console.print(f"[yellow]note:[/] {note}", highlight=False)
    if report["tins"]:
        tins = ", ".join(f"{n} {t['lot'] or '(no lot number)'}" for n, t in report["tins"].items())
        console.print(f"poured from {report['tins_from']}: {tins}", highlight=False)
    if found is not None:
        habits = " with the shop's habits" if found["habits"] else ""
        console.print(
            f"the spray-out from its recipe's prediction: ΔE00 {found['de00']:.2f} at "
            f"{found['geometry']} ({found['model']}{habits})",
            highlight=False,
        )
    elif unchecked := report["from_prediction_unchecked"]:
        console.print(f"[yellow]note:[/] not checked against a model: {unchecked}", highlight=False)
    if is_mismatched(found):
        errors.print(
            f"[yellow]warning:[/] {mismatch_message(found['de00'], found['geometry'])}; it is "
            f"recorded: 'cases habits' leaves it out, 'cases remove {case_id}' removes it",
            highlight=False,
        )
    if left_out:
        console.print(
            f"[yellow]note:[/] the target's {', '.join(left_out)} are not kept "
            f"({'--instrument chooses' if chosen else 'the spray-out was not read there'})",
            highlight=False,
        )
    count = report["cases_in_database"]
    errors.print(f"{counted(count, 'case')} in {database_label(report['database'])}",
                 highlight=False)  # fmt: skip


@cases_app.command("record-all")
@reports_errors
def record_all(
    manifest: Annotated[
        Path,
        typer.Argument(
            help="CSV manifest, one spray-out a row: target, recipe, sprayed files (paths "
            "relative to it), and optionally sample, sprayed_sample, shop, outcome, at, case_id, "
            "lots (the shop's toner-lot file then: the case records its tins)."
        ),
    ],
    shop: Annotated[
        str,
        typer.Option(
            envvar=WORKPLACE_SHOP, callback=shop_spelled, help="Shop of the rows that name none."
        ),
    ] = "unknown",
    instrument: KeptGeometriesOption = None,
    library: LibraryOption = None,
    tolerance: ToleranceOption = DEFAULT_TOLERANCE,
    database: DatabaseOption = None,
    check: CheckOption = True,
    json_output: JsonOption = False,
) -> None:
    """Record a shop's spray-out history from its instrument files, all or none.

    Every row of the manifest is recorded as 'cases record' records one, in one
    transaction. The first bad row is named with its column and nothing is stored; a row already
    recorded, or one the manifest lists twice, is refused the same way."""
    from flakelab.cases.case import OUTCOMES, worst_differences
    from flakelab.cases.database import add_cases, count_cases, existing_case_ids, open_database
    from flakelab.cases.manifest import cases_from_manifest, read_manifest
    from flakelab.io import read_library, read_tolerance
    from flakelab.match.mixups import is_mismatched, recorded_checks

    instrument = instrument and instrument_key(instrument)
    tol = read_tolerance(tolerance)
    lib = read_library(library)
    with interrupted("nothing was recorded"):
        numbered = cases_from_manifest(
            manifest,
            lib,
            tolerance=tol,
            shop=shop,
            instrument=instrument,
            rows=tracked(read_manifest(manifest), "reading the spray-outs", disable=json_output),
        )
    rows, cases = [n for n, _ in numbered], [c for _, c in numbered]
    engine = open_database(database)
    stored = existing_case_ids(engine, (c.case_id for c in cases))
    if stored:
        number, case = next((n, c) for n, c in zip(rows, cases, strict=True) if c.case_id in stored)
        raise FlakelabError(
            f"{manifest}: row {number}: case {case.case_id} is already recorded in "
            f"{database_label(engine)} "
            f"({len(stored)} of the {len(cases)} rows are); nothing was stored"
        )
    left = _left_by_storing(engine, cases, "recorded")
    with interrupted(left):  # one transaction: a writer in between is refused whole
        add_cases(engine, cases)
    worst, where = worst_differences(cases)
    checks, unchecked = [None] * len(cases), None
    if check:
        with interrupted(left):
            checks, unchecked = recorded_checks(cases, lib, existing_engine(database))
    recorded = [
        {
            "row": number,
            "case_id": c.case_id,
            "shop": c.shop,
            "colour_code": c.colour_code,
            "instrument": c.instrument,
            "outcome": c.outcome,
            "target_recovered": c.target_recovered,
            "sprayout_recovered": c.sprayout_recovered,
            "created_at": c.created_at.isoformat(),
            "worst_de00": round(float(de), 3),
            "worst_geometry": g,
            "from_prediction": found,
        }
        for number, c, de, g, found in zip(rows, cases, worst, where, checks, strict=True)
    ]
    mismatched = [row for row in recorded if is_mismatched(row["from_prediction"])]
    readers = [instruments_reading(c.geometry_names) for c in cases]
    learners = {model: sum(model in r for r in readers) for model in INSTRUMENT_GEOMETRIES}
    report = {
        "manifest": str(manifest),
        "recorded": len(cases),
        "outcomes": {o: sum(c.outcome == o for c in cases) for o in OUTCOMES},
        "cases_per_model": learners,
        "tolerance": tol.name,
        "cases": recorded,
        "mismatched_rows": [row["row"] for row in mismatched],
        "from_prediction_unchecked": unchecked,
        "database": str(engine.url),
        "cases_in_database": count_cases(engine),
    }
    if json_output:
        print_report(report)
        return
    title = f"Recorded {counted(len(cases), 'spray-out')} from {manifest}"
    table = Table(title=title, box=box.SIMPLE_HEAD)
    table.add_column("row", justify="right")
    columns = ("case", "shop", "outcome", "worst ΔE00", "from prediction", "instrument")
    for column in columns if check else tuple(c for c in columns if c != "from prediction"):
        table.add_column(column, no_wrap=column != "shop")
    for row in recorded:
        cells = [str(row["row"]), row["case_id"], row["shop"], row["outcome"]]
        cells.append(_worst_cell(row))
        cells += [_shown_check(row["from_prediction"])] if check else []
        table.add_row(*cells, row["instrument"])
    console.print(table)
    _tell_recovered(recorded)
    counts = ", ".join(f"{n} {o}" for o, n in report["outcomes"].items() if n)
    models = ", ".join(f"{m} {n}" for m, n in learners.items() if n) or "none"
    console.print(f"outcomes: {counts}; cases each model learns from: {models}", highlight=False)
    _tell_mix_ups(len(mismatched), f"rows {', '.join(str(r['row']) for r in mismatched)}",
                  unchecked)  # fmt: skip
    count = report["cases_in_database"]
    errors.print(f"{counted(count, 'case')} in {database_label(engine)}", highlight=False)


@cases_app.command("list")
@reports_errors
def list_cases(
    shop: Annotated[
        str | None, typer.Option(callback=shop_spelled, help="Only this shop's cases.")
    ] = None,
    colour_code: ColourCodeOption = None,
    since: SinceOption = None,
    last: Annotated[
        int, typer.Option(min=1, max=COUNT_MAX, help="How many of the newest cases.")
    ] = 20,
    check: Annotated[
        bool,
        typer.Option(
            "--check",
            help="Also each spray-out's worst ΔE00 from its recipe's prediction by the current "
            "model (with the shop's stored habits), as 'cases record' checks it.",
        ),
    ] = False,
    mix_ups: Annotated[
        bool,
        typer.Option(
            "--mix-ups",
            help="Only the likely mix-ups among them: spray-outs further than SPRAYOUT_MISMATCH "
            "from their recipe's prediction (checks them).",
        ),
    ] = False,
    library: LibraryOption = None,
    database: DatabaseOption = None,
    json_output: JsonOption = False,
) -> None:
    """The newest cases: outcome, recipe and each spray-out's worst ΔE00 from its target.

    Newest first, with when each was made, its id (for 'cases remove') and the geometry of
    the worst ΔE00; with --check, how far each spray-out lies from its recipe's prediction."""
    from flakelab.cases.case import tin_fields, worst_differences
    from flakelab.cases.database import SHORT_ID_LENGTH, latest_cases, open_database, short_id

    engine = open_database(database, must_exist=True)
    cases = latest_cases(engine, last, shop=shop, colour_code=colour_code, since=since)
    worst, where = worst_differences(cases) if cases else ([], [])
    rows = [
        {
            "case_id": c.case_id,
            "created_at": c.created_at.isoformat(),
            "shop": c.shop,
            "colour_code": c.colour_code,
            "instrument": c.instrument,
            "outcome": c.outcome,
            "synthetic": c.synthetic,
            "target_recovered": c.target_recovered,
            "sprayout_recovered": c.sprayout_recovered,
            "recipe": {k: round(v, 6) for k, v in sorted(c.recipe.items(), key=lambda t: -t[1])},
            "tins": {name: tin_fields(tin) for name, tin in sorted(c.tins.items())},
            "worst_de00": round(float(de), 3),
            "worst_geometry": g,
        }
        for c, de, g in zip(cases, worst, where, strict=True)
    ]
    shops = sorted({c.shop for c in cases})
    checked, unchecked = check or mix_ups, None
    if checked and cases:
        from flakelab.io import read_library
        from flakelab.match.mixups import is_mismatched, recorded_checks

        checks, unchecked = recorded_checks(cases, read_library(library), engine)
        for row, found in zip(rows, checks, strict=True):
            row["from_prediction"] = found
        if unchecked and mix_ups:
            raise FlakelabError(f"--mix-ups: not checked against a model: {unchecked}")
        if mix_ups:
            rows = [row for row in rows if is_mismatched(row["from_prediction"])]
    if json_output:
        report = {"database": str(engine.url), "cases": rows}
        if checked:
            report["from_prediction_unchecked"] = unchecked
        print_report(report)
        return
    whose = f"{shops[0]!r}" if len(shops) == 1 else "every shop"
    chosen = (f" of colour code {colour_code!r}" if colour_code else "") + (
        f" since {shown_time(since)}" if since else ""
    )
    if not rows:  # which cases were looked at: the newest alone, not the whole history
        of = (f"shop {shop!r}" if shop else "any shop") + chosen
        of += cases_hint_in(engine, shop, colour_code) if not cases else ""
        newest = "the newest " if len(cases) == last else "the "
        more = " (--last N checks more of them)" if len(cases) == last else ""
        none = (
            f"no likely mix-ups among {newest}{counted(len(cases), 'case')} of {of} in "
            f"{database_label(engine)}{more}"
            if cases
            else f"no cases of {of} in {database_label(engine)}"
        )
        errors.print(none, highlight=False)
        return
    title = "Likely mix-ups among the newest" if mix_ups else "Newest"
    table = Table(
        title=f"{title} {counted(len(cases), 'case')} of {whose}{chosen} in "
        f"{database_label(engine)}",
        box=box.SIMPLE_HEAD,
        collapse_padding=True,
    )
    codes = any(row["colour_code"] for row in rows)
    for column in ("made", "case", *(["colour code"] * codes), "outcome", "worst ΔE00"):
        right = "right" if "ΔE" in column else "left"
        table.add_column(column, no_wrap=column != "colour code", justify=right)
    if checked:  # in the recipe's place, which --json keeps
        table.add_column("from prediction", no_wrap=True, justify="right")
    else:
        table.add_column("recipe (share)")
    if len(shops) > 1:
        table.add_column("shop")
    for row in rows:
        cells = [
            shown_time(row["created_at"]),
            short_id(row["case_id"]),
            *([row["colour_code"]] * codes),
            row["outcome"],
            _worst_cell(row),
        ]
        if checked:
            cells.append(_shown_check(row.get("from_prediction")))
        else:
            cells.append(shares_text(row["recipe"], 2))
        if len(shops) > 1:
            cells.append(row["shop"] + (" [dim](synthetic)[/]" if row["synthetic"] else ""))
        table.add_row(*cells)
    console.print(table)
    _tell_recovered(rows)
    if any(short_id(row["case_id"]) != row["case_id"] for row in rows):
        errors.print(
            f"ids shortened to their first {SHORT_ID_LENGTH} characters: 'cases remove' takes "
            "any unique beginning of one; --json gives them whole",
            style="dim",
            highlight=False,
        )
    _tell_mix_ups(0, "", unchecked)


RECOVERED_MARKS = {"target_recovered": "*", "sprayout_recovered": "†"}
"""How a table of cases marks a target (a spray-out) known by its L*a*b* alone."""


def _worst_cell(row: dict) -> str:
    """A case's worst ΔE00 and its geometry, marked where a reading is known by its colour
    alone (:func:`_tell_recovered`)."""
    marks = "".join(mark for flag, mark in RECOVERED_MARKS.items() if row[flag])
    return f"{row['worst_de00']:.2f} {row['worst_geometry']}{marks}"


def _tell_recovered(rows: list[dict]) -> None:
    """The footnotes of a table of cases some of whose readings are known by their colour
    alone."""
    from flakelab.cases.case import recovered_note

    for flag, mark in RECOVERED_MARKS.items():
        if any(row[flag] for row in rows):
            target = flag == "target_recovered"  # what a model learns: the spray-out's say
            note = recovered_note(target, not target, learning=not target)
            errors.print(f"{mark} {note}", style="dim", highlight=False)


def _left_by_storing(engine, cases: list, verb: str, some_stored: bool = False):
    """What a Ctrl-C left where ``cases`` go into the database in one transaction, all or
    none, and are checked against a model after it: asked of the database, since a signal
    that meets the commit is raised once it is done. With ``some_stored``, those stored
    before are told apart (read now, before the transaction)."""
    from flakelab.cases.database import existing_case_ids

    ids = [case.case_id for case in cases]
    before = existing_case_ids(engine, ids) if some_stored else set()

    def left() -> str:
        stored = len(existing_case_ids(engine, ids) - before)
        if not stored:
            return f"nothing was {verb}; {database_label(engine)} is as it was"
        which, were = (
            ("the case", "it was") if stored == 1 else (counted(stored, "case"), "they were")
        )
        return (
            f"{database_label(engine)} holds {which} {verb}; {were} not checked against a model "
            "('cases list --mix-ups' checks them)"
        )

    return left


def _tell_mix_ups(count: int, which: str, unchecked: str | None) -> None:
    """Warn of ``count`` likely mix-ups stored (``which`` names them), or say why none was
    checked."""
    from flakelab.match.mixups import SPRAYOUT_MISMATCH

    if count:
        errors.print(
            f"[yellow]warning:[/] {counted(count, 'spray-out')} further than ΔE00 "
            f"{SPRAYOUT_MISMATCH:g} from what their recipe predicts, likely mix-ups (another "
            f"panel, recipe or target), {which}: stored all the same; 'cases habits' leaves them "
            "out, 'cases remove' removes them",
            highlight=False,
        )
    elif unchecked:
        errors.print(f"note: not checked against a model: {unchecked}", highlight=False)


def _shown_check(check: dict | None) -> str:
    """A :func:`~flakelab.match.mixups.recorded_checks` entry for a table: the worst ΔE00
    and its geometry, red beyond SPRAYOUT_MISMATCH; empty where no model reads the case."""
    from flakelab.match.mixups import is_mismatched

    if check is None:
        return ""
    shown = f"{check['de00']:.2f} {check['geometry']}"
    return f"[red]{shown}[/]" if is_mismatched(check) else shown


@cases_app.command("nearest")
@reports_errors
def nearest(
    target: Annotated[Path, typer.Argument(help="Target measurement file (the car).")],
    sample: SampleOption = None,
    average: AverageOption = False,
    database: CaseSourceOption = None,
    shop: ShopOption = None,
    colour_code: ColourCodeOption = None,
    since: SinceOption = None,
    instrument: InstrumentOption = DEFAULT_INSTRUMENT,
    tolerance: ToleranceOption = DEFAULT_TOLERANCE,
    count: Annotated[
        int, typer.Option("--count", "-n", min=1, max=COUNT_MAX, help="Cases to show.")
    ] = 5,
    recipe_out: Annotated[
        Path | None,
        typer.Option(
            help="Write the recipe of case --pick, weighed for --quantity, as a file "
            "{toner: grams} that 'weigh', 'correct' and 'cases record' read."
        ),
    ] = None,  # fmt: skip
    pick: Annotated[
        int, typer.Option(min=1, max=COUNT_MAX, help="The case --recipe-out writes.")
    ] = 1,
    quantity: Annotated[
        str, typer.Option(help="Can --recipe-out weighs, e.g. 250g (or by volume, 0.5l).")
    ] = CAN_QUANTITY,
    resolution: ResolutionOption = SCALE_RESOLUTION_G,
    library: LibraryOption = None,
    json_output: JsonOption = False,
) -> None:
    """The shop's recorded recipes whose spray-outs lie closest to a car, nearest first.

    A recipe that already gave a panel near this colour, in this shop, is the surest
    start: ranked by the worst geometry's share of --tolerance, the spray-out against the
    target (the car each was mixed for, and texture, shown beside)."""
    from flakelab.cases.database import default_url
    from flakelab.io import read_library, read_tolerance, write_recipe
    from flakelab.match.recipe import order_can, weigh

    tol = read_tolerance(tolerance)
    check_output_file(recipe_out, "--recipe-out", reads={
        "TARGET": target, "--database": database, "--library": library,
        "--tolerance": tolerance})  # fmt: skip
    if pick > count:
        raise FlakelabError(f"--pick: {pick} is more than the {counted(count, 'case')} shown")
    geometries = INSTRUMENT_GEOMETRIES[instrument_key(instrument)]
    can = order_can(quantity, resolution)  # a can the scale cannot weigh: before the search
    reading = read_reading_at(target, sample, average, geometries, instrument)
    source = database or default_url()
    spectra = reading.storage_spectra(list(geometries))
    found, searched = recorded_nearest(source, shop, geometries, spectra, tol, count,
                                       reading.texture, colour_code, since=since)  # fmt: skip
    if not searched:
        raise FlakelabError(
            f"{source}: no cases {which_cases(shop, since, colour_code)}"
            f"{cases_hint_in(source, shop, colour_code)} read at the geometries "
            f"{tuple(geometries)}"
        )
    report = {
        "target": reading.sample,
        "cases": hidden_passwords(source),
        "cases_searched": searched,
        "shop": shop,
        "colour_code": colour_code,
        "since": since and since.isoformat(),  # zoned as typed (typed_time)
        "geometries": list(geometries),
        "tolerance": tol.name,
        "nearest": [near.to_dict() for near in found],
    }
    if recipe_out is not None:
        if pick > len(found):
            shown = counted(len(found), "case")
            raise FlakelabError(f"--pick: {pick} is more than the {shown} found")
        fractions = dict(found[pick - 1].case.recipe)
        grams = can.for_toners(read_library(library), fractions).grams_for(fractions)
        write_recipe({ln.toner: ln.grams for ln in weigh(fractions, grams, resolution)}, recipe_out)
        report["recipe_out"] = {"file": str(recipe_out), "case": pick, "quantity_g": grams}
        errors.print(f"wrote case {pick}'s recipe, {grams:g} g, to {recipe_out}", highlight=False)
    if json_output:
        print_report(report)
        return
    _print_nearest(report)


def recorded_nearest(
    source: str,
    shop,
    geometries,
    spectra,
    tolerance,
    count: int,
    texture,
    colour_code=None,
    cases: list | None = None,
    since: datetime | None = None,
):
    """The ``count`` recorded cases of ``source`` (a database, or a case file; ``shop``'s, of
    ``colour_code``, made at or after ``since``, where given) whose spray-outs lie closest to
    ``spectra`` at ``geometries``, and how many were searched; a database gives only its
    spray-outs until the nearest are known. ``cases``: those cases, where the caller read them
    whole already (:func:`recorded_cases`)."""
    from flakelab.cases.database import open_database
    from flakelab.cases.exchange import is_case_file
    from flakelab.cases.nearest import nearest_cases, nearest_stored_cases

    if cases is None and is_case_file(Path(source)):
        cases = recorded_cases(source, shop, geometries, colour_code, since)
    if cases is not None:
        found = nearest_cases(spectra, cases, tolerance, count, texture) if cases else []
        return found, len(cases)
    engine = open_database(source, must_exist=True)
    return nearest_stored_cases(engine, spectra, tuple(geometries), tolerance, count, shop=shop,
                                colour_code=colour_code, since=since,
                                target_texture=texture)  # fmt: skip


def recorded_cases(source: str, shop, geometries, colour_code=None, since=None) -> list:
    """The recorded cases of ``source`` (a case file, or a database that must exist;
    ``shop``'s, of ``colour_code``, made at or after ``since``, where given) read at
    ``geometries``, restricted to them."""
    from flakelab.cases.case import cases_at
    from flakelab.cases.database import iter_cases, open_database
    from flakelab.cases.exchange import is_case_file
    from flakelab.cli.sources import load_cases

    if is_case_file(Path(source)):
        return cases_at(load_cases(source, shop, since, colour_code), geometries)
    engine = open_database(source, must_exist=True)
    return cases_at(iter_cases(engine, shop=shop, colour_code=colour_code, since=since), geometries)


def _print_nearest(report: dict) -> None:
    """The nearest cases as a colorist reads them, and what to do next."""
    rows = report["nearest"]
    shops = sorted({row["shop"] for row in rows})
    whose = f" of {shops[0]!r}" if len(shops) == 1 else ""
    code = f" of colour code {report['colour_code']!r}" if report["colour_code"] else ""
    code += f" since {shown_time(report['since'])}" if report.get("since") else ""
    title = (
        f"The {len(rows)} of {report['cases_searched']} cases{whose}{code} whose spray-outs "
        f"lie closest to {report['target']} ({report['tolerance']})"
    )
    console.print(nearest_table(rows, title))
    passing = sum(row["passes"] for row in rows)
    if passing:
        console.print(
            f"{counted(passing, 'recipe')} of the shop already gave a panel within "
            f"{report['tolerance']} of this car: start from the first (--recipe-out), and "
            "correct it from its spray-out",
            highlight=False,
        )
    else:
        console.print(
            f"[yellow]note:[/] no recorded spray-out is within {report['tolerance']} of this "
            "car: match it (flakelab match TARGET)",
            highlight=False,
        )


def nearest_table(rows: list[dict], title: str) -> Table:
    """Recorded cases (:meth:`~flakelab.cases.nearest.NearCase.to_dict`) as a table: the
    spray-out's worst ΔE00 from the target (green where it passes), its own car's, the
    recipe; the shop where they come from several."""
    from flakelab.cases.database import short_id

    shops = sorted({row["shop"] for row in rows})
    codes = any(row["colour_code"] for row in rows)
    table = Table(title=title, box=box.SIMPLE_HEAD, collapse_padding=True)
    columns = ["#", "case", "made", *(["colour code"] * codes), "outcome", "spray-out ΔE00",
               "its car", "recipe (share)"]  # fmt: skip
    for column in columns + (["shop"] if len(shops) > 1 else []):
        right = column in ("#", "spray-out ΔE00", "its car")
        wraps = column in ("colour code", "recipe (share)", "shop")
        table.add_column(column, justify="right" if right else "left", no_wrap=not wraps)
    for k, row in enumerate(rows, 1):
        colour = "green" if row["passes"] else "red"
        cells = [
            str(k),
            short_id(row["case_id"]),
            shown_time(row["created_at"], day=True),
            *([row["colour_code"]] * codes),
            row["outcome"],
            f"[{colour}]{row['sprayout_de00_max']:.2f}[/] {row['worst_geometry']}",
            f"{row['target_de00_max']:.2f}",
            shares_text(row["recipe"]),
        ]
        table.add_row(*cells, *([row["shop"]] if len(shops) > 1 else []))
    return table


@cases_app.command("remove")
@reports_errors
def remove(
    case_id: Annotated[
        str | None,
        typer.Argument(
            help="The case to remove: its id, or any unique beginning of it ('cases "
            "list' shows them).",
            show_default=False,
        ),  # fmt: skip
    ] = None,
    synthetic: Annotated[
        bool,
        typer.Option(
            "--synthetic",
            help="Remove every synthetic case instead ('cases generate'), of --shop alone "
            "where given; the recorded cases stay.",
        ),
    ] = False,
    shop: Annotated[
        str | None,
        typer.Option(
            callback=shop_spelled, help="With --synthetic: only this shop's synthetic cases."
        ),
    ] = None,
    yes: Annotated[bool, typer.Option("--yes", help="Remove without asking.")] = False,
    database: DatabaseOption = None,
) -> None:
    """Remove one case recorded by mistake (the wrong spray-out or recipe), or every
    synthetic case: a generation stored among the shop's recorded cases."""
    from flakelab.cases.database import find_case_id, open_database, remove_case

    if (case_id is None) == (not synthetic):
        raise FlakelabError("expected a case id or --synthetic (one of them)")
    if shop is not None and not synthetic:
        raise FlakelabError("--shop: with --synthetic (a case id names one case)")
    engine = open_database(database, must_exist=True)
    if synthetic:
        _remove_synthetic(engine, shop, yes)
        return
    try:
        case_id = find_case_id(engine, case_id)
    except FlakelabError as error:
        raise FlakelabError(f"{error}; nothing was removed") from None
    where = database_label(engine)
    _confirm(f"remove case {case_id} from {where}?", f"cases remove {case_id}", yes)
    case = remove_case(engine, case_id)
    what = (
        "its stored values could not be read"
        if case is None
        else f"{case.shop}, {case.outcome}, {shown_time(case.created_at)}"
    )
    errors.print(f"removed case {case_id} ({what}) from {where}", highlight=False)


def _confirm(question: str, command: str, yes: bool) -> None:
    """Go on only with ``--yes``, or once the user says so at a terminal."""
    import sys

    if yes:
        return
    if not sys.stdin.isatty():
        raise FlakelabError(f"{command}: confirm with --yes")
    typer.confirm(question, abort=True)


def _remove_synthetic(engine, shop: str | None, yes: bool) -> None:
    """``cases remove --synthetic``: every synthetic case (of ``shop``), asked first with
    how many of each shop."""
    from flakelab.cases.database import remove_synthetic_cases, synthetic_cases

    of = f" of shop {shop!r}" if shop else ""
    where = database_label(engine)
    held = synthetic_cases(engine, shop)
    if not held:
        of += cases_hint_in(engine, shop)
        errors.print(f"no synthetic cases{of} in {where}; nothing was removed", highlight=False)
        return
    _confirm(f"remove {_by_shop(held)} from {where}?", "cases remove --synthetic", yes)
    removed = remove_synthetic_cases(engine, shop)
    kept = sum(synthetic_cases(engine, recorded=True).values())
    stay = f"; its {counted(kept, 'recorded case')} stay" if kept else ""
    errors.print(f"removed {_by_shop(removed)} from {where}{stay}", highlight=False)


def _by_shop(counts: dict[str, int]) -> str:
    """'520 synthetic cases (synthetic shop 500, north 20)'."""
    shops = ", ".join(f"{shop} {n}" for shop, n in counts.items())
    return f"{counted(sum(counts.values()), 'synthetic case')} ({shops})"


@cases_app.command("export")
@reports_errors
def export_cases(
    target: Annotated[Path, typer.Argument(help="CSV or CxF3 file to write.")],
    database: DatabaseOption = None,
    shop: ShopOption = None,
    since: SinceOption = None,
    colour_code: ColourCodeOption = None,
    instrument: Annotated[
        str | None,
        typer.Option(
            "--instrument",
            "-i",
            callback=instrument_spelled,
            help="Only the cases read at this instrument's geometries, at those alone.",
            show_default="every case, at every geometry it was read at",
        ),
    ] = None,
    decimal_comma: Annotated[
        bool,
        typer.Option(
            "--decimal-comma",
            help="A CSV as a spreadsheet opens it in most of Europe: cells separated by "
            "semicolons, readings with a decimal comma ('cases import' reads it back).",
        ),
    ] = False,
) -> None:
    """Export case histories as CSV or CxF3: a shop's, since a date, of a colour code, at one
    geometry set."""
    from flakelab.cases.case import select_cases
    from flakelab.cases.database import count_cases, iter_cases, open_database
    from flakelab.cases.exchange import check_case_file_suffix, write_cases

    check_case_file_suffix(target, decimal_comma=decimal_comma)
    # before the database is read
    check_output_file(target, "TARGET", reads={"--database": database})
    geometries = instrument and INSTRUMENT_GEOMETRIES[instrument_key(instrument)]
    engine = open_database(database, must_exist=True)
    chosen = {"shop": shop, "since": since, "colour_code": colour_code}
    stored = count_cases(engine, **chosen)  # 30,000 cases: 6 s to read
    read = tracked(iter_cases(engine, **chosen), "reading the cases", total=stored)
    cases = select_cases(read, geometries=geometries)
    if not cases:
        at = f" read at the {instrument}'s geometries" if instrument else ""
        raise FlakelabError(
            f"{database_label(engine)}: no cases {which_cases(**chosen)}"
            f"{cases_hint_in(engine, shop, colour_code)}{at}; nothing written"
        )
    with progress_bar() as bar:  # and 4 s to write
        task = bar.add_task(f"writing {target.name}", total=len(cases))
        write_cases(cases, target, decimal_comma=decimal_comma, progress=lambda: bar.advance(task))
    errors.print(f"wrote {counted(len(cases), 'case')} to {target}", highlight=False)


@cases_app.command("realism")
@reports_errors
def realism(
    seed: Annotated[int, seed_option("Seed.")] = 0,
    n: Annotated[
        int, typer.Option("--n", min=20, max=COUNT_MAX, help="Formulations per statistic.")
    ] = 400,
    instrument: InstrumentOption = DEFAULT_INSTRUMENT,
    library: LibraryOption = None,
    plot: Annotated[
        Path | None,
        typer.Option(
            "--plot",
            help="Also draw each statistic's draws beside the range a real shop shows (PNG, PDF "
            "or SVG).",
        ),
    ] = None,
    json_output: JsonOption = False,
) -> None:
    """How hard the generated world is: remeasure, respray, batch and weathering ΔE00.

    Each beside the range a real shop shows, and the texture readings'
    repeatability."""
    from flakelab.cases.generator import REALISTIC_RANGES, World
    from flakelab.io import read_library

    check_figure_file(plot, "--plot")
    draws = World(read_library(library), instrument).realism_draws(n, seed)
    report = draws.summary()
    ranges = REALISTIC_RANGES
    report["realistic_ranges"] = ranges
    if plot is not None:
        from flakelab.render.plots import plot_realism

        title = f"Generated world, {instrument} (seed {seed}, {n} formulations)"
        plot_realism(draws, ranges, plot, title=title)
        report["plot"] = str(plot)
        errors.print(f"wrote {plot}", highlight=False)
    if json_output:
        print_report(report)
        return
    table = Table(
        title=f"Generated world realism (seed {seed}, {n} formulations)", box=box.SIMPLE_HEAD
    )
    for column in ("statistic", "value", "realistic range"):
        table.add_column(column)
    for key, (lo, hi) in ranges.items():
        shown = f"{lo}–{hi}" + (" (metallics)" if key == "respray_de00_median" else "")
        table.add_row(key, f"{report[key]:.3f}", shown)
    for family, value in report["respray_de00_median_by_family"].items():
        table.add_row(f"respray_de00_median, {family}s", f"{value:.3f}", "")
    table.add_row("near_black_share", f"{report['near_black_share']:.3f}",
                  "(nominal L* < 1 at every geometry: no real paint reads so dark)")  # fmt: skip
    for key in ("exact_model_de00_mean", "exact_model_de00_p95"):
        table.add_row(key, f"{report[key]:.3f}", "(the cases' noise floor)")
    for family, value in report["exact_model_de00_mean_by_family"].items():
        table.add_row(f"exact_model_de00_mean, {family}s", f"{value:.3f}", "")
    for reading, value in report["remeasure_texture_median"].items():
        table.add_row(f"remeasure_texture_median, |Δ{reading}|", f"{value:.3f}", "(effect paints)")
    console.print(table)


@cases_app.command("habits")
@reports_errors
def habits(
    cases: CasesArgument,
    shop: ShopModelOption = None,
    since: SinceOption = None,
    model: ModelFileOption = None,
    instrument: InstrumentOption = DEFAULT_INSTRUMENT,
    library: LibraryOption = None,
    database: DatabaseOption = None,
    out: Annotated[
        Path | None,
        typer.Option("--out", "-o", help="Write them as a habits file (match/correct --habits)."),
    ] = None,
    save: Annotated[
        bool,
        typer.Option(
            "--save", help="Store them in the database for the shop (match/correct --shop)."
        ),
    ] = False,
    plot: Annotated[
        Path | None,
        typer.Option(help="Figure (PNG/PDF/SVG): the spray-outs' offsets and the habits'."),
    ] = None,
    prior: Annotated[
        bool,
        typer.Option(
            "--prior/--no-prior",
            help="Draw habits read from few spray-outs towards none (PRIOR_SD).",
        ),
    ] = True,
    no_tins: NoTinsOption = False,
    json_output: JsonOption = False,
) -> None:
    """A shop's habits from its spray-outs: film build, flake alignment, instrument gain.

    Each as the shop's mean against the model's cases (the current model, the shop's own with
    --shop where one was adapted to it), read through the physics of application. Cases that
    record the tins their recipe was poured from are read at the standard tins, as the model
    predicts for the tins ('match --lots'): the tins' strengths and shades are then not
    taken for the shop's film build and gain."""
    from flakelab.cases.database import open_database
    from flakelab.match.habits import (
        MIN_DRIFT_CASES,
        PRIOR_SD,
        habits_drift,
        habits_fit,
        save_habits,
        screened_habits,
        write_habits,
    )
    from flakelab.match.mixups import SPRAYOUT_MISMATCH

    reads = {"CASES": cases, "--model": model, "--library": library, "--database": database}
    check_figure_file(plot, "--plot", reads=reads)
    check_output_file(out, "--out", reads=reads, writes={"--plot": plot})
    if save:  # a command that stores creates its database, as the others do
        open_database(database)
    lib, forward = learned_forward(library, instrument, model, database, shop)
    learned = forward.model
    chosen = shop_cases(cases, shop, learned.geometries, since)
    chosen.sort(key=attrgetter("created_at"))  # in the order made: the change check splits it
    shops = {c.shop for c in chosen}
    if save and shop is None and len(shops) > 1:
        raise FlakelabError(f"{cases}: cases of {len(shops)} shops; name the one to save (--shop)")
    data, tinned = recorded_tins_used(source_arrays(cases, chosen, lib), lib, no_tins)
    # three stages: the habits less the mix-ups, how far they explain, whether they changed
    # (a shop's history of 30,000 spray-outs: 42 s)
    with progress_bar(json_output) as bar:
        stage = bar.add_task(f"reading the habits of {counted(len(chosen), 'spray-out')}", total=3)
        found, mixed_up = screened_habits(
            forward, lib, data.x, data.R, prior_sd=PRIOR_SD if prior else None
        )
        bar.advance(stage)
        if mixed_up.all():
            raise FlakelabError(
                f"{cases}: every spray-out lies further than ΔE00 {SPRAYOUT_MISMATCH:g} from "
                "the model's prediction of its recipe: are these the model's toners and "
                "geometries?"
            )
        left_out = [c.case_id for c, m in zip(chosen, mixed_up, strict=True) if m]
        if left_out:  # the habits were read from the others, and so is the rest
            chosen = [c for c, m in zip(chosen, mixed_up, strict=True) if not m]
            data = data.subset(np.flatnonzero(~mixed_up))
            tinned = tinned[~mixed_up]
        found = replace(
            found,
            shop=shop or (shops.pop() if len(shops) == 1 else None),
            cases_with_tins=int(tinned.sum()),
        )
        fit = habits_fit(forward, lib, found, data.x, data.R)
        bar.advance(stage)
        drifting = len(chosen) >= MIN_DRIFT_CASES
        drift = habits_drift(forward, lib, data.x, data.R) if drifting else None
        bar.advance(stage)
    if drift and drift["changed"].any():  # kept with the habits, so that their users are told
        found = replace(found, changed_since=chosen[drift["split"]].created_at.isoformat())
    if out is not None:
        write_habits(found, out)
    if save:
        save_habits(open_database(database), found, learned.instrument)
    if plot is not None:
        from flakelab.render.plots import plot_habits

        plot_habits(
            fit,
            plot,
            title=f"Habits of {found.shop or hidden_passwords(cases)}: {found.describe()}",
            scan=drift and _scan_for_plot(drift, chosen),
        )
    report = found.report() | {
        "file": str(out) if out else None,
        "saved": save,
        "explained": {k: v.tolist() if hasattr(v, "tolist") else v for k, v in fit.items()},
        "drift": drift and _drift_report(drift, chosen),
        "left_out_mismatched": left_out,
    }
    if json_output:
        print_report(report)
        return
    whose = shop or hidden_passwords(cases)
    _print_habits(report, fit, f"Habits of {whose} against {model or 'the current model'}")


def _scan_for_plot(drift: dict, chosen: list) -> dict:
    """The change scan by the time of each split, for :func:`~flakelab.render.plots.plot_habits`."""
    from flakelab.match.habits import DRIFT_Z, HABITS

    return {
        "when": [chosen[k].created_at for k in drift["scan"]["splits"]],
        "z": drift["scan"]["z"],
        "names": [name.replace("_", " ") for name in HABITS],
        "bar": DRIFT_Z,
        "split_when": chosen[drift["split"]].created_at,
        "changed": bool(drift["changed"].any()),
    }


def _drift_report(drift: dict, chosen: list) -> dict:
    """Where the habits changed over the cases, and the habits before and after."""
    from flakelab.match.habits import HABITS

    split = chosen[drift["split"]].created_at
    changed = [n for n, c in zip(HABITS, drift["changed"], strict=True) if c]
    early, late = drift["early"].report(), drift["late"].report()
    message = (
        "the habits changed over these cases: "
        + ", ".join(f"{n.replace('_', ' ')} {early[n]:+.2%} → {late[n]:+.2%}" for n in changed)
        + f" from about {shown_time(split)} (the last {len(chosen) - drift['split']} of "
        f"{counted(len(chosen), 'case')}); read them from those cases with {since_option(split)}"
    )
    return {
        "split_at": split.isoformat(),
        "cases_before": drift["split"],
        "early": early,
        "late": late,
        "z": dict(zip(HABITS, drift["z"].round(2).tolist(), strict=True)),
        # the Student's t degrees of freedom z was read with; null: a habit not shown
        "dof": {
            name: round(float(dof), 1) if np.isfinite(dof) else None
            for name, dof in zip(HABITS, drift["dof"], strict=True)
        },
        "changed": changed,
        "message": message if changed else None,
    }


def _print_habits(report: dict, fit: dict, title: str) -> None:
    """A shop's habits as a table of estimates and meanings, how much of the spray-outs'
    offsets they explain (``fit``), and what was left out or has changed."""
    from flakelab.match.habits import habit_meaning
    from flakelab.match.mixups import SPRAYOUT_MISMATCH

    table = Table(title=title, box=box.SIMPLE_HEAD)
    for column in ("habit", "estimate", "± s.e.", "meaning"):
        table.add_column(column, justify="right")
    rows = (("film build", "film_build", ".1%"), ("flake spread", "flake_spread", ".1%"),
            ("instrument gain", "instrument_gain", ".2%"))  # fmt: skip
    for name, key, fmt in rows:
        se = report[key + "_se"]  # None: no spray-out moves with it (flakes, in a shop of solids)
        meaning = habit_meaning(key, report[key], se)
        table.add_row(name, f"{report[key]:+{fmt}}", "" if se is None else f"{se:{fmt}}", meaning)
    console.print(table)
    console.print(_explained_table(fit))
    if report["drift"] and report["drift"]["changed"]:
        errors.print(f"[yellow]warning:[/] {report['drift']['message']}", highlight=False)
    if left_out := report["left_out_mismatched"]:
        errors.print(
            f"[yellow]warning:[/] left out {counted(len(left_out), 'spray-out')} further than ΔE00 "
            f"{SPRAYOUT_MISMATCH:g} from the model's prediction with these habits, likely "
            f"mix-ups (another panel, recipe or target): {', '.join(left_out[:5])}"
            + (" …" if len(left_out) > 5 else ""),
            highlight=False,
        )
    errors.print(
        f"from {report['cases']} spray-outs"
        + (
            f", {report['cases_with_tins']} of them read at the tins they record"
            if report["cases_with_tins"]
            else ""
        )
        + (f"; written to {report['file']}" if report["file"] else "")
        + (f"; stored for {report['shop']!r}" if report["saved"] else ""),
        highlight=False,
    )


def _explained_table(fit: dict) -> Table:
    """Per geometry: the spray-outs' mean ΔE00 from the model alone and with the habits."""
    table = Table(title="Mean ΔE00 of the spray-outs from the model", box=box.SIMPLE_HEAD)
    table.add_column("")
    for name in [*fit["geometries"], "mean"]:
        table.add_column(name, justify="right")
    for label, key in (("model alone", "de00_model"), ("with the habits", "de00_habits")):
        values = [*fit[key], fit[key].mean()]
        table.add_row(label, *(f"{v:.2f}" for v in values))
    return table


@cases_app.command("shops")
@reports_errors
def shops(database: DatabaseOption = None, json_output: JsonOption = False) -> None:
    """The shops in the database: their cases by outcome, their stored habits and tins, and
    their own models (adapted to their cases: 'flakelab model adapt --shop')."""
    from flakelab.cases.case import OUTCOMES
    from flakelab.cases.database import open_database, shop_summary
    from flakelab.cases.shop_lots import list_stored_lots
    from flakelab.match.habits import ShopHabits, list_habits
    from flakelab.models.registry import shop_models

    engine = open_database(database, must_exist=True)
    habits = {h["shop"]: h for h in list_habits(engine)}
    tins = {t["shop"]: t for t in list_stored_lots(engine)}
    models = shop_models(engine)
    rows = [
        s | {"first": s["first"].isoformat(), "last": s["last"].isoformat()}
        for s in shop_summary(engine)
    ]
    named = {row["shop"] for row in rows}
    rows += [{"shop": name, "cases": 0} for name in sorted({*habits, *tins, *models} - named)]
    for row in rows:
        row["habits"] = habits.get(row["shop"])
        row["tins"] = tins.get(row["shop"])
        row["models"] = models.get(row["shop"], [])
    if json_output:
        print_report({"shops": rows})
        return
    table = Table(title=f"Shops in {database_label(engine)}", box=box.SIMPLE_HEAD)
    columns = ("shop", "cases", " / ".join(OUTCOMES), "last case", "habits", "tins", "own model")
    for column in columns:
        table.add_column(column)
    for row in rows:
        outcomes = row.get("outcomes", {})
        h, t = row["habits"], row["tins"]
        read, saved = (
            shown_time(h and h["created_at"], day=True),
            shown_time(t and t["saved_at"], day=True),
        )
        habits = h and f"{ShopHabits.from_report(h).describe()}, {read}"
        tins = t and f"{t['tins']}, version {t['version']}, {saved}"
        table.add_row(
            row["shop"],
            str(row["cases"]),
            " / ".join(str(outcomes.get(k, 0)) for k in OUTCOMES),
            shown_time(row.get("last"), day=True),
            habits or "",
            tins or "",
            ", ".join(row["models"]),
        )
    console.print(table)
