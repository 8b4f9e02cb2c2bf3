"""Measurement files: MA-T12 xlsx, CxF3, CSV and JSON behind one interface.

``read_measurements(path)`` detects the format from the file's content (not its name);
``write_measurements(measurements, path)`` picks it from the extension. Every problem is a
:class:`~flakelab.errors.MeasurementFileError` naming the file, the field and the problem.
"""

from __future__ import annotations

import codecs
import os
import sys
import tempfile
import warnings
import zipfile
from collections.abc import Callable
from dataclasses import replace
from os import PathLike
from pathlib import Path

import numpy as np

from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E_CIE2000
from flakelab.core.measurement import Measurement
from flakelab.errors import MeasurementFileError, Note
from flakelab.io.csv_table import read_csv, write_csv
from flakelab.io.cxf import read_cxf, write_cxf
from flakelab.io.json_document import read_json, write_json
from flakelab.io.library_file import read_library, write_library
from flakelab.io.mat12_xlsx import read_mat12_xlsx, write_mat12_xlsx
from flakelab.io.recipe_file import read_recipe, write_recipe
from flakelab.io.records import (
    NOT_UTF8,
    STANDARD_STREAM,
    UTF16_BOMS,
    csv_separator,
    is_no_regular_file,
    kind_of_binary,
    nul_problem,
    standard_input,
    standard_of,
    text_encoding,
    utf8_of_utf16,
    utf16_without_mark,
)
from flakelab.io.tolerance_file import read_tolerance

__all__ = [
    "FORMATS",
    "STANDARD_STREAM",
    "detect_format",
    "read_measurements",
    "read_measurement",
    "pick_sample",
    "standard_of",
    "write_measurements",
    "read_tolerance",
    "read_recipe",
    "write_recipe",
    "read_library",
    "write_library",
]

Reader = Callable[[str | PathLike], list[Measurement]]
Writer = Callable[[list[Measurement], str | PathLike], None]

FORMATS: dict[str, tuple[Reader, Writer, tuple[str, ...]]] = {
    "mat12-xlsx": (read_mat12_xlsx, write_mat12_xlsx, (".xlsx",)),
    "cxf": (read_cxf, write_cxf, (".cxf", ".xml")),
    "csv": (read_csv, write_csv, (".csv", ".txt", ".tsv")),
    "json": (read_json, write_json, (".json",)),
}
"""Format name → (reader, writer, file extensions written)."""

COLOUR_ALONE_FORMATS = ("csv", "cxf")
"""The formats that hold L*a*b* without spectra, in which measurements whose spectra were
recovered from it are written (as they were read)."""


def _utf8_lines(head: bytes) -> list[str] | None:
    """Lines of a file's head read as UTF-8, or None where it is not UTF-8."""
    try:  # the head may end inside a character: not an error of the file
        return codecs.getincrementaldecoder("utf-8")().decode(head).splitlines()
    except UnicodeDecodeError:
        return None


def detect_format(path: str | PathLike) -> str:
    """Name of the measurement format of a file, judged by its content."""
    try:
        with open(path, "rb") as handle:  # the head alone, not the whole file
            head = handle.read(4096)
    except FileNotFoundError:
        raise MeasurementFileError(path, "no such file") from None
    except IsADirectoryError:
        raise MeasurementFileError(path, "a folder, not a measurement file") from None
    except OSError as error:
        raise MeasurementFileError(path, f"cannot be read ({error.strerror})") from None
    if not head.strip():
        raise MeasurementFileError(path, "empty file")
    if head.startswith(b"PK\x03\x04"):
        try:
            with zipfile.ZipFile(path) as archive:
                names = set(archive.namelist())
        except zipfile.BadZipFile:
            raise MeasurementFileError(path, "truncated or corrupt ZIP/xlsx archive") from None
        if "xl/workbook.xml" not in names:
            raise MeasurementFileError(path, "a ZIP archive, but not an Excel workbook")
        return "mat12-xlsx"
    if kind := kind_of_binary(head):
        raise MeasurementFileError(path, f"not a measurement file: this is {kind}")
    if head.startswith(UTF16_BOMS):  # a spreadsheet's "Unicode Text": judged as its UTF-8
        try:
            head = codecs.getincrementaldecoder("utf-16")().decode(head).encode("utf-8")
        except UnicodeDecodeError as error:
            raise MeasurementFileError(path, f"not UTF-16 text ({error.reason})") from None
    text = head.lstrip(b"\xef\xbb\xbf \t\r\n")
    if not text:  # a byte-order mark alone
        raise MeasurementFileError(path, "empty file")
    lines = _utf8_lines(text)
    if utf16_without_mark(text) or (lines is not None and b"\x00" in text):
        raise MeasurementFileError(path, f"not a measurement file: {nul_problem(text)}")
    if text.startswith(b"<"):
        if b"colorexchangeformat.com/CxF3" in head or b"<CxF" in head or b":CxF" in head:
            return "cxf"
        raise MeasurementFileError(path, "an XML file, but not CxF3 (no CxF3 namespace)")
    if text.startswith((b"{", b"[")):
        return "json"
    if lines is None:
        header = head.split(b"\n")[0].decode("latin-1")  # any byte, to look for separators
        binary = b"\x00" in head or csv_separator(header) is None
        raise MeasurementFileError(
            path, "not a measurement file: binary content" if binary else NOT_UTF8
        )
    if not lines:  # a character's first bytes alone
        raise MeasurementFileError(path, "not a measurement file: binary content")
    first_line = lines[0].lower()
    if (
        "geometry" in first_line
        or first_line.startswith("#")
        or csv_separator(first_line) is not None
    ):
        return "csv"
    raise MeasurementFileError(
        path,
        "not a measurement file: expected MA-T12 xlsx, CxF3, flakelab JSON or a CSV with "
        "a 'sample' column and a 'geometry' column, or columns at a geometry ('L* 45as15')",
    )


def read_measurements(path: str | PathLike) -> list[Measurement]:
    """All measurements in a file, whatever its supported format; spectra an instrument's
    export wrote in percent read as reflectance factors (:func:`percent_evidence`); a note
    where one reads brighter than a white (:func:`brighter_than_white`)."""
    if os.fspath(path) == STANDARD_STREAM:
        path, read = "stdin", _read_through_a_copy(STANDARD_STREAM)
    elif is_no_regular_file(path) or _is_utf16(path):
        read = _read_through_a_copy(path)
    else:
        read = _read_as_written(path)
    measurements = _as_factors(path, read)
    _note_brighter_than_white(path, measurements)
    return measurements


def _read_as_written(path: str | PathLike) -> list[Measurement]:
    return FORMATS[detect_format(path)][0](path)


PERCENT_SIGN = 2.0
"""A reflectance factor no paint reaches 75° or more from the specular direction (a white
reads 0.9 there, a fluorescent at most about 1.5): a reading above it there is in percent."""

WHITE_LIMIT = 1.05
"""A reflectance factor 75° or more from the specular direction above which a reading is
brighter than the perfect white diffuser (1 by definition) by more than a calibration errs:
a fluorescent paint, or an instrument calibrated against the wrong white. The brightest of
the 230 real MA-T12 readings in ``shared/data`` reads 0.89 there."""


def _brightest_far_from_specular(measurement: Measurement) -> tuple[int, float] | None:
    """The geometry 75° or more from specular that reads brightest, and its largest
    reflectance factor; None where no geometry lies so far."""
    far = np.flatnonzero([abs(g.aspecular) >= 75 for g in measurement.geometries])
    if not far.size:
        return None
    peaks = measurement.reflectance[far].max(axis=1)
    return int(far[np.argmax(peaks)]), float(peaks.max())


def percent_evidence(measurement: Measurement) -> str | None:
    """Why ``measurement``'s spectra are in percent, not reflectance factors, as many
    instruments' exports write them; None where nothing says so. Its stored L*a*b*, where it
    has one, is that of its spectra divided by 100 and not that of its spectra; without one,
    a geometry 75° or more from specular reads above :data:`PERCENT_SIGN`. A very dark paint
    in percent with no L*a*b* beside it is not told from a light one in factors."""
    R = measurement.reflectance
    if measurement.stored_lab is not None:
        conditions, stored = measurement.stored_lab_conditions, measurement.stored_lab
        as_read = delta_E_CIE2000(reflectance_to_Lab(R, measurement.wavelengths, conditions),
                                  stored)  # fmt: skip
        as_percent = delta_E_CIE2000(
            reflectance_to_Lab(R / 100, measurement.wavelengths, conditions), stored
        )
        if np.median(as_percent) < 1.0 < np.median(as_read) / 10:
            return "its L*a*b* is that of its spectra divided by 100"
        return None
    brightest = _brightest_far_from_specular(measurement)
    if brightest is not None and brightest[1] > PERCENT_SIGN:
        i, peak = brightest
        return (
            f"{measurement.geometries[i].name} reads up to {peak:.3g}, a reflectance "
            "factor no paint reaches so far from specular"
        )
    return None


def brighter_than_white(measurement: Measurement) -> str | None:
    """Where ``measurement`` reads brighter than a white far from specular (above
    :data:`WHITE_LIMIT`), what a note says of it; None otherwise. Read as given: a
    fluorescent paint does so."""
    brightest = _brightest_far_from_specular(measurement)
    if brightest is None or brightest[1] <= WHITE_LIMIT:
        return None
    i, peak = brightest
    return (
        f"{measurement.geometries[i].name} reads up to {peak:.3g}, brighter than a perfect "
        "white so far from specular: a fluorescent paint, or an instrument calibrated against "
        "the wrong white; read as given"
    )


def _note_brighter_than_white(path: str | PathLike, measurements: list[Measurement]) -> None:
    """A note naming the file and the first of its ``measurements`` brighter than a white."""
    found = ((m.sample, brighter_than_white(m)) for m in measurements)
    shown = next(((sample, why) for sample, why in found if why), None)
    if shown is not None:
        warnings.warn(f"{path}: sample {shown[0]!r}: {shown[1]}", Note, stacklevel=3)


def _as_factors(path: str | PathLike, measurements: list[Measurement]) -> list[Measurement]:
    """``measurements`` with spectra in percent divided by 100, and a note naming the file."""
    found = [(m, percent_evidence(m)) for m in measurements]
    shown = next(((m.sample, why) for m, why in found if why), None)
    if shown is None:
        return measurements
    warnings.warn(f"{path}: reflectance read as percent and divided by 100 (sample "
                  f"{shown[0]!r}: {shown[1]})", Note, stacklevel=3)  # fmt: skip
    return [replace(m, reflectance=m.reflectance / 100) if why else m for m, why in found]


def _is_utf16(path: str | PathLike) -> bool:
    try:
        return text_encoding(path) == "utf-16"
    except OSError:  # detect_format names it
        return False


def _read_through_a_copy(source: str | PathLike) -> list[Measurement]:
    """The measurements of a pipe (``/dev/stdin``, ``<(…)``) or of UTF-16 text (a
    spreadsheet's "Unicode Text"), read once into a temporary UTF-8 file and read from there.
    A pipe's format is judged from its head and the reader reads it from the start, but its
    head, once read, is gone (the reader met the rest alone and called it, say, a CSV file
    missing its 'sample' column); UTF-16 was called "binary content". Errors name the
    source, standard input (:data:`STANDARD_STREAM`) as ``stdin``."""
    piped = os.fspath(source) == STANDARD_STREAM
    named = "stdin" if piped else source
    with tempfile.TemporaryDirectory(prefix="flakelab-") as folder:
        copy = Path(folder) / (Path(named).name or "input")
        try:
            data = standard_input() if piped else Path(source).read_bytes()
            if data.startswith(UTF16_BOMS):
                data = utf8_of_utf16(data)
            copy.write_bytes(data)
        except OSError as error:
            raise MeasurementFileError(named, f"cannot be read ({error.strerror})") from None
        except UnicodeDecodeError as error:
            raise MeasurementFileError(named, f"not UTF-16 text ({error.reason})") from None
        try:
            return _read_as_written(copy)
        except MeasurementFileError as error:
            raise MeasurementFileError(named, error.problem, field=error.field) from None


def read_measurement(path: str | PathLike, sample: str | None = None) -> Measurement:
    """One measurement: the sample named, else the standard the file names, else its first
    (:func:`pick_sample`)."""
    return pick_sample(read_measurements(path), sample, path)


def pick_sample(
    measurements: list[Measurement], sample: str | None, path: str | PathLike
) -> Measurement:
    """The sample named among a file's ``measurements``; else the standard it names
    (:func:`standard_of`), else its first."""
    if sample is None:
        return standard_of(measurements) or measurements[0]
    for m in measurements:
        if m.sample == sample:
            return m
    names = ", ".join(m.sample for m in measurements[:10])
    raise MeasurementFileError(path, f"no sample {sample!r} (samples: {names})")


def format_for_path(path: str | PathLike) -> str:
    if os.fspath(path) == STANDARD_STREAM:
        raise MeasurementFileError(
            "stdout", f"no extension to take the format from: name one ({', '.join(FORMATS)})"
        )
    if name := _format_said(path):
        return name
    suffix = Path(path).suffix.lower()
    known = ", ".join(s for _, _, ss in FORMATS.values() for s in ss)
    raise MeasurementFileError(path, f"unknown output extension {suffix!r} (known: {known})")


def _format_said(path: str | PathLike) -> str | None:
    """The format that ``path``'s extension names, if any."""
    suffix = Path(path).suffix.lower()
    return next((name for name, (_, _, ss) in FORMATS.items() if suffix in ss), None)


def write_measurements(
    measurements: list[Measurement],
    path: str | PathLike,
    format: str | None = None,
    *,
    decimal_comma: bool = False,
    wide: bool = False,
) -> None:
    """Write measurements; the format comes from ``format`` or the extension of ``path``.
    ``decimal_comma``: a CSV file as a spreadsheet in most of Europe opens it; ``wide``: a CSV
    file of a row per sample."""
    if not measurements:
        raise ValueError("expected at least one measurement to write, got none")
    name = format or format_for_path(path)
    if name not in FORMATS:
        raise ValueError(f"expected a format among {', '.join(FORMATS)}, got {name!r}")
    to_stdout = os.fspath(path) == STANDARD_STREAM
    if not to_stdout and format and (said := _format_said(path)) not in (None, format):
        raise MeasurementFileError(path, f"its extension says {said}, not {format}")
    for option, what in ((decimal_comma, "a decimal comma"), (wide, "a row per sample")):
        if option and name != "csv":
            raise MeasurementFileError(
                "stdout" if to_stdout else path, f"{what} is for a CSV file, not {name}"
            )
    recovered = next((m for m in measurements if m.spectra_recovered), None)
    if recovered and name not in COLOUR_ALONE_FORMATS:
        raise MeasurementFileError(
            "stdout" if to_stdout else path,
            f"{recovered.sample}'s spectra were recovered from L*a*b*: a {name} file would give "
            f"them as measured; write {' or '.join(COLOUR_ALONE_FORMATS)}, which keep its "
            "L*a*b* alone",
        )
    options = {k: True for k, v in (("decimal_comma", decimal_comma), ("wide", wide)) if v}
    if to_stdout:
        return _write_to_stdout(measurements, name, options)
    try:
        FORMATS[name][1](measurements, path, **options)
    except ValueError as error:
        if isinstance(error, MeasurementFileError):
            raise
        raise MeasurementFileError(path, str(error)) from None
    except OSError as error:
        raise MeasurementFileError(path, f"cannot be written ({error.strerror})") from None


def _write_to_stdout(measurements: list[Measurement], name: str, options: dict) -> None:
    """``measurements`` written in format ``name`` to standard output, whole or not at all:
    through a temporary file, as every writer writes. A workbook, binary, is refused where
    standard output is a terminal."""
    if name == "mat12-xlsx" and sys.stdout.isatty():
        raise MeasurementFileError(
            "stdout", "a terminal: an xlsx workbook is binary; redirect it into a file"
        )
    with tempfile.TemporaryDirectory(prefix="flakelab-") as folder:
        copy = Path(folder) / f"stdout{FORMATS[name][2][0]}"
        try:
            FORMATS[name][1](measurements, copy, **options)
        except ValueError as error:
            raise MeasurementFileError("stdout", getattr(error, "problem", str(error))) from None
        sys.stdout.flush()
        sys.stdout.buffer.write(copy.read_bytes())
        sys.stdout.buffer.flush()
