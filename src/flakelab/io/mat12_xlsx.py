"""X-Rite MA-T12 QC export (.xlsx), as the instrument software writes it.

Sheets: ``Color Data`` (L*a*b* per geometry), ``Spectral Data`` (reflectance factor per
geometry, 400–700 nm), ``Texture Data``, ``Texture Images``. Each data sheet opens with
``QC JOB:``, ``STANDARD:`` (and ``ILLUMINANT/OBSERVER:``) rows, then a header row starting
with ``Name``. The shared exports carry no texture values, so the layout of texture columns
in a real export is not known here; flakelab reads and writes texture as one row per sample
with columns named as :data:`~flakelab.core.measurement.TEXTURE_READINGS`. An optional
``INSTRUMENT:`` preamble row (written by flakelab for other instruments) names the instrument.

``Texture Images`` holds the instrument camera's pictures of the measured spot as drawings:
the sample's name heads a column (row 1), each geometry names a row (column A: ``15as-45`` …
``15as80`` under the 15° lamp, ``15d`` under diffuse light), and each picture is anchored in
its sample's column and its geometry's row (480 × 360 pixels, 8-bit sRGB, in the shared
exports). Those hold one sample each, so a job of several is read as columns side by side,
each headed by its sample: a guess at a layout not seen here. The labels place the camera at
the instrument's 15° detector, six lamps lighting it in turn (``MA-T12_geometry_scheme.png``
of the shared data): by reciprocity, the 15° lamp of the geometries' names.
:func:`read_mat12_images` reads them; flakelab does not write them.
"""

from __future__ import annotations

import gc
import re
import sys
import warnings
import zipfile
from datetime import datetime
from os import PathLike
from pathlib import Path

import numpy as np
import openpyxl
from numpy.typing import NDArray

from flakelab.core.colorimetry import D65_10
from flakelab.core.measurement import TEXTURE_READINGS, Measurement
from flakelab.core.spectra import WAVELENGTHS
from flakelab.errors import MeasurementFileError, Note
from flakelab.io.records import (
    Reading,
    assemble,
    parse_conditions,
    parse_geometry_name,
    parse_lab,
    parse_spectrum,
    parse_texture,
    parse_wavelength_header,
    recovered_readings,
    write_atomically,
)

__all__ = [
    "read_mat12_xlsx",
    "read_mat12_images",
    "camera_pictures_in",
    "is_diffuse_picture",
    "write_mat12_xlsx",
    "INSTRUMENT",
    "PREAMBLE_KEYS",
    "ROW_KEYS",
    "instrument_of_sheet",
    "job_of",
    "split_sheet",
]

INSTRUMENT = "X-Rite MA-T12"
_SPECTRAL, _COLOR, _TEXTURE, _IMAGES = (
    "Spectral Data",
    "Color Data",
    "Texture Data",
    "Texture Images",
)
_DIFFUSE_IMAGE = re.compile(r"\d+d")
"""A camera picture's row label under diffuse light (``15d``), where the others name a
geometry."""
ROW_KEYS = ("Name", "Date/Time", "Geometry")
"""The columns that open each data sheet's rows."""
PREAMBLE_KEYS = ("QC JOB", "STANDARD", "ILLUMINANT/OBSERVER", "INSTRUMENT")
"""The rows (``QC JOB:`` …) a data sheet may open with, before its header."""
_DAMAGED_WORKBOOK = (zipfile.BadZipFile, OSError, ValueError, SyntaxError, TypeError, LookupError)
"""What openpyxl raises for a workbook whose parts are damaged: a zip it cannot open, a
part's XML that does not parse (xml's ``ParseError`` is a ``SyntaxError``) or names an
unknown encoding (``LookupError``), a value of the wrong type for its field (``TypeError``),
a shared string's index past the table's end (``IndexError``, a ``LookupError``)."""
_DROPPED_PICTURE = re.compile(r"image (\S+) will be removed")
"""openpyxl's warning for a picture it could not open (``openpyxl.reader.drawings``)."""


def split_sheet(rows: list[tuple]) -> tuple[dict[str, str], int]:
    """Preamble key/values (``QC JOB`` …) and the index of the header row (first cell 'Name')."""
    preamble: dict[str, str] = {}
    for i, row in enumerate(rows):
        first = str(row[0]).strip() if row and row[0] is not None else ""
        if first == "Name":
            return preamble, i
        if first.endswith(":"):
            preamble[first[:-1]] = "" if len(row) < 2 or row[1] is None else str(row[1])
    return preamble, -1


def _date(value: object) -> datetime | None:
    if isinstance(value, datetime):
        return value
    if isinstance(value, str) and value.strip():
        try:
            return datetime.fromisoformat(value.strip())
        except ValueError:
            return None
    return None


def _data_rows(rows: list[tuple], header: int) -> list[tuple[int, tuple]]:
    return [
        (i + 1, row)
        for i, row in enumerate(rows[header + 1 :], start=header + 1)
        if row and any(v not in (None, "") for v in row)
    ]


def _sheets(path: str | PathLike, handle) -> dict[str, list[tuple]]:
    """Every sheet's rows of the workbook open in ``handle``. Read from a handle, not a path:
    openpyxl refuses a path that does not end .xlsx (an internal error for a workbook named
    otherwise, or read from a pipe), and the file was judged a workbook by its content."""
    try:
        workbook = openpyxl.load_workbook(handle, read_only=True, data_only=True)
    except _DAMAGED_WORKBOOK as error:
        raise MeasurementFileError(path, f"not a readable Excel workbook ({error})") from None
    try:
        with warnings.catch_warnings():
            # a Date/Time cell whose serial is no date: openpyxl warns and gives an error
            # value, which reads as no date, as any other Date/Time that is not one does
            warnings.filterwarnings("ignore", "Cell .* is marked as a date", UserWarning)
            return {ws.title: [tuple(r) for r in ws.iter_rows(values_only=True)] for ws in workbook}
    except _DAMAGED_WORKBOOK as error:
        raise MeasurementFileError(path, f"truncated or corrupt workbook ({error})") from None
    finally:
        workbook.close()


def read_mat12_xlsx(path: str | PathLike) -> list[Measurement]:
    """Read every sample of an MA-T12 QC export.

    Raises
    ------
    MeasurementFileError
        For a truncated or corrupt workbook, a missing sheet or header, a wavelength header that
        is not a regular grid, a non-numeric or NaN value, or an unknown geometry name.
    """
    try:
        with open(path, "rb") as handle:
            sheets = _sheets(path, handle)
    except OSError as error:
        raise MeasurementFileError(path, f"cannot be read ({error.strerror})") from None
    color_preamble = split_sheet(sheets[_COLOR])[0] if _COLOR in sheets else {}
    lab_conditions = D65_10
    if color_preamble.get("ILLUMINANT/OBSERVER"):
        lab_conditions = parse_conditions(
            path, color_preamble["ILLUMINANT/OBSERVER"], f"{_COLOR}, ILLUMINANT/OBSERVER"
        )
    if _SPECTRAL not in sheets and (colour := _color_rows(path, sheets.get(_COLOR))):
        # saved with its Color Data alone: each reading's spectrum recovered from its colour
        readings = recovered_readings(path, colour, lab_conditions)
        return _assembled(path, sheets, readings, WAVELENGTHS, color_preamble, lab_conditions,
                          recovered=True)  # fmt: skip
    if _SPECTRAL not in sheets:
        raise MeasurementFileError(
            path, f"no sheet {_SPECTRAL!r} (sheets: {', '.join(sheets) or 'none'})"
        )
    spectral = sheets[_SPECTRAL]
    preamble, header = split_sheet(spectral)
    if header < 0:
        raise MeasurementFileError(path, "no header row starting with 'Name'", field=_SPECTRAL)
    labels = list(spectral[header])
    while labels and labels[-1] in (None, ""):
        labels.pop()
    if labels[:3] != list(ROW_KEYS):
        raise MeasurementFileError(
            path,
            f"expected columns Name, Date/Time, Geometry, got {labels[:3]}",
            field=f"{_SPECTRAL}, row {header + 1}",
        )
    wavelengths = parse_wavelength_header(
        path,
        labels[3:],
        f"{_SPECTRAL}, row {header + 1}",
        [f"column {openpyxl.utils.get_column_letter(i)}" for i in range(4, len(labels) + 1)],
    )
    n = wavelengths.size
    labs = {(r.sample, r.geometry.name): r.lab for r in _color_rows(path, sheets.get(_COLOR))}

    readings = []
    for number, row in _data_rows(spectral, header):
        where = f"{_SPECTRAL}, row {number}"
        cells = list(row) + [None] * (3 + n - len(row))
        sample = str(cells[0]).strip() if cells[0] is not None else ""
        if not sample:
            raise MeasurementFileError(path, "empty sample name", field=f"{where}, Name")
        geometry = parse_geometry_name(path, cells[2], f"{where}, Geometry")
        readings.append(
            Reading(
                where=where,
                sample=sample,
                geometry=geometry,
                reflectance=parse_spectrum(path, cells[3 : 3 + n], wavelengths, where),
                lab=labs.get((sample, geometry.name)) if labs else None,
                measured_at=_date(cells[1]),
            )
        )
    return _assembled(path, sheets, readings, wavelengths, preamble, lab_conditions)


def job_of(preamble: dict[str, str]) -> dict[str, str]:
    """What a sheet's ``preamble`` says of the job, as each measurement's metadata keeps it."""
    job = (("qc_job", preamble.get("QC JOB")), ("standard", preamble.get("STANDARD")))
    return {k: v for k, v in job if v}


def instrument_of_sheet(preamble: dict[str, str]) -> str:
    """The instrument a sheet's ``preamble`` names (written by flakelab for others), else the
    MA-T12 whose software wrote it."""
    return preamble.get("INSTRUMENT") or INSTRUMENT


def _assembled(path, sheets, readings, wavelengths, preamble, lab_conditions, recovered=False):
    """The export's measurements of ``readings``, with the texture sheet's readings and what
    the sheet's ``preamble`` says of the job."""
    return assemble(
        path,
        readings,
        wavelengths,
        instrument=instrument_of_sheet(preamble),
        lab_conditions=lab_conditions,
        texture=_read_texture_sheet(path, sheets.get(_TEXTURE)),
        metadata={r.sample: job_of(preamble) for r in readings},
        spectra_recovered=recovered,
    )


def read_mat12_images(path: str | PathLike) -> dict[str, dict[str, NDArray[np.uint8]]]:
    """The camera pictures of an MA-T12 export: sample → row label (``15as-45`` …, ``15d``) →
    ``[rows, cols, 3]`` 8-bit sRGB, in the sheet's row order; empty without the sheet.

    Raises
    ------
    MeasurementFileError
        For a workbook that cannot be read, a picture that cannot be decoded, one anchored in
        a row without a geometry or a column without a sample, a row label that names no
        geometry, or two pictures in one cell.
    """
    try:
        with open(path, "rb") as handle, warnings.catch_warnings(record=True) as dropped:
            warnings.simplefilter("always")
            # openpyxl drops a picture it cannot decode with a warning (reader.drawings)
            sheet = _images_sheet(path, handle)
    except OSError as error:
        raise MeasurementFileError(path, f"cannot be read ({error.strerror})") from None
    for warning in dropped:
        if found := _DROPPED_PICTURE.search(str(warning.message)):
            raise MeasurementFileError(path, f"picture {found[1]} cannot be decoded", field=_IMAGES)
    if sheet is None:
        return {}
    pictures: dict[str, dict[str, NDArray[np.uint8]]] = {}
    for picture, (row, column) in sorted(sheet["pictures"], key=lambda p: p[1]):
        where = f"{_IMAGES}, {openpyxl.utils.get_column_letter(column)}{row}"
        sample = sheet["samples"].get(column)
        if not sample:
            raise MeasurementFileError(path, "a picture in a column no sample heads", field=where)
        label = _picture_label(path, sheet["labels"].get(row), f"{_IMAGES}, A{row}")
        if label in pictures.setdefault(sample, {}):
            raise MeasurementFileError(path, f"a second picture of {label}", field=where)
        pictures[sample][label] = _decode_picture(path, picture, where)
    return pictures


def camera_pictures_in(path: str | PathLike) -> int:
    """How many pictures a workbook with a ``Texture Images`` sheet holds (0 for any other
    file), counted from its parts without decoding them: what a conversion leaves behind."""
    try:
        with zipfile.ZipFile(path) as archive:
            names = archive.namelist()
            sheets = archive.read("xl/workbook.xml") if "xl/workbook.xml" in names else b""
    except (zipfile.BadZipFile, OSError, ValueError):
        return 0
    if f'name="{_IMAGES}"'.encode() not in sheets:
        return 0
    return sum(name.startswith("xl/media/") for name in names)


def _images_sheet(path: str | PathLike, handle) -> dict | None:
    """The ``Texture Images`` sheet's pictures with their (row, column), 1-based, its row
    labels (column A) and its sample names (row 1); None without the sheet. The whole
    workbook is loaded (not read-only), as openpyxl reads drawings only then."""
    try:
        workbook = openpyxl.load_workbook(handle, data_only=True)
    except _DAMAGED_WORKBOOK as error:
        raise MeasurementFileError(path, f"not a readable Excel workbook ({error})") from None
    try:
        if _IMAGES not in workbook.sheetnames:
            return None
        sheet = workbook[_IMAGES]
        cells = {(c.row, c.column): c.value for row in sheet.iter_rows() for c in row}
        text = {k: str(v).strip() for k, v in cells.items() if v not in (None, "")}
        return {
            # Worksheet._images: openpyxl's only handle on the pictures it read (no public one)
            "pictures": [
                (p, (p.anchor._from.row + 1, p.anchor._from.col + 1)) for p in sheet._images
            ],
            "labels": {row: v for (row, column), v in text.items() if column == 1},
            "samples": {column: v for (row, column), v in text.items() if row == 1},
        }
    finally:
        workbook.close()


def is_diffuse_picture(label: str) -> bool:
    """Whether a camera picture's row label names diffuse light (``15d``), not a geometry.

    >>> is_diffuse_picture("15d"), is_diffuse_picture("15as15")
    (True, False)
    """
    return _DIFFUSE_IMAGE.fullmatch(label) is not None


def _picture_label(path: str | PathLike, label: str | None, where: str) -> str:
    if label is None:
        raise MeasurementFileError(path, "a picture in a row that names no geometry", field=where)
    if is_diffuse_picture(label):
        return label
    return parse_geometry_name(path, label, where).name


def _decode_picture(path: str | PathLike, picture, where: str) -> NDArray[np.uint8]:
    from PIL import Image

    try:
        with Image.open(picture.ref) as image:
            return np.asarray(image.convert("RGB"))
    except (OSError, ValueError) as error:
        raise MeasurementFileError(
            path, f"picture cannot be decoded ({error})", field=where
        ) from None


def _color_rows(path: str | PathLike, rows: list[tuple] | None) -> list[Reading]:
    """The Color Data sheet's readings: sample, geometry, L*a*b* and date, no spectrum."""
    if not rows:
        return []
    _, header = split_sheet(rows)
    if header < 0:
        return []
    readings = []
    for number, row in _data_rows(rows, header):
        where = f"{_COLOR}, row {number}"
        if len(row) < 6:
            raise MeasurementFileError(path, f"expected 6 columns, got {len(row)}", field=where)
        sample = str(row[0]).strip() if row[0] is not None else ""
        if not sample:
            raise MeasurementFileError(path, "empty sample name", field=f"{where}, Name")
        geometry = parse_geometry_name(path, row[2], f"{where}, Geometry")
        lab = parse_lab(path, row[3:6], [f"{where}, {k}" for k in "Lab"])
        readings.append(Reading(where, sample, geometry, None, lab, _date(row[1])))
    return readings


def _read_texture_sheet(path: str | PathLike, rows: list[tuple] | None) -> dict:
    if not rows:
        return {}
    _, header = split_sheet(rows)
    if header < 0:
        return {}
    labels = [str(v).strip() if v is not None else "" for v in rows[header]]
    columns = {i: k for i, k in enumerate(labels) if k in TEXTURE_READINGS}
    _note_unread_texture(path, labels, _data_rows(rows, header))
    texture: dict[str, dict[str, float]] = {}
    for number, row in _data_rows(rows, header):
        where = f"{_TEXTURE}, row {number}"
        values = {
            k: parse_texture(path, row[i], f"{where}, {k}")
            for i, k in columns.items()
            if i < len(row) and row[i] not in (None, "")
        }
        if values:
            texture.setdefault(str(row[0]).strip(), {}).update(values)
    return texture


def _note_unread_texture(path: str | PathLike, labels: list[str], rows: list[tuple[int, tuple]]):
    """A :class:`~flakelab.errors.Note` naming the ``Texture Data`` columns that hold values
    flakelab does not read: the shared exports' texture sheets are empty, so the instrument's
    own column names are not known here, and its readings would otherwise vanish unsaid."""
    unread = [
        label or f"column {openpyxl.utils.get_column_letter(i + 1)}"
        for i, label in enumerate(labels)
        if i >= len(ROW_KEYS) and label not in TEXTURE_READINGS
        and any(i < len(row) and row[i] not in (None, "") for _, row in rows)
    ]  # fmt: skip
    if unread:
        warnings.warn(
            f"{path}: {_TEXTURE}: {', '.join(map(repr, unread))} not read (flakelab reads "
            f"texture as {', '.join(TEXTURE_READINGS)}); the rest of the file is read",
            Note,
            stacklevel=4,
        )


def write_mat12_xlsx(measurements: list[Measurement], path: str | PathLike) -> None:
    """Write measurements in the MA-T12 QC export layout (all samples in one workbook)."""
    wavelengths = measurements[0].wavelengths
    if any(not np.array_equal(m.wavelengths, wavelengths) for m in measurements):
        raise ValueError("expected all measurements on one wavelength grid for one workbook")
    workbook = openpyxl.Workbook()
    standard = measurements[0].metadata.get("standard", measurements[0].sample)
    job = measurements[0].metadata.get("qc_job", "flakelab export")
    conditions = measurements[0].stored_lab_conditions

    color = workbook.active
    color.title = _COLOR
    color.append(["QC JOB:", job])
    color.append(["STANDARD:", standard])
    color.append(["ILLUMINANT/OBSERVER:", str(conditions)])
    color.append([*ROW_KEYS, *(f"{k}* ({conditions})" for k in "Lab")])
    texture = workbook.create_sheet(_TEXTURE)
    texture.append(["QC JOB:", job])
    texture.append(["STANDARD:", standard])
    texture.append([*ROW_KEYS, *TEXTURE_READINGS])
    spectral = workbook.create_sheet(_SPECTRAL)
    spectral.append(["QC JOB:", job])
    spectral.append(["STANDARD:", standard])
    if measurements[0].instrument and measurements[0].instrument != INSTRUMENT:
        spectral.append(["INSTRUMENT:", measurements[0].instrument])
    spectral.append([*ROW_KEYS, *(f"{w:g}" for w in wavelengths)])
    for m in measurements:
        lab = m.stored_lab if m.stored_lab is not None else m.lab(conditions)
        when = _cell_time(m.measured_at)
        for i, g in enumerate(m.geometries):
            color.append([m.sample, when, g.name, *map(float, lab[i])])
            spectral.append([m.sample, when, g.name, *map(float, m.reflectance[i])])
        if m.texture:
            texture.append([m.sample, when, None, *(m.texture.get(k) for k in TEXTURE_READINGS)])
    write_atomically(path, lambda temporary: _save(workbook, Path(temporary)))


def _cell_time(time: datetime | None) -> datetime | None:
    """A measurement's time as the instrument's export holds it: local time without a zone
    (Excel keeps none; read back, a time without one is this machine's local time)."""
    if time is None or time.tzinfo is None:
        return time
    return time.astimezone().replace(tzinfo=None)


def _save(workbook: openpyxl.Workbook, path: Path) -> None:
    """``workbook.save``. Where the disk refuses it, the sheet writers it leaves half done are
    closed here, quietly: collected later, each tries to finish its XML in the file that
    failed, and Python printed "Exception ignored in: <generator …>" and a traceback after
    flakelab's one-line error."""
    try:
        workbook.save(path)
        return
    except OSError as error:
        failure = error
    quiet, sys.unraisablehook = sys.unraisablehook, lambda _unraisable: None
    try:
        failure.__traceback__ = failure.__context__ = None  # the frames holding the writers
        gc.collect()
    finally:
        sys.unraisablehook = quiet
    raise failure
