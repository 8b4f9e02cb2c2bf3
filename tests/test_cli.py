"""The flakelab command as a user runs it (a real process: no traceback may leak)."""

from __future__ import annotations

import contextlib
import inspect
import io
import json
import os
import re
import signal
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from flakelab.cli.common import Terminated, progress_bar, reports_errors, run_command_line, tracked
from flakelab.core import compare, tolerance_preset
from flakelab.data import example_path
from flakelab.errors import Note
from flakelab.io import read_measurement, read_measurements, write_measurements
from flakelab.models.registry import shipped_model


def test_inspect_json_carries_lab_per_geometry_and_flop_index(ma_t12_files, cli):
    result = cli("inspect", ma_t12_files[0], "--json")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    m = read_measurement(ma_t12_files[0])
    assert [g["name"] for g in report["geometries"]] == list(m.geometry_names)
    lab = np.array([[g["L"], g["a"], g["b"]] for g in report["geometries"]])
    np.testing.assert_allclose(lab, m.stored_lab, atol=1e-3)  # the instrument's own numbers
    assert report["flop_index"] == pytest.approx(m.flop_index())


def test_inspect_images_draws_the_camera_pictures_with_the_spectra_colour(ma_t12_files, tmp_path,
                                                                         cli):  # fmt: skip
    """``inspect --images``: the MA-T12's seven camera pictures in one figure, each above a
    swatch of the colour its geometry's spectrum gives (a flat patch of exactly that sRGB)."""
    from matplotlib.image import imread

    from flakelab.core.colorimetry import Lab_to_sRGB

    figure = tmp_path / "pictures.png"
    result = cli("inspect", ma_t12_files[0], "--images", figure, "--json")
    assert result.returncode == 0, result.stderr
    drawn = json.loads(result.stdout)["camera_pictures"]
    assert drawn["geometries"] == ["15as-45", "15as-30", "15as-15", "15as15", "15as45", "15as80",
                                   "15d"]  # fmt: skip
    assert (drawn["width"], drawn["height"]) == (480, 360)
    pixels = np.round(imread(figure)[..., :3] * 255).reshape(-1, 3)
    m = read_measurement(ma_t12_files[0])
    for geometry in drawn["geometries"][:-1]:
        swatch = np.round(Lab_to_sRGB(m.lab()[m.index(geometry)]) * 255)
        assert (np.abs(pixels - swatch).max(axis=1) <= 1).sum() > 5000, geometry
    said = cli("inspect", ma_t12_files[0]).stdout  # without --images, where to find them
    assert "camera pictures: 7 in the file ('--images FIGURE' draws them)" in said
    assert "camera pictures" not in cli("inspect", "--example").stdout
    figure.unlink()
    result = cli("inspect", example_path("target"), "--images", figure)
    assert result.returncode == 2 and "read from MA-T12 exports" in result.stderr, result.stderr
    assert not figure.exists()


def _export_with_pictures(readings, path: Path) -> Path:
    """``readings`` as one MA-T12 export with a ``Texture Images`` sheet as the instrument
    writes it: each sample heading a column from B, a flat picture in each geometry's row."""
    import openpyxl
    from openpyxl.drawing.image import Image as Picture
    from PIL import Image

    write_measurements(readings, path)
    workbook = openpyxl.load_workbook(path)
    sheet = workbook.create_sheet("Texture Images")
    rows = ("15as-45", "15as-30", "15as-15", "15as15", "15as45", "15as80", "15d")
    for row, label in enumerate(rows, start=2):
        sheet.cell(row, 1).value = label
    for column, reading in enumerate(readings, start=2):
        sheet.cell(1, column).value = reading.sample
        for row in range(2, len(rows) + 2):
            png = io.BytesIO()
            Image.new("RGB", (48, 36), (40 * column, 20 * row, 90)).save(png, format="png")
            sheet.add_image(Picture(png), f"{chr(64 + column)}{row}")
    workbook.save(path)
    return path


def test_inspect_images_of_several_readings_draws_a_row_of_each(ma_t12_files, tmp_path, cli):
    """``inspect --images --all`` (and ``--average``) on an export of two samples: the
    pictures of each, a row each, every one above the swatch of its own sample's spectrum.
    Both were refused before stop 99 ("one sample at a time")."""
    from matplotlib.image import imread

    from flakelab.core.colorimetry import Lab_to_sRGB

    readings = [read_measurement(f) for f in ma_t12_files[:2]]
    export = _export_with_pictures(readings, tmp_path / "two.xlsx")
    for option in ("--all", "--average"):
        figure = tmp_path / f"pictures{option}.png"
        result = cli("inspect", export, option, "--images", figure, "--json")
        assert result.returncode == 0, result.stderr
        drawn = json.loads(result.stdout)["camera_pictures"]
        assert drawn["readings"] == 2 and drawn["geometries"][-1] == "15d"
        pixels = np.round(imread(figure)[..., :3] * 255).reshape(-1, 3)
        for m in readings:
            swatch = np.round(Lab_to_sRGB(m.lab()[m.index("15as15")]) * 255)
            assert (np.abs(pixels - swatch).max(axis=1) <= 1).sum() > 2000, (option, m.sample)
    said = cli("inspect", export, "--all", "--images", tmp_path / "again.png").stderr
    assert "7 camera pictures of each of 2 readings" in " ".join(said.split()), said


def test_compare_images_draws_the_reference_above_the_sample(ma_t12_files, tmp_path, cli):
    """``compare --images``: two exports' camera pictures in one figure, each above the swatch
    of its own spectrum; with an averaged reading, a row of each reading averaged (refused
    before stop 99: no one picture shows the mean)."""
    from matplotlib.image import imread

    from flakelab.core.colorimetry import Lab_to_sRGB

    reference, sample = ma_t12_files[:2]
    figure = tmp_path / "pictures.png"
    result = cli("compare", reference, sample, "--images", figure, "--json")
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["camera_pictures"]["geometries"][-1] == "15d"
    pixels = np.round(imread(figure)[..., :3] * 255).reshape(-1, 3)
    for file in (reference, sample):
        m = read_measurement(file)
        swatch = np.round(Lab_to_sRGB(m.lab()[m.index("15as15")]) * 255)
        assert (np.abs(pixels - swatch).max(axis=1) <= 1).sum() > 2000, file.name
    # the car read at two spots, averaged: a row of each spot's pictures above the spray-out's
    readings = [read_measurement(f) for f in ma_t12_files[2:4]]
    car = _export_with_pictures(readings, tmp_path / "car.xlsx")
    averaged = cli("compare", car, sample, "--images", figure, "--average", "--json")
    assert averaged.returncode == 0, averaged.stderr
    assert json.loads(averaged.stdout)["camera_pictures"]["readings"] == 3
    pixels = np.round(imread(figure)[..., :3] * 255).reshape(-1, 3)
    for m in [*readings, read_measurement(sample)]:
        swatch = np.round(Lab_to_sRGB(m.lab()[m.index("15as15")]) * 255)
        assert (np.abs(pixels - swatch).max(axis=1) <= 1).sum() > 1000, m.sample


def test_convert_says_the_camera_pictures_stay_behind(ma_t12_files, tmp_path, cli):
    """flakelab writes readings only: converting an export with pictures says so, once."""
    converted = tmp_path / "spot.json"
    result = cli("convert", ma_t12_files[0], converted)
    assert result.returncode == 0, result.stderr
    assert "7 camera pictures stay behind" in result.stderr
    again = cli("convert", converted, tmp_path / "spot.xlsx")
    assert again.returncode == 0 and "stay behind" not in again.stderr, again.stderr


def test_convert_lab_only_writes_the_colour_and_no_spectra(tmp_path, cli):
    """``convert --lab-only``: the example car as L*a*b* under the conditions named, no
    spectra, in CSV or CxF3 (software that takes a colour per angle). Read back, its spectra
    are recovered: the same colour under those conditions to 1e-6, another under daylight
    (a metamer); JSON, which would give them as measured, is refused before anything is read
    or written."""
    target = example_path("target")
    written = tmp_path / "car.csv"
    done = cli("convert", target, written, "--lab-only", "--conditions", "A/10")
    assert done.returncode == 0, done.stderr
    header = written.read_text().splitlines()[0].split(",")
    assert header[:5] == ["sample", "geometry", "L", "a", "b"] and "R400" not in header
    for file in (written, tmp_path / "car.cxf"):
        if file.suffix == ".cxf":
            cli("convert", written, file)  # colour alone stays colour alone
            assert "ReflectanceSpectrum" not in file.read_text()
        under_a = json.loads(cli("compare", target, file, "--conditions", "A/10", "--json").stdout)
        daylight = json.loads(cli("compare", target, file, "--json").stdout)
        assert under_a["de00_max"] < 1e-6 and daylight["de00_max"] > 0.1
        assert under_a["spectra_recovered"] and under_a["metamerism_index_max"] == {}
    again = cli("convert", written, tmp_path / "daylight.csv", "--lab-only")
    said = " ".join(again.stderr.split())
    assert "L*a*b* under D65/10 is an estimate: its file gave it under A/10 alone" in said, said
    refused = cli("convert", target, tmp_path / "car.json", "--lab-only")
    assert refused.returncode == 2
    assert "--lab-only: L*a*b* without spectra is written as csv" in refused.stderr
    assert not (tmp_path / "car.json").exists()


def test_compare_all_judges_each_sample_as_compare_judges_it_alone(tmp_path, cli):
    """``compare REFERENCE SAMPLES --all``: each panel of a batch judged against the target as
    ``compare`` judges it alone (its worst ΔE00 and verdict), a row each, how many pass, and
    ``--fail-on-reject`` exits 1 when any fails. A panel read at five geometries is judged at
    those, the others named, and ``--plot`` draws every panel at those five, saying so; one
    sharing none is refused by name; options that pick one sample are refused."""
    from flakelab.core.geometry import Geometry, instrument_geometries

    target, sprayout = (read_measurement(example_path(n)) for n in ("target", "sprayout"))
    five = [sprayout.index(g) for g in instrument_geometries("five-angle")]
    batch = [
        replace(sprayout, sample="first"),
        replace(sprayout, sample="too light", reflectance=sprayout.reflectance * 1.15),
        replace(sprayout, sample="five", geometries=tuple(sprayout.geometries[i] for i in five),
                reflectance=sprayout.reflectance[five]),
    ]  # fmt: skip
    panels = tmp_path / "batch.csv"
    write_measurements(batch, panels, wide=True)
    done = cli("compare", example_path("target"), panels, "--all", "--json")
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    assert (report["compared"], report["passed"]) == (3, 2)
    for row in report["samples"]:
        alone = cli("compare", example_path("target"), panels, "--sample-name", row["sample"],
                    "--json")  # fmt: skip
        assert json.loads(alone.stdout)["de00_max"] == row["de00_max"]
        assert json.loads(alone.stdout)["pass"] == row["pass"], row["sample"]
        worst = max(row["geometries"], key=lambda g: g["limit_share"])
        assert row["de00_max_at"] == max(row["geometries"], key=lambda g: g["de00"])["name"]
        assert (row["limit_share_at"], row["limit_share_max"]) == (
            worst["name"],
            worst["limit_share"],
        )
    judged = [g.name for g in instrument_geometries("five-angle")]
    assert [g["name"] for g in report["samples"][2]["geometries"]] == judged
    left = [g for g in target.geometry_names if g not in judged]
    assert report["samples"][2]["not_compared"] == {"reference": left, "sample": []}
    chart = tmp_path / "batch.png"
    drawn = cli("compare", example_path("target"), panels, "--all", "--plot", chart)
    assert drawn.returncode == 0 and chart.read_bytes().startswith(b"\x89PNG"), drawn.stderr
    said = " ".join(drawn.stderr.split())
    drawn_at = "--plot draws the 5 geometries every sample shares with the reference, not "
    assert drawn_at + ", ".join(left) in said, said
    shown = cli("compare", example_path("target"), panels, "--all", "--fail-on-reject")
    assert shown.returncode == 1
    said = " ".join(shown.stdout.split())
    assert "2 of 3 samples pass" in said and "too light" in said and "fail at" in said
    lacks = "not compared for five: 7 of the reference's geometries, which the sample lacks: "
    assert lacks + ", ".join(left) in said
    refused = cli("compare", example_path("target"), panels, "--all", "--sample-name", "five")
    assert refused.returncode == 2 and "--all compares every sample of SAMPLE" in refused.stderr
    apart = replace(sprayout, sample="apart", geometries=(Geometry(45, 60),),
                    reflectance=sprayout.reflectance[:1])  # fmt: skip
    write_measurements([batch[0], apart], tmp_path / "apart.csv", wide=True)
    lost = cli("compare", example_path("target"), tmp_path / "apart.csv", "--all")
    assert (
        lost.returncode == 2
        and "sample 'apart'" in lost.stderr
        and "share no geometry" in (" ".join(lost.stderr.split()))
    )


def test_compare_all_of_a_qc_job_judges_its_trials_against_its_standard(tmp_path, cli, monkeypatch):
    """``compare JOB --all``: an MA-T12 QC job holding its standard (named by its
    ``STANDARD:`` row, here not its first sample) and two trials; each trial is judged against
    the standard, which is left out of the samples, and commands that read one sample of the
    job read its standard, and say so. The job is read once, standard and trials."""
    import flakelab.io

    reads, read_measurements = [], flakelab.io.read_measurements
    monkeypatch.setattr(flakelab.io, "read_measurements",
                        lambda path: reads.append(path) or read_measurements(path))  # fmt: skip
    sprayout = read_measurement(example_path("sprayout"))
    target = replace(read_measurement(example_path("target")), sample="std")
    job = tmp_path / "job.xlsx"
    trials = [replace(sprayout, sample=f"trial {i}", reflectance=sprayout.reflectance * i)
              for i in (1.0, 1.1)]  # fmt: skip
    write_measurements([replace(trials[0], metadata={"standard": "std"}), target, trials[1]], job)
    reads.clear()
    done = cli("compare", job, "--all", "--json")
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    assert report["reference"] == "std" and report["reference_left_out"] and reads == [job]
    assert [s["sample"] for s in report["samples"]] == ["trial 1.0", "trial 1.1"]
    alone = json.loads(cli("compare", example_path("target"), job, "--sample-name", "trial 1.1",
                           "--json").stdout)  # fmt: skip
    assert report["samples"][1]["de00_max"] == pytest.approx(alone["de00_max"], abs=1e-9)
    said = " ".join(done.stderr.split())
    assert "holds 3 samples; read its QC job's standard, 'std'" in said, said
    shown = cli("compare", job, "--all")
    assert "the reference, 'std', is left out of its own file's samples" in " ".join(
        shown.stdout.split()
    )
    assert "std" in cli("inspect", job).stdout.splitlines()[0]


def test_convert_wide_writes_a_row_per_sample_that_reads_back(tmp_path, cli):
    """``convert --wide``: the example car in one row, its spectra at each of the 12
    geometries in columns; compared with the car it differs by nothing, and ``--lab-only``
    gives its colour alone in 36 columns. A format other than CSV is refused, nothing
    written. A panel headed by aspecular angles alone is read, and the note says at which
    lamp."""
    target = example_path("target")
    written = tmp_path / "car.csv"
    assert cli("convert", target, written, "--wide").returncode == 0
    header, row = written.read_text().splitlines()
    assert header.split(",")[1] == "R400 15as-45" and len(row.split(",")) == 1 + 12 * 31 + 10
    same = json.loads(cli("compare", target, written, "--json").stdout)
    assert same["de00_max"] == 0 and not same["spectra_recovered"]
    assert cli("convert", target, tmp_path / "lab.csv", "--wide", "--lab-only").returncode == 0
    header = (tmp_path / "lab.csv").read_text().splitlines()[0].split(",")
    assert header[1:37] == [f"{q} {g}" for g in read_measurement(target).geometry_names
                            for q in ("L*", "a*", "b*")]  # fmt: skip
    refused = cli("convert", target, tmp_path / "car.json", "--wide")
    assert refused.returncode == 2 and not (tmp_path / "car.json").exists()
    assert "a row per sample is for a CSV file, not json" in refused.stderr
    panel = tmp_path / "panel.csv"
    panel.write_text("sample,L* 15°,a* 15°,b* 15°,L* 45°,a* 45°,b* 45°\nblue,40,-2,-30,25,0,-20\n")
    with pytest.warns(Note, match=r"read at a 45° lamp \(15° as 45as15, 45° as 45as45\)"):
        shown = cli("inspect", panel)  # the command prints it as a note: pytest catches it here
    assert shown.returncode == 0, shown.stderr
    assert "45as15" in shown.stdout and "40.00" in shown.stdout


def test_convert_of_a_file_of_both_kinds_says_how_to_write_it(tmp_path, cli):
    """A CxF3 file of a measured trial and a standard's colour alone converts with
    ``--lab-only`` (both as L*a*b*) or ``--sample`` (one); without either it is refused,
    saying so, and nothing is written, but for a CxF3 file, which holds both."""
    both = tmp_path / "both.cxf"
    car = read_measurement(example_path("target"))
    car = replace(car, stored_lab=car.lab())
    write_measurements([replace(car, sample="standard"), replace(car, sample="trial")], both)
    text = both.read_text()
    trial = text.index('Name="trial"')
    spectrum = r"<(\w+:)ReflectanceSpectrum[^>]*>[^<]*</\1ReflectanceSpectrum>"
    both.write_text(re.sub(spectrum, "", text[:trial]) + text[trial:])
    refused = cli("convert", both, tmp_path / "out.csv")
    assert refused.returncode == 2 and not (tmp_path / "out.csv").exists()
    said = " ".join(refused.stderr.split())
    assert "holds measured spectra and L*a*b* alone ('standard')" in said, said
    assert "--lab-only writes every one as L*a*b*, --sample NAME one of them" in said
    assert cli("convert", both, tmp_path / "out.csv", "--lab-only").returncode == 0
    assert len(read_measurements(tmp_path / "out.csv")) == 2
    assert cli("convert", both, tmp_path / "trial.json", "--sample", "trial").returncode == 0
    assert "a CxF3 file holds both" in said  # and is written whole, as read
    assert cli("convert", both, tmp_path / "again.cxf").returncode == 0
    again = read_measurements(tmp_path / "again.cxf")
    assert [m.spectra_recovered for m in again] == [True, False]


def test_compare_example_agrees_with_library_and_tolerance(cli):
    result = cli("compare", "--example", "--json", "--tolerance", "de00-1.0")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    direct = compare(
        read_measurement(example_path("target")),
        read_measurement(example_path("sprayout")),
        "de00-1.0",
    )
    assert report["de00_max"] == pytest.approx(direct.de00_max)
    for g in report["geometries"]:
        assert g["pass"] == (g["de00"] <= 1.0)
    assert report["pass"] == all(g["pass"] for g in report["geometries"])
    assert report["not_compared"] == {"reference": [], "sample": []}  # both read at all twelve
    assert "not compared" not in cli("compare", "--example").stdout
    assert cli("compare", "--example", "--fail-on-reject").returncode == (
        0 if report["pass"] else 1
    )
    # the metamerism index under a booth's own lights, as the library computes it
    booth = json.loads(cli("compare", "--example", "--json", "--lights", "A,F2").stdout)
    lit = compare(read_measurement(example_path("target")),
                  read_measurement(example_path("sprayout")), lights=("A", "FL2"))  # fmt: skip
    assert booth["metamerism_index_max"] == pytest.approx(
        {k: float(v.max()) for k, v in lit.metamerism.items()}, abs=5e-4
    )  # to the thousandth, as every report gives it
    refused = cli("compare", "--example", "--conditions", "A/10", "--lights", "A")
    assert refused.returncode == 2 and "--lights: A is the reference illuminant" in refused.stderr


def test_compare_names_the_geometries_a_five_angle_spray_out_leaves_out(tmp_path, cli):
    target = read_measurement(example_path("target"))
    five = tmp_path / "five.json"
    write_measurements([read_measurement(example_path("sprayout")).select(
        ["45as15", "45as25", "45as45", "45as75", "45as110"])], five)  # fmt: skip
    run = cli("compare", str(example_path("target")), str(five))
    assert run.returncode == 0, run.stderr
    left = [g for g in target.geometry_names if g.startswith("15") or g == "45as-15"]
    assert "not compared: 7 of the reference's geometries, which the sample lacks: " in run.stdout
    assert ", ".join(left) in " ".join(run.stdout.split())


def test_a_file_of_several_samples_says_which_it_read(tmp_path, cli):
    both = tmp_path / "both.json"
    target, sprayout = (read_measurement(example_path(k)) for k in ("target", "sprayout"))
    write_measurements([target, sprayout], both)
    run = cli("inspect", str(both), "--json")
    assert run.returncode == 0 and json.loads(run.stdout)["sample"] == target.sample
    note = " ".join(run.stderr.split())
    assert f"note: {both} holds 2 samples; read its first, '{target.sample}' (--sample" in note
    run = cli("inspect", str(both), "--sample", sprayout.sample, "--json")
    assert json.loads(run.stdout)["sample"] == sprayout.sample and "note" not in run.stderr
    assert "note" not in cli("inspect", "--example").stderr  # one sample: nothing to say
    run = cli("compare", str(both), str(both), "--sample-name", sprayout.sample)
    note = " ".join(run.stderr.split())  # the option that names another is the command's own
    assert "(--reference-sample names another)" in note and note.count("note:") == 1


def test_compare_draws_reference_above_sample_only_into_a_figure_file(tmp_path, cli):
    from matplotlib.image import imread

    picture, chart = tmp_path / "side-by-side.png", tmp_path / "chart.png"
    run = cli("compare", "--example", "--render", picture, "--plot", chart)
    assert run.returncode == 0, run.stderr
    assert str(picture) in run.stderr and imread(picture).shape[2] in (3, 4)
    assert f"wrote {chart}" in run.stderr and imread(chart).shape[1] > imread(chart).shape[0]
    run = cli("compare", "--example", "--render", tmp_path / "side-by-side.bmp")
    assert run.returncode == 2 and "side-by-side.bmp" in run.stderr and ".png" in run.stderr
    run = cli("compare", "--example", "--plot", tmp_path / "chart.bmp")
    assert run.returncode == 2 and "chart.bmp" in run.stderr and ".png" in run.stderr
    target = read_measurement(example_path("target"))
    lit_at_15 = tmp_path / "lit-at-15.csv"  # nothing lit at 45°: drawn under the 15° lamp
    write_measurements([target.select([g for g in target.geometry_names if g[:2] == "15"])],
                       lit_at_15)  # fmt: skip
    low = tmp_path / "low.png"
    run = cli("compare", lit_at_15, lit_at_15, "--render", low)
    assert run.returncode == 0 and imread(low).shape[2] in (3, 4), run.stderr
    one_each = tmp_path / "one-each.csv"  # one geometry under each lamp: no curve to draw
    write_measurements([target.select(["15as15", "45as45"])], one_each)
    run = cli("compare", one_each, one_each, "--render", tmp_path / "none.png")
    said = " ".join(run.stderr.split())
    assert run.returncode == 2 and "--render" in said and "a lamp at 45° needs two or" in said
    for args, said in ((("--render-lamps", "15"), "give --render"),
                       (("--render", picture, "--render-lamps", "90"), "0 to 89°")):  # fmt: skip
        run = cli("compare", "--example", *args)
        assert run.returncode == 2 and "--render-lamps: " in run.stderr and said in run.stderr
    assert sorted(tmp_path.iterdir()) == [chart, lit_at_15, low, one_each, picture]


def test_compare_a_measurement_with_itself_passes_with_zero_difference(ma_t12_files, cli):
    result = cli("compare", ma_t12_files[0], ma_t12_files[0], "--json", "-t", "components")
    report = json.loads(result.stdout)
    assert report["pass"] and report["de00_max"] == pytest.approx(0, abs=1e-9)


def test_user_tolerance_file(tmp_path, cli):
    toml = tmp_path / "shop.toml"
    toml.write_text('name = "shop"\n[default]\nde00 = 5.0\n[geometries."45as75"]\nde00 = 0.1\n')
    report = json.loads(cli("compare", "--example", "--json", "-t", toml).stdout)
    assert report["tolerance"] == "shop"
    assert report["failing_geometries"] == ["45as75"]


def test_convert_then_inspect_gives_the_same_numbers(ma_t12_files, tmp_path, cli):
    out = tmp_path / "converted.cxf"
    assert cli("convert", ma_t12_files[1], out).returncode == 0
    a = json.loads(cli("inspect", ma_t12_files[1], "--json").stdout)
    b = json.loads(cli("inspect", out, "--json").stdout)
    assert [g["L"] for g in a["geometries"]] == pytest.approx([g["L"] for g in b["geometries"]])


def test_plot_writes_a_png(tmp_path, cli):
    out = tmp_path / "flop.png"
    result = cli("plot", example_path("target"), "-o", out)
    assert result.returncode == 0, result.stderr
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 20_000
    tilted = tmp_path / "flop-tilt.png"
    result = cli("plot", example_path("target"), "--against", "flake-tilt", "-o", tilted)
    assert result.returncode == 0 and tilted.read_bytes() != out.read_bytes(), result.stderr
    result = cli("plot", example_path("target"), "--against", "tilt", "-o", tmp_path / "x.png")
    assert result.returncode == 2 and "'--against'" in result.stderr


def test_a_postscript_plot_says_in_a_note_that_it_drops_transparency(tmp_path):
    """PostScript holds no transparency. Matplotlib said so in a bare line that named no file,
    "The PostScript backend does not support transparency; …"; now a note names the file and
    the formats that keep it. A PDF needs none."""
    plot = [sys.executable, "-m", "flakelab.cli.main", "plot", str(example_path("target")), "-o"]
    eps = subprocess.run([*plot, str(tmp_path / "flop.eps")], capture_output=True, text=True,
                         timeout=300)  # fmt: skip
    assert eps.returncode == 0 and (tmp_path / "flop.eps").read_bytes().startswith(b"%!PS")
    said = " ".join(eps.stderr.split())
    assert said.startswith(f"note: {tmp_path / 'flop.eps'}: PostScript holds no transparency")
    assert "PostScript backend" not in said
    pdf = subprocess.run([*plot, str(tmp_path / "flop.pdf")], capture_output=True, text=True,
                         timeout=300)  # fmt: skip
    assert pdf.returncode == 0 and "note" not in pdf.stderr


def _bad_files(tmp_path: Path, source: Path) -> dict[str, tuple[Path, str]]:
    truncated = tmp_path / "truncated.xlsx"
    truncated.write_bytes(source.read_bytes()[:30_000])
    other = tmp_path / "picture.xlsx"
    other.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(64))
    header = "sample,geometry," + ",".join(f"R{w}" for w in range(400, 710, 10))
    row = "S,45as15," + ",".join(["0.4"] * 31)
    nan = tmp_path / "nan.csv"
    nan.write_text(header + "\n" + row.replace("0.4", "NaN", 1) + "\n")
    wrong = tmp_path / "wavelengths.csv"
    wrong.write_text(header.replace("R500", "R505") + "\n" + row + "\n")
    unknown = tmp_path / "geometry.csv"
    unknown.write_text(header + "\n" + row.replace("45as15", "45az15") + "\n")
    return {
        "truncated": (truncated, "truncated or corrupt"),
        "other kind": (other, "PNG image"),
        "NaN": (nan, "row 2, 400 nm: expected a finite number"),
        "wavelengths": (
            wrong,
            "header: expected increasing wavelengths with a constant step",
        ),
        "geometry": (unknown, "row 2, geometry: expected a geometry name"),
    }


def test_bad_files_exit_nonzero_with_one_line_naming_file_and_problem(ma_t12_files, tmp_path, cli):
    for label, (path, problem) in _bad_files(tmp_path, ma_t12_files[0]).items():
        result = cli("inspect", path)
        assert result.returncode == 2, label
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1, (label, result.stderr)
        assert str(path) in lines[0].replace("\n", "") and problem in lines[0], (label, lines[0])
        assert "Traceback" not in result.stderr + result.stdout


def test_bad_options_exit_nonzero_without_traceback(cli):
    for args, problem in (
        (("inspect", "--example", "-c", "D66/10"), "expected an illuminant"),
        (("compare", "--example", "-t", "no-such"), "neither a tolerance preset"),
        (("inspect",), "give a measurement file"),
        (("match", "--example", "--no-target-texture"), "for the harness"),
        (("match", "--example", "--resprays", "5"), "for the harness"),
        (("match", "--example", "--colour-alone"), "for the harness"),
        (("match", "evaluate", "--resprays", "-1"), "--resprays"),
    ):
        result = cli(*args)
        assert result.returncode == 2 and problem in result.stderr, result.stderr
        assert "Traceback" not in result.stderr


def test_an_instrument_is_taken_as_the_instrument_spells_it(cli):
    """``-i MA-T12``, as the instrument's label spells it, is ``ma-t12``: ``match`` refused it,
    "no shipped model for 'MA-T12' (shipped: five-angle, ma-t12)"; a name of no instrument is
    refused naming the instruments, not as one without a model."""
    spelt = json.loads(cli("match", "--example", "-i", "MA T12", "--candidates", "1",
                           "--json").stdout)  # fmt: skip
    plain = json.loads(cli("match", "--example", "-i", "ma-t12", "--candidates", "1",
                           "--json").stdout)  # fmt: skip
    assert spelt["model_id"] == plain["model_id"] and "ma-t12" in spelt["model_id"]
    assert spelt["candidates"][0]["recipe"] == plain["candidates"][0]["recipe"]
    refused = cli("match", "--example", "-i", "mat99")
    assert refused.returncode == 2 and refused.stderr.strip() == (
        "error: --instrument: expected one of byk-mac-i, ma-t6, ma-t12, five-angle, got 'mat99'"
    )


def test_a_reader_that_stops_reading_stops_the_command_quietly():
    """``flakelab … | head`` : the pipe's reader gone, the command ends as the shell's tools
    do (status 128 + SIGPIPE) instead of printing an error about its own output, whether it
    writes JSON or a table, and with ``2>&1`` too. A table (Rich's console) ended with
    status 1, and one whose note went to a stderr gone too, with 1 as well."""
    inspect = [sys.executable, "-m", "flakelab.cli.main", "inspect", "--example"]
    for command in (inspect + ["--json"], inspect):
        process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        process.stdout.close()
        said = process.stderr.read().decode()
        assert process.wait(timeout=120) == 141 and said == "", command
    for command, status in ((inspect, 141), (inspect[:-1] + ["no-such.csv"], 2)):
        reader, writer = os.pipe()
        os.close(reader)  # before the command writes a byte, to stdout or to stderr
        process = subprocess.Popen(command, stdout=writer, stderr=writer)
        os.close(writer)
        assert process.wait(timeout=120) == status, command


_A_LONG_TABLE = """
import sys, typer
from rich.table import Table
from flakelab.cli.common import console, print_report, reports_errors

@reports_errors
def show():
    rows = [(f"{row:013d}", "Al medium 98%, Phthalo blue GS 2%") for row in range(4000)]
    if sys.argv[1:] == ["--json"]:
        print_report({"cases": rows})
        return
    table = Table("case", "recipe")
    for row in rows:
        table.add_row(*row)
    console.print(table)

try:
    show()
except typer.Exit as stop:
    sys.exit(stop.exit_code)
"""


def test_a_table_its_reader_leaves_half_way_stops_the_command(tmp_path):
    """``flakelab cases list --last 3000 | head``: the reader gone after the first lines, the
    table's write returns the part written, and Python's buffered stream counted the rest
    written too; the command ended with status 0, its table lost past the pipe's 64 KiB. A
    reader still reading, and a pipe the command writes nothing to, are no such end."""
    for json_output in ([], ["--json"]):
        process = subprocess.Popen([sys.executable, "-c", _A_LONG_TABLE, *json_output],
                                   stdout=subprocess.PIPE, stderr=subprocess.PIPE)  # fmt: skip
        process.stdout.read(200)
        process.stdout.close()
        assert process.wait(timeout=120) == 141 and process.stderr.read() == b""  # 0 before
    from flakelab.cli.common import reader_gone

    reader, writer = os.pipe()
    with os.fdopen(writer, "w") as stream, os.fdopen(reader) as still_reading:
        assert not reader_gone(stream) and not reader_gone(still_reading)
        still_reading.close()
        assert reader_gone(stream)
        with contextlib.suppress(BrokenPipeError):
            stream.close()
    assert not reader_gone(io.StringIO()) and not reader_gone(open(tmp_path / "f", "w"))


def test_a_report_is_written_whole_whatever_the_standard_streams(tmp_path):
    """Output in an encoding that cannot write ΔE00 (a redirected stream on Windows writes
    cp1252) stopped the report half written, "'charmap' codec can't encode character 'Δ'":
    it is written whole, in UTF-8. A closed stdout (``>&-``) stopped with a traceback, a
    closed stdin with another: the command runs, as with /dev/null there."""
    compare_example = [sys.executable, "-m", "flakelab.cli.main", "compare", "--example"]
    legacy = {**os.environ, "PYTHONIOENCODING": "cp1252"}
    run = subprocess.run(compare_example, capture_output=True, env=legacy, timeout=300)
    assert run.returncode == 0, run.stderr.decode("utf-8", "replace")
    assert "ΔE00" in run.stdout.decode("utf-8") and "PASS" in run.stdout.decode("utf-8")
    closed = subprocess.run(compare_example, stderr=subprocess.PIPE, preexec_fn=lambda: os.close(1),
                            timeout=300)  # fmt: skip
    assert closed.returncode == 0 and closed.stderr == b""
    database = tmp_path / "shop.db"
    remove = [sys.executable, "-m", "flakelab.cli.main", "cases", "remove", "--synthetic", "-d",
              str(database)]  # fmt: skip
    generate = [*remove[:4], "generate", "--n", "2", "-d", str(database)]
    assert subprocess.run(generate, capture_output=True, timeout=300).returncode == 0
    asked = subprocess.run(remove, capture_output=True, text=True, preexec_fn=lambda: os.close(0),
                           timeout=300)  # fmt: skip
    assert asked.returncode == 2 and asked.stderr.startswith("error: cases remove --synthetic: "
                                                            "confirm with --yes")  # fmt: skip


def test_a_command_in_a_removed_folder_says_so(tmp_path):
    """The folder a command runs in, removed under its shell (``rm -r`` from another
    terminal, a USB stick taken out): 'match' died in torch's import ("Intel oneMKL FATAL
    ERROR: Cannot load …libtorch_cpu.so") and an output named without a whole path was
    "[Errno 2] No such file or directory", naming none. It stops at once, saying why."""
    gone = tmp_path / "gone"
    gone.mkdir()

    def enter_and_remove():
        os.chdir(gone)
        os.rmdir(gone)

    run = subprocess.run(
        [sys.executable, "-c", "from flakelab.cli.main import run; run()", "match", "--example"],
        capture_output=True, text=True, preexec_fn=enter_and_remove, timeout=300,
    )  # fmt: skip
    assert run.returncode == 2, run.stderr
    assert run.stderr == "error: the folder this runs in no longer exists (removed, or its disk "\
                         "taken out): cd to another\n"  # fmt: skip


def test_a_message_to_a_log_stays_on_one_line(tmp_path, cli):
    """A command's message on a stderr that is no terminal is one line however long, so that
    a log can be searched for it: Rich wrapped it at 80 columns, between words."""
    for length in range(1, 30):  # wherever the 80th column would have fallen
        folder = tmp_path / ("f" * length)
        folder.mkdir()
        out = folder / "target.json"
        run = cli("convert", example_path("target"), out)
        assert run.returncode == 0 and run.stderr == f"wrote 1 measurement to {out}\n"


def test_convert_refuses_unknown_extension_and_keeps_existing_file(tmp_path, cli):
    existing = tmp_path / "out.bmp"
    existing.write_text("keep me")
    result = cli("convert", example_path("target"), existing)
    assert result.returncode == 2 and "unknown output extension" in result.stderr
    assert existing.read_text() == "keep me"


def _inputs(folder: Path) -> dict[str, Path]:
    """Copies of the example's files, and files standing for a case file, a model and a lot
    file: the output checks refuse them before any is read."""
    shipped = {k: example_path(k) for k in ("target", "sprayout")}
    shipped["recipe"] = shipped["target"].with_name("blue-metallic-recipe.json")
    files = {k: folder / path.name for k, path in shipped.items()}
    for kind, path in files.items():
        path.write_bytes(shipped[kind].read_bytes())
    for key, name in (("cases", "cases.csv"), ("model", "model.pt"), ("tins", "tins.json")):
        files[key] = folder / name
        files[key].write_text(f"{name}: to be kept\n")
    return files


# (arguments with {file} for the _inputs, the option refused, the file it names as read)
WRITTEN_OVER_INPUTS = [
    (["convert", "{target}", "{target}"], "TARGET", "SOURCE"),
    (["match", "{target}", "--recipe-out", "{target}"], "--recipe-out", "TARGET"),
    (["correct", "{target}", "--recipe", "{recipe}", "--sprayed", "{sprayout}",
      "--recipe-out", "{recipe}"], "--recipe-out", "--recipe"),
    (["correct", "{target}", "--recipe", "{recipe}", "--sprayed", "{sprayout}",
      "--recipe-out", "{sprayout}"], "--recipe-out", "--sprayed"),
    (["weigh", "{recipe}", "--recipe-out", "{recipe}"], "--recipe-out", "RECIPE"),
    (["cases", "nearest", "{target}", "--recipe-out", "{target}"], "--recipe-out", "TARGET"),
    (["cases", "export", "{cases}", "-d", "{cases}"], "TARGET", "--database"),
    (["cases", "habits", "{cases}", "--out", "{cases}"], "--out", "CASES"),
    (["train", "{cases}", "--loss-log", "{cases}"], "--loss-log", "CASES"),
    (["model", "adapt", "{cases}", "--model", "{model}", "--out", "{model}"],
     "--out", "--model"),
    (["model", "show", "{model}", "--out", "{model}"], "--out", "MODEL"),
    (["lots", "show", "{tins}", "--out", "{tins}"], "--out", "LOTS"),
    (["lots", "calibrate", "{sprayout}", "--recipe", "{recipe}", "--lots", "{recipe}"],
     "--lots", "--recipe"),
]  # fmt: skip


@pytest.mark.parametrize(
    ("args", "option", "read"),
    WRITTEN_OVER_INPUTS,
    ids=[f"{a[0]} {o} {r}" for a, o, r in WRITTEN_OVER_INPUTS],
)
def test_an_output_that_is_a_file_the_command_reads_is_refused(tmp_path, cli, args, option,
                                                               read):  # fmt: skip
    """An output named as one of the command's inputs (a car's measurement, the recipe that
    was sprayed, the cases) would lose what it holds: refused before any work, naming both,
    the file as it was; through a link to it too."""
    files = _inputs(tmp_path)
    before = {path: path.read_bytes() for path in files.values()}
    database = [] if args[0] == "convert" or "-d" in args else ["-d", tmp_path / "shop.db"]
    run = cli(*[a.format(**files) for a in args], *database)
    said = f"{option}: .* is also {read}, which this command reads"
    assert run.returncode == 2 and re.search(said, run.stderr), run.stderr
    assert {path: path.read_bytes() for path in files.values()} == before
    assert not (tmp_path / "shop.db").exists()
    link = tmp_path / "link"
    link.symlink_to(files[re.search(r"\{(.+?)\}", args[-1])[1]])
    linked = [*[a.format(**files) for a in args[:-1]], str(link)]
    run = cli(*linked, *database)
    assert run.returncode == 2 and re.search(said, run.stderr), run.stderr
    assert {path: path.read_bytes() for path in files.values()} == before


def test_two_outputs_of_one_file_are_refused(tmp_path, cli):
    """A training's model, checkpoint and loss log each its own file: one written over
    another (the checkpoint removed once the model is written) is refused before any work."""
    cases = tmp_path / "cases.csv"
    cases.write_text("kept\n")
    for args, said in ((["--out", "m.pt", "--checkpoint", "m.pt"], "--checkpoint: m.pt is "
                        "also --out, which this command writes too"),
                       (["--checkpoint", "c", "--loss-log", "c"], "--loss-log: c is also "
                        "--checkpoint"),
                       (["--loss-log", "l.png", "--plot", "l.png"], "--plot: l.png is also "
                        "--loss-log")):  # fmt: skip
        run = cli("train", cases, "-d", tmp_path / "shop.db", *args)
        assert run.returncode == 2 and said in run.stderr, run.stderr
    assert cases.read_text() == "kept\n" and sorted(p.name for p in tmp_path.iterdir()) == [
        "cases.csv"
    ]


def test_multi_sample_inspect_all(tmp_path, cli):
    m = read_measurement(example_path("target"))
    path = tmp_path / "two.json"
    write_measurements([m, read_measurement(example_path("sprayout"))], path)
    report = json.loads(cli("inspect", path, "--all", "--json").stdout)
    assert [x["sample"] for x in report["measurements"]] == [
        x.sample for x in read_measurements(path)
    ]


def test_tolerance_presets_are_documented():
    for name in ("refinish", "de00-1.0", "components"):
        assert tolerance_preset(name).description


def test_validate_scaling_reproduces_the_papers_observations(tmp_path, cli):
    run = cli(
        "validate", "scaling", "--json", "--photons", "5000", "--spreads", "10,5",
        "--plots", str(tmp_path),
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    report = json.loads(run.stdout)
    # the dye's fingerprint in g̃ and the linear span survive multiple flake bounces …
    assert report["shape_correlation_min"] > 0.99
    assert report["span_linearity_r2"] > 0.99
    # … but single-collision magnitudes do not, while the path-table model does
    assert report["single_collision_de00_mean"] > 5 * report["de00_mean"]
    assert report["de00_mean"] < 1.0
    entry = report["orientation_series"][0]
    assert entry["spread_deg"] == 5 and entry["g_relative_change_median"]["single_collision"] < 0.01
    assert entry["g_relative_change_median"]["monte_carlo"] > 0.02
    assert sorted(Path(p).name for p in report["plots"]) == [
        "scaling-spread-10.png", "scaling-spread-5.png",
    ]  # fmt: skip


def test_validate_scaling_rejects_bad_spreads_and_plots_before_the_monte_carlo(tmp_path, cli):
    run = cli("validate", "scaling", "--spreads", "0,90", "--plots", "")
    assert run.returncode == 2 and "--spreads" in run.stderr and "Traceback" not in run.stderr
    file = tmp_path / "plots.png"
    file.write_bytes(b"")
    for options, message in (
        (("--spreads", "abc"), "--spreads: expected degrees such as 10,5,15, got 'abc'"),
        (("--plots", str(file)), f"--plots: {file}: is a file, expected a folder"),
        (("--plots", str(tmp_path / "no" / "plots")), "no folder"),
    ):
        run = cli("validate", "scaling", "--photons", "1000", *options)
        assert run.returncode == 2 and message in run.stderr, run.stderr
        assert "Monte Carlo" not in run.stderr  # refused before it ran


def test_texture_evaluate_refuses_an_image_no_machine_holds(cli):
    # 100,000² pixels was a MemoryError after the first process had been generated
    run = cli("texture", "evaluate", "--size", "100000", "--points", "2")
    said = " ".join(run.stderr.split())
    assert run.returncode == 2 and "'--size': Input should be less than or equal to 8192" in said


def test_a_job_too_large_for_memory_is_an_error_not_a_bug(capsys):
    import typer

    @reports_errors
    def too_large():
        np.empty(2**62, dtype=np.uint8)  # numpy refuses: no machine holds 4 EiB

    with pytest.raises(typer.Exit) as exited:
        too_large()
    said = " ".join(capsys.readouterr().err.split())
    assert exited.value.exit_code == 2  # not 70, the status of an internal error
    assert "error: not enough memory for this job (Unable to allocate" in said
    assert "ask for less" in said and "internal error" not in said


def test_a_library_s_key_error_is_a_fault_of_the_code_not_of_the_user(capsys):
    """A KeyError a library raises (Pillow's ``KeyError('TIF')`` for a suffix it names
    otherwise) is the code's fault: an internal error, status 70, asking to report it. It
    read "error: TIF", status 2, as if the user's input were wrong. A geometry a file was
    not read at is the user's: one line, status 2, the message as written."""
    import typer

    from flakelab.data import example_path
    from flakelab.io import read_measurement

    reading = read_measurement(example_path("target"))

    @reports_errors
    def bug():
        return {"PNG": 1}["TIF"]

    @reports_errors
    def geometry_not_read():
        return reading.index("45as60")

    with pytest.raises(typer.Exit) as exited:
        bug()
    assert exited.value.exit_code == 70
    assert capsys.readouterr().err.startswith("internal error: KeyError: 'TIF' (set FLAKELAB_")
    with pytest.raises(typer.Exit) as exited:
        geometry_not_read()
    assert exited.value.exit_code == 2
    said = capsys.readouterr().err.strip()
    assert said == f"error: {reading.sample}: no geometry 45as60", said
    with pytest.raises(KeyError):  # a lookup that finds nothing, as before
        reading.storage_spectra(["45as60"])


def test_a_ctrl_c_stops_a_command_with_one_line_and_the_shells_status(capsys):
    import typer

    @reports_errors
    def long_job():
        raise KeyboardInterrupt

    with pytest.raises(typer.Exit) as exited:
        long_job()
    assert exited.value.exit_code == 130  # 128 + SIGINT, as the shell's tools exit
    assert capsys.readouterr().err.strip() == "interrupted: stopped before it finished"


@pytest.mark.parametrize(("stop", "status", "said"), [
    (KeyboardInterrupt(), 130, "interrupted"),
    (Terminated(signal.SIGTERM), 143, "terminated"),
])  # fmt: skip
def test_a_signal_met_while_the_options_are_read_stops_as_in_the_command(
    monkeypatch, capsys, stop, status, said
):
    """Typer turns a Ctrl-C met outside the command, in an option's check (``--shop``'s
    imports colour-science: seconds), into exit 130 and no word, a SIGTERM too."""
    import typer

    def checked(value: str) -> str:
        raise stop

    app = typer.Typer()

    @app.command()
    def job(shop: str = typer.Option("x", callback=checked)) -> None:
        pass

    monkeypatch.setattr(sys, "argv", ["flakelab", "--shop", "y"])
    with pytest.raises(SystemExit) as exited:
        run_command_line(app, "flakelab")
    assert exited.value.code == status
    assert capsys.readouterr().err.strip() == f"{said}: stopped before it began; nothing was done"
    # any other exit is Typer's own
    monkeypatch.setattr(sys, "argv", ["flakelab", "--shop"])
    with pytest.raises(SystemExit) as exited:
        run_command_line(app, "flakelab")
    assert exited.value.code == 2 and "requires an argument" in capsys.readouterr().err


def test_a_file_the_system_refuses_is_named_first(tmp_path, capsys):
    import typer

    @reports_errors
    def write_where_no_file_can_be():
        (tmp_path / "gone" / "p.png").write_bytes(b"")

    with pytest.raises(typer.Exit) as exited:
        write_where_no_file_can_be()
    said = " ".join(capsys.readouterr().err.split())
    # it said "error: [Errno 2] No such file or directory: '…/gone/p.png'"
    assert exited.value.exit_code == 2
    assert said == f"error: {tmp_path / 'gone' / 'p.png'}: No such file or directory"


def test_wrong_conditions_are_named_by_their_option(cli):
    for command in (("compare", "--example"), ("inspect", "--example")):
        run = cli(*command, "--conditions", "D65/3")
        said = " ".join(run.stderr.split())
        assert run.returncode == 2 and "'--conditions' / '-c'" in said
        assert "expected observer '2' or '10', got '3'" in said


def test_progress_off_a_terminal_logs_a_line_per_tenth_and_nothing_when_disabled(capsys):
    with progress_bar() as bar:
        task = bar.add_task("work", total=40)
        for _ in range(40):
            bar.advance(task)
    with progress_bar(disable=True) as bar:
        task = bar.add_task("quiet", total=40)
        bar.advance(task, 40)
    lines = capsys.readouterr().err.splitlines()
    assert [ln.split()[1] for ln in lines] == [f"{4 * k}/40" for k in range(1, 11)]
    assert lines[-1].startswith("work: 40/40 (100 %)") and "left" not in lines[-1]
    # the iterator form yields every item in order and ends on the whole count
    assert list(tracked("abcde", "each")) == list("abcde")
    assert capsys.readouterr().err.splitlines()[-1].startswith("each: 5/5 (100 %)")


def _commands(command, path=()):
    yield path, command
    for name, sub in getattr(command, "commands", {}).items():
        yield from _commands(sub, (*path, name))


def test_the_command_line_starts_without_colour_science_or_torch():
    """``flakelab --help`` and ``--version`` load neither colour-science (about a second:
    it imports matplotlib and scipy) nor torch; ``flakelab.core`` hands out its names on
    first use, and a name it lacks is an AttributeError, as a module's would be."""
    script = (
        "import sys\nfrom flakelab.cli.main import app\n"
        "for args in (['--help'], ['--version'], ['cases', '--help'], ['model', '--help']):\n"
        "    try:\n        app(args)\n    except SystemExit:\n        pass\n"
        "heavy = ('colour', 'torch', 'matplotlib')\n"
        "print('loaded:', sorted(m for m in heavy if m in sys.modules))\n"
        "import flakelab.core as core\n"
        "print('compare' in dir(core), core.compare.__module__, 'colour' in sys.modules)\n"
        "try:\n    core.nothing\nexcept AttributeError as error:\n    print(error)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=True
    )
    assert "loaded: []" in done.stdout
    assert "True flakelab.core.comparison True" in done.stdout
    assert "module 'flakelab.core' has no attribute 'nothing'" in done.stdout


def test_the_version_names_python_and_every_library_a_bug_report_needs(cli):
    """``flakelab --version`` said "flakelab 0.1.0" alone; a bug report needs Python's and
    the machine's, and the version of each library flakelab requires, as installed."""
    import platform
    from importlib.metadata import version

    from flakelab import __version__

    run = cli("--version")
    first, python, libraries = run.stdout.splitlines()
    assert first == f"flakelab {__version__}"
    assert python.startswith(f"Python {platform.python_version()} (")
    for name in ("torch", "numpy", "colour-science", "sqlalchemy", "typer"):
        assert f"{name} {version(name)}" in libraries.split(", "), name
    assert np.__version__ == version("numpy")


def test_help_shows_the_matchers_defaults_without_importing_torch():
    """The defaults are the numbers the library uses, printed as numbers; the help of the main
    job must not pay torch's import (over a second) to print them."""
    from flakelab.match.correction import correct
    from flakelab.match.search import MatchSettings

    script = (
        "import sys\nfrom flakelab.cli.main import app\n"
        "for args in (['correct', '--help'], ['match', '--help']):\n"
        "    try:\n        app(args)\n    except SystemExit:\n        pass\n"
        "print('torch imported:', 'torch' in sys.modules)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        env={**os.environ, "COLUMNS": "300"},
        check=True,
    )
    assert "torch imported: False" in done.stdout
    defaults = inspect.signature(correct).parameters
    for option, value in (
        ("--extra-toners", defaults["extra_toners"].default),
        ("--model-sd", defaults["model_sd"].default),
        ("--model-risk", MatchSettings().model_risk),
    ):
        row = re.split(r"\n  -", done.stdout.split(option, 1)[1], maxsplit=1)[0]
        assert re.search(rf"\[default: {value}[];]", " ".join(row.split())), row


def test_a_record_without_its_check_does_not_import_torch(tmp_path):
    """`cases record --no-check` is the record as it was before the check: torch's import and
    the model (about 2 s and 280 MB) are the check's alone."""
    from flakelab.data import example_path

    target, sprayed = example_path("target"), example_path("sprayout")
    recipe = target.parent / "blue-metallic-recipe.json"
    args = ["cases", "record", str(target), "--recipe", str(recipe), "--sprayed", str(sprayed),
            "-d", str(tmp_path / "shop.db"), "--json"]  # fmt: skip
    script = (
        f"import sys\nfrom flakelab.cli.main import app\nargs = {args!r}\n"
        "for extra in (['--no-check'], []):\n"
        "    try:\n        app([*args, *extra, '--shop', str(extra)])\n"
        "    except SystemExit:\n        pass\n"
        "    print('torch imported:', 'torch' in sys.modules)\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.count("torch imported: False") == 1
    assert done.stdout.rstrip().endswith("torch imported: True")  # the check's own


def test_listing_a_databases_shops_cases_and_models_does_not_import_torch(tmp_path, cli):
    """`cases shops` lists each shop's habits, tins and models: stored rows, no model run. It
    imported torch (through the habits' and the registry's modules) and took 5.9 s on a
    200-case database; 2.6 s without it (stop 99). `model list` loaded the shipped models
    for their toner counts: 7.2 s against 4.8 s without on a fresh machine (stop 127,
    `python benchmarks/cli_start.py --command model-list`), 380 MB against 182."""
    database = tmp_path / "shop.db"
    assert cli("cases", "generate", "--n", "30", "--seed", "3", "-d", database).returncode == 0
    script = (
        "import sys\nfrom flakelab.cli.main import app\n"
        f"for args in (['cases', 'shops', '-d', {str(database)!r}],"
        f" ['cases', 'list', '-d', {str(database)!r}],"
        f" ['model', 'list', '-d', {str(database)!r}]):\n"
        "    try:\n        app(args)\n    except SystemExit:\n        pass\n"
        "print('torch imported:', 'torch' in sys.modules)\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert "synthetic" in done.stdout and done.stdout.rstrip().endswith("torch imported: False")
    toners = len(shipped_model("ma-t12").toners)
    assert re.search(rf"ma-t12 +shipped +current +{toners} ", done.stdout), done.stdout


def test_every_help_reads_whole_in_an_80_column_terminal():
    """Each command's help at 80 columns: every paragraph of its own, every option's help and
    each of its commands' first paragraphs printed whole, as written, within 80 columns, with
    what an option does beginning by the 34th. Typer's Rich panels squeezed that into 16
    characters at the right of ``match --help`` (394 lines; 167 now), read a unit in brackets
    ("[g]") as a style tag and dropped it, and listed a group's commands cut short ("Paper
    001 Fig."). A group run alone shows its help too ('cases', 'model', 'texture' and
    'validate' said "Missing command"). What an option takes is named, as argparse names
    it (``--seed N``, ``--library LIBRARY``), where typer wrote ``<int range>``, ``<path>``,
    and an argument is in capitals, bracketed only where it may be left out (``SOURCE``,
    ``[TARGET]``; typer wrote ``{source}``, ``[target]`` and ``SOURCE <path>``)."""
    import typer.core
    import typer.main
    from typer.testing import CliRunner

    from flakelab.cli.main import app

    def flat(text):  # a line broken after a word's hyphen ("comma-", "separated") joined
        return " ".join(re.sub(r"-\n\s+", "-", text).split())

    runner = CliRunner()
    for path, command in _commands(typer.main.get_command(app)):
        shown = runner.invoke(app, [*path, "--help"], env={"COLUMNS": "80"}).output
        lines = shown.splitlines()
        assert max(len(line) for line in lines) <= 80, path
        assert max(len(line) - len(line.lstrip(" ")) for line in lines) <= 34, path
        texts = [p for p in (command.help or "").split("\n\n") if p]
        texts += [p.help for p in command.params if getattr(p, "help", None)]
        for sub in getattr(command, "commands", {}).values():
            texts.append((sub.help or "").split("\n\n")[0])
        for text in texts:
            assert flat(text) in flat(shown), (" ".join(path), text)
        # what an option takes is named (--seed N), not typed (--seed <int range>); an
        # argument in capitals, as messages name it ("TARGET: …")
        assert not re.search(r"(-[\w-]+|^\s+[A-Z_]+) <", shown, re.M), (path, shown)
        for argument in (p for p in command.params if isinstance(p, typer.core.TyperArgument)):
            name = argument.name.upper()
            shape = name if argument.required else rf"\[{name}\]"
            assert re.search(rf"(?<![{{\[]){shape}(?![}}\]])", lines[0]), (path, lines[0])
        if getattr(command, "commands", None):  # a group run alone shows its help
            assert runner.invoke(app, list(path), env={"COLUMNS": "80"}).output == shown, path


def test_every_seed_option_takes_what_torch_s_generators_take(cli):
    """A seed past 64 bits was refused by torch ("Overflow when unpacking long long") after
    the command had begun, naming no option. Every ``--seed`` is bounded at
    :data:`~flakelab.cli.common.SEED_MAX`, which torch's generators take and one more they
    refuse."""
    import torch
    import typer.main

    from flakelab.cli.common import SEED_MAX
    from flakelab.cli.main import app

    torch.Generator().manual_seed(SEED_MAX)
    with pytest.raises((ValueError, RuntimeError), match="Overflow"):
        torch.Generator().manual_seed(SEED_MAX + 1)
    seeded = {
        " ".join(path): next(p for p in command.params if p.name == "seed")
        for path, command in _commands(typer.main.get_command(app))
        if any(p.name == "seed" for p in command.params)
    }
    assert {"cases generate", "match", "train", "model adapt"} <= seeded.keys(), seeded
    assert {(t.min, t.max) for t in seeded.values()} == {(0, SEED_MAX)}, seeded
    run = cli("cases", "generate", "--n", "1", "--seed", SEED_MAX + 1)
    assert run.returncode == 2 and "--seed" in run.stderr and str(SEED_MAX) in run.stderr


def test_every_whole_number_option_is_bounded_within_the_database_s_integers(cli):
    """A count past 64 bits was an internal error where numpy or SQLite met it ('match
    evaluate --targets', 'cases realism --n', 'cases list --last', 'lots show --version':
    "Python int too large to convert to C long", "… to SQLite INTEGER"). Every whole-number
    option has a largest value, which typer names; counts stop at
    :data:`~flakelab.cli.common.COUNT_MAX`, within PostgreSQL's 32-bit integers, so that a
    version asked for is looked for, not overflowed."""
    import typer.main

    from flakelab.cli.common import COUNT_MAX, SEED_MAX
    from flakelab.cli.main import app

    assert COUNT_MAX < 2**31 - 1 and SEED_MAX == 2**64 - 1
    unbounded, counted_options = [], 0
    for path, command in _commands(typer.main.get_command(app)):
        for p in command.params:
            annotation = getattr(getattr(p, "type_descriptor", None), "annotation", None)
            if annotation not in (int, int | None):
                continue
            counted_options += 1
            bound = SEED_MAX if p.name == "seed" else COUNT_MAX
            if p.max is None or p.max > bound:
                unbounded.append((" ".join(path), p.name, p.max))
    assert counted_options > 30 and not unbounded, unbounded
    huge = str(10**23)
    for args, said in (
        (("match", "evaluate", "--targets", huge), "Invalid value for '--targets'"),
        (("cases", "list", "--last", huge), "Invalid value for '--last'"),
        (("model", "show", f"five-angle:{huge}"), f"VERSION: expected at most {COUNT_MAX:,}"),
        (("model", "show", "five-angle:²"), "expected a model file, NAME:VERSION"),
    ):
        run = cli(*args)
        assert run.returncode == 2 and said in " ".join(run.stderr.split()), (args, run.stderr)


def test_an_objective_s_weights_are_finite(cli):
    """An infinite weight made every recipe's loss infinite: 'match --model-risk inf' said
    "fractions: row 0 holds an amount that is not a number", 'correct --metamerism inf'
    "recipe: amounts sum to zero". Each weight stops at
    :data:`~flakelab.cli.common.WEIGHT_MAX`, named by its option."""
    import typer.main

    from flakelab.cli.common import WEIGHT_MAX
    from flakelab.cli.main import app

    weights = {"model_risk", "metamerism", "model_sd", "colour_weight"}
    found = {
        (" ".join(path), p.name): p.max
        for path, command in _commands(typer.main.get_command(app))
        for p in command.params
        if p.name in weights
    }
    assert {name for _, name in found} == weights, found
    assert set(found.values()) == {WEIGHT_MAX}, found
    for args, option in (
        (("match", "--example", "--model-risk", "inf"), "--model-risk"),
        (
            ("correct", "t.cxf", "-r", "r.json", "-s", "s.cxf", "--metamerism", "inf"),
            "--metamerism",
        ),  # fmt: skip
    ):
        run = cli(*args)
        assert run.returncode == 2 and f"Invalid value for '{option}'" in run.stderr, run.stderr


def _table_like_the_case_list():
    """A table as 'cases list' draws one: padding collapsed, unwrapped columns of times and
    ids, and a recipe column that wraps."""
    from rich import box
    from rich.table import Table

    table = Table(title="Newest cases", box=box.SIMPLE_HEAD, collapse_padding=True)
    for column in ("made", "case", "worst ΔE00"):
        table.add_column(column, no_wrap=True, justify="right" if "ΔE" in column else "left")
    table.add_column("recipe (share)")
    table.add_row(
        "2026-01-02 00:03", "4790f3af-2a88", "1.69 45as110", "Al medium 98%, Phthalo blue GS 2%"
    )
    table.add_row("2026-01-01 23:26", "446c14c4-da82", "3.78 45as15",
                  "Pearl interference red 55%, Pearl interference green 42% +2")  # fmt: skip
    return table


@pytest.mark.parametrize("width", [30, 50, 60, 80, 200])
def test_a_table_too_wide_for_the_terminal_cuts_no_cell(width):
    """However narrow the terminal, a table's cells are whole: its wrapping columns narrowed
    to their longest word and no more, and drawn past the terminal's edge where that is not
    narrow enough. Rich cut cells with an ellipsis ("2026-01-02 00:…", "Pearl interferen…"),
    and at 40 columns left the recipe column out; where the table fits, it is Rich's own."""

    from rich.console import Console

    from flakelab.cli.common import _Console

    out = io.StringIO()
    _Console(file=out, width=width, color_system=None).print(_table_like_the_case_list())
    drawn = out.getvalue()
    lines = drawn.splitlines()
    assert "…" not in drawn
    for cell in ("2026-01-02 00:03", "4790f3af-2a88", "1.69 45as110", "3.78 45as15"):
        assert cell in drawn, (width, cell)  # on one line: these columns do not wrap
    assert len(re.findall(r"\binterference\b", drawn)) == 2  # wrapped, no word cut
    tightest = 16 + 13 + 12 + len("interference") + 5 + 5  # and the pads and borders
    assert max(map(len, lines)) == tightest if width < tightest else max(map(len, lines)) <= width
    if width == 200:  # room enough: drawn as Rich draws it
        plain = io.StringIO()
        Console(file=plain, width=width, color_system=None).print(_table_like_the_case_list())
        assert drawn == plain.getvalue()


def test_the_match_shows_every_number_whole_in_a_narrow_terminal(cli, monkeypatch):
    """In a 60-column terminal the main job's per-geometry table read "62.…" and "-1…" for
    L* and a*; every number of it is now whole, as its JSON report gives it."""
    from flakelab.cli import common

    report = json.loads(cli("match", "--example", "--json").stdout)["candidates"][0]
    monkeypatch.setattr(common.console, "width", 60)
    shown = cli("match", "--example").stdout
    assert "…" not in shown
    for name, g in report["geometries"].items():
        row = next(line.split() for line in shown.splitlines() if line.split()[:1] == [name])
        assert row[1:4] == [f"{g[k]:.2f}" for k in ("L", "a", "b")], name


class _Stream:
    def __init__(self, tty: bool):
        self.tty = tty

    def isatty(self) -> bool:
        return self.tty

    def fileno(self) -> int:
        return 1


@pytest.mark.parametrize(
    "columns, tty, width",
    [("", False, 110), ("0", False, 110), ("00", False, 110), ("abc", False, 110),
     ("72", False, None), ("", True, None), ("abc", True, None), ("72", True, None),
     ("0", True, 97)],
)  # fmt: skip
def test_a_console_draws_at_columns_or_the_terminals_width_never_at_zero(
    monkeypatch, columns, tty, width
):
    """Rich took ``COLUMNS=0`` for a width of 0 and drew nothing: every table, report and
    error of a command vanished and it still exited 0 (or 2, silent). The width is Rich's
    own (None: ``COLUMNS``, else the terminal's) where that is a width, the terminal's where
    ``COLUMNS`` is 0, and the piped width (110) for a file or a pipe without one."""
    from rich.console import Console

    from flakelab.cli.common import _drawing_width

    monkeypatch.setenv("COLUMNS", columns)
    monkeypatch.setattr(os, "get_terminal_size", lambda fd: os.terminal_size((97, 30)))
    assert _drawing_width(_Stream(tty), 110) == width
    shown = io.StringIO()
    Console(file=shown, width=_drawing_width(_Stream(tty), 110)).print("45as15 ΔE00 0.22")
    assert shown.getvalue() == "45as15 ΔE00 0.22\n"


def test_a_json_report_writes_a_number_that_is_none_as_null(capsys):
    """JSON has no NaN or infinity: Python wrote ``NaN``, which JavaScript's ``JSON.parse``
    and any strict reader refuse. A number that is none is ``null``, however deep in the
    report."""
    from flakelab.cli.common import print_report

    print_report({"flop": np.nan, "rows": [1.5, (np.inf, -np.inf)], "by": {"45as15": np.nan}})

    def refuse(constant):
        raise ValueError(f"not JSON: {constant}")

    shown = json.loads(capsys.readouterr().out, parse_constant=refuse)
    assert shown == {"flop": None, "rows": [1.5, [None, None]], "by": {"45as15": None}}
