"""CLI: appearance-based rendering (``render``, ``render-grid``) and the texture processes."""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer

from flakelab.cli.common import (
    ConditionsOption,
    JsonOption,
    SampleOption,
    check_output_file,
    command_group,
    console,
    errors,
    print_report,
    read_sample,
    reports_errors,
    seed_option,
)
from flakelab.core.defaults import DEFAULT_CONDITIONS
from flakelab.errors import FlakelabError

OutputOption = Annotated[
    Path, typer.Option("--output", "-o", help="Image to write (.png, .jpg, .tif).")
]
LightOption = Annotated[
    float,
    typer.Option(
        "--light", min=0.0, max=1.0, help="Diffuse fraction of the light, 0 (spot) to 1 (dome)."
    ),
]
SeedOption = Annotated[int, seed_option("Seed of the texture.")]


class View(StrEnum):
    panel = "panel"
    curved = "curved"


def _appearance(measurement: Path | None, sample: str | None, conditions: str,
                lamp: float | None = None):  # fmt: skip
    from flakelab.core.colorimetry import Conditions
    from flakelab.data import example_path
    from flakelab.render.appearance import LAMP_DEG, appearance_of, appearance_under, lamps_of

    path = measurement if measurement is not None else example_path("target")
    reading = read_sample(path, sample)
    conditions = Conditions.parse(conditions)
    try:
        if lamp is None or lamp in lamps_of(reading):  # by default 45°, or refused saying why
            return appearance_of(reading, conditions, LAMP_DEG if lamp is None else lamp)
        drawn = appearance_under(reading, lamp, conditions)
    except ValueError as error:
        raise FlakelabError(f"{path}: {error}") from None
    errors.print(
        f"note: {reading.sample} was not read under a lamp at {lamp:g}°: drawn from its "
        f"{drawn.interpolated_from:g}° readings interpolated over flake tilt (an MA-T12's 15° "
        "readings so predicted from its 45° ones lie a median ΔE00 1.5 from the measured, on "
        "230 real samples; docs/texture.md)",
        highlight=False,
    )
    return drawn


def render_command(
    measurement: Annotated[
        Path | None, typer.Argument(help="Measurement file (default: the shipped example).")
    ] = None,
    output: OutputOption = Path("render.png"),
    view: Annotated[View, typer.Option(help="Flat panel at one angle, or curved 0–110°.")] = (
        View.curved
    ),
    light: LightOption = 0.7,
    distance: Annotated[str, typer.Option(help="Observation distance, e.g. 0.5m, 2m.")] = "0.5m",
    aspecular: Annotated[
        float | None, typer.Option(help="panel: aspecular angle [°] (default 45).")
    ] = None,
    size: Annotated[int, typer.Option(min=16, max=8192, help="Image width in pixels.")] = 1024,
    lamp: Annotated[
        float | None,
        typer.Option(
            min=0.0,
            max=89.0,
            help="The lamp's angle from the normal [°]: 45 (default; every instrument lights "
            "at 45°), another the reading was lit at (15 on an MA-T12), or any other: its 45° "
            "readings interpolated over flake tilt.",
        ),
    ] = None,
    no_texture: Annotated[bool, typer.Option("--no-texture", help="Colour only.")] = False,
    sample: SampleOption = None,
    conditions: ConditionsOption = DEFAULT_CONDITIONS,
    seed: SeedOption = 0,
) -> None:
    """Render a measured paint with its colour and texture (Kirchner et al.'s method)."""
    from flakelab.render.appearance import (
        PANEL_ASPECULAR_DEG,
        image_format,
        parse_distance,
        render_curved,
        render_panel,
        save_image,
    )

    check_output_file(output, "--output", image_format)  # before the render
    if aspecular is not None and view is not View.panel:
        raise FlakelabError("--aspecular: for --view panel (the curved panel sweeps 0–110°)")
    appearance = _appearance(measurement, sample, conditions, lamp)
    options = dict(
        diffuse_fraction=light, distance_m=parse_distance(distance), texture=not no_texture
    )
    if view is View.panel:
        angle = PANEL_ASPECULAR_DEG if aspecular is None else aspecular
        image = render_panel(appearance, angle, size, seed=seed, **options)
    else:
        image = render_curved(appearance, (size // 2, size), seed=seed, **options)
    save_image(image, output)
    errors.print(f"wrote {output} ({image.shape[1]}×{image.shape[0]})", highlight=False)


def render_grid_command(
    measurement: Annotated[
        Path | None, typer.Argument(help="Measurement whose colour to use (default: example).")
    ] = None,
    output: OutputOption = Path("render-grid.png"),
    steps: Annotated[int, typer.Option(min=2, max=16, help="Steps of glint and coarseness.")] = 8,
    tile: Annotated[int, typer.Option(min=16, max=512, help="Tile size in pixels.")] = 128,
    light: LightOption = 0.5,
    sample: SampleOption = None,
    conditions: ConditionsOption = DEFAULT_CONDITIONS,
    seed: SeedOption = 0,
) -> None:
    """Paper 001 Fig. 3: colour fixed, glint rises across, diffuse coarseness rises upward."""
    from flakelab.render.appearance import image_format, render_grid, save_image

    check_output_file(output, "--output", image_format)  # before the render
    appearance = _appearance(measurement, sample, conditions)
    image = render_grid(appearance, steps, tile, diffuse_fraction=light, seed=seed)
    save_image(image, output)
    errors.print(f"wrote {output} ({steps}×{steps} tiles)", highlight=False)


texture_app = command_group("Appearance-based texture processes: closed loop and fitting.")


@texture_app.command("evaluate")
@reports_errors
def texture_evaluate(
    points: Annotated[int, typer.Option(min=2, max=100, help="Prescribed values per process.")] = 9,
    size: Annotated[
        int, typer.Option(min=64, max=8192, help="Generated image side in pixels (as render).")
    ] = 1024,
    seed: SeedOption = 100,
    json_output: JsonOption = False,
) -> None:
    """Closed loop: images made at prescribed coarseness and glint, measured back.

    Over the usable range, each image measured with the texture metrics; the relative
    errors reported."""
    from flakelab.texture.calibration import roundtrip, shipped_processes

    report = {
        name: roundtrip(process, points, size, seed)
        for name, process in shipped_processes().items()
    }
    report["roundtrip_rel_error_max"] = max(r["rel_error_max"] for r in report.values())
    if json_output:
        print_report(report)
        return
    for name in ("coarseness", "glint"):
        r = report[name]
        console.print(f"[bold]{name}[/]  max relative error {r['rel_error_max']:.3f}")
        for p, m, e in zip(r["prescribed"], r["measured"], r["rel_error"], strict=True):
            console.print(f"  prescribed {p:7.3f}  measured {m:7.3f}  error {e:6.3f}")


@texture_app.command("fit")
@reports_errors
def texture_fit(
    output: Annotated[Path, typer.Option("--output", "-o", help="JSON file to write.")],
    process: Annotated[
        list[str] | None,
        typer.Option(
            metavar="NAME", help="Refit only this process (coarseness, glint); others kept from -o."
        ),
    ] = None,
    grey_only: Annotated[
        bool,
        typer.Option(
            "--grey-only",
            help="Refit only the coarseness grey level of the processes in -o to the anchors' "
            "brightness, keeping every other control.",
        ),
    ] = False,
    seed: SeedOption = 0,
    json_output: JsonOption = False,
) -> None:
    """Fit the processes to the anchor ladders (the shipped file: src/flakelab/data/)."""
    from flakelab.texture.calibration import (
        fit_process,
        load_processes,
        refit_grey,
        roundtrip,
        save_processes,
    )
    from flakelab.texture.generator import PROCESSES

    check_output_file(output, "--output")  # before the fit, which takes minutes
    if grey_only:
        fitted = dict(load_processes(output))
        fitted["coarseness"] = refit_grey(fitted["coarseness"], seed=seed)
        save_processes(fitted, output)
        errors.print(f"wrote {output} (coarseness grey level refitted)", highlight=False)
        return
    names = process or list(PROCESSES)
    unknown = sorted(set(names) - set(PROCESSES))
    if unknown:
        raise ValueError(f"--process: expected one of {', '.join(PROCESSES)}, got {unknown}")
    fitted = {} if set(names) == set(PROCESSES) else dict(load_processes(output))
    reports = {}
    for name in names:
        fitted[name], reports[name] = fit_process(
            name, seed=seed, progress=lambda m: errors.print(m)
        )
        reports[name]["roundtrip"] = roundtrip(fitted[name])
    save_processes(fitted, output)
    if json_output:
        print_report(reports)
    for name, r in reports.items():
        errors.print(f"{name}: closed-loop max error {r['roundtrip']['rel_error_max']:.3f}")
    errors.print(f"wrote {output}", highlight=False)
