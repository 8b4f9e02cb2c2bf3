"""CLI: ``flakelab cases codes`` and ``flakelab cases variants``: the colour codes a shop has
painted, and the variants of one (:mod:`flakelab.cases.variants`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich import box
from rich.table import Table

from flakelab.cli.common import (
    JsonOption,
    ToleranceOption,
    check_figure_file,
    console,
    errors,
    print_report,
    shares_text,
)
from flakelab.cli.sources import (
    CaseSourceOption,
    DatabaseOption,
    InstrumentOption,
    ShopOption,
    colour_code_hint_in,
    colour_code_spelled,
    instrument_key,
    load_cases,
    which_cases,
)
from flakelab.core.defaults import DEFAULT_TOLERANCE
from flakelab.core.geometry import DEFAULT_INSTRUMENT, INSTRUMENT_GEOMETRIES
from flakelab.core.times import shown_time
from flakelab.core.wording import counted, database_label, hidden_passwords
from flakelab.errors import FlakelabError

__all__ = ["codes_command", "variants_command"]


def codes_command(
    shop: ShopOption = None,
    database: DatabaseOption = None,
    json_output: JsonOption = False,
) -> None:
    """The colour codes the shop's cases record: their cases by outcome, first and last.

    'cases variants CODE' then groups the cars of one code into its variants."""
    from flakelab.cases.case import OUTCOMES
    from flakelab.cases.database import code_summary, open_database

    engine = open_database(database, must_exist=True)
    rows = [
        s | {"first": s["first"].isoformat(), "last": s["last"].isoformat()}
        for s in code_summary(engine, shop=shop)
    ]
    if json_output:
        print_report({"cases": hidden_passwords(str(engine.url)), "shop": shop, "codes": rows})
        return
    if not rows:
        errors.print(
            f"no cases {which_cases(shop, None)} in {database_label(engine)} record a colour "
            "code ('cases record --colour-code', a case file's colour_code column)",
            highlight=False,
            soft_wrap=True,
        )
        return
    whose = f" of shop {shop!r}" if shop else ""
    table = Table(title=f"Colour codes{whose} in {database_label(engine)}", box=box.SIMPLE_HEAD)
    for column in ("colour code", "cases", " / ".join(OUTCOMES), "first case", "last case"):
        table.add_column(column, justify="right" if column == "cases" else "left")
    for row in rows:
        outcomes = row["outcomes"]
        table.add_row(
            row["colour_code"],
            str(row["cases"]),
            " / ".join(str(outcomes.get(k, 0)) for k in OUTCOMES),
            shown_time(row["first"], day=True),
            shown_time(row["last"], day=True),
        )
    console.print(table)


def variants_command(
    colour_code: Annotated[
        str,
        typer.Argument(
            callback=colour_code_spelled,
            help="The car maker's colour code, as on the car's plate ('Toyota 1G3', 'nh731p').",
        ),
    ],
    database: CaseSourceOption = None,
    shop: ShopOption = None,
    instrument: InstrumentOption = DEFAULT_INSTRUMENT,
    tolerance: ToleranceOption = DEFAULT_TOLERANCE,
    within: Annotated[
        float,
        typer.Option(
            help="Largest share of the tolerance's limit between a car and its variant's "
            "centre car, at every geometry.",
        ),
    ] = 1.0,
    plot: Annotated[
        Path | None,
        typer.Option(
            help="Save a figure: each variant's cars, L* against aspecular angle and a*, b* "
            "from geometry to geometry (.png, .pdf, .svg)."
        ),
    ] = None,
    json_output: JsonOption = False,
) -> None:
    """The variants of a colour code among the shop's cars: as few as cover them, every car
    within --tolerance of its variant's centre car at every geometry.

    Each variant is shown by its centre car, how far that lies from the main variant's (the
    most cars), and the recorded recipe whose spray-out lies nearest it. 'cases nearest CAR
    --colour-code CODE' then finds the recipes nearest the car in the booth."""
    from flakelab.cases.case import cases_at
    from flakelab.cases.database import default_url
    from flakelab.cases.variants import colour_variants
    from flakelab.io import read_tolerance

    if not 0 < within < float("inf"):
        raise FlakelabError(f"--within: expected a share of the limit above 0, got {within:g}")
    check_figure_file(plot, "--plot", reads={"--database": database, "--tolerance": tolerance})
    tol = read_tolerance(tolerance)
    geometries = INSTRUMENT_GEOMETRIES[instrument_key(instrument)]
    source = database or default_url()
    cases = cases_at(load_cases(source, shop, colour_code=colour_code), geometries)
    if not cases:
        raise FlakelabError(
            f"{hidden_passwords(source)}: no cases {which_cases(shop, None, colour_code)}"
            f"{colour_code_hint_in(source, shop, colour_code)} read at the geometries "
            f"{tuple(geometries)}"
        )
    found = colour_variants(cases, tol, within)
    report = {
        "cases": hidden_passwords(source),
        "shop": shop,
        "colour_code": colour_code,
        "geometries": list(geometries),
        "tolerance": tol.name,
        "within": within,
        "cars": len(cases),
        "variants": [variant.to_dict() for variant in found],
    }
    if plot is not None:
        from flakelab.render.plots import plot_variants

        title = f"Colour code {colour_code!r}: {counted(len(found), 'variant')} ({tol.name})"
        plot_variants(found, plot, title=title)
        report["plot"] = str(plot)
        errors.print(f"wrote {plot}", highlight=False)
    if json_output:
        print_report(report)
        return
    _print_variants(report)


def _print_variants(report: dict) -> None:
    """A code's variants as a colorist reads them: each one's cars, spread, offset from the
    main variant, and the recipe nearest its centre."""
    from flakelab.cases.database import short_id

    rows = report["variants"]
    whose = f" of shop {report['shop']!r}" if report["shop"] else ""
    title = (
        f"Colour code {report['colour_code']!r}{whose}: "
        f"{counted(len(rows), 'variant')} among {counted(report['cars'], 'car')} "
        f"({report['tolerance']}, every car within {report['within']:g}× the limit of its centre)"
    )
    table = Table(title=title, box=box.SIMPLE_HEAD, collapse_padding=True)
    columns = ("#", "cars", "spread", "from #1 ΔE00", "ΔL* ΔC* ΔH*", "centre car",
               "nearest spray-out", "its recipe (share)")  # fmt: skip
    for column in columns:
        right = column in ("#", "cars", "spread", "from #1 ΔE00")
        table.add_column(column, justify="right" if right else "left",
                         no_wrap=column != "its recipe (share)")  # fmt: skip
    for k, row in enumerate(rows, 1):
        near = row["recipe"]
        colour = "green" if near["passes"] else "red"
        shift = row["offset_dLCH"]
        table.add_row(
            str(k),
            str(row["cases"]),
            f"{row['spread']:.2f}",
            f"{row['offset_de00_max']:.2f} {row['offset_geometry']}" if k > 1 else "",
            f"{shift['dL']:+.2f} {shift['dC']:+.2f} {shift['dH']:+.2f}" if k > 1 else "",
            short_id(row["centre_case_id"]),
            f"{short_id(near['case_id'])} [{colour}]{near['sprayout_de00_max']:.2f}[/]",
            shares_text(near["recipe"]),
        )
    console.print(table)
    console.print(
        "spread: the share of the limit its furthest car lies from its centre car; from #1: its "
        "centre car against the main variant's, at the geometry where they differ most; "
        "nearest spray-out: the recorded case whose spray-out lies nearest the centre car "
        "(worst ΔE00, green within the tolerance). Measure the car and find its recipes: "
        f"flakelab cases nearest CAR --colour-code {report['colour_code']!r}",
        highlight=False,
    )
