"""CLI: ``flakelab cases codes`` and ``flakelab cases variants``: the colour codes a shop has
painted, and the variants of one (:mod:`flakelab.cases.variants`)."""

from __future__ import annotations

import shlex
from pathlib import Path
from typing import Annotated

import typer
from rich import box
from rich.table import Table

from flakelab.cli.common import (
    AverageOption,
    JsonOption,
    SampleOption,
    ToleranceOption,
    check_figure_file,
    check_output_file,
    console,
    errors,
    print_report,
    progress_bar,
    read_reading_at,
    shares_text,
)
from flakelab.cli.sources import (
    CaseSourceOption,
    InstrumentOption,
    ShopOption,
    SinceOption,
    cases_hint_in,
    colour_code_spelled,
    database_option,
    instrument_key,
    load_cases,
    which_cases,
)
from flakelab.core.defaults import DEFAULT_TOLERANCE
from flakelab.core.geometry import DEFAULT_INSTRUMENT, INSTRUMENT_GEOMETRIES
from flakelab.core.times import shown_time
from flakelab.core.wording import counted, database_label, hidden_passwords
from flakelab.errors import FlakelabError

__all__ = ["car_from_variants", "codes_command", "variants_command"]


def codes_command(
    shop: ShopOption = None,
    database: CaseSourceOption = None,
    json_output: JsonOption = False,
) -> None:
    """The colour codes the shop's cases record: their cases by outcome, first and last.

    'cases variants CODE' then groups the cars of one code into its variants."""
    from flakelab.cases.case import OUTCOMES
    from flakelab.cases.database import code_summary

    engine, label = _summarised(database, shop)
    rows = [
        s | {"first": s["first"].isoformat(), "last": s["last"].isoformat()}
        for s in code_summary(engine, shop=shop)
    ]
    if json_output:
        print_report({"cases": hidden_passwords(label), "shop": shop, "codes": rows})
        return
    if not rows:
        errors.print(
            f"no cases {which_cases(shop, None)}{_shop_hint(database, shop)} in {label} record "
            "a colour code ('cases record --colour-code', a case file's colour_code column)",
            highlight=False,
            soft_wrap=True,
        )
        return
    whose = f" of shop {shop!r}" if shop else ""
    table = Table(title=f"Colour codes{whose} in {label}", box=box.SIMPLE_HEAD)
    shops = shop is None  # one shop's codes: each its own
    columns = ("colour code", "cases", *["shops"] * shops, " / ".join(OUTCOMES), "first case",
               "last case")  # fmt: skip
    for column in columns:
        table.add_column(column, justify="right" if column in ("cases", "shops") else "left")
    for row in rows:
        outcomes = row["outcomes"]
        table.add_row(
            row["colour_code"],
            str(row["cases"]),
            *[str(row["shops"])] * shops,
            " / ".join(str(outcomes.get(k, 0)) for k in OUTCOMES),
            shown_time(row["first"], day=True),
            shown_time(row["last"], day=True),
        )
    console.print(table)


def _shop_hint(database: str | None, shop: str | None) -> str:
    """The shop that ``shop`` likely means among the cases of ``database`` (a case file's
    too, whose summary holds ``shop``'s cases alone): :func:`cases_hint_in`."""
    from flakelab.cases.database import default_url

    return cases_hint_in(database or default_url(), shop)


def _summarised(database: str | None, shop: str | None):
    """An engine on the cases of ``database`` (a case file's ``shop``'s cases held in an
    in-memory database, so that one query summarises either), and how to name them."""
    from flakelab.cases.database import add_cases, default_url, open_database
    from flakelab.cases.exchange import is_case_file

    source = database or default_url()
    if not is_case_file(Path(source)):
        engine = open_database(database, must_exist=True)
        return engine, database_label(engine)
    engine = open_database("sqlite://")
    add_cases(engine, load_cases(source, shop))
    return engine, source


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
    since: SinceOption = None,
    instrument: InstrumentOption = DEFAULT_INSTRUMENT,
    tolerance: ToleranceOption = DEFAULT_TOLERANCE,
    within: Annotated[
        float,
        typer.Option(
            help="Largest share of the tolerance's limit between a car and its variant's "
            "centre car, at every geometry.",
        ),
    ] = 1.0,
    car: Annotated[
        Path | None,
        typer.Option(
            help="The car in the booth (a measurement file): how far it lies from each "
            "variant's centre, and the variant it is nearest."
        ),
    ] = None,
    sample: SampleOption = None,
    average: AverageOption = False,
    plot: Annotated[
        Path | None,
        typer.Option(
            help="Save a figure: every car's ΔL*, Δa*, Δb* from the main variant's centre car "
            "against aspecular angle, and --car's (.png, .pdf, .svg)."
        ),
    ] = None,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            "-o",
            help="Write the variant chips: each variant's centre car as a sample named "
            "'CODE #k', in a measurement file (format from the extension: .cxf, .json, "
            ".csv, .xlsx; CxF3 and JSON keep which cars and recipe each stands for), for "
            "'compare' and 'match' to take as standards.",
        ),
    ] = None,
    json_output: JsonOption = False,
) -> None:
    """The variants of a colour code among the shop's cars: as few as cover them, every car
    within --tolerance of its variant's centre car at every geometry.

    Each variant is shown by its centre car, how far that lies from the main variant's (the
    most cars), and the recorded recipe whose spray-out lies nearest it. 'cases nearest CAR
    --colour-code CODE' then finds the recipes nearest the car in the booth; --car says
    which variant it is; --out writes the variants' centre cars as a chip book."""
    from flakelab.cases.case import cases_at
    from flakelab.cases.database import default_url
    from flakelab.cases.variants import colour_variants, variant_chips
    from flakelab.io import format_for_path, read_tolerance, write_measurements

    if not 0 < within < float("inf"):
        raise FlakelabError(f"--within: expected a share of the limit above 0, got {within:g}")
    reads = {"--database": database, "--tolerance": tolerance, "--car": car}
    check_figure_file(plot, "--plot", reads=reads, writes={"--out": out})
    check_output_file(out, "--out", format_for_path, reads=reads, writes={"--plot": plot})
    tol = read_tolerance(tolerance)
    geometries = INSTRUMENT_GEOMETRIES[instrument_key(instrument)]
    reading = car and read_reading_at(car, sample, average, geometries, instrument)
    source = database or default_url()
    cases = cases_at(load_cases(source, shop, since, colour_code), geometries)
    if not cases:
        raise FlakelabError(
            f"{hidden_passwords(source)}: no cases {which_cases(shop, since, colour_code)}"
            f"{cases_hint_in(source, shop, colour_code)} read at the geometries "
            f"{tuple(geometries)}"
        )
    pairs = len(cases) * (len(cases) + 1) // 2  # 5,000 cars: 19 s
    with progress_bar(json_output) as bar:
        task = bar.add_task(f"comparing {counted(len(cases), 'car')} pair by pair", total=pairs)
        found = colour_variants(cases, tol, within, lambda n: bar.advance(task, n))
    report = {
        "cases": hidden_passwords(source),
        "shop": shop,
        "since": since and since.isoformat(),  # zoned as typed (typed_time)
        "colour_code": colour_code,
        "geometries": list(geometries),
        "tolerance": tol.name,
        "within": within,
        "cars": len(cases),
        "variants": [variant.to_dict() for variant in found],
    }
    spectra = reading and reading.storage_spectra(list(geometries))
    if reading is not None:
        report["car"] = {"file": str(car), "sample": reading.sample,
                         **_car_report(found, spectra, tol, report)}  # fmt: skip
    if plot is not None:
        from flakelab.render.plots import plot_variants

        title = f"Colour code {colour_code!r}: {counted(len(found), 'variant')} ({tol.name})"
        plot_variants(found, plot, title=title, car=spectra)
        report["plot"] = str(plot)
        errors.print(f"wrote {plot}", highlight=False)
    if out is not None:
        write_measurements(variant_chips(found, colour_code, tol, within), out)
        report["out"] = str(out)
        errors.print(f"wrote {counted(len(found), 'variant chip')} to {out}", highlight=False)
    if json_output:
        print_report(report)
        return
    chosen = (f" --sample {shlex.quote(sample)}" if sample else "") + " --average" * average
    _print_variants(report, database_option(database), chosen)


def _car_report(found, spectra, tolerance, report: dict) -> dict:
    """The car's worst ΔE00 and share from each variant's centre (added to each variant's
    row of ``report``) and the variant it lies nearest."""
    rows, nearest = car_from_variants(found, spectra, tolerance)
    for row, car in zip(report["variants"], rows, strict=True):
        row["car"] = car
    return {"nearest_variant": nearest + 1, "within_tolerance": any(r["passes"] for r in rows)}


def car_from_variants(found, spectra, tolerance) -> tuple[list[dict], int]:
    """A car's (reflectance ``[G, 31]`` at the variants' geometries) worst ΔE00, its
    geometry, worst share of the limit and pass/fail from each variant's centre car in
    ``found``, and the index of the variant it lies nearest."""
    from flakelab.cases.variants import car_from_centres

    de00, shares, passes = car_from_centres(found, spectra, tolerance)
    names = found[0].centre.geometry_names
    rows = [
        {
            "de00_max": round(float(d.max()), 3),
            "geometry": names[int(d.argmax())],
            "limit_share_max": round(float(share), 3),
            "passes": bool(ok),
        }
        for d, share, ok in zip(de00, shares, passes, strict=True)
    ]
    return rows, int(shares.argmin())


def _print_variants(report: dict, where: str = "", chosen: str = "") -> None:
    """A code's variants as a colorist reads them: each one's cars, spread, offset from the
    main variant, and the recipe nearest its centre. The commands it suggests next read the
    cases ``where`` (:func:`~flakelab.cli.sources.database_option`) and the car's reading
    ``chosen`` from its file."""
    from flakelab.cases.database import short_id

    rows = report["variants"]
    whose = f" of shop {report['shop']!r}" if report["shop"] else ""
    whose += f" since {shown_time(report['since'])}" if report["since"] else ""
    title = (
        f"Colour code {report['colour_code']!r}{whose}: "
        f"{counted(len(rows), 'variant')} among {counted(report['cars'], 'car')} "
        f"({report['tolerance']}, every car within {report['within']:g}× the limit of its centre)"
    )
    table = Table(title=title, box=box.SIMPLE_HEAD, collapse_padding=True)
    car = report.get("car")
    grainy = any("G" in row["offset_texture"] for row in rows)  # the cars' texture was read
    columns = ("#", "cars", "spread", "from #1 ΔE00", "ΔL* ΔC* ΔH*", *(["ΔG"] * grainy),
               *(["the car"] * bool(car)), "centre car", "nearest spray-out",
               "its recipe (share)")  # fmt: skip
    for column in columns:
        right = column in ("#", "cars", "spread", "from #1 ΔE00", "ΔG")
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
            *([_grain_cell(row["offset_texture"]) if k > 1 else ""] * grainy),
            *([_car_cell(row["car"], k == car["nearest_variant"])] if car else []),
            short_id(row["centre_case_id"]),
            f"{short_id(near['case_id'])} [{colour}]{near['sprayout_de00_max']:.2f}[/]",
            shares_text(near["recipe"]),
        )
    console.print(table)
    console.print(
        "spread: the share of the limit its furthest car lies from its centre car; from #1: its "
        "centre car against the main variant's, at the geometry where they differ most (ΔG: "
        "its graininess, coarser above 0); "
        "nearest spray-out: the recorded case whose spray-out lies nearest the centre car "
        "(worst ΔE00, green within the tolerance). Measure the car and find its recipes: "
        f"flakelab cases nearest CAR{where} --colour-code {report['colour_code']!r}",
        highlight=False,
    )
    if car:
        _print_car(report, where, chosen)


def _grain_cell(texture: dict) -> str:
    """A variant's graininess against the main one's (coarser above 0), where both were
    read."""
    return f"{texture['G']:+.2f}" if "G" in texture else ""


def _car_cell(row: dict, nearest: bool) -> str:
    """The car's worst ΔE00 from a variant's centre, green within the tolerance; ◀ marks
    the nearest."""
    colour = "green" if row["passes"] else "red"
    return f"[{colour}]{row['de00_max']:.2f}[/] {row['geometry']}" + (" ◀" if nearest else "")


def _print_car(report: dict, where: str, chosen: str) -> None:
    """Which variant the car in the booth is, and what to do next (:func:`_print_variants`'s
    ``where`` and ``chosen``)."""
    k = report["car"]["nearest_variant"]
    near = report["variants"][k - 1]["car"]
    said = (
        f"{report['car']['sample']} lies nearest variant #{k}: worst ΔE00 {near['de00_max']:.2f} "
        f"at {near['geometry']} from its centre car"
    )
    car = f"{shlex.quote(report['car']['file'])}{chosen}"
    nearest = f"flakelab cases nearest {car}{where} --colour-code {report['colour_code']!r}"
    if near["passes"]:
        console.print(f"{said}, within {report['tolerance']}; the shop's recipes nearest it: "
                      f"{nearest}", highlight=False)  # fmt: skip
    else:
        console.print(
            f"[yellow]note:[/] {said}, outside {report['tolerance']}: no variant the shop has "
            f"painted is this car's colour; match it (flakelab match {car})",
            highlight=False,
        )
