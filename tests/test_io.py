"""Measurement files: round trips between formats and clear errors on bad input."""

from __future__ import annotations

import contextlib
import csv
import io
import json
import os
import random
import re
import shutil
import sqlite3
import stat
import sys
import time
import warnings
from dataclasses import replace
from datetime import datetime
from pathlib import Path

import numpy as np
import pytest

from flakelab.core import delta_E_CIE2000
from flakelab.core.spectra import WAVELENGTHS
from flakelab.errors import FlakelabError, MeasurementFileError
from flakelab.io import (
    FORMATS,
    detect_format,
    read_measurement,
    read_measurements,
    read_recipe,
    write_measurements,
    write_recipe,
)


def _assert_same(a, b, *, texture=True, metadata=True):
    assert a.sample == b.sample
    assert a.geometry_names == b.geometry_names
    np.testing.assert_allclose(b.reflectance, a.reflectance, atol=1e-6, rtol=0)
    np.testing.assert_array_equal(a.wavelengths, b.wavelengths)
    assert a.measured_at == b.measured_at
    assert a.instrument == b.instrument
    if a.stored_lab is not None:
        np.testing.assert_allclose(b.stored_lab, a.stored_lab, atol=1e-9)
        assert a.stored_lab_conditions == b.stored_lab_conditions
    if texture:
        assert dict(a.texture) == dict(b.texture)
    if metadata:
        assert dict(a.metadata) == dict(b.metadata)


def test_xlsx_to_cxf_to_json_to_csv_keeps_every_spectrum_and_geometry(ma_t12_files, tmp_path):
    for source in ma_t12_files:
        original = read_measurement(source)
        current, path = original, source
        for suffix in (".cxf", ".json", ".csv"):
            path = tmp_path / f"{source.stem}{suffix}"
            write_measurements([current], path)
            current = read_measurement(path)
            _assert_same(original, current, metadata=suffix != ".csv")


@pytest.mark.parametrize("fmt", sorted(FORMATS))
def test_every_format_round_trips_every_field_it_can_hold(fmt, rich_measurement, tmp_path):
    path = tmp_path / f"out{FORMATS[fmt][2][0]}"
    write_measurements([rich_measurement], path)
    back = read_measurements(path)
    assert len(back) == 1
    _assert_same(rich_measurement, back[0], metadata=fmt in ("cxf", "json"))
    assert detect_format(path) == fmt


@pytest.mark.parametrize("fmt", sorted(FORMATS))
def test_every_format_keeps_the_moment_of_a_zoned_time(fmt, rich_measurement, tmp_path):
    """A time with a zone (a CxF3 file's, a case's in UTC) is the same moment read back:
    where the format keeps no zone (an MA-T12 export), as this machine's local time. Excel
    refused a zoned time, and 'convert' to .xlsx ended in an internal error."""
    from dataclasses import replace
    from datetime import timedelta, timezone

    from flakelab.core.times import zoned_here

    tokyo = datetime(2026, 3, 4, 5, 6, 7, tzinfo=timezone(timedelta(hours=9)))
    path = tmp_path / f"zoned{FORMATS[fmt][2][0]}"
    write_measurements([replace(rich_measurement, measured_at=tokyo)], path)
    assert zoned_here(read_measurement(path).measured_at) == tokyo


def test_multi_sample_files_keep_order(rich_measurement, tmp_path):
    from dataclasses import replace

    others = [replace(rich_measurement, sample=f"trial {i}") for i in range(3)]
    for suffix in (".csv", ".json", ".cxf", ".xlsx"):
        path = tmp_path / f"many{suffix}"
        write_measurements([rich_measurement, *others], path)
        assert [m.sample for m in read_measurements(path)] == [rich_measurement.sample] + [
            f"trial {i}" for i in range(3)
        ]
        assert read_measurement(path, "trial 2").sample == "trial 2"


def test_format_is_detected_by_content_not_name(rich_measurement, tmp_path):
    cxf = tmp_path / "a.cxf"
    write_measurements([rich_measurement], cxf)
    disguised = tmp_path / "measurement.txt"
    shutil.copy(cxf, disguised)
    assert detect_format(disguised) == "cxf"
    _assert_same(rich_measurement, read_measurement(disguised))


def _csv(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "bad.csv"
    path.write_text(text)
    return path


HEADER = "sample,geometry," + ",".join(f"R{w}" for w in range(400, 710, 10))
ROW = "S1,45as15," + ",".join(["0.5"] * 31)
WIDE = "sample,L* 15°,a* 15°,b* 15°,L* 45°,a* 45°,b* 45°"
WIDE_ROW = "S1,50,1,2,30,1,2"
WIDE_BANDS = "sample," + ",".join(f"R{w} {g}" for g in ("15°", "45°") for w in range(400, 710, 10))


@pytest.mark.parametrize(
    ("text", "field", "problem"),
    [
        (HEADER + "\n" + ROW.replace(",0.5", ",nan", 1), "row 2, 400 nm", "finite number"),
        (HEADER + "\n" + ROW.replace(",0.5", ",abc", 1), "row 2, 400 nm", "expected a number"),
        (HEADER.replace("R410", "R415") + "\n" + ROW, "header", "constant step"),
        (HEADER.replace("R410", "Rxx") + "\n" + ROW, "header, column 4", "expected a wavelength"),
        (HEADER + "\n" + ROW.replace("45as15", "45as15x"), "row 2, geometry", "geometry name"),
        (HEADER + "\n" + ROW + "\n" + ROW, "row 3", "appears twice"),
        (HEADER + "\n" + ROW[:40], "row 2", "truncated line"),
        (HEADER.replace("geometry", "angle") + "\n" + ROW, "header", "missing column 'geometry'"),
        (HEADER + "\n" + ROW.replace(",0.5", ",-3", 1), "row 2, 400 nm", "reflectance factor"),
        ("sample,geometry,instrument\nS1,45as15,x", "header", "no reflectance columns"),
        ("sample,geometry,L,a,b\nS1,45as15,50,1,2\nS1,45as45,,1,2", "row 3, L", "a number"),
        ("sample,geometry,L,a,b\nS1,45as15,50,130,2", "row 2", "no colour a surface reflects"),
        ("sample,geometry,L,a,b\nS1,45as15,2500,0,0", "row 2", "over the 100 any paint reaches"),
        ("sample,geometry,L,C\nS1,45as15,50,1", "header", "columns L, C without the rest"),
        ("sample,geometry,L,L*,a,b\nS1,45as15,50,50,1,2", "header", "'L' and 'L*' both"),
        ("sample,geometry,L,C,h\nS1,45as15,50,-1,2", "row 2, C", "a chroma of 0 or more"),
        (
            "sample,geometry,L,a,b,lab_conditions\nS1,45as15,50,1,2,D65/10\nS1,45as45,50,1,2,A/10",
            "row 3, lab_conditions",
            "'A/10', where row 2 names 'D65/10'",
        ),
        (
            "sample,geometry,L,a,b,lab_conditions\nS1,45as15,50,1,2,D65/99",
            "row 2, lab_conditions",
            "observer",
        ),
        ("sample,geometry,X,Y,Z\nS1,45as15,20,1e9,20", "row 2, as L*a*b* L", "within ±2500"),
        # a row per sample, its geometries in the header
        ("sample,geometry,L* 15°,a* 15°,b* 15°\nS1,45as15,50,1,2", "header", "a row per sample"),
        (
            WIDE.replace("L* 45°", "L 45°") + ",L* 45°\n" + WIDE_ROW + ",1",
            "header, 45°",
            "columns 'L 45°' and 'L* 45°' both",
        ),  # fmt: skip
        (WIDE + ",L* 45as45\n" + WIDE_ROW + ",1", "header, L* 45as45", "headed both '45°'"),
        (WIDE + ",L\n" + WIDE_ROW + ",1", "header", "column 'L' gives no geometry"),
        (
            WIDE + ",dE 15°\n" + WIDE_ROW + ",1",
            "header",
            "column 'dE 15°' is no quantity flakelab reads",
        ),
        (WIDE + ",L* 75°,a* 75°\n" + WIDE_ROW + ",1,2", "header, 75°", "L* 75°, a* 75° without"),
        (WIDE + ",L* 140°\n" + WIDE_ROW + ",1", "header, L* 140°", "detector above"),
        (
            WIDE + ",R400 15°,R410 15°,R420 15°\n" + WIDE_ROW + ",0.5" * 3,
            "header, 45°",
            "45° has no reflectance columns where 15° has",
        ),  # fmt: skip
        (
            WIDE_BANDS.replace("R400 45°,", "") + "\nS1" + ",0.5" * 61,
            "header, 45°",
            "another wavelength grid",
        ),  # fmt: skip
        (WIDE + "\n" + "S1" + "," * 6, "row 2", "'S1' is read at no geometry"),
        (WIDE + "\n" + WIDE_ROW.replace("50", "x", 1), "row 2, 15°, L*", "expected a number"),
        (WIDE_BANDS + "\nS1" + ",0.5" * 31 + ",-3" * 31, "row 2, 45°, 400 nm", "reflectance"),
        (WIDE + "\n" + WIDE_ROW + "\n" + WIDE_ROW, "row 3, 15°", "appears twice"),
    ],
)
def test_bad_csv_names_file_field_and_problem(tmp_path, text, field, problem):
    path = _csv(tmp_path, text)
    with pytest.raises(MeasurementFileError) as caught:
        read_measurements(path)
    message = str(caught.value)
    assert message.startswith(str(path)), message
    assert field in message and problem in message, message


def test_truncated_xlsx_is_reported(ma_t12_files, tmp_path):
    data = ma_t12_files[0].read_bytes()
    path = tmp_path / "cut.xlsx"
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(MeasurementFileError, match="truncated or corrupt"):
        read_measurements(path)


@pytest.mark.parametrize(
    ("part", "damage"),
    [
        ("xl/worksheets/sheet3.xml", lambda xml: xml[: len(xml) // 2]),  # cut: ParseError
        ("xl/workbook.xml", lambda xml: xml.replace(b'"UTF-8"', b'"UTF-99"')),  # LookupError
        ("xl/workbook.xml", lambda xml: xml.replace(b'activeTab="3"', b'activeTab="x"')),
        ("xl/sharedStrings.xml", lambda xml: xml[: xml.index(b"<si>")] + b"</sst>"),  # IndexError
    ],
    ids=["sheet-cut", "encoding", "attribute", "shared-strings"],
)
def test_an_export_with_a_damaged_part_is_reported_naming_the_file(
    ma_t12_files, tmp_path, part, damage
):
    """A workbook whose zip is whole but one of its parts is damaged was an internal error
    (xml's ParseError, LookupError, TypeError, IndexError from openpyxl) until stop 128; both
    readers name the file."""
    import zipfile

    from flakelab.io.mat12_xlsx import read_mat12_images

    path = tmp_path / "damaged.xlsx"
    with zipfile.ZipFile(ma_t12_files[0]) as source, zipfile.ZipFile(path, "w") as damaged:
        for name in source.namelist():
            content = source.read(name)
            damaged.writestr(name, damage(content) if name == part else content)
    for reader in (read_measurements, read_mat12_images):
        with pytest.raises(MeasurementFileError) as caught:
            reader(path)
        said = str(caught.value)
        assert said.startswith(f"{path}: ") and " workbook (" in said, said


def test_mat12_camera_pictures_are_read_by_the_geometry_of_their_row(ma_t12_files):
    """The six exports' camera pictures: seven each, 480 × 360 sRGB, labelled by the rows they
    are anchored in (six geometries under the 15° lamp, then diffuse light). Read one row off,
    the first would take the second's label and the last none. Over the six geometries, the
    pictures' mean lightness ranks as the spectra's L* does (Spearman 0.31-0.94, mean 0.77;
    0.24 with the pictures' order reversed), 10-28 L* darker: the camera is no colorimeter."""
    from colour.models import eotf_sRGB
    from scipy.stats import spearmanr

    from flakelab.core.colorimetry import linear_sRGB_to_Lab
    from flakelab.io.mat12_xlsx import read_mat12_images

    order = ["15as-45", "15as-30", "15as-15", "15as15", "15as45", "15as80", "15d"]
    agreement = []
    for file in ma_t12_files:
        measurement = read_measurement(file)
        pictures = read_mat12_images(file)
        assert list(pictures) == [measurement.sample]
        found = pictures[measurement.sample]
        assert list(found) == order
        assert {p.shape for p in found.values()} == {(360, 480, 3)}
        assert {p.dtype for p in found.values()} == {np.dtype(np.uint8)}
        directional = order[:-1]
        camera = [linear_sRGB_to_Lab(eotf_sRGB(found[g] / 255).reshape(-1, 3).mean(0))[0]
                  for g in directional]  # fmt: skip
        spectra = measurement.lab()[[measurement.index(g) for g in directional], 0]
        assert 5 < np.min(spectra - camera) and np.max(spectra - camera) < 35
        agreement.append(spearmanr(camera, spectra)[0])
    assert min(agreement) > 0.2 and np.mean(agreement) > 0.6, agreement


def _damaged_pictures(source: Path, folder: Path, damage) -> Path:
    """A real export, loaded with its pictures, changed by ``damage(sheet)`` and saved."""
    import openpyxl

    workbook = openpyxl.load_workbook(source)
    damage(workbook["Texture Images"])
    path = folder / "damaged.xlsx"
    workbook.save(path)
    return path


def _second_picture_on_first(sheet) -> None:
    sheet._images[1].anchor._from.row = sheet._images[0].anchor._from.row


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (
            lambda sheet: setattr(sheet["A3"], "value", None),
            r"A3: a picture in a row that names no",
        ),
        (lambda sheet: setattr(sheet["A4"], "value", "15xx"), r"A4: expected a geometry name"),
        (lambda sheet: setattr(sheet["B1"], "value", None), r"B2: a picture in a column no sample"),
        (_second_picture_on_first, r"B2: a second picture of 15as-45"),
    ],
    ids=["unlabelled row", "unknown geometry", "no sample", "two in one cell"],
)
def test_mat12_camera_pictures_misplaced_are_refused_by_cell(ma_t12_files, tmp_path, damage,
                                                             message):  # fmt: skip
    from flakelab.io.mat12_xlsx import read_mat12_images

    path = _damaged_pictures(ma_t12_files[0], tmp_path, damage)
    with pytest.raises(MeasurementFileError, match=f"damaged.xlsx: Texture Images, {message}"):
        read_mat12_images(path)


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (lambda data: data[:100], r"Texture Images, B4: picture cannot be decoded \(image file is"),
        (lambda data: b"no picture", r"Texture Images: picture xl/media/image3.png cannot be"),
    ],
    ids=["cut short", "not an image"],
)
def test_mat12_camera_picture_that_cannot_be_decoded_is_refused(ma_t12_files, tmp_path, damage,
                                                                message):  # fmt: skip
    """A picture cut short fails as it is decoded; one that is no image at all openpyxl drops
    with a warning. flakelab refuses both, naming the cell or the picture."""
    import zipfile

    from flakelab.io.mat12_xlsx import read_mat12_images

    path = tmp_path / "broken.xlsx"
    with zipfile.ZipFile(ma_t12_files[0]) as source, zipfile.ZipFile(path, "w") as target:
        for item in source.infolist():
            data = source.read(item)
            target.writestr(item, damage(data) if item.filename == "xl/media/image3.png" else data)
    with pytest.raises(MeasurementFileError, match=f"broken.xlsx: {message}"):
        read_mat12_images(path)
    assert read_measurement(path).sample  # the spectra are still read


def test_mat12_export_without_pictures_has_none(rich_measurement, tmp_path):
    from flakelab.io.mat12_xlsx import read_mat12_images

    path = tmp_path / "written.xlsx"
    write_measurements([rich_measurement], path)
    assert read_mat12_images(path) == {}


def test_mat12_texture_columns_flakelab_does_not_know_are_named(rich_measurement, tmp_path):
    """The shared exports' ``Texture Data`` sheets are empty (a header of Name, Date/Time,
    Geometry), so an instrument's own texture columns are not known here: one that holds values
    is named in a note, not dropped unsaid; the readings flakelab knows are still read."""
    import openpyxl

    from flakelab.errors import Note

    path = tmp_path / "export.xlsx"
    write_measurements([rich_measurement], path)
    workbook = openpyxl.load_workbook(path)
    sheet = workbook["Texture Data"]
    header = next(r for r in range(1, sheet.max_row + 1) if sheet.cell(r, 1).value == "Name")
    known = sheet.max_column
    sheet.cell(header, known + 1).value = "Sparkle Intensity"
    sheet.cell(header, known + 2).value = "Unused"  # a header over no values: nothing to say
    sheet.cell(header + 1, known + 1).value = 3.2
    sheet.cell(header + 1, known + 3).value = 7.0  # a value under no header
    workbook.save(path)
    with pytest.warns(Note, match=r"export.xlsx: Texture Data: 'Sparkle Intensity', 'column "
                                  r"[A-Z]+' not read") as notes:  # fmt: skip
        read = read_measurement(path)
    assert len(notes) == 1 and "Unused" not in str(notes[0].message)
    assert dict(read.texture) == dict(rich_measurement.texture)


def test_mat12_wavelength_header_that_is_none_is_named_by_its_column(ma_t12_files, tmp_path):
    """A Spectral Data header cell that is no wavelength is named by its spreadsheet column
    (the fifth label is column E); it was named by its place among the wavelengths (column 2)."""
    import openpyxl

    workbook = openpyxl.load_workbook(ma_t12_files[0])
    sheet = workbook["Spectral Data"]
    header = next(r for r in range(1, sheet.max_row + 1) if sheet.cell(r, 1).value == "Name")
    sheet.cell(header, 5).value = "Comment"
    path = tmp_path / "export.xlsx"
    workbook.save(path)
    with pytest.raises(MeasurementFileError, match=rf"Spectral Data, row {header}, column E: "
                                                   r"expected a wavelength"):  # fmt: skip
        read_measurement(path)


def test_spectra_in_percent_are_read_as_reflectance_factors(ma_t12_dir, ma_t12_files, tmp_path):
    """Many instruments' exports write spectra in percent. Read as factors they gave L* of 274
    with no word: now they are divided by 100, with a note naming the file and why. Where a
    reading carries its L*a*b*, that decides, the darkest sample too; without one, a geometry
    75° or more from specular reading above any paint's factor there. None of the 230 real
    MA-T12 readings, in factors, is taken for percent (their farthest geometries read 0.89 at
    most)."""
    from dataclasses import replace

    from flakelab.data import example_path
    from flakelab.errors import Note
    from flakelab.io import percent_evidence

    real = read_measurements(ma_t12_dir / "all_samples_spectra.csv")
    assert len(real) == 230 and not any(percent_evidence(m) for m in real)
    for file in ma_t12_files:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Note)  # no note: the file is in factors
            read_measurements(file)
    measured = read_measurements(ma_t12_files[0])
    darkest = min(measured, key=lambda m: m.reflectance.max())
    percent = [replace(m, reflectance=m.reflectance * 100) for m in (darkest, *measured)]
    written = tmp_path / "percent.json"  # the readings' L*a*b* beside the spectra
    write_measurements(percent, written)
    with pytest.warns(
        Note,
        match=r"percent.json: reflectance read as percent and divided by "
        r"100 \(sample .*: its L\*a\*b\* is that of its spectra",
    ):
        back = read_measurements(written)
    for read, original in zip(back, (darkest, *measured), strict=True):
        np.testing.assert_allclose(read.reflectance, original.reflectance, rtol=1e-12)
    target = read_measurement(example_path("target"))  # no L*a*b* beside it
    write_measurements([replace(target, reflectance=target.reflectance * 100)], written)
    highest = f"{(target.select(['15as80']).reflectance * 100).max():.2f}"  # 3.77 (stop 116)
    with pytest.warns(Note, match=rf"15as80 reads up to {highest}, a reflectance factor no paint"):
        (back,) = read_measurements(written)
    np.testing.assert_allclose(back.reflectance, target.reflectance, rtol=1e-12)


def test_a_reading_brighter_than_a_white_far_from_specular_is_noted_and_read_as_given(
    ma_t12_dir, tmp_path
):
    """A reflectance factor above 1.05 at 75° or more from specular is brighter than the
    perfect white diffuser: a fluorescent paint, or an instrument calibrated against the wrong
    white. The file is read as given, with a note naming it, the sample and the geometry. A
    perfect white, and every real MA-T12 reading (0.89 at most there), get none."""
    from dataclasses import replace

    from flakelab.data import example_path
    from flakelab.errors import Note
    from flakelab.io import brighter_than_white

    real = read_measurements(ma_t12_dir / "all_samples_spectra.csv")
    assert len(real) == 230 and not any(brighter_than_white(m) for m in real)
    target = read_measurement(example_path("target"))
    written = tmp_path / "bright.json"
    white = replace(target, sample="white", reflectance=np.ones_like(target.reflectance))
    write_measurements([white], written)
    with warnings.catch_warnings():
        warnings.simplefilter("error", Note)
        read_measurements(written)
    fluorescent = white.reflectance.copy()
    fluorescent[target.index("45as110"), 15] = 1.3  # 550 nm
    bright = replace(white, sample="bright", reflectance=fluorescent)
    write_measurements([white, bright], written)
    with pytest.warns(Note, match=r"bright.json: sample 'bright': 45as110 reads up to 1.3, "
                                  r"brighter than a perfect white") as notes:  # fmt: skip
        back = read_measurements(written)
    assert len(notes) == 1
    for read, original in zip(back, (white, bright), strict=True):
        np.testing.assert_allclose(read.reflectance, original.reflectance, rtol=1e-12)


def test_a_european_spreadsheet_s_csv_reads_as_the_comma_separated_one(rich_measurement, tmp_path):
    """Semicolons between cells and decimal commas, as Excel writes CSV in most of Europe."""
    plain = tmp_path / "plain.csv"
    write_measurements([rich_measurement], plain)
    rows = list(csv.reader(plain.read_text().splitlines()))
    european = tmp_path / "european.csv"
    out = io.StringIO()
    csv.writer(out, delimiter=";").writerows(
        [cell.replace(".", ",") if _is_decimal(cell) else cell for cell in row] for row in rows
    )
    european.write_text(out.getvalue().replace("rich;", "Müller;"), encoding="cp1252")
    with pytest.raises(MeasurementFileError, match="when asked for 'CSV UTF-8'"):
        read_measurements(european)  # the spreadsheet's default encoding: told how to save
    european.write_text(out.getvalue())
    assert "0," in european.read_text()  # the numbers are written the European way
    (back,) = read_measurements(european)
    (expected,) = read_measurements(plain)
    np.testing.assert_array_equal(back.reflectance, expected.reflectance)
    assert back.texture == expected.texture and back.sample == expected.sample
    # Excel's hint on its first line, which instrument software writes and Excel hides:
    # refused before, "header: missing column 'sample'"
    for hint, text in (("sep=;", out.getvalue()), ('"sep=,"', plain.read_text())):
        hinted = tmp_path / "hinted.csv"
        hinted.write_text(f"{hint}\r\n{text}")
        (back,) = read_measurements(hinted)
        np.testing.assert_array_equal(back.reflectance, expected.reflectance)
    hinted.write_text("sep=;\n")
    with pytest.raises(MeasurementFileError, match="hinted.csv: empty CSV file"):
        read_measurements(hinted)
    # a sheet once used further right or lower: ";;;" at every line's end, blank rows ";;;;"
    # between; refused before, "column '' appears twice"
    lines = out.getvalue().splitlines()
    widened = [line + ";;;" for line in lines]
    hinted.write_text("\n".join([widened[0], ";" * 50, *widened[1:], ";;;;"]) + "\n")
    (back,) = read_measurements(hinted)
    np.testing.assert_array_equal(back.reflectance, expected.reflectance)
    assert back.texture == expected.texture
    hinted.write_text("\n".join([widened[0], lines[1] + ";;x"]) + "\n")  # a cell past them
    with pytest.raises(MeasurementFileError, match="row 2: expected .* columns, got"):
        read_measurements(hinted)
    # its "Unicode Text": UTF-16 with a byte-order mark (either order), tab-separated;
    # called "binary content" before
    tabbed = io.StringIO()
    csv.writer(tabbed, delimiter="\t").writerows(
        [cell.replace(".", ",") if _is_decimal(cell) else cell for cell in row] for row in rows
    )
    for mark, encoding in ((b"\xff\xfe", "utf-16-le"), (b"\xfe\xff", "utf-16-be")):
        european.write_bytes(mark + tabbed.getvalue().encode(encoding))
        (back,) = read_measurements(european)
        np.testing.assert_array_equal(back.reflectance, expected.reflectance)
        assert back.sample == expected.sample and back.texture == expected.texture
        # without its mark: refused as such, where its header was "s a m p l e …", a CSV
        # missing its 'sample' column
        for text in (tabbed.getvalue(), tabbed.getvalue().replace("rich;", "Müller;")):
            european.write_bytes(text.encode(encoding))  # the ü: not UTF-8 either
            with pytest.raises(MeasurementFileError, match="UTF-16 text without its byte-order"):
                read_measurements(european)


def test_utf16_files_are_judged_and_read_as_their_text(rich_measurement, tmp_path):
    """A file in UTF-16 with its byte-order mark is judged by its text ("binary content"
    before, so ``--images`` called a UTF-16 CSV binary), and a CxF3 file is read whether its
    declaration names UTF-16, as it should, or UTF-8; declaring UTF-16, it was refused
    ("encoding specified in XML declaration is incorrect")."""
    cxf, csv_file = tmp_path / "m.cxf", tmp_path / "m.csv"
    write_measurements([rich_measurement], cxf)
    write_measurements([rich_measurement], csv_file)
    texts = {cxf: cxf.read_text(encoding="utf-8"), csv_file: csv_file.read_text(encoding="utf-8")}
    assert 'encoding="UTF-8"' in texts[cxf].splitlines()[0]
    texts[tmp_path / "declared.cxf"] = texts[cxf].replace('encoding="UTF-8"', "encoding='utf-16'")
    for encoding in ("utf-16", "utf-16-be"):  # the mark of the machine's order, or big-endian
        for path, text in texts.items():
            path.write_bytes(
                (b"\xfe\xff" if encoding == "utf-16-be" else b"") + text.encode(encoding)
            )
            assert detect_format(path) == path.suffix[1:], (path.name, encoding)
            (back,) = read_measurements(path)
            _assert_same(rich_measurement, back, metadata=False)


def test_a_csv_written_for_a_european_spreadsheet_is_the_one_it_saves(rich_measurement, tmp_path):
    """``convert … --decimal-comma`` writes the file the test above builds by hand (with the
    byte-order mark a spreadsheet needs to read UTF-8), and reads back to full precision,
    stored L*a*b* and texture too; another format has no such form."""
    plain, european = tmp_path / "plain.csv", tmp_path / "european.csv"
    write_measurements([rich_measurement], plain)
    write_measurements([rich_measurement], european, decimal_comma=True)
    rows = list(csv.reader(plain.read_text().splitlines()))
    by_hand = io.StringIO()
    csv.writer(by_hand, delimiter=";", lineterminator="\n").writerows(
        [cell.replace(".", ",") if _is_decimal(cell) else cell for cell in row] for row in rows
    )
    assert european.read_text(encoding="utf-8") == "\ufeff" + by_hand.getvalue()
    (back,) = read_measurements(european)
    _assert_same(rich_measurement, back, metadata=False)  # a CSV holds no metadata
    np.testing.assert_array_equal(back.reflectance, rich_measurement.reflectance)
    with pytest.raises(MeasurementFileError, match="a decimal comma is for a CSV file, not json"):
        write_measurements([rich_measurement], tmp_path / "m.json", decimal_comma=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["european.csv", "plain.csv"]


def _is_decimal(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return "." in cell


def test_truncated_cxf_and_json_are_reported(rich_measurement, tmp_path):
    for suffix, problem in ((".cxf", "not valid CxF3"), (".json", "invalid JSON")):
        path = tmp_path / f"m{suffix}"
        write_measurements([rich_measurement], path)
        path.write_bytes(path.read_bytes()[:-200])
        with pytest.raises(MeasurementFileError, match=problem):
            read_measurements(path)


def test_a_json_measurement_file_that_is_not_utf8_is_refused_naming_the_byte(
    rich_measurement, tmp_path
):
    """A byte that is not UTF-8 in a JSON measurement file was said without the file's name
    ("error: 'utf-8' codec can't decode byte 0xff in position 3565")."""
    path = tmp_path / "m.json"
    write_measurements([rich_measurement], path)
    data = path.read_bytes()
    at = data.index(b'"sample"')
    path.write_bytes(data[:at] + b"\xff" + data[at:])
    said = rf"^{re.escape(str(path))}: not UTF-8 text \(invalid start byte at byte {at + 1}\)$"
    with pytest.raises(MeasurementFileError, match=said):
        read_measurements(path)


def test_a_cxf_declaring_an_unknown_encoding_is_reported(rich_measurement, tmp_path):
    """An XML declaration naming an encoding Python lacks was an internal error
    (LookupError) until stop 118; the file's stored content is not touched."""
    path = tmp_path / "m.cxf"
    write_measurements([rich_measurement], path)
    text = re.sub(r"^<\?xml[^>]*\?>", '<?xml version="1.0" encoding="abc"?>', path.read_text())
    path.write_text(text)
    with pytest.raises(MeasurementFileError, match=r"m\.cxf.*not valid CxF3 XML.*unknown encoding"):
        read_measurements(path)
    assert path.read_text() == text


def test_xml_that_cxf_has_no_place_for_is_a_note_naming_the_file(
    rich_measurement, tmp_path, caplog
):
    """Text where CxF3's schema has no place for it (an element's tags damaged) was printed on
    stderr by xsdata's logger as a bare "Unassigned parsed object None", naming no file. It
    is a note naming the file, and the spectra read are the file's."""
    from flakelab.errors import Note

    path = tmp_path / "m.cxf"
    write_measurements([rich_measurement], path)
    (before,) = read_measurements(path)
    text = path.read_text()
    damaged = re.sub(r"<(\w+:)?Observer>[^<]*</(\w+:)?Observer>", "bserver>", text, count=1)
    assert damaged != text
    path.write_text(damaged)
    with pytest.warns(Note, match=r"m\.cxf: part of the XML has no place in CxF3's schema and "
                                  r"was skipped \(Unassigned parsed object None\)"):  # fmt: skip
        (after,) = read_measurements(path)
    assert not [r for r in caplog.records if r.name.startswith("xsdata")]
    assert np.array_equal(after.reflectance, before.reflectance)
    assert after.geometries == before.geometries


def test_a_json_document_s_every_flaw_is_named_by_its_field(rich_measurement, tmp_path):
    path = tmp_path / "m.json"
    write_measurements([rich_measurement], path)
    good = json.loads(path.read_text())

    def first(document):
        return document["measurements"][0]

    flawed = {  # each was read without a word, or named the wrong thing, before
        "version: expected version 1 (the one this flakelab reads), got 2": lambda d: d.update(
            version=2
        ),
        "measurements[0].instrument: expected a text, got dict": lambda d: first(d).update(
            instrument={"serial": 1}
        ),
        "measurements[0]: expected an object, got int": lambda d: d["measurements"].insert(0, 5),
        "measurements[0].geometries: expected at least one geometry": lambda d: first(d).update(
            geometries=[]
        ),
        "json: measurements: expected list, got dict": lambda d: d.update(measurements={}),
        "measurements[0].wavelengths: expected increasing": lambda d: first(d).update(
            wavelengths=first(d)["wavelengths"][::-1]
        ),
        # an internal error before ('float' object has no attribute 'strip')
        "measurements[0].lab_conditions: expected illuminant/observer such as 'D65/10', got "
        "1e+308": lambda d: first(d).update(lab_conditions=1e308),
    }
    for message, edit in flawed.items():
        document = json.loads(json.dumps(good))
        edit(document)
        path.write_text(json.dumps(document))
        with pytest.raises(MeasurementFileError) as raised:
            read_measurements(path)
        assert message in str(raised.value), str(raised.value)


@pytest.mark.parametrize("bad", ["abc", "0.2o5", "nan"])
def test_a_cxf_value_that_is_not_a_number_is_named_by_wavelength(rich_measurement, tmp_path, bad):
    """xsdata leaves a spectrum it cannot convert as the element's text, with a warning; the
    reader names the value itself at its wavelength, and nothing else is printed."""
    import warnings

    path = tmp_path / "m.cxf"
    write_measurements([rich_measurement], path)
    text = path.read_text()
    start = text.index(">", text.index("<ns0:ReflectanceSpectrum")) + 1
    end = text.index("<", start)
    values = text[start:end].split()
    values[3] = bad  # the fourth band: 430 nm
    path.write_text(text[:start] + " ".join(values) + text[end:])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(MeasurementFileError, match=f"430 nm: expected a .*{bad}"):
            read_measurements(path)


@pytest.mark.parametrize(
    ("good", "bad", "message"),
    [  # each was an internal error (a text met in arithmetic), or read without a word
        ('StartWL="400"', 'StartWL="[]"', "CS_45as15, StartWL: expected a number, got '[]'"),
        ('Increment="10"', 'Increment="abc"', "WavelengthRange Increment: expected a number"),
        (
            'Increment="10"',
            'Increment="20"',
            "expected wavelengths within 360–780 nm, got 400–1000",
        ),
        ("<ns0:L>", "<ns0:L>x", "ColorCIELab CS_45as15, L: expected a number, got 'x"),
        (
            ":06:07</ns0:CreationDate>",
            ":06:nan</ns0:CreationDate>",
            "CreationDate: expected an xs:",
        ),
    ],
)
def test_a_cxf_attribute_or_element_that_is_not_a_number_is_named(
    rich_measurement, tmp_path, good, bad, message
):
    path = tmp_path / "m.cxf"
    write_measurements([rich_measurement], path)
    text = path.read_text()
    assert good in text
    path.write_text(text.replace(good, bad))
    with pytest.raises(MeasurementFileError, match=re.escape(message)):
        read_measurements(path)


def test_other_kinds_of_file_are_named(tmp_path):
    png = tmp_path / "photo.csv"
    png.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(100))
    with pytest.raises(MeasurementFileError, match="this is a PNG image"):
        read_measurements(png)
    empty = tmp_path / "empty.json"
    empty.write_text("")
    with pytest.raises(MeasurementFileError, match="empty file"):
        read_measurements(empty)
    with pytest.raises(MeasurementFileError, match="no such file"):
        read_measurements(tmp_path / "missing.cxf")
    mark = tmp_path / "mark.csv"  # a byte-order mark alone: an internal error before
    mark.write_bytes(b"\xef\xbb\xbf\n")
    with pytest.raises(MeasurementFileError, match="mark.csv: empty file"):
        read_measurements(mark)
    mark.write_bytes(b"\xc3")  # a character's first byte alone
    with pytest.raises(MeasurementFileError, match="binary content"):
        read_measurements(mark)
    # bytes that are not UTF-8 and hold NULs (a comma among them): binary, not the hint
    # for UTF-16 text that valid UTF-8 with NULs is given
    blob = tmp_path / "blob.csv"
    blob.write_bytes(b"a,b\x00\xff\xfe\x00\x93\n" * 40)
    with pytest.raises(MeasurementFileError, match="blob.csv: not a measurement file: binary"):
        read_measurements(blob)
    blob.write_bytes(b"a,b\x00\x00\x00\x00\n" * 40)  # valid UTF-8, NULs in both bytes of pairs
    with pytest.raises(MeasurementFileError, match="blob.csv: not a measurement file: binary"):
        read_measurements(blob)
    # a case database given for a measurement (it had the hint for UTF-16 text)
    database = tmp_path / "shop.csv"
    sqlite3.connect(database).execute("CREATE TABLE t (x)").connection.commit()
    with pytest.raises(MeasurementFileError, match="shop.csv: .*this is a SQLite database$"):
        read_measurements(database)


def test_a_csv_whose_head_ends_inside_a_character_is_read(rich_measurement, tmp_path):
    """The format is judged from a file's first 4,096 bytes; a 'ü' cut there by that count
    had a valid UTF-8 file refused as "binary content"."""
    plain = tmp_path / "plain.csv"
    write_measurements([rich_measurement], plain)
    for offset in (0, 1):  # the cut after the ü's first byte, and after the whole ü
        comment = "# Türkis " + "x" * (4096 - len("# Türkis ") - 3 + offset) + "ü\n"
        cut = tmp_path / f"cut{offset}.csv"
        cut.write_text(comment + plain.read_text(encoding="utf-8"), encoding="utf-8")
        assert cut.read_bytes()[4094 + offset : 4096 + offset] == "ü".encode()
        (back,) = read_measurements(cut)
        _assert_same(rich_measurement, back, metadata=False)


def test_a_failed_write_leaves_the_previous_file_intact(rich_measurement, tmp_path):
    path = tmp_path / "kept.cxf"
    write_measurements([rich_measurement], path)
    before = path.read_bytes()
    shifted = type(rich_measurement)(
        sample="x",
        geometries=rich_measurement.geometries,
        wavelengths=np.arange(420.0, 730.0, 10.0),
        reflectance=rich_measurement.reflectance,
    )
    with pytest.raises(MeasurementFileError, match="360–400 nm"):
        write_measurements([shifted], path)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["kept.cxf"]  # no temporary left behind


def test_an_atomic_write_names_the_file_asked_for_when_it_cannot_write(tmp_path):
    """Not the temporary file beside it; a folder is never replaced, nothing is left behind."""
    from flakelab.io.records import write_atomically

    (tmp_path / "panel.png").mkdir()
    with pytest.raises(IsADirectoryError, match="panel.png"):
        write_atomically(tmp_path / "panel.png", lambda t: t.write_text("x"))
    missing = tmp_path / "missing" / "panel.png"
    with pytest.raises(FileNotFoundError) as raised:
        write_atomically(missing, lambda t: t.write_text("x"))
    assert raised.value.filename == str(missing)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["panel.png"]
    assert list((tmp_path / "panel.png").iterdir()) == []


def test_an_atomic_write_takes_the_longest_name_the_file_system_takes(tmp_path):
    """A file name of 250 characters, which the file system takes, is written: the
    temporary file beside it, named after it, was eight characters longer and refused "File
    name too long"; nothing is left beside it."""
    from flakelab.io.records import write_atomically

    longest = tmp_path / f"{'a' * 246}.csv"
    longest.touch()
    longest.unlink()  # the file system takes the name
    write_atomically(longest, lambda t: t.write_text("x"))
    assert longest.read_text() == "x" and [p.name for p in tmp_path.iterdir()] == [longest.name]


def test_an_atomic_write_goes_through_a_link_and_keeps_the_file_s_permissions(tmp_path):
    """A link written to stays a link, and the file it names holds what was written; a file
    replaced keeps its mode (a private recipe stays private); a dangling link makes its
    file."""
    from flakelab.io import read_recipe, write_recipe

    kept = tmp_path / "recipes" / "door.json"
    kept.parent.mkdir()
    write_recipe({"Al medium": 100.0}, kept)
    kept.chmod(0o600)
    link = tmp_path / "current.json"
    link.symlink_to(kept)
    write_recipe({"Al medium": 90.0, "Carbon black": 10.0}, link)
    assert link.is_symlink() and link.resolve() == kept
    assert read_recipe(kept) == {"Al medium": 90.0, "Carbon black": 10.0}
    assert stat.S_IMODE(kept.stat().st_mode) == 0o600
    dangling = tmp_path / "next.json"
    dangling.symlink_to(tmp_path / "recipes" / "next.json")
    write_recipe({"Al medium": 1.0}, dangling)
    assert dangling.is_symlink() and read_recipe(tmp_path / "recipes" / "next.json")
    assert sorted(p.name for p in kept.parent.iterdir()) == ["door.json", "next.json"]


def _fed_through_a_pipe(pipe: Path, data: bytes):
    """A named pipe at ``pipe`` that a thread writes ``data`` into once it is opened. A reader
    that opens it a second time, when nothing writes any more, would wait for ever: after
    30 s it is given an empty pipe, so that such a test fails instead of hanging."""
    import threading

    def feed():
        pipe.write_bytes(data)
        time.sleep(30)
        with contextlib.suppress(OSError):  # no reader waits, or the pipe is gone
            os.close(os.open(pipe, os.O_WRONLY | os.O_NONBLOCK))

    os.mkfifo(pipe)
    threading.Thread(target=feed, daemon=True).start()


def test_a_measurement_is_read_from_a_pipe_whatever_its_format(tmp_path, cli):
    """``inspect /dev/stdin``, ``match <(…)``: the format is judged from a file's head, and a
    pipe's head, once read, is gone; the reader met the rest alone, "header: missing column
    'sample'" or "not valid CxF3 XML". A pipe now gives the file's measurements in every
    format. So does a workbook named without .xlsx, which openpyxl refused (internal error)."""
    from flakelab.data import example_path

    measurements = read_measurements(example_path("target"))
    for suffix in (".csv", ".cxf", ".json", ".xlsx"):
        file = tmp_path / f"m{suffix}"
        write_measurements(measurements, file)
        _fed_through_a_pipe(tmp_path / "pipe", file.read_bytes())
        piped = read_measurements(tmp_path / "pipe")
        (tmp_path / "pipe").unlink()
        read = read_measurements(file)
        assert [m.sample for m in piped] == [m.sample for m in read]
        np.testing.assert_array_equal(piped[0].reflectance, read[0].reflectance)
    nameless = tmp_path / "scan"
    shutil.copy(tmp_path / "m.xlsx", nameless)
    workbook = read_measurements(tmp_path / "m.xlsx")[0].reflectance
    np.testing.assert_array_equal(read_measurements(nameless)[0].reflectance, workbook)
    _fed_through_a_pipe(tmp_path / "pipe", b"sample,geometry\n")
    with pytest.raises(MeasurementFileError, match=f"^{tmp_path / 'pipe'}: "):  # the pipe named
        read_measurements(tmp_path / "pipe")


def test_a_measurement_named_dash_is_read_from_standard_input(tmp_path, cli, monkeypatch):
    """``cat car.cxf | flakelab inspect -``, as most command-line tools read: "-: no such
    file" before. What is piped in is read in any format (here CxF3 and an MA-T12 workbook);
    errors name ``stdin``; a terminal is refused rather than waited on, and the camera's
    pictures, which are read from a file named, are refused by name."""
    import flakelab.io
    from flakelab.data import example_path
    from flakelab.io.library_file import demo_library_path

    target = example_path("target")
    named = cli("inspect", target, "--json")
    piped = cli("inspect", "-", "--json", input=target.read_bytes())
    assert piped.returncode == 0, piped.stderr
    assert json.loads(piped.stdout)["geometries"] == json.loads(named.stdout)["geometries"]
    workbook = tmp_path / "m.xlsx"
    write_measurements(read_measurements(target), workbook)
    piped = cli("compare", target, "-", "--json", input=workbook.read_bytes())
    assert piped.returncode == 0 and json.loads(piped.stdout)["de00_max"] < 1e-3, piped.stderr
    assert cli("inspect", "-", input=b"").stderr.strip() == "error: stdin: empty file"
    # standard input holds one file: a second - is refused, where it met it empty
    twice = cli("compare", "-", "-", input=target.read_bytes())
    assert twice.returncode == 2 and "stdin: read already for another of this command's" in (
        " ".join(twice.stderr.split())
    )
    # a recipe or a library is read from it too: "… | flakelab weigh - --quantity 1l"
    recipe = target.with_name("blue-metallic-recipe.json")
    weighed = cli("weigh", "-", "--quantity", "1l", "--json", input=recipe.read_bytes())
    assert weighed.returncode == 0, weighed.stderr
    from_file = json.loads(cli("weigh", recipe, "--quantity", "1l", "--json").stdout)
    assert json.loads(weighed.stdout) == from_file | {"recipe": "-"}
    tight = b'name = "tight"\n[default]\nde00 = 0.3\n'
    judged = cli("compare", "--example", "--tolerance", "-", "--json", input=tight)
    assert json.loads(judged.stdout)["tolerance"] == "tight", judged.stderr
    library = cli("library", "show", "-", "--json", input=demo_library_path().read_bytes())
    assert library.returncode == 0 and json.loads(library.stdout)["library"] == "flakelab demo"
    # a car piped where a recipe is read is named as such, as a file named is (stop 99)
    mixed_up = cli("weigh", "-", input=target.read_bytes())
    assert mixed_up.returncode == 2 and "this is a CxF3 file, not JSON" in mixed_up.stderr
    refused = cli("inspect", "-", "--images", tmp_path / "pictures", input=workbook.read_bytes())
    assert refused.returncode == 2 and "--images: stdin:" in refused.stderr, refused.stderr
    with open(os.devnull) as null:  # not a terminal: read, empty
        monkeypatch.setattr(sys, "stdin", null)
        with pytest.raises(MeasurementFileError, match="^stdin: empty file"):
            flakelab.io.read_measurements("-")
        monkeypatch.setattr(null, "isatty", lambda: True)
        with pytest.raises(MeasurementFileError, match="^stdin: a terminal, not a file"):
            flakelab.io.read_measurements("-")
        monkeypatch.undo()


def test_a_file_named_stdin_is_read_as_a_file(tmp_path, monkeypatch):
    """Only ``-`` stands for standard input: a UTF-16 file (read through a copy, as a pipe
    is) that happens to be named ``stdin`` is read from its file, where the copy took the
    name its errors give for standard input and read standard input."""
    from flakelab.data import example_path

    monkeypatch.chdir(tmp_path)
    write_measurements(read_measurements(example_path("target")), tmp_path / "t.csv")
    (tmp_path / "stdin").write_bytes((tmp_path / "t.csv").read_text().encode("utf-16"))
    with open(os.devnull) as null:
        monkeypatch.setattr(sys, "stdin", null)
        read = read_measurements("stdin")
    np.testing.assert_array_equal(
        read[0].reflectance, read_measurements(tmp_path / "t.csv")[0].reflectance
    )


def test_measurements_are_converted_to_standard_output(tmp_path, cli, capsysbinary):
    """``flakelab convert scan.xlsx - --format csv | …``: a TARGET of ``-`` is standard
    output, in the format ``--format`` names (before: "-: unknown output extension ''"), and
    read back as written; a workbook too. ``--format`` that contradicts TARGET's extension
    is refused, and nothing written; the option's choices are :data:`~flakelab.io.FORMATS`."""
    from flakelab.cli.main import MeasurementFormat
    from flakelab.data import example_path
    from flakelab.io import FORMATS

    assert [f.value for f in MeasurementFormat] == list(FORMATS)
    target = example_path("target")
    expected = read_measurements(target)[0].reflectance
    for format, suffix in (("csv", ".csv"), ("json", ".json"), ("cxf", ".cxf")):
        written = cli("convert", target, "-", "--format", format)
        assert written.stderr == "wrote 1 measurement to stdout\n", written.stderr
        (tmp_path / f"out{suffix}").write_text(written.stdout)
        read = read_measurements(tmp_path / f"out{suffix}")[0].reflectance
        np.testing.assert_allclose(read, expected, rtol=1e-12)
    write_measurements(read_measurements(target), "-", "mat12-xlsx")
    (tmp_path / "out.xlsx").write_bytes(capsysbinary.readouterr().out)
    np.testing.assert_allclose(read_measurements(tmp_path / "out.xlsx")[0].reflectance,
                               expected, rtol=1e-12)  # fmt: skip
    unnamed = cli("convert", target, "-")
    assert unnamed.returncode == 2 and "--format names it" in unnamed.stderr, unnamed.stderr
    contrary = cli("convert", target, tmp_path / "x.csv", "--format", "json")
    assert contrary.stderr.strip().endswith("x.csv: its extension says csv, not json")
    assert not (tmp_path / "x.csv").exists()


def test_an_output_or_a_database_named_dash_is_refused(tmp_path, cli, monkeypatch):
    """Where ``-`` reads standard input, an output file or a database named ``-`` wrote a file
    of that name (``--recipe-out -``, ``cases generate --out -``, ``-d -``); each is refused,
    naming the option, and nothing is written."""
    monkeypatch.chdir(tmp_path)
    for args, said in (
        (("match", "--example", "--recipe-out", "-"), "--recipe-out: - is standard output"),
        (("render", "-o", "-"), "--output: - is standard output"),
        (("cases", "generate", "--n", "2", "--out", "-"), "-: a database is a file or"),
        (("cases", "list", "-d", "-"), "-: a database is a file or"),
    ):
        run = cli(*args)
        assert run.returncode == 2 and said in run.stderr, (args, run.stderr)
    assert not list(tmp_path.iterdir())


def test_a_case_history_is_imported_from_a_pipe(tmp_path, cli):
    """``cases import /dev/stdin``: the progress bar counted the pipe's lines first, and the
    import met it empty ("expected a header starting with case_id"). It now counts none."""
    history = tmp_path / "history.csv"
    assert cli("cases", "generate", "--n", "3", "--seed", "1", "--out", history).returncode == 0
    _fed_through_a_pipe(tmp_path / "pipe", history.read_bytes())
    run = cli("cases", "import", tmp_path / "pipe", "-d", tmp_path / "shop.db", "--no-check")
    assert run.returncode == 0 and "imported 3 cases" in run.stderr, run.stderr


def test_a_quote_left_open_is_named_by_its_row_in_every_csv(tmp_path, cli):
    """A quote left open takes every line after it into one cell, past csv's limit of 131,072
    characters: "internal error: Error: field larger than field limit" in the measurement,
    case-history and manifest readers. Each now names the file and the row."""
    from flakelab.cases.exchange import CaseFileError, read_cases
    from flakelab.cases.manifest import ManifestError, read_manifest
    from flakelab.data import example_path

    left_open = '"' + "0.5," * 40_000  # a cell of 160,000 characters
    measurements = tmp_path / "m.csv"
    write_measurements(read_measurements(example_path("target")), measurements)
    lines = measurements.read_text().splitlines()
    measurements.write_text("\n".join([lines[0], lines[1], left_open, *lines[2:]]))
    history = tmp_path / "h.csv"
    assert cli("cases", "generate", "--n", "2", "--seed", "1", "--out", history).returncode == 0
    history.write_text(history.read_text() + left_open)
    manifest = tmp_path / "manifest.csv"
    manifest.write_text(f"target,recipe,sprayed\n{left_open}\n")
    for read, path, error, row in ((read_measurements, measurements, MeasurementFileError, 3),
                                   (read_cases, history, CaseFileError, 4),
                                   (read_manifest, manifest, ManifestError, 2)):  # fmt: skip
        with pytest.raises(error, match=f"^{path}: row {row}: a cell longer than 131,072 "):
            read(path)


def test_json_nested_too_deeply_is_refused_by_name_in_every_reader(tmp_path, cli):
    """``[[[[…`` a hundred thousand deep (a damaged or hostile file) stopped every JSON reader
    with "internal error: RecursionError"; each now refuses it as JSON that does not parse,
    naming the file."""
    from flakelab.io import read_library
    from flakelab.io.lots_file import read_lots
    from flakelab.io.tolerance_file import read_tolerance
    from flakelab.match.habits import read_habits

    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    readers = (read_measurements, read_recipe, read_library, read_tolerance, read_lots,
               read_habits)  # fmt: skip
    for read in readers:
        with pytest.raises(FlakelabError, match=f"^{deep}: .*nested too deeply to be read"):
            read(deep)
    deep_toml = tmp_path / "deep.toml"  # a library or tolerance in TOML, too
    deep_toml.write_text("a = " + "[" * 5000 + "]" * 5000 + "\n")
    for read in (read_library, read_tolerance):
        with pytest.raises(FlakelabError, match=f"^{deep_toml}: .*nested too deeply"):
            read(deep_toml)
    from flakelab.cases.exchange import read_cases  # a case history's recipe cell, too

    history = tmp_path / "history.csv"
    assert cli("cases", "generate", "--n", "1", "--seed", "1", "--out", history).returncode == 0
    rows = [*csv.reader(history.read_text().splitlines())]
    rows[1][rows[0].index("recipe")] = "[" * 60_000 + "]" * 60_000
    with history.open("w", newline="") as handle:
        csv.writer(handle).writerows(rows)
    with pytest.raises(FlakelabError, match=f"^{history}: row 2: recipe: expected a JSON") as e:
        read_cases(history)
    assert len(str(e.value)) < len(str(history)) + 150  # the cell quoted cut, not 120,000 long


HUGE = {"1e21": "1" + "0" * 21, "1e400": "1" + "0" * 400}
"""Integers past 64 bits, written out in digits: a double, and past a double's range."""


@pytest.mark.parametrize("huge", list(HUGE))
def test_an_integer_past_64_bits_is_judged_as_the_number_it_names(tmp_path, rich_measurement, huge):
    """An integer past 64 bits was an internal error wherever numpy or a float met it (a
    habits file's film build: "ufunc 'isfinite' not supported"; a spectrum's value, a tin's
    strength: OverflowError). JSON and TOML integers past 64 bits are read as the doubles they
    name, as most tools read JSON: a field with a range refuses it by name, and past a
    double's range it is infinity, which every field refuses."""
    from flakelab.core.documents import json_value, toml_value
    from flakelab.io import read_library, write_measurements
    from flakelab.io.library_file import demo_library_path
    from flakelab.io.lots_file import read_lots
    from flakelab.io.tolerance_file import read_tolerance
    from flakelab.match.habits import ShopHabits, read_habits, write_habits

    digits, infinite = HUGE[huge], huge == "1e400"
    assert json_value(f"[{digits}, -{digits}, 12]") == [float(huge), -float(huge), 12]
    assert toml_value(f"a = [{digits}, 12]") == {"a": [float(huge), 12]}
    assert type(json_value("999999999999999999")) is int  # 18 digits: an int, exactly

    habits = tmp_path / "habits.json"
    write_habits(ShopHabits(np.array([0.04, -0.04, 0.005]), np.full(3, 0.01), 9, "m"), habits)
    measurement = tmp_path / "m.json"
    write_measurements([rich_measurement], measurement)
    library = tmp_path / "library.json"
    library.write_text(demo_library_path().read_text())
    lots = tmp_path / "lots.json"
    lots.write_text(json.dumps({"format": "flakelab-toner-lots", "version": 3, "lots": [
        {"toner": "Phthalo blue GS", "strength": 1.031, "strength_sd": 0.006}]}))  # fmt: skip
    recipe = tmp_path / "recipe.json"
    recipe.write_text('{"Al medium": 1.0, "Carbon black": 2.0}')
    tolerance = tmp_path / "tolerance.toml"
    tolerance.write_text('name = "mine"\n[default]\nde00 = 1.0\n')
    cases = [  # the file, its reader, the number made huge, what is said; read where in range
        (habits, read_habits, r'"film_build": (\S+),', "film_build: expected", False),
        (measurement, read_measurements, r'"reflectance": \[\s*([^,\s]+)', "reflectance", False),
        (library, read_library, r'"refractive_index": ([^,\s]+)', "refractive_index", False),
        (lots, read_lots, r'"strength": ([^,\s]+)', "lots[0] (Phthalo blue GS): strength", False),
        (recipe, read_recipe, r'"Al medium": ([^,\s]+)', "Al medium: expected", True),
        (tolerance, read_tolerance, r"de00 = (\S+)", "default: expected a positive limit", True),
    ]
    for path, reader, number, said, in_range in cases:
        text = path.read_text()
        found = re.search(number, text)
        assert found, (path, number)
        path.write_text(text[: found.start(1)] + digits + text[found.end(1) :])
        if in_range and not infinite:
            reader(path)  # a recipe of 10²¹ grams, a limit of 10²¹: numbers, and in range
            continue
        with pytest.raises(FlakelabError) as caught:
            reader(path)
        message = str(caught.value)
        assert message.startswith(f"{path}: ") and said in message, message


def test_a_named_pipe_is_written_into_not_replaced(tmp_path, cli):
    """``--recipe-out`` to a named pipe (or /dev/stdout, /dev/null): the recipe goes down the
    pipe, which stays one. Renamed over, it would become a regular file, and /dev/null
    with it when the user is root."""
    import threading

    from flakelab.data import example_path
    from flakelab.io import read_recipe

    recipe = example_path("target").with_name("blue-metallic-recipe.json")
    pipe = tmp_path / "scale"
    os.mkfifo(pipe)
    received = []

    def read_the_pipe():
        with open(pipe, encoding="utf-8") as reader:
            received.append(reader.read())

    reader = threading.Thread(target=read_the_pipe, daemon=True)
    reader.start()
    run = cli("weigh", recipe, "--quantity", "100g", "--recipe-out", pipe, "--json")
    reader.join(timeout=60)
    assert run.returncode == 0, run.stderr
    assert stat.S_ISFIFO(pipe.lstat().st_mode)
    weighed = json.loads(received[0])
    assert weighed == {w["toner"]: w["grams"] for w in json.loads(run.stdout)["weights_g"]}
    assert sum(weighed.values()) == pytest.approx(100.0)
    assert set(weighed) == set(read_recipe(recipe))


def _run_cli_with_file_limit(limit_bytes: int, *args: object):
    """The CLI in a process whose files may not grow past ``limit_bytes`` (RLIMIT_FSIZE): a
    full disk as the kernel reports it (Python ignores SIGXFSZ, so a write fails, EFBIG)."""
    import resource
    import subprocess
    import sys

    def limit():
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, resource.RLIM_INFINITY))

    command = [sys.executable, "-m", "flakelab.cli.main", *map(str, args)]
    return subprocess.run(command, capture_output=True, text=True, preexec_fn=limit, timeout=300)


def test_a_file_the_disk_cannot_hold_is_named_and_nothing_is_half_written(tmp_path, cli):
    """A case file or a training checkpoint that cannot be written whole: one line naming
    the file asked for (not the temporary one, nor torch's internal error), the file there
    before left as it was, no temporary file left behind."""
    cases = tmp_path / "cases.csv"
    assert cli("cases", "generate", "--n", "60", "--seed", "1", "--out", cases).returncode == 0
    before = cases.read_bytes()
    run = _run_cli_with_file_limit(
        len(before) // 2, "cases", "generate", "--n", "60", "--seed", "2", "--out", cases
    )
    assert run.returncode == 2, run.stderr
    assert run.stderr.strip().splitlines() == [
        f"error: {cases}: File too large while writing it; the file there is left as it was"
    ]
    assert cases.read_bytes() == before
    checkpoint = tmp_path / "training.ckpt"
    # not registered: a new database (70 kB) outgrows the limit, and the test failed run alone
    run = _run_cli_with_file_limit(
        64_000, "train", cases, "--out", tmp_path / "m.pt", "--epochs", "1",
        "--checkpoint", checkpoint, "--members", "1", "--no-register",
    )  # fmt: skip
    assert run.returncode == 2, run.stderr
    assert run.stderr.strip().splitlines()[-1] == (
        f"error: {checkpoint}: File too large while writing it; no file was written"
    )
    from flakelab.data import example_path

    workbook = tmp_path / "export.xlsx"  # openpyxl's sheet writers, left half done
    run = _run_cli_with_file_limit(2048, "convert", example_path("target"), workbook)
    assert run.returncode == 2, run.stderr
    assert run.stderr.strip().splitlines() == [
        f"error: {workbook}: cannot be written (File too large while writing it; no file was "
        "written)"
    ]  # before, "Exception ignored in: <generator …>" and a traceback followed
    figure = tmp_path / "plot.pdf"  # matplotlib's PDF stream, closed after the refusal
    run = _run_cli_with_file_limit(2048, "plot", example_path("target"), "-o", figure)
    assert run.returncode == 2, run.stderr  # before, 70: "internal error: error: Error -2 …"
    assert run.stderr.strip().splitlines() == [
        f"error: {figure}: File too large while writing it; no file was written"
    ]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cases.csv"]


@pytest.mark.parametrize(("stop", "said_as"), [("SIGTERM", "terminated"), ("SIGHUP", "hung up")])
def test_a_command_stopped_by_sigterm_stops_as_a_ctrl_c_stops_it(tmp_path, stop, said_as):
    """``kill``, ``timeout`` or a service manager stop a command with SIGTERM, a closed
    terminal or a dropped SSH session with SIGHUP: it ends as a Ctrl-C ends it, one line and
    exit status 128 + the signal, the file it was writing removed and the one there before
    left as it was. Before, Python ended it on the spot, exit -15 or -1, and left the
    temporary file beside it, as large as what had been written."""
    import signal
    import subprocess
    import sys

    stop = getattr(signal, stop)

    cases = tmp_path / "cases.csv"
    cases.write_text("kept\n")
    command = [sys.executable, "-m", "flakelab.cli.main", "cases", "generate", "--n", "100000",
               "--seed", "1", "--out", str(cases)]  # fmt: skip
    # as from a terminal: a suite run under nohup would pass its hangups ignored on, and a
    # command started so rightly keeps ignoring them
    run = subprocess.Popen(
        command,
        stderr=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGHUP, signal.SIG_DFL),
    )
    first = run.stderr.readline()  # the bar's first line: the file is being written
    run.send_signal(stop)
    said = first + run.communicate(timeout=120)[1]
    assert "generating cases" in first, said
    assert run.returncode == 128 + stop, said
    assert said.strip().splitlines()[-1].startswith(f"{said_as}: ") and "Traceback" not in said
    assert cases.read_text() == "kept\n" and [p.name for p in tmp_path.iterdir()] == [cases.name]


def test_a_spectrum_s_cells_read_at_once_are_those_read_one_by_one():
    """numpy parses a reading's cells at once; a cell it cannot take as a finite number (or
    a bool, which it would) is named as :func:`parse_number` names it."""
    from flakelab.io.records import parse_number, parse_spectrum

    wavelengths = np.arange(400.0, 710.0, 10.0)
    cells = [" 0.5", "1e-3", "12", "+.25", "7_5", *["0.1"] * 26]
    read = parse_spectrum("f.csv", cells, wavelengths, "sample s")
    assert read.tolist() == [parse_number("f.csv", c, "") for c in cells]
    flawed = {True: "got True", None: "got an empty cell", "0,5": "got '0,5'",
              "inf": "expected a finite number, got 'inf'", "[]": "got '[]'"}  # fmt: skip
    for bad, said in flawed.items():
        with pytest.raises(MeasurementFileError, match="sample s, 550 nm: expected") as e:
            parse_spectrum("f.csv", [*cells[:15], bad, *cells[16:]], wavelengths, "sample s")
        assert said in str(e.value)


def test_a_recipe_file_round_trips_heaviest_first(tmp_path):
    path = tmp_path / "recipe.json"
    write_recipe({"Carbon black": 3.6, "Al medium": 194.0, "Phthalo blue GS": 16.6}, path)
    assert list(read_recipe(path).items()) == [
        ("Al medium", 194.0),
        ("Phthalo blue GS", 16.6),
        ("Carbon black", 3.6),
    ]


def test_json_and_toml_files_windows_writes_are_read(tmp_path, rich_measurement):
    """A recipe, a library, a tolerance, a measurement JSON as Windows writes them: UTF-16
    from PowerShell's ``>``, UTF-8 with the byte-order mark of an older Notepad. Both were
    refused ("Unexpected UTF-8 BOM", "can't decode byte 0xff")."""
    from flakelab.io import read_library, read_tolerance, write_library

    recipe, library, tolerance = tmp_path / "r.json", tmp_path / "l.json", tmp_path / "t.toml"
    measured = tmp_path / "m.json"
    write_recipe({"Al medium": 194.0, "Carbon black": 3.6}, recipe)
    write_library(read_library(), library)
    tolerance.write_text('name = "shop"\ndefault = { de00 = 1.2 }\n')
    write_measurements([rich_measurement], measured)
    expected = (read_recipe(recipe), read_library(library).names, read_tolerance(tolerance).name,
                read_measurements(measured)[0].reflectance)  # fmt: skip
    texts = {path: path.read_text() for path in (recipe, library, tolerance, measured)}
    for encoding in ("utf-16", "utf-16-be", "utf-8-sig"):
        for path, text in texts.items():
            mark = b"\xfe\xff" if encoding == "utf-16-be" else b""
            path.write_bytes(mark + text.encode(encoding))
        read = (read_recipe(recipe), read_library(library).names, read_tolerance(tolerance).name,
                read_measurements(measured)[0].reflectance)  # fmt: skip
        assert read[:3] == expected[:3], encoding
        np.testing.assert_array_equal(read[3], expected[3])
    # UTF-16 without its mark: each refused as such, where JSON said "Expecting property
    # name enclosed in double quotes" at line 1, column 2
    readers = {recipe: read_recipe, library: read_library, tolerance: read_tolerance,
               measured: read_measurements}  # fmt: skip
    for path, text in texts.items():
        path.write_bytes(text.encode("utf-16-le"))
        with pytest.raises(FlakelabError, match=f"{path.name}: .*it holds NUL bytes.*UTF-16"):
            readers[path](path)


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ('["Al medium", 10]', "expected a JSON object toner → grams"),
        ("{}", "with at least one toner"),
        ('{"Al medium": "ten"}', "Al medium: expected grams as a number, got 'ten'"),
        ('{"Al medium": -3}', "Al medium: expected non-negative grams, got -3"),
        ('{"Al medium": 0}', "the amounts sum to zero grams"),
        ('{"Al medium": 1e308, "Al fine": 1e308}', "sum to more grams than a number holds"),
        ('{"Al medium": 10,', "expected a JSON object toner → grams (Expecting"),
    ],
)
def test_bad_recipe_files_name_file_toner_and_problem(tmp_path, text, problem):
    path = tmp_path / "recipe.json"
    path.write_text(text)
    with pytest.raises(FlakelabError, match=r"recipe\.json: ") as raised:
        read_recipe(path)
    assert problem in str(raised.value)
    with pytest.raises(FlakelabError, match="no such recipe file"):
        read_recipe(tmp_path / "missing.json")


def test_a_document_given_to_the_wrong_reader_is_named(tmp_path):
    """A flakelab JSON document given where another is read is refused naming what it is: a
    recipe to 'inspect', a measurement file or a match report to '--recipe' (before, the
    latter read "format: expected grams as a number, got 'flakelab-measurements'")."""
    from flakelab.data import example_path
    from flakelab.io import read_library, read_measurement, write_library, write_measurements
    from flakelab.match.habits import HABITS_FORMAT

    measured = tmp_path / "target.json"
    write_measurements([read_measurement(example_path("target"))], measured)
    library = tmp_path / "library.json"
    write_library(read_library(None), library)
    habits, report, recipe = tmp_path / "habits.json", tmp_path / "m.json", tmp_path / "r.json"
    habits.write_text(json.dumps({"format": HABITS_FORMAT, "version": 1, "shop": "A"}))
    report.write_text(json.dumps({"target": "car", "candidates": []}))
    recipe.write_text(json.dumps({"Al medium": 194.0, "Carbon black": 3.6}))
    for path, kind in [(recipe, "a recipe file, toner → grams (--recipe)"),
                       (library, "a toner library (--library)"),
                       (habits, "a shop's habits (--habits)"),
                       (report, "a report of 'flakelab match --json'")]:  # fmt: skip
        with pytest.raises(MeasurementFileError) as raised:
            read_measurements(path)
        assert f"format 'flakelab-measurements'; this is {kind}" in str(raised.value)
    for path, kind in [(measured, "a measurement file"), (report, "a report of 'flakelab")]:
        with pytest.raises(FlakelabError, match=f"toner → grams; this is {re.escape(kind)}"):
            read_recipe(path)
    assert read_recipe(recipe) == {"Al medium": 194.0, "Carbon black": 3.6}
    unknown = tmp_path / "other.json"
    unknown.write_text(json.dumps({"format": "someone-elses", "x": 1}))
    with pytest.raises(MeasurementFileError) as raised:
        read_measurements(unknown)
    assert str(raised.value).endswith("expected a JSON object with format 'flakelab-measurements'")
    # a file of another format where JSON is read, or a case history where measurements
    # are, is named for what it is (before: "Expecting value: line 1 column 1 (char 0)",
    # "missing column 'sample' (columns: case_id, shop, …)")
    for suffix, kind in ((".cxf", "a CxF3 file"), (".xlsx", "an xlsx workbook"),
                         (".csv", "a CSV file")):  # fmt: skip
        write_measurements([read_measurement(example_path("target"))], tmp_path / f"m{suffix}")
        with pytest.raises(FlakelabError, match=f"toner → grams; this is {kind}, not JSON$"):
            read_recipe(tmp_path / f"m{suffix}")
        with pytest.raises(FlakelabError, match=f"toner library; this is {kind}, not JSON$"):
            read_library(tmp_path / f"m{suffix}")
    from flakelab.cases.exchange import read_cases
    from flakelab.io.lots_file import read_lots
    from flakelab.match.habits import read_habits

    with pytest.raises(FlakelabError, match="this is a CxF3 file, not JSON$"):
        read_habits(tmp_path / "m.cxf")
    # a folder: named so, where the messages quoted "[Errno 21] Is a directory: '…'"
    for reader, what in ((read_recipe, "recipe file"), (read_library, "toner library"),
                         (read_habits, "habits file"), (read_lots, "toner-lot file")):  # fmt: skip
        with pytest.raises(FlakelabError, match=f"a folder, not a {what}$"):
            reader(tmp_path)
    with pytest.raises(FlakelabError, match="a folder, not a measurement file$"):
        read_measurements(tmp_path)
    # an empty file: named so, where the messages quoted "Expecting value: line 1 column 1"
    # or asked a case file for its header at row 1
    empty = tmp_path / "empty.json"
    empty.write_text(" \n")
    for reader, what in ((read_recipe, "a JSON object toner → grams"),
                         (read_library, "a toner library"), (read_habits, "a JSON habits file"),
                         (read_lots, "a JSON toner-lot file")):  # fmt: skip
        with pytest.raises(FlakelabError, match=f"empty.json: empty file; expected {what}$"):
            reader(empty)
    blank_history = tmp_path / "empty.csv"
    blank_history.write_text("\n")
    with pytest.raises(FlakelabError, match="empty file; expected a case history's header"):
        read_cases(blank_history)
    with pytest.raises(FlakelabError, match="a folder, not a case file$"):
        read_cases(tmp_path)
    (tmp_path / "broken.json").write_text('{"Al medium": 1')
    with pytest.raises(FlakelabError, match=r"toner → grams \(Expecting ',' delimiter"):
        read_recipe(tmp_path / "broken.json")
    history = tmp_path / "history.csv"
    history.write_text("case_id,shop,instrument\nc1,A,five-angle\n")
    with pytest.raises(MeasurementFileError, match="this is a case history, which 'flakelab"):
        read_measurements(history)


def test_the_cielab_limit_holds_every_reflectance_a_file_may_hold():
    """LAB_LIMIT follows from REFLECTANCE_RANGE: a flat factor of 100 reads L* 522.4
    (116 · 100^⅓ − 16), and no spectrum of factors at either end of the range, band by band
    in blocks (the optimal colours), reaches the limit under D65/10 or A/2. Within it ΔE00
    stays finite, without the overflow of an a* of 10³⁰⁸."""
    import warnings

    from flakelab.core.colorimetry import Conditions, reflectance_to_Lab
    from flakelab.core.difference import delta_E
    from flakelab.core.measurement import LAB_LIMIT, REFLECTANCE_RANGE

    low, high = REFLECTANCE_RANGE
    band = np.arange(len(WAVELENGTHS))
    blocks = [(i <= band) & (band < j) for i in band for j in range(i + 1, band.size + 1)]
    ends = np.where(np.array(blocks), high, low)
    spectra = np.concatenate([ends, high + low - ends])
    flat = reflectance_to_Lab(np.full(band.size, high))[0]
    np.testing.assert_allclose(flat, 116 * high ** (1 / 3) - 16)
    for conditions in ("D65/10", "A/2"):
        lab = reflectance_to_Lab(spectra, conditions=Conditions.parse(conditions))
        assert np.abs(lab).max() < LAB_LIMIT
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert np.isfinite(delta_E(np.array([LAB_LIMIT, LAB_LIMIT, -LAB_LIMIT]), np.zeros(3)))


@pytest.mark.parametrize("fmt", sorted(FORMATS))
def test_a_stored_cielab_no_reflectance_could_give_is_refused_by_its_cell(
    fmt, rich_measurement, tmp_path
):
    """An a* of 10³⁰⁸ in a file: overflowed ΔE00 to NaN with a warning before (MA-T12 exports
    fuzzed at stop 66); now refused, naming the cell, in every format that stores L*a*b*."""
    from dataclasses import replace

    lab = rich_measurement.stored_lab.copy()
    lab[1, 1] = 1e308
    path = tmp_path / f"out{FORMATS[fmt][2][0]}"
    write_measurements([replace(rich_measurement, stored_lab=lab)], path)
    with pytest.raises(MeasurementFileError) as raised:
        read_measurements(path)
    message = str(raised.value)
    field = {"mat12-xlsx": "row 6, a:", "cxf": "ColorCIELab", "csv": "row 3, a:",
             "json": "geometries[1].lab[1]:"}[fmt]  # fmt: skip
    assert message.startswith(str(path)) and field in message, message
    assert "expected a CIELAB value within ±2500, got 1e+308" in message, message


@pytest.mark.parametrize("fmt", sorted(FORMATS))
@pytest.mark.parametrize("value", [1e300, -1.0])
def test_a_texture_reading_no_instrument_gives_is_refused_by_its_cell(
    fmt, value, rich_measurement, tmp_path
):
    """A graininess of 10³⁰⁰ was read and printed the match's share of its limit as a
    300-digit percentage, after a NaN warning (fuzzed at stop 66); a negative one was read."""
    from dataclasses import replace

    path = tmp_path / f"out{FORMATS[fmt][2][0]}"
    texture = {**rich_measurement.texture, "G": value}
    write_measurements([replace(rich_measurement, texture=texture)], path)
    with pytest.raises(MeasurementFileError) as raised:
        read_measurements(path)
    message = str(raised.value)
    field = {"mat12-xlsx": "Texture Data, row 4, G:", "cxf": "Tag texture:G:",
             "csv": "row 2, G:", "json": "measurements[0].texture.G:"}[fmt]  # fmt: skip
    assert message.startswith(str(path)) and field in message, message
    assert f"expected a texture reading in [0, 1000], got {value:g}" in message, message


def test_a_date_cell_whose_serial_is_no_date_reads_as_no_date(rich_measurement, tmp_path):
    """openpyxl warns of a Date/Time cell formatted as a date whose serial no date has (a
    warning on the command line before, fuzzed at stop 66); it reads as no date, as any
    Date/Time that is not one does, and the spectra as written."""
    import warnings

    import openpyxl

    path = tmp_path / "m.xlsx"
    write_measurements([rich_measurement], path)
    workbook = openpyxl.load_workbook(path)
    for sheet in workbook.worksheets:
        for row in sheet.iter_rows():
            if isinstance(row[1].value, datetime):
                row[1].value = 1e308
                row[1].number_format = "yyyy-mm-dd h:mm:ss"
    workbook.save(path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        back = read_measurement(path)
    assert back.measured_at is None
    np.testing.assert_allclose(back.reflectance, rich_measurement.reflectance, atol=1e-9)


def test_a_file_of_lab_alone_is_read_with_spectra_recovered_from_it(ma_t12_dir, tmp_path):
    """The instrument's own L*a*b* of the 230 real MA-T12 samples (2,760 readings, no spectra):
    each reading gets a spectrum that gives the file's colour (to ΔE00 1e-6) and so the colour
    of the measured spectra to the instrument's 5.6e-6. Written as CSV or CxF it is written as
    read, L*a*b* alone; JSON or xlsx, which would give the spectra as measured, are refused,
    and so is one file of both kinds."""
    labs = ma_t12_dir / "all_samples_instrument_lab_d65_10.csv"
    recovered = read_measurements(labs)
    measured = read_measurements(ma_t12_dir / "all_samples_spectra.csv")
    assert len(recovered) == 230 and all(m.spectra_recovered for m in recovered)
    assert not any(m.spectra_recovered for m in measured)
    for r, m in zip(recovered, measured, strict=True):
        assert r.sample == m.sample and r.geometry_names == m.geometry_names
        assert delta_E_CIE2000(r.lab(), r.stored_lab).max() < 1e-6
        assert delta_E_CIE2000(r.lab(), m.lab()).max() < 1e-4
    written = tmp_path / "again.csv"
    write_measurements(recovered[:3], written)
    assert (
        written.read_text().splitlines()[0]
        == "sample,geometry,L,a,b,lab_conditions,instrument,measured_at"
    )
    again = read_measurements(written)
    assert all(a.spectra_recovered for a in again)
    np.testing.assert_allclose(again[2].reflectance, recovered[2].reflectance, atol=1e-12)
    cxf = tmp_path / "again.cxf"
    write_measurements(recovered[:3], cxf)
    assert "ReflectanceSpectrum" not in cxf.read_text()
    through_cxf = read_measurements(cxf)
    assert all(a.spectra_recovered for a in through_cxf)
    np.testing.assert_allclose(through_cxf[1].stored_lab, recovered[1].stored_lab, atol=1e-12)
    for suffix in (".json", ".xlsx"):
        with pytest.raises(
            MeasurementFileError, match="recovered from L.a.b.: a .* file would give"
        ):
            write_measurements(recovered[:1], tmp_path / f"out{suffix}")
        assert not (tmp_path / f"out{suffix}").exists()
    both = tmp_path / "both.csv"  # a table holds one kind: its columns are a spectrum's or L*a*b*
    with pytest.raises(MeasurementFileError, match="measured, or L.a.b. alone, not both"):
        write_measurements([measured[0], recovered[1]], both)
    assert not both.exists()
    both = tmp_path / "both.cxf"  # a CxF3 document holds both, Object by Object, as read
    write_measurements([measured[0], recovered[1]], both)
    kept, alone = read_measurements(both)
    assert not kept.spectra_recovered and alone.spectra_recovered
    np.testing.assert_allclose(kept.reflectance, measured[0].reflectance, atol=1e-12)
    np.testing.assert_allclose(alone.stored_lab, recovered[1].stored_lab, atol=1e-12)


def test_a_dark_metallic_s_flop_reading_of_lab_alone_is_read_as_its_spectra_would_be(tmp_path):
    """A black metallic read at 45as110 gives L* -0.27 (its measured spectrum dips to -4e-4,
    instrument noise the spectral readers accept): as L*a*b* alone the reading is read too,
    its spectrum recovered dipping as little. It was refused, "no colour a surface reflects"."""
    table = tmp_path / "black.csv"
    table.write_text(
        "sample,geometry,L,a,b\nB,45as15,13.51,1.2,-3.4\nB,45as45,1.57,0.1,-0.6\n"
        "B,45as110,-0.27,-0.09,-0.31\n"
    )
    black = read_measurement(table)
    assert black.spectra_recovered
    assert delta_E_CIE2000(black.lab(), black.stored_lab).max() < 1e-6
    assert -0.001 < black.reflectance.min() < 0.0


def test_a_cxf_of_colorcielab_alone_is_read_with_spectra_recovered(rich_measurement, tmp_path):
    """A CxF3 file whose Objects hold ColorCIELab and no ReflectanceSpectrum (a paint maker's
    colour data): its readings get spectra that give its colours, at its geometries, under the
    conditions its ColorSpecifications name."""
    cxf = tmp_path / "spectra.cxf"
    write_measurements([rich_measurement], cxf)
    text = cxf.read_text()
    spectrum = r"<(\w+:)ReflectanceSpectrum[^>]*>[^<]*</\1ReflectanceSpectrum>"
    alone = tmp_path / "colour.cxf"
    alone.write_text(re.sub(spectrum, "", text))
    assert "ReflectanceSpectrum" not in alone.read_text()
    read = read_measurement(alone)
    assert read.spectra_recovered and read.geometry_names == rich_measurement.geometry_names
    conditions = rich_measurement.stored_lab_conditions
    assert read.stored_lab_conditions == conditions
    assert delta_E_CIE2000(read.lab(conditions), rich_measurement.stored_lab).max() < 1e-6
    nothing = tmp_path / "nothing.cxf"
    lab = r"<(\w+:)ColorCIELab[^>]*>.*?</\1ColorCIELab>"
    nothing.write_text(re.sub(lab, "", alone.read_text()))
    with pytest.raises(MeasurementFileError, match="no ReflectanceSpectrum or ColorCIELab"):
        read_measurement(nothing)


def test_a_cxf_of_measured_objects_and_colour_alone_ones_reads_each_as_it_is(
    rich_measurement, tmp_path
):
    """A CxF3 file whose first Object is measured and whose second gives ColorCIELab alone (a
    standard's colour beside a measured trial): both are read, in the file's order, the second
    with spectra recovered from its colour; it was passed over, unsaid. A geometry of colour
    alone in a measured Object is refused by name, where it was dropped."""
    both = tmp_path / "both.cxf"
    write_measurements([rich_measurement, replace(rich_measurement, sample="standard")], both)
    text = both.read_text()
    spectrum = r"<(\w+:)ReflectanceSpectrum[^>]*>[^<]*</\1ReflectanceSpectrum>"
    second = text.index("standard")
    both.write_text(text[:second] + re.sub(spectrum, "", text[second:]))
    trial, standard = read_measurements(both)
    assert (trial.sample, standard.sample) == (rich_measurement.sample, "standard")
    assert not trial.spectra_recovered and standard.spectra_recovered
    np.testing.assert_array_equal(trial.reflectance, rich_measurement.reflectance)
    conditions = rich_measurement.stored_lab_conditions
    assert delta_E_CIE2000(standard.lab(conditions), rich_measurement.stored_lab).max() < 1e-6
    partly = tmp_path / "partly.cxf"
    partly.write_text(re.sub(spectrum, "", text, count=1))
    with pytest.raises(
        MeasurementFileError, match="ColorCIELab .*a colour without a ReflectanceSpectrum"
    ):
        read_measurements(partly)


def test_a_cxf_qc_job_marks_its_standard_by_object_type(rich_measurement, ma_t12_files, tmp_path):
    """A CxF3 QC job whose one Object of ObjectType "Standard" is not its first (trials
    before it): commands that take one sample read that standard, not the first trial. A
    document of several Standards (a library of them) names none, and its first is read. An
    MA-T12 job written as CxF3 marks the standard its ``STANDARD:`` row names, which reads
    back as that job's standard. Before, every CxF3 file gave its first Object."""
    job = tmp_path / "job.cxf"
    samples = [replace(rich_measurement, sample=name) for name in ("trial 1", "std", "trial 2")]
    write_measurements(samples, job)
    text = job.read_text()
    assert text.count('ObjectType="Sample"') == 3  # none named: none marked
    job.write_text(
        text.replace('ObjectType="Sample" Name="std"', 'ObjectType="Standard" Name="std"')
    )
    assert read_measurement(job).sample == "std"
    assert {m.metadata["standard"] for m in read_measurements(job)} == {"std"}
    job.write_text(text.replace('ObjectType="Sample"', 'ObjectType="Standard"'))
    assert read_measurement(job).sample == "trial 1"
    assert all("standard" not in m.metadata for m in read_measurements(job))
    export = read_measurements(ma_t12_files[0])
    trials = [replace(export[0], sample=f"trial {i}") for i in (1, 2)]
    standard = export[0].metadata["standard"]
    written = tmp_path / "export.cxf"
    write_measurements([trials[0], replace(export[0], sample=standard), trials[1]], written)
    marked = re.findall(r'ObjectType="(\w+)" Name="([^"]+)"', written.read_text())
    assert marked == [("Trial", "trial 1"), ("Standard", standard), ("Trial", "trial 2")]
    assert read_measurement(written).sample == standard


def test_an_export_of_colour_alone_is_read_with_spectra_recovered(ma_t12_files, tmp_path):
    """An MA-T12 export saved with its Color Data sheet and no Spectral Data: each reading's
    spectrum recovered from the sheet's L*a*b*, at its geometries and date. Without either
    sheet it is refused naming the sheets it has."""
    import openpyxl

    measured = read_measurement(ma_t12_files[0])
    workbook = openpyxl.load_workbook(ma_t12_files[0])
    del workbook["Spectral Data"]
    path = tmp_path / "colour.xlsx"
    workbook.save(path)
    read = read_measurement(path)
    assert read.spectra_recovered and read.geometry_names == measured.geometry_names
    assert read.measured_at == measured.measured_at and read.sample == measured.sample
    assert delta_E_CIE2000(read.lab(), measured.stored_lab).max() < 1e-6
    workbook = openpyxl.load_workbook(ma_t12_files[0])  # its pictures are read once, as saved
    del workbook["Spectral Data"], workbook["Color Data"]
    workbook.save(path)
    with pytest.raises(MeasurementFileError, match="no sheet 'Spectral Data' .sheets: "):
        read_measurements(path)


def test_a_cxf_object_of_lch_or_xyz_alone_is_read_as_that_colour(tmp_path):
    """An Object that gives ColorCIELCh, or ColorCIEXYZ [Y 0–100], per geometry and no
    spectra, as some instruments export a colour, is read as its L*a*b* (converted by
    colour-science under its ColorSpecification's D65/10), spectra recovered and flagged; the
    file was refused, "no ReflectanceSpectrum or ColorCIELab in any Object". A cell that is
    no number is named. An Object giving ColorCIELab beside ColorCIELCh is read as the Lab
    where they agree and refused, naming both, where they do not (the LCh was passed over)."""
    from flakelab.core.colorimetry import Lab_to_LCh, reflectance_to_XYZ
    from flakelab.core.measurement import known_by_colour
    from flakelab.data import example_path

    car = read_measurement(example_path("target"))
    given = tmp_path / "lab.cxf"
    write_measurements([known_by_colour(car)], given)
    text = given.read_text()
    tristimulus = 100 * reflectance_to_XYZ(car.reflectance, car.wavelengths)
    for kind, names, values in (
        ("ColorCIELCh", "LCH", Lab_to_LCh(car.lab())),
        ("ColorCIEXYZ", "XYZ", tristimulus),
    ):
        rows = iter(values.tolist())

        def swapped(m, kind=kind, names=names, rows=rows):
            row = zip(names, next(rows), strict=True)
            cells = "".join(f"<{m[1]}{n}>{v!r}</{m[1]}{n}>" for n, v in row)
            return f"<{m[1]}{kind} {m[2]}>{cells}</{m[1]}{kind}>"

        path = tmp_path / f"{kind}.cxf"
        path.write_text(re.sub(r"<(\w+:)ColorCIELab ([^>]*)>.*?</\1ColorCIELab>", swapped, text))
        assert "ColorCIELab" not in path.read_text() and kind in path.read_text()
        read = read_measurement(path)
        assert read.spectra_recovered and read.geometry_names == car.geometry_names
        assert delta_E_CIE2000(read.lab(), car.lab()).max() < 1e-4, kind
    broken = tmp_path / "broken.cxf"
    broken.write_text(re.sub(r"<(\w+:)X>[^<]*</", r"<\1X>abc</", path.read_text(), count=1))
    with pytest.raises(MeasurementFileError, match=r"ColorCIEXYZ CS_\S+, X: expected a number"):
        read_measurement(broken)
    # ColorCIELab and ColorCIELCh side by side: read as the Lab where they agree, else refused
    for hue_off, where in ((0.0, None), (20.0, 2)):
        lch = Lab_to_LCh(car.lab())
        if where is not None:
            lch[where, 2] += hue_off
        rows = iter(lch.tolist())

        def beside(m, rows=rows):
            row = zip("LCH", next(rows), strict=True)
            cells = "".join(f"<{m[1]}{n}>{v!r}</{m[1]}{n}>" for n, v in row)
            return f"{m[0]}<{m[1]}ColorCIELCh {m[2]}>{cells}</{m[1]}ColorCIELCh>"

        both = tmp_path / "both.cxf"
        both.write_text(re.sub(r"<(\w+:)ColorCIELab ([^>]*)>.*?</\1ColorCIELab>", beside, text))
        if where is None:
            assert delta_E_CIE2000(read_measurement(both).lab(), car.lab()).max() < 1e-4
            continue
        with pytest.raises(MeasurementFileError, match=r"CS_\S+: its ColorCIELCh read as L\*a\*b\* "
                                                       r"\(.*\) lies ΔE00 \d+\.\d\d from its "
                                                       r"ColorCIELab"):  # fmt: skip
            read_measurement(both)


def _same_readings(read, written) -> None:
    """Two lists of measurements hold the same readings, exactly."""
    assert [m.sample for m in read] == [m.sample for m in written]
    for a, b in zip(read, written, strict=True):
        assert a.geometries == b.geometries and a.texture == b.texture, a.sample
        assert np.array_equal(a.reflectance, b.reflectance), a.sample
        assert (a.stored_lab is None) == (b.stored_lab is None), a.sample
        if a.stored_lab is not None:
            assert np.array_equal(a.stored_lab, b.stored_lab), a.sample
        assert (a.instrument, a.measured_at) == (b.instrument, b.measured_at), a.sample
        assert a.spectra_recovered == b.spectra_recovered, a.sample


def test_a_csv_of_a_row_per_sample_reads_as_its_row_per_reading(rich_measurement, tmp_path):
    """``write_measurements(..., wide=True)`` writes a row per sample, its L*a*b* and spectra
    at each geometry in columns (``L* 45as15``, ``R400 45as15``); read back it gives the
    readings exactly, as the row-per-reading file does: the example target and spray-out (12
    geometries, texture, date), a third sample read at five of them (its other cells empty), a
    fourth with stored L*a*b* at an out-of-plane geometry and a name with quotes and
    separators, with a decimal comma too; and their colour alone."""
    from flakelab.core.colorimetry import D65_10
    from flakelab.core.geometry import instrument_geometries
    from flakelab.data import example_path

    target, sprayout = (read_measurement(example_path(n)) for n in ("target", "sprayout"))
    five = [target.index(g) for g in instrument_geometries("five-angle")]
    subset = replace(
        sprayout,
        sample="five-angle panel",
        geometries=tuple(sprayout.geometries[i] for i in five),
        reflectance=sprayout.reflectance[five][:, ::-1],
        stored_lab=None,
        texture={},
    )
    rich = replace(rich_measurement, metadata={}, instrument=target.instrument)  # one per file
    written = [target, sprayout, subset, rich]
    long = tmp_path / "long.csv"
    write_measurements(written, long)
    for decimal_comma in (False, True):
        wide = tmp_path / f"wide-{decimal_comma}.csv"
        write_measurements(written, wide, wide=True, decimal_comma=decimal_comma)
        lines = wide.read_text(encoding="utf-8-sig").splitlines()
        assert len(lines) == 1 + len(written)
        header = lines[0].split(";" if decimal_comma else ",")
        assert header[1:3] == ["L* 15as-45", "a* 15as-45"] and "R400 45as25az90" in header
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # full geometry names: nothing to note
            _same_readings(read_measurements(wide), read_measurements(long))
        _same_readings(read_measurements(wide), written)
    colours = [
        replace(m, stored_lab=m.lab(D65_10), stored_lab_conditions=D65_10, spectra_recovered=True)
        for m in written[:2]
    ]
    write_measurements(colours, tmp_path / "lab.csv", wide=True)
    write_measurements(colours, tmp_path / "lab-long.csv")
    assert (tmp_path / "lab.csv").read_text().startswith("sample,L* 15as-45,a* 15as-45,b* 15as-45,")
    _same_readings(
        read_measurements(tmp_path / "lab.csv"), read_measurements(tmp_path / "lab-long.csv")
    )
    with pytest.raises(MeasurementFileError, match="a row per sample is for a CSV file, not json"):
        write_measurements(written, tmp_path / "wide.json", wide=True)


def test_a_wide_csv_headed_as_a_spreadsheet_of_panels_is_read(tmp_path):
    """The headers of a row per panel, as spreadsheets and instrument exports write them: the
    quantity first or the geometry first, joined by a space, an underscore or nothing, and an
    aspecular angle alone (``L* -15°``, ``a*-15``, ``-15°_b*``) read at the 45° lamp with a
    note; L*C*h° beside them; sparkle headed with its lamp apart (``Sa 15°``). Each reading
    lands at its geometry as the same colours written a row per reading do."""
    from flakelab.core.colorimetry import Lab_to_LCh
    from flakelab.errors import Note

    lab = np.array([[38.2, -3.1, -31.0], [33.5, -2.0, -28.4], [21.7, 0.4, -17.9]])
    lch = Lab_to_LCh(lab)
    header = (
        "sample;L* -15°;a*-15;-15°_b*;45as15 L*;45as15 a*;45as15 b*;L 45;a 45;b 45;C* 45°;h° 45°"
        ";Sa 15°;Si_15;G"
    )
    row = ["blue", *(f"{v:.4f}".replace(".", ",") for v in lab.ravel())]
    row += [f"{lch[2, 1]:.4f}".replace(".", ","), f"{lch[2, 2]:.4f}".replace(".", ",")]
    row += ["2,5", "3,25", "1,5"]
    wide = _csv(tmp_path, header + "\n" + ";".join(row))
    with pytest.warns(Note, match=r"45° lamp \(-15° as 45as-15, 45 as 45as45\)"):
        (read,) = read_measurements(wide)
    assert [g.name for g in read.geometries] == ["45as-15", "45as15", "45as45"]
    assert read.spectra_recovered and read.texture == {"Sa15": 2.5, "Si15": 3.25, "G": 1.5}
    np.testing.assert_allclose(read.stored_lab, np.round(lab, 4), atol=1e-9)
    long = tmp_path / "long.csv"
    long.write_text("sample,geometry,L,a,b,Sa15,Si15,G\n" + "\n".join(
        f"blue,{g},{L:.4f},{a:.4f},{b:.4f},2.5,3.25,1.5" for g, (L, a, b) in
        zip(("45as-15", "45as15", "45as45"), lab, strict=True)
    ))  # fmt: skip
    _same_readings([read], read_measurements(long))


def _sheet_as_csv(export: Path, sheet: str, path: Path, european: bool = False) -> Path:
    """One sheet of an MA-T12 export saved as CSV, as a spreadsheet saves the sheet it shows:
    its preamble rows, dates as it shows them (``29.05.2024 19:02:51``), numbers in full; with
    ``european``, semicolons and decimal commas."""
    import openpyxl

    workbook = openpyxl.load_workbook(export, read_only=True)
    buffer = io.StringIO()
    writer = csv.writer(buffer, delimiter=";" if european else ",", lineterminator="\n")
    for row in workbook[sheet].iter_rows(values_only=True):
        cells = []
        for cell in row:
            if isinstance(cell, datetime):
                cell = cell.strftime("%d.%m.%Y %H:%M:%S")
            elif isinstance(cell, float):
                cell = repr(cell).replace(".", ",") if european else repr(cell)
            cells.append("" if cell is None else cell)
        writer.writerow(cells)
    workbook.close()
    path.write_text(buffer.getvalue(), encoding="utf-8")
    return path


def test_a_sheet_of_an_ma_t12_export_saved_as_csv_reads_as_the_export(ma_t12_files, tmp_path):
    """A sheet of each of the six real MA-T12 exports saved as CSV, as a spreadsheet saves the
    sheet it shows: ``QC JOB:``, ``STANDARD:`` (and ``ILLUMINANT/OBSERVER:``) rows, then
    ``Name, Date/Time, Geometry`` and ``L* (D65/10)`` or wavelengths. Its Spectral Data reads
    as the workbook does (spectra exactly, the instrument, the job, the date); its Color Data
    as the workbook saved with that sheet alone (the instrument's L*a*b*, spectra recovered),
    with semicolons and decimal commas too. Before, each was refused "missing column
    'sample'"."""
    for export in ma_t12_files:
        (workbook,) = read_measurements(export)
        spectral = _sheet_as_csv(export, "Spectral Data", tmp_path / "spectral.csv")
        (read,) = read_measurements(spectral)
        assert (read.sample, read.geometries) == (workbook.sample, workbook.geometries)
        np.testing.assert_array_equal(read.reflectance, workbook.reflectance)
        assert read.instrument == workbook.instrument == "X-Rite MA-T12"
        assert read.metadata == workbook.metadata and "qc_job" in read.metadata
        assert read.measured_at == workbook.measured_at.replace(microsecond=0)
        # a sheet once used further right: ",,," closes every line, the preamble's too
        spectral.write_text("".join(f"{line},,,\n" for line in spectral.read_text().splitlines()))
        (padded,) = read_measurements(spectral)
        np.testing.assert_array_equal(padded.reflectance, workbook.reflectance)
        for european in (False, True):
            colour = _sheet_as_csv(export, "Color Data", tmp_path / "colour.csv", european)
            (read,) = read_measurements(colour)
            assert read.spectra_recovered and read.geometries == workbook.geometries
            np.testing.assert_array_equal(read.stored_lab, workbook.stored_lab)
            assert read.metadata == workbook.metadata, export.name


@pytest.mark.parametrize(
    ("damage", "field", "problem"),
    [
        (lambda t: t.replace("Name,", "Sample,", 1), "row 4", "without its header row"),
        (lambda t: t.replace("Date/Time", "When", 1), "header", "expected columns Name, Date"),
        (
            lambda t: t.replace("a* (D65/10)", "a* (A/10)"),
            "header, a* (A/10)",
            "A/10, where preamble, ILLUMINANT/OBSERVER states D65/10",
        ),  # fmt: skip
        (
            lambda t: t.replace("D65/10,", "D65/99,", 1),
            "preamble, ILLUMINANT/OBSERVER",
            "expected observer",
        ),  # fmt: skip
        (lambda t: t.replace("15as-30", "15as-300", 1), "row 6, geometry", "detector above"),
        (lambda t: t.replace(",15as-30,", ",15as-30,x", 1), "row 6, L*", "expected a number"),
        # after Excel's separator line, which it hides: the row it shows
        (lambda t: "sep=,\n" + t.replace(",15as-30,", ",15as-30,x", 1), "row 6, L*", "a number"),
    ],
)
def test_a_damaged_ma_t12_sheet_saved_as_csv_is_refused_by_its_row(
    ma_t12_files, tmp_path, damage, field, problem
):
    """Refusals of a sheet saved as CSV name the spreadsheet's own row (the header is row 4,
    under three preamble rows) or the header's column; the Texture Data sheet, which holds no
    colour, is told which to save."""
    texture = _sheet_as_csv(ma_t12_files[0], "Texture Data", tmp_path / "texture.csv")
    with pytest.raises(MeasurementFileError, match="save its Spectral Data or Color Data sheet"):
        read_measurements(texture)
    colour = _sheet_as_csv(ma_t12_files[0], "Color Data", tmp_path / "colour.csv")
    colour.write_text(damage(colour.read_text()))
    with pytest.raises(MeasurementFileError) as caught:
        read_measurements(colour)
    said = str(caught.value)
    assert f"colour.csv: {field}" in said and problem in said, said


def test_a_csv_colour_headed_as_instruments_export_it_is_read(tmp_path):
    """A CSV of colour alone headed ``L*, a*, b*``, or giving L*C*h° or XYZ [Y 0–100], as
    instruments and spreadsheets export a colour, is read as that colour (colour-science's
    conversions, under the file's lab_conditions); a row giving several forms keeps its
    L*a*b* where they agree to ΔE00 0.2 and is refused naming both where they do not. Before,
    each header was taken for a wavelength ("expected a wavelength such as 'R400' or '400',
    got 'L*'"), named by its place among the wavelengths, not the file's."""
    from flakelab.core.colorimetry import (
        D65_10,
        Conditions,
        Lab_to_LCh,
        reflectance_to_Lab,
        reflectance_to_XYZ,
    )
    from flakelab.data import example_path

    car = read_measurement(example_path("target"))
    for conditions in (D65_10, Conditions.parse("A/10")):
        lab = reflectance_to_Lab(car.reflectance, car.wavelengths, conditions)
        forms = {
            "L*;a*;b*": lab,
            "L*;C*;h°": Lab_to_LCh(lab),
            "X;Y;Z": 100 * reflectance_to_XYZ(car.reflectance, car.wavelengths, conditions),
        }
        for header, values in [
            *forms.items(),
            ("L*;a*;b*;C*;h°", np.hstack([lab, Lab_to_LCh(lab)[:, 1:]])),
        ]:
            lines = [f"sample;geometry;{header};lab_conditions"]
            lines += [
                f"car;{g};"
                + ";".join(repr(float(v)).replace(".", ",") for v in row)
                + f";{conditions}"
                for g, row in zip(car.geometry_names, values, strict=True)
            ]
            path = _csv(tmp_path, "\n".join(lines))
            read = read_measurement(path)
            assert read.spectra_recovered and read.stored_lab_conditions == conditions, header
            assert delta_E_CIE2000(read.stored_lab, lab).max() < 1e-3, (header, conditions)
    wrong = np.hstack([lab, Lab_to_LCh(lab)[:, 1:]])
    wrong[2, 4] += 20  # a hue 20° off at the third geometry
    lines = ["sample,geometry,R400,R410,R420,L*,a*,b*,C*,h°"]
    lines += [
        f"car,{g},0.1,0.1,0.1," + ",".join(map(str, row))
        for g, row in zip(car.geometry_names, wrong, strict=True)
    ]
    with pytest.raises(
        MeasurementFileError,
        match=r"row 4: its L\*, C\*, h° read as L\*a\*b\* \(\S+, \S+, \S+\) lies ΔE00",
    ):
        read_measurement(_csv(tmp_path, "\n".join(lines)))


_BAD_TOKENS = ("", "abc", "nan", "inf", "-1", "1e400", "0", "\x00", "😀", '"', "<", "&", "[]", "{}")


def _mutated(text: str, rng: random.Random) -> str:
    """``text`` with one to three random edits: a number or a quoted string replaced by a bad
    token (a string's quotes kept or not), a line dropped, doubled or swapped with another,
    or the text cut short."""
    for _ in range(rng.randint(1, 3)):
        lines = text.splitlines(keepends=True)
        edit = rng.randrange(5)
        tokens = list(re.finditer(r'-?\d+(\.\d+)?(e-?\d+)?|"[^"\n]*"', text))
        if edit == 0 and tokens:  # a quoted string keeps its quotes half the time
            m, bad = rng.choice(tokens), rng.choice(_BAD_TOKENS)
            quoted = m.group().startswith('"') and rng.random() < 0.5
            text = text[: m.start()] + (f'"{bad}"' if quoted else bad) + text[m.end() :]
        elif edit == 1 and lines:
            del lines[rng.randrange(len(lines))]
            text = "".join(lines)
        elif edit == 2 and lines:
            i = rng.randrange(len(lines))
            text = "".join(lines[: i + 1] + lines[i:])
        elif edit == 3 and len(lines) > 1:
            i, j = rng.sample(range(len(lines)), 2)
            lines[i], lines[j] = lines[j], lines[i]
            text = "".join(lines)
        else:
            text = text[: rng.randrange(len(text) + 1)]
    return text


def _valid_file(kind: str, measurement, folder: Path) -> tuple[Path, object]:
    """A valid file of ``kind`` in ``folder`` and the reader that reads it."""
    from flakelab.core.tolerance import TOLERANCE_PRESETS
    from flakelab.io import read_library, read_tolerance
    from flakelab.io.library_file import demo_library_path
    from flakelab.io.lots_file import read_lots, write_lots
    from flakelab.library.lots import TonerLot, TonerLots

    path = folder / f"valid.{kind if kind in ('cxf', 'csv') else 'json'}"
    if kind in ("cxf", "csv", "json"):
        write_measurements([measurement], path)
        return path, read_measurements
    if kind == "recipe":
        write_recipe({"Al medium": 194.0, "Phthalo blue GS": 16.6, "Carbon black": 3.6}, path)
        return path, read_recipe
    if kind == "library":
        shutil.copyfile(demo_library_path(), path)
        return path, read_library
    if kind == "tolerance":
        path.write_text(json.dumps(TOLERANCE_PRESETS["refinish"].to_dict()))
        return path, read_tolerance
    write_lots(TonerLots.of([TonerLot("Carbon black", 0.97, 0.01, "K-9")]), path)
    return path, read_lots


@pytest.mark.parametrize("kind", ["cxf", "json", "csv", "recipe", "library", "tolerance", "lots"])
def test_a_mutated_file_is_read_or_refused_by_name(kind, rich_measurement, tmp_path):
    """Fuzzing, seeded: 60 random mutations of a valid file of each kind each either read
    or raise a FlakelabError that names the file, never another exception (the CLI would
    show one as an internal error). Fuzzing of this kind, longer, found the CxF declaration
    of an unknown encoding above."""
    valid, read = _valid_file(kind, rich_measurement, tmp_path)
    text, rng = valid.read_text(encoding="utf-8"), random.Random(f"{kind} 118")
    read(valid)  # the unmutated file reads
    refused = 0
    for k in range(60):
        path = tmp_path / f"mutated-{k}{valid.suffix}"
        path.write_text(_mutated(text, rng), encoding="utf-8")
        try:
            read(path)
        except FlakelabError as error:
            assert path.name in str(error), (path.read_text(), str(error))
            refused += 1
    assert refused >= 40, refused  # most mutations break the file: the readers are put to work
