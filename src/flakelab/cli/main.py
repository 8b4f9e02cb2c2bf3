"""The ``flakelab`` command: thin wrappers that parse, call library functions and present."""

from __future__ import annotations

import re
import shlex
from dataclasses import replace
from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any

import typer
from rich import box
from rich.markup import escape
from rich.table import Table

from flakelab import __version__
from flakelab.cli.cases import cases_app
from flakelab.cli.codes import codes_command, variants_command
from flakelab.cli.common import (
    COUNT_MAX,
    AverageOption,
    AverageSprayedOption,
    ConditionsOption,
    JsonOption,
    LightsOption,
    PlotOption,
    RenderLampsOption,
    SampleOption,
    ToleranceOption,
    check_figure_file,
    check_output_file,
    command_group,
    console,
    draw_differences,
    draw_side_by_side,
    errors,
    lights_option,
    print_report,
    progress_bar,
    read_readings,
    read_sample,
    readings_note,
    refuse_a_removed_folder,
    render_lamps,
    reports_errors,
    run_command_line,
    sample_of,
    seed_option,
    stop_on_signals,
    texture_table,
)
from flakelab.cli.correct import correct_command
from flakelab.cli.hiding import hiding_command
from flakelab.cli.library import library_app
from flakelab.cli.lots import lots_app
from flakelab.cli.match import match_command
from flakelab.cli.models import model_app, train
from flakelab.cli.rendering import render_command, render_grid_command, texture_app
from flakelab.cli.weigh import weigh_command
from flakelab.core.defaults import DEFAULT_CONDITIONS, DEFAULT_TOLERANCE
from flakelab.core.geometry import FLOP_AXES
from flakelab.core.wording import counted
from flakelab.data import example_path
from flakelab.errors import FlakelabError, MeasurementFileError

app = command_group(
    "flakelab: match, predict and show the appearance of car paints.",
    pretty_exceptions_enable=False,
    add_completion=False,
)


def _fmt(value: float | None, digits: int = 2) -> str:
    return "–" if value is None else f"{value:.{digits}f}"


def _print_description(info: dict[str, Any]) -> None:
    console.print(f"[bold]{info['sample']}[/]  ({info['conditions']})", highlight=False)
    table = Table(box=box.SIMPLE_HEAD, collapse_padding=True)
    stored = any("de00_vs_stored" in g for g in info["geometries"])
    for column in ("geometry", "θ_flake", "θ_inc", "L*", "a*", "b*", "C*", "h°") + (
        ("ΔE00 vs file",) if stored else ()
    ):
        table.add_column(column, justify="left" if column == "geometry" else "right", no_wrap=True)
    for g in info["geometries"]:
        cells = [g["name"], _fmt(g["theta_flake"], 1), _fmt(g["theta_inc"], 1)]
        cells += [_fmt(g[k]) for k in ("L", "a", "b", "C")] + [_fmt(g["h"], 1)]
        cells += [f"{g['de00_vs_stored']:.4f}"] if stored else []
        table.add_row(*cells)
    console.print(table)
    line = f"flop index: {_fmt(info['flop_index'])}"
    if info["instrument"]:
        line += f"   instrument: {info['instrument']}"
    if info["measured_at"]:
        line += f"   measured: {info['measured_at']}"
    console.print(line, highlight=False)
    if info["texture"]:
        console.print("texture: " + "  ".join(f"{k} {v:.2f}" for k, v in info["texture"].items()))
    if info["spectra_recovered"]:
        console.print(f"note: {info['spectra_recovered']}", highlight=False)


@app.command()
@reports_errors
def inspect(
    path: Annotated[
        Path | None, typer.Argument(help="Measurement file (xlsx, CxF, CSV, JSON; - reads stdin).")
    ] = None,
    sample: SampleOption = None,
    all_samples: Annotated[bool, typer.Option("--all", help="Every sample in the file.")] = False,
    average: Annotated[
        bool,
        typer.Option(
            "--average",
            help="The mean of every reading in the file, and how far each lies from it, "
            "judged against --tolerance.",
        ),
    ] = False,
    tolerance: Annotated[
        str,
        typer.Option(
            "--tolerance",
            "-t",
            help="With --average: the tolerance the readings' spread is judged against "
            "(preset or TOML/JSON file).",
        ),
    ] = DEFAULT_TOLERANCE,
    conditions: ConditionsOption = DEFAULT_CONDITIONS,
    as_json: JsonOption = False,
    example: Annotated[
        bool, typer.Option("--example", help="Inspect the shipped example target.")
    ] = False,
    pictures: Annotated[
        Path | None,
        typer.Option(
            "--images",
            help="An MA-T12 export: draw the instrument camera's pictures of the sample (with "
            "--all or --average, of each, a row each), each with the colour its spectra give at "
            "that geometry, to this figure (.png, .pdf, .svg).",
        ),
    ] = None,
) -> None:
    """Per-geometry L*a*b*, C*, h, flake angles, flop index and texture of a measurement."""
    from flakelab.core.colorimetry import Conditions
    from flakelab.core.comparison import describe, spread_of_readings
    from flakelab.io import read_measurements, read_tolerance
    from flakelab.io.mat12_xlsx import camera_pictures_in

    if path is None and not example:
        raise FlakelabError("give a measurement file, or --example")
    if average and all_samples:
        raise FlakelabError("--all and --average: expected one of them, not both")
    cond = Conditions.parse(conditions)
    source = path if path is not None else example_path("target")
    if pictures is not None:
        check_figure_file(pictures, "--images", reads={"measurement": source})
    if average:
        tol = read_tolerance(tolerance)
        mean, readings = read_readings(source, sample, average)
        info = describe(mean, cond) | {"readings": spread_of_readings(readings, mean, tol, cond)}
        info["readings"]["tolerance"] = tol.name
        if pictures is not None:  # each reading's, a row each: the mean has none
            spots = [(source, r) for r in readings]
            info["camera_pictures"] = _draw_camera_pictures(spots, pictures, cond)
        if as_json:
            print_report(info, indent=1)
            return
        _print_description(info)
        _print_readings_spread(info["readings"], "file")
        if pictures is not None:
            _say_pictures_drawn(info["camera_pictures"])
        return
    measurements = read_measurements(source) if all_samples else [read_sample(source, sample)]
    infos = [describe(m, cond) for m in measurements]
    out = infos[0] if not all_samples else {"file": str(source), "measurements": infos}
    if pictures is not None:
        spots = [(source, m) for m in measurements]
        out["camera_pictures"] = _draw_camera_pictures(spots, pictures, cond)
    if as_json:
        print_report(out, indent=1)
        return
    for info in infos:
        _print_description(info)
    if pictures is not None:
        _say_pictures_drawn(out["camera_pictures"])
    elif held := camera_pictures_in(source):
        console.print(
            f"camera pictures: {held} in the file ('--images FIGURE' draws them)", highlight=False
        )


def _say_pictures_drawn(drawn: dict) -> None:
    """The line that tells where ``--images`` drew the camera's pictures, and of what."""
    each = f" of each of {drawn['readings']} readings" if drawn["readings"] > 1 else ""
    errors.print(
        f"wrote {drawn['file']}: {counted(len(drawn['geometries']), 'camera picture')}{each} "
        f"({', '.join(drawn['geometries'])})",
        highlight=False,
    )


def _draw_camera_pictures(readings: list[tuple[Path, Any]], figure: Path, conditions):
    """``--images``: the camera pictures of each (file, measurement) of ``readings``, read
    from its MA-T12 export (each export once), drawn to ``figure``, a row a reading where
    there are several; what the report says of them."""
    from flakelab.render.plots import plot_camera_pictures

    exports = {source: _camera_pictures_in(source) for source, _ in readings}
    found = [
        (measurement, _pictures_of(source, exports[source], measurement))
        for source, measurement in readings
    ]
    plot_camera_pictures(found, figure, conditions=conditions)
    labels = list(dict.fromkeys(label for _, pictures in found for label in pictures))
    height, width = next(iter(found[0][1].values())).shape[:2]
    return {
        "file": str(figure),
        "geometries": labels,
        "width": width,
        "height": height,
        "readings": len(found),
    }


def _camera_pictures_in(source: Path) -> dict:
    """The camera pictures in the MA-T12 export ``source``, by sample."""
    from flakelab.io import STANDARD_STREAM, detect_format
    from flakelab.io.mat12_xlsx import read_mat12_images

    if str(source) == STANDARD_STREAM:
        raise FlakelabError(
            "--images: stdin: the camera's pictures are read from an MA-T12 export named, not "
            "piped; name the file"
        )
    if (kind := detect_format(source)) != "mat12-xlsx":
        raise FlakelabError(
            f"--images: {source}: the camera's pictures are read from MA-T12 exports (.xlsx), "
            f"this is a {kind} file"
        )
    return read_mat12_images(source)


def _pictures_of(source: Path, pictures: dict, measurement) -> dict:
    """The camera pictures of ``measurement``'s sample among ``pictures``, those of the
    export ``source``."""
    if not (found := pictures.get(measurement.sample)):
        others = f", only of {', '.join(map(repr, pictures))}" if pictures else ""
        raise FlakelabError(
            f"--images: {source}: no camera pictures of {measurement.sample!r} "
            f"(sheet 'Texture Images'{others})"
        )
    return found


@app.command()
@reports_errors
def compare(
    reference: Annotated[Path | None, typer.Argument(help="Target / standard measurement.")] = None,
    sample: Annotated[
        Path | None,
        typer.Argument(
            help="Sample (spray-out) measurement; with --all, the samples (default: the "
            "reference's file, its standard left out)."
        ),
    ] = None,
    tolerance: ToleranceOption = DEFAULT_TOLERANCE,
    reference_sample: Annotated[
        str | None,
        typer.Option(
            "--reference-sample", help="The reference's sample name in a multi-sample file."
        ),
    ] = None,
    sample_name: Annotated[
        str | None,
        typer.Option("--sample-name", help="The sample's name in a multi-sample file."),
    ] = None,
    average: AverageOption = False,
    average_sprayed: AverageSprayedOption = False,
    conditions: ConditionsOption = DEFAULT_CONDITIONS,
    lights: LightsOption = None,
    as_json: JsonOption = False,
    example: Annotated[
        bool,
        typer.Option("--example", help="Compare the shipped example spray-out with its target."),
    ] = False,
    fail_on_reject: Annotated[
        bool, typer.Option("--fail-on-reject", help="Exit with status 1 when a geometry fails.")
    ] = False,
    render: Annotated[
        Path | None,
        typer.Option(
            help="Also draw the reference above the sample as curved panels, at the geometries "
            "they share (PNG, PDF or SVG)."
        ),
    ] = None,
    lamps: RenderLampsOption = None,
    plot: PlotOption = None,
    nearest: Annotated[
        int,
        typer.Option(
            min=0,
            max=COUNT_MAX,
            help="Rank every standard in the reference file (a chip deck, 'cases variants "
            "--out') by the sample's worst share of the tolerance from it, show the N "
            "nearest, and compare the sample with the nearest.",
        ),
    ] = 0,
    pictures: Annotated[
        Path | None,
        typer.Option(
            "--images",
            help="Both are MA-T12 exports: draw the instrument camera's pictures of the "
            "reference above the sample's (of each reading averaged, a row each), each with the "
            "colour its spectrum gives, to this figure (.png, .pdf, .svg).",
        ),
    ] = None,
    every: Annotated[
        bool,
        typer.Option(
            "--all",
            help="Compare every sample of SAMPLE with the reference (a batch of panels, a QC "
            "job's trials): a row each and how many pass; --plot draws them all, "
            "--fail-on-reject exits 1 when any fails.",
        ),
    ] = False,
) -> None:
    """Multi-angle colour difference of a sample against a reference, with pass/fail.

    With --nearest, the reference file holds many standards, and the sample is compared with
    the one it lies nearest; with --all, every sample of the sample file is compared with the
    reference."""
    from flakelab.core.colorimetry import Conditions
    from flakelab.core.comparison import compare as compare_measurements
    from flakelab.core.comparison import spread_of_readings
    from flakelab.core.difference import METAMERISM_ILLUMINANTS
    from flakelab.io import read_tolerance

    if every and not example and sample is None:  # a QC job: its trials against its standard
        sample = reference
    if not example and (reference is None or sample is None):
        raise FlakelabError("give a reference and a sample file, or --example")
    if nearest and (reference_sample or average):
        raise FlakelabError("--nearest ranks every standard of the reference file: "
                            "not with --reference-sample or --average")  # fmt: skip
    if every and (sample_name or average_sprayed or nearest or render or pictures):
        raise FlakelabError("--all compares every sample of SAMPLE: not with --sample-name, "
                            "--average-sprayed, --nearest, --render or --images")  # fmt: skip
    check_figure_file(render)
    check_figure_file(plot, "--plot")
    check_figure_file(pictures, "--images", reads={"REFERENCE": reference, "SAMPLE": sample},
                      writes={"--render": render, "--plot": plot})  # fmt: skip
    lamps = render_lamps(lamps, render)
    tol = read_tolerance(tolerance)
    light = Conditions.parse(conditions)
    tests = lights_option(lights, light) or tuple(
        t for t in METAMERISM_ILLUMINANTS if t != light.illuminant
    )
    if every:
        from flakelab.io import read_measurements

        path = sample or example_path("sprayout")
        itself = not average and Path(path).resolve() == Path(reference or "").resolve()
        samples = read_measurements(path)
        if itself:  # a QC job: its standard is read from the same file, once
            ref = sample_of(samples, path, reference_sample, "--reference-sample")
        else:
            ref, _ = read_readings(reference or example_path("target"), reference_sample,
                                   average, "--reference-sample")  # fmt: skip
        passed = _compare_every(ref, samples, path, tol, light, tests, as_json, plot, itself)
        if fail_on_reject and not passed:
            raise typer.Exit(1)
        return
    smp, smp_readings = read_readings(
        sample or example_path("sprayout"), sample_name, average_sprayed, "--sample-name",
        "--average-sprayed",
    )  # fmt: skip
    ranked = []
    if nearest:
        ranked = _ranked_references(reference or example_path("target"), smp, tol, light)
        ref, ref_readings = ranked[0].reference, [ranked[0].reference]
    else:
        ref, ref_readings = read_readings(
            reference or example_path("target"), reference_sample, average, "--reference-sample"
        )
    result = compare_measurements(ref, smp, tol, conditions=light, lights=tests)
    report = result.to_dict()
    if nearest:
        report["nearest_references"] = [r.to_dict() for r in ranked[:nearest]]
        report["references_ranked"] = len(ranked)
    for key, wanted, readings, mean in (
        ("reference_readings", average, ref_readings, ref),
        ("sample_readings", average_sprayed, smp_readings, smp),
    ):
        if wanted:
            report[key] = spread_of_readings(readings, mean, tol, light)
    if render is not None:
        _render_comparison(ref, smp, report, render, light, lamps)
    if plot is not None:
        title = f"{smp.sample} vs {ref.sample} ({light}): {'PASS' if result.all_pass else 'FAIL'}"
        samples = {smp.sample: result.lab_sample}
        draw_differences(result.geometries, result.lab_reference, samples, tol, plot, title,
                         texture={smp.sample: result.texture_share})  # fmt: skip
        report["plot"] = str(plot)
    if pictures is not None:  # each reading averaged a row: the mean has no picture
        spots = [(reference or example_path("target"), r) for r in ref_readings]
        spots += [(sample or example_path("sprayout"), r) for r in smp_readings]
        report["camera_pictures"] = _draw_camera_pictures(spots, pictures, light)
    if as_json:
        print_report(report, indent=1)
    else:
        if nearest:
            _print_ranked(report, reference or example_path("target"))
        _print_comparison(report, tol)
    if fail_on_reject and not result.all_pass:
        raise typer.Exit(1)


def _compare_every(
    ref, samples: list, path, tol, light, tests, as_json: bool, plot, itself: bool
) -> bool:
    """``compare --all``: every one of ``samples`` (read from ``path``) compared with ``ref``,
    reported as a table (or JSON) and drawn with ``--plot``, but ``ref`` itself where the file
    holds it (``itself``: the reference's file); whether every one passes."""
    from flakelab.core.comparison import compare as compare_measurements

    if itself:
        samples = [m for m in samples if m.sample != ref.sample]
        if not samples:
            raise MeasurementFileError(path, f"holds {ref.sample!r} alone: nothing to compare")
    results = []
    for smp in samples:
        try:
            results.append(compare_measurements(ref, smp, tol, conditions=light, lights=tests))
        except ValueError as error:
            raise MeasurementFileError(path, str(error), field=f"sample {smp.sample!r}") from None
    passed = sum(r.all_pass for r in results)
    report = {"reference": ref.sample, "conditions": str(light), "tolerance": tol.name,
              "compared": len(results), "passed": passed, "reference_left_out": itself,
              "samples": [r.to_dict() for r in results]}  # fmt: skip
    if plot is not None:
        report["plot"] = _draw_every(results, path, ref, tol, light, plot)
    if as_json:
        print_report(report, indent=1)
    else:
        _print_every(report, path)
    return passed == len(results)


def _draw_every(results, path, ref, tol, light, plot) -> str:
    """``compare --all --plot``: every sample's difference from the reference on one chart, at
    the geometries every sample shares with it (a note names the others)."""
    shared = [g for g in results[0].geometries if all(g in r.geometries for r in results)]
    if not shared:
        raise FlakelabError(f"--plot: the samples of {path} share no geometry with each other "
                            f"and {ref.sample!r}, for one chart to draw them at")  # fmt: skip
    left = list(dict.fromkeys(g for r in results for g in r.geometries if g not in shared))
    if left:
        errors.print(
            f"[yellow]note:[/] --plot draws the {len(shared)} geometries every sample shares "
            f"with the reference, not {', '.join(left)}",
            highlight=False,
        )

    def at_shared(lab, r):
        return lab[[r.geometries.index(g) for g in shared]]

    passed = sum(r.all_pass for r in results)
    title = (f"{path.name if isinstance(path, Path) else path} vs {ref.sample} ({light}): "
             f"{passed} of {len(results)} pass")  # fmt: skip
    samples = {r.sample.sample: at_shared(r.lab_sample, r) for r in results}
    texture = {r.sample.sample: r.texture_share for r in results}
    reference_lab = at_shared(results[0].lab_reference, results[0])
    draw_differences(tuple(shared), reference_lab, samples, tol, plot, title, texture=texture)
    return str(plot)


def _print_every(report: dict[str, Any], path) -> None:
    """``compare --all``'s table: each sample's worst ΔE00 and share of the limit, and what
    fails it."""
    from flakelab.core.tolerance import failures

    title = (f"Each sample of {path} against {report['reference']} ({report['tolerance']}, "
             f"{report['conditions']})")  # fmt: skip
    rows = [
        (row["sample"], row["de00_max"], row["de00_max_at"], row["limit_share_max"],
         row["limit_share_at"], "[green]pass[/]" if row["pass"] else "[red]fail[/] at "
         + ", ".join(failures(row["failing_geometries"], row["failing_texture"])))
        for row in report["samples"]
    ]  # fmt: skip
    console.print(_worst_table(title, "sample", rows))
    compared, passed = report["compared"], report["passed"]
    colour = "green" if passed == compared else "red"
    console.print(f"[{colour}]{passed} of {counted(compared, 'sample')} pass[/]", highlight=False)
    if report["reference_left_out"]:
        console.print(f"the reference, {escape(repr(report['reference']))}, is left out of its "
                      "own file's samples", highlight=False)  # fmt: skip
    for row in report["samples"]:
        for which, names in row["not_compared"].items():
            other = "sample" if which == "reference" else "reference"
            if names:
                console.print(
                    f"[yellow]not compared for {escape(row['sample'])}:[/] {len(names)} of the "
                    f"{which}'s geometries, which the {other} lacks: {', '.join(names)}",
                    highlight=False,
                )


def _ranked_references(path, sample, tolerance, conditions) -> list:
    """Every standard of the file at ``path`` that shares a geometry with ``sample``, nearest
    first (:func:`~flakelab.core.comparison.rank_references`)."""
    from flakelab.core.comparison import rank_references
    from flakelab.io import read_measurements

    standards = read_measurements(path)
    ranked = rank_references(standards, sample, tolerance, conditions=conditions)
    if not ranked:
        raise MeasurementFileError(
            path, f"no standard shares a geometry with {sample.sample!r} "
            f"({', '.join(sample.geometry_names)})"
        )  # fmt: skip
    return ranked


def _print_ranked(report: dict[str, Any], path) -> None:
    """The standards nearest the sample, nearest first, each green where it passes."""
    ranked = report["nearest_references"]
    title = (f"The {len(ranked)} of {report['references_ranked']} standards in {path} nearest "
             f"{report['sample']} ({report['tolerance']})")  # fmt: skip
    rows = [
        (row["reference"], row["de00_max"], row["geometry"], row["limit_share_max"],
         row["limit_share_at"], "[green]pass[/]" if row["pass"] else "[red]fail[/]")
        for row in ranked
    ]  # fmt: skip
    console.print(_worst_table(title, "standard", rows))


def _worst_table(title: str, named: str, rows: list[tuple]) -> Table:
    """Comparisons a row each, numbered: what is compared (its column headed ``named``), its
    worst ΔE00 and where, its worst share of the limit and where, and its verdict."""
    table = Table(title=title, box=box.SIMPLE_HEAD, collapse_padding=True)
    for column in ("#", named, "worst ΔE00", "worst share of the limit", "verdict"):
        table.add_column(column, justify="right" if column == "#" else "left")
    for k, (name, de00, de00_at, share, share_at, verdict) in enumerate(rows, 1):
        table.add_row(str(k), escape(name), f"{de00:.2f} {de00_at}", f"{share:.0%} {share_at}",
                      verdict)  # fmt: skip
    return table


def _render_comparison(ref, smp, report: dict, path: Path, conditions, lamps) -> None:
    from flakelab.core.tolerance import failures

    shared = [g["name"] for g in report["geometries"]]
    failing = failures(report["failing_geometries"], report["failing_texture"])
    verdict = "FAIL at " + ", ".join(failing) if failing else "PASS"
    labels = [f"reference: {ref.sample}", f"sample: {smp.sample}"]
    title = f"{smp.sample} vs {ref.sample}: {verdict}"
    readings = [ref.select(shared), smp.select(shared)]
    draw_side_by_side(readings, labels, path, title, conditions=conditions, lamps=lamps)


_LIMIT_LABELS = {"de00": "ΔE≤", "dL": "L≤", "dC": "C≤", "dH": "H≤"}


def _print_comparison(report: dict[str, Any], tol: Any) -> None:
    from flakelab.core.tolerance import failures

    console.print(
        f"[bold]{report['sample']}[/] vs [bold]{report['reference']}[/]  "
        f"({report['conditions']}, tolerance {report['tolerance']})",
        highlight=False,
    )
    table = Table(box=box.SIMPLE_HEAD, collapse_padding=True)
    columns = ("geometry", "L* ref", "L* smp", "ΔL*", "ΔC*", "ΔH*", "ΔE00", "limit", "used", "")
    for column in columns:
        table.add_column(column, justify="left" if column == "geometry" else "right", no_wrap=True)
    for g in report["geometries"]:
        limit = tol.limit(g["name"]).to_dict()
        shown = " ".join(f"{_LIMIT_LABELS[k]}{v:g}" for k, v in limit.items())
        verdict = "[green]pass[/]" if g["pass"] else "[bold red]FAIL[/]"
        table.add_row(
            g["name"],
            _fmt(g["L_reference"]),
            _fmt(g["L_sample"]),
            _fmt(g["dL"]),
            _fmt(g["dC"]),
            _fmt(g["dH"]),
            _fmt(g["de00"]),
            shown,
            f"{g['limit_share']:.0%}",
            verdict,
        )
    console.print(table)
    for which, names in report["not_compared"].items():
        if names:
            console.print(
                f"[yellow]not compared:[/] {len(names)} of the {which}'s geometries, which the "
                f"{'sample' if which == 'reference' else 'reference'} lacks: {', '.join(names)}",
                highlight=False,
            )
    failing = failures(report["failing_geometries"], report["failing_texture"])
    verdict = "[green]PASS[/]" if report["pass"] else "[bold red]FAIL[/] at " + ", ".join(failing)
    console.print(
        f"ΔE00 max {report['de00_max']:.2f}, mean {report['de00_mean']:.2f}   "
        f"flop index {_fmt(report['flop_index_reference'])} → "
        f"{_fmt(report['flop_index_sample'])}   "
        f"{verdict}",
        highlight=False,
    )
    if report["metamerism_index_max"]:
        worst = "  ".join(f"{k} {v:.2f}" for k, v in report["metamerism_index_max"].items())
        against = f"ISO 18314-4, ΔE00 from {report['conditions']}, worst geometry"
        console.print(f"metamerism index ({against}): {worst}", highlight=False)
    for note in report["spectra_recovered"]:
        console.print(f"note: {note}; no metamerism index is taken against it", highlight=False)
    if report["texture_difference"]:
        limits = {k: tol.texture_limits()[k] for k in report["texture_limit_share"]}
        texture = report["texture_difference"]
        console.print(
            texture_table("sample − reference", texture, limits, report["failing_texture"])
        )
    for what in ("reference", "sample"):
        if spread := report.get(f"{what}_readings"):
            _print_readings_spread(spread, what)


def _print_readings_spread(spread: dict, what: str) -> None:
    """How far the furthest of the readings averaged lies from their mean, and a note where
    it lies far."""
    console.print(
        f"{what}: the mean of {counted(len(spread['readings']), 'reading')}, the furthest "
        f"({spread['furthest']}) {spread['limit_share_max']:.0%} of the tolerance from it",
        highlight=False,
    )
    if note := readings_note(spread, what):
        console.print(f"[yellow]note:[/] {note}", highlight=False)


MeasurementFormat = StrEnum(
    "MeasurementFormat", {"mat12_xlsx": "mat12-xlsx", "cxf": "cxf", "csv": "csv", "json": "json"}
)
"""``convert --format``: the names of :data:`flakelab.io.FORMATS`, written out so that the
command line starts without importing the readers (a test keeps the two the same)."""


@app.command()
@reports_errors
def convert(
    source: Annotated[
        Path, typer.Argument(help="Measurement file to read (any supported format).")
    ],
    target: Annotated[
        Path,
        typer.Argument(help="File to write; format from the extension (- writes stdout)."),
    ],
    sample: SampleOption = None,
    to: Annotated[
        MeasurementFormat | None,
        typer.Option(
            "--format", help="The format to write, where TARGET's extension does not say it."
        ),
    ] = None,
    decimal_comma: Annotated[
        bool,
        typer.Option(
            "--decimal-comma",
            help="A CSV as a spreadsheet opens it in most of Europe: cells separated by "
            "semicolons, numbers with a decimal comma (flakelab reads it back).",
        ),
    ] = False,
    wide: Annotated[
        bool,
        typer.Option(
            "--wide",
            help="A CSV of a row per sample, its L*a*b* and spectra at each geometry in columns "
            "('L* 45as15', 'R400 45as15'), as a spreadsheet of panels holds them (flakelab "
            "reads it back).",
        ),
    ] = False,
    lab_only: Annotated[
        bool,
        typer.Option(
            "--lab-only",
            help="Write L*a*b* alone (under --conditions) and no spectra, as CSV or CxF3: for "
            "software that takes a colour per angle. flakelab reads it back with spectra "
            "recovered from it.",
        ),
    ] = False,
    conditions: ConditionsOption = DEFAULT_CONDITIONS,
) -> None:
    """Convert measurement files between MA-T12 xlsx, CxF3, CSV and JSON."""
    from flakelab.core.colorimetry import Conditions
    from flakelab.io import (
        COLOUR_ALONE_FORMATS,
        STANDARD_STREAM,
        format_for_path,
        read_measurements,
        write_measurements,
    )
    from flakelab.io.mat12_xlsx import camera_pictures_in

    to_stdout = str(target) == STANDARD_STREAM
    if to_stdout and to is None:
        raise FlakelabError(
            f"TARGET -: standard output has no extension to name the format: --format names it "
            f"({'|'.join(MeasurementFormat)})"
        )
    if not to_stdout:
        check_output_file(target, "TARGET", reads={"SOURCE": source})
    written_as = to.value if to else format_for_path(target)
    if lab_only and written_as not in COLOUR_ALONE_FORMATS:
        raise FlakelabError(
            f"--lab-only: L*a*b* without spectra is written as {' or '.join(COLOUR_ALONE_FORMATS)}"
            f", not {written_as}"
        )
    measurements = [read_sample(source, sample)] if sample else read_measurements(source)
    kinds = {m.spectra_recovered for m in measurements}
    if len(kinds) > 1 and not lab_only and written_as != "cxf":  # a CxF3 file of both kinds
        alone = next(m.sample for m in measurements if m.spectra_recovered)
        raise FlakelabError(
            f"{source} holds measured spectra and L*a*b* alone ({alone!r}), and a {written_as} "
            "file holds one kind: --lab-only writes every one as L*a*b*, --sample NAME one of "
            "them; a CxF3 file holds both"
        )
    if lab_only:  # written as a file of colour alone is: the writers give such spectra none
        cond = Conditions.parse(conditions)
        for m in measurements:
            if m.spectra_recovered and m.stored_lab_conditions != cond:
                estimate = (
                    f"{m.sample}'s L*a*b* under {cond} is an estimate: its file gave it under "
                    f"{m.stored_lab_conditions} alone, and its spectra are recovered from that"
                )
                errors.print(f"[yellow]note:[/] {escape(estimate)}", highlight=False)
        measurements = [
            replace(m, stored_lab=m.lab(cond), stored_lab_conditions=cond, spectra_recovered=True)
            for m in measurements
        ]
    write_measurements(
        measurements, target, to and to.value, decimal_comma=decimal_comma, wide=wide
    )
    written = "stdout" if to_stdout else target
    errors.print(f"wrote {counted(len(measurements), 'measurement')} to {written}", highlight=False)
    if pictures := camera_pictures_in(source):
        left = (
            f"{source}'s {counted(pictures, 'camera picture')} stay behind: flakelab writes the "
            f"readings only ('flakelab inspect {shlex.quote(str(source))} --images FIGURE' draws "
            "them)"
        )
        errors.print(f"[yellow]note:[/] {escape(left)}", highlight=False)


FlopAxis = StrEnum("FlopAxis", [(axis.replace("-", "_"), axis) for axis in FLOP_AXES])
"""``plot --against``: :data:`~flakelab.core.geometry.FLOP_AXES`."""


@app.command()
@reports_errors
def plot(
    path: Annotated[Path, typer.Argument(help="Measurement file.")],
    output: Annotated[
        Path, typer.Option("--output", "-o", help="Image to write (.png, .svg, .pdf).")
    ],
    sample: SampleOption = None,
    conditions: ConditionsOption = DEFAULT_CONDITIONS,
    against: Annotated[
        FlopAxis,
        typer.Option(
            help="Draw L* and C* against the aspecular angle, or the flake tilt each geometry "
            "needs (θ_flake): over it an effect paint's readings under different lamps fall "
            "on one curve."
        ),
    ] = FlopAxis.aspecular,
) -> None:
    """Spectra per geometry and L*, C* versus aspecular angle (or flake tilt)."""
    from flakelab.core.colorimetry import Conditions
    from flakelab.render.plots import plot_measurements

    check_figure_file(output, "--output")
    reading = read_sample(path, sample)
    plot_measurements(
        [reading], output, conditions=Conditions.parse(conditions), against=str(against)
    )
    errors.print(f"wrote {output}", highlight=False)


app.command("match")(reports_errors(match_command))
app.command("correct")(reports_errors(correct_command))
app.command("weigh")(reports_errors(weigh_command))
app.command("hiding")(reports_errors(hiding_command))
cases_app.command("codes")(reports_errors(codes_command))
cases_app.command("variants")(reports_errors(variants_command))
app.add_typer(cases_app, name="cases")
app.add_typer(model_app, name="model")
app.add_typer(lots_app, name="lots")
app.add_typer(library_app, name="library")
app.command("train")(reports_errors(train))
app.command("render")(reports_errors(render_command))
app.command("render-grid")(reports_errors(render_grid_command))
app.add_typer(texture_app, name="texture")
validate_app = command_group("Validation experiments against the reference Monte Carlo.")
app.add_typer(validate_app, name="validate")


@validate_app.command("scaling")
@reports_errors
def validate_scaling(
    json_output: JsonOption = False,
    photons: Annotated[
        int, typer.Option(help="Photons per Monte Carlo spectrum.", min=1000, max=COUNT_MAX)
    ] = 200_000,
    seed: Annotated[int, seed_option("Seed of the Monte Carlo runs.")] = 51,
    spreads: Annotated[
        str, typer.Option(help="Orientation spreads [°]: reference first, then the series.")
    ] = "10,5,15",
    plots: Annotated[
        Path | None, typer.Option("--plots", help="Folder for the figures (one per spread).")
    ] = Path("scaling-plots"),
) -> None:
    """The hybrid paper's scaling experiment: Monte Carlo, fast model and scaling.

    Its Table 1 dye series, each reflectance by the reference Monte Carlo against the fast
    model and the single-collision scaling."""
    from flakelab.physics.scaling import SERIES_RUNS, run_series, scaling_report
    from flakelab.render.plots import plot_scaling

    try:
        values = [float(v) for v in spreads.split(",") if v.strip()]
    except ValueError:
        raise FlakelabError(
            f"--spreads: expected degrees such as 10,5,15, got {spreads!r}"
        ) from None
    if plots is not None and plots.exists() and not plots.is_dir():
        raise FlakelabError(f"--plots: {plots}: is a file, expected a folder for the figures")
    if plots is not None and not plots.resolve().parent.is_dir():
        raise FlakelabError(f"--plots: {plots}: no folder {plots.resolve().parent}")
    if not values or any(not 0 < v <= 45 for v in values):
        raise FlakelabError(f"--spreads: expected degrees in (0, 45], got {spreads!r}")
    series = []
    with progress_bar(json_output) as progress:
        task = progress.add_task("Monte Carlo photons", total=SERIES_RUNS * len(values) * photons)
        for value in values:
            series.append(
                run_series(value, photons, seed, progress=lambda n: progress.advance(task, n))
            )
    report = scaling_report(series[0], series[1:])
    if plots is not None:
        plots.mkdir(parents=True, exist_ok=True)
        for one in series:
            plot_scaling(one, plots / f"scaling-spread-{one.spread_deg:g}.png")
        report["plots"] = sorted(str(p) for p in plots.glob("scaling-spread-*.png"))
    if json_output:
        print_report(report)
        return
    _print_scaling(report)


def _print_scaling(report: dict[str, Any]) -> None:
    table = Table(
        title=f"Scaling experiment ({report['photons_per_spectrum']:,} photons/spectrum)",
        box=box.SIMPLE_HEAD,
    )
    table.add_column("figure")
    table.add_column("value", justify="right")
    table.add_column("goal")
    rows = (
        ("shape correlation (min)", report["shape_correlation_min"], "≥ 0.99"),
        ("span linearity R² (min)", report["span_linearity_r2"], "≥ 0.99"),
        ("fast model ΔE00 mean", report["de00_mean"], "≤ 0.5"),
        ("fast model ΔE00 max", report["de00_max"], "≤ 1.0"),
        ("atlas ΔE00 mean", report["atlas_de00_mean"], ""),
        ("atlas ΔE00 max", report["atlas_de00_max"], ""),
        ("single collision ΔE00 mean", report["single_collision_de00_mean"], "reported"),
        ("single collision ΔE00 max", report["single_collision_de00_max"], "reported"),
        ("speed-up (MC / fast)", report["speedup"], "≥ 1000"),
    )
    for name, value, goal in rows:
        table.add_row(name, f"{value:.4g}", goal)
    console.print(table)
    for entry in report.get("orientation_series", []):
        change = entry["g_relative_change_median"]
        console.print(
            f"spread {entry['spread_deg']:g}°: g changes by {change['monte_carlo']:.1%} (MC), "
            f"{change['fast']:.1%} (fast), {change['single_collision']:.1%} (single collision); "
            f"fast ΔE00 mean {entry['de00_mean']:.2f}, "
            f"single {entry['single_collision_de00_mean']:.2f}"
        )


@app.callback(invoke_without_command=True)
def main(
    version: Annotated[
        bool,
        typer.Option(
            "--version",
            help="Print the versions of flakelab, Python and the libraries it runs on, and exit.",
        ),
    ] = False,
) -> None:
    if version:
        print(version_text())
        raise typer.Exit()


def version_text() -> str:
    """flakelab's version, then Python's and the machine's, then the version of each library
    it runs on, as its installed metadata requires them: what a bug report needs. Read from
    the packages' metadata without importing them (torch's import takes seconds)."""
    import platform
    from importlib.metadata import PackageNotFoundError, requires, version

    lines = [
        f"flakelab {__version__}",
        f"Python {platform.python_version()} ({platform.python_implementation()}), "
        f"{platform.system()} {platform.machine()}",
    ]
    try:
        required = [r for r in requires("flakelab") or [] if "extra ==" not in r]
    except PackageNotFoundError:  # run from a source tree that was never installed
        return "\n".join(lines)
    found = []
    for requirement in required:
        name = re.match(r"[A-Za-z0-9_.-]+", requirement).group()
        try:
            found.append(f"{name} {version(name)}")
        except PackageNotFoundError:
            found.append(f"{name} missing")
    return "\n".join([*lines, ", ".join(found)])


def run() -> None:
    """Console entry point."""
    stop_on_signals()
    refuse_a_removed_folder()
    run_command_line(app, "flakelab")


if __name__ == "__main__":
    run()
