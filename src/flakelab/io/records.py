"""Shared parsing and checks for every measurement reader: one row = one sample × geometry.

Readers turn their format into :class:`Reading` rows and call :func:`assemble`, so every
format reports the same problems the same way (file, field, problem).
"""

from __future__ import annotations

import csv
import errno
import itertools
import math
import os
import re
import stat
import sys
import tempfile
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from datetime import datetime
from os import PathLike
from pathlib import Path

import numpy as np

from flakelab.core.colorimetry import (
    D65_10,
    Conditions,
    UnreachableColour,
    reflectance_from_Lab,
    stated_to_Lab,
)
from flakelab.core.difference import delta_E_CIE2000
from flakelab.core.documents import json_value
from flakelab.core.geometry import Geometry
from flakelab.core.measurement import (
    LAB_LIMIT,
    REFLECTANCE_RANGE,
    TEXTURE_RANGE,
    TEXTURE_READINGS,
    Measurement,
    outside,
)
from flakelab.core.spectra import WAVELENGTHS, shape_of
from flakelab.errors import FlakelabError, MeasurementFileError

__all__ = [
    "Reading",
    "assemble",
    "parse_wavelength_header",
    "parse_number",
    "parse_lab",
    "parse_colour",
    "STATED_ALIKE",
    "agreed_colour",
    "recovered_spectra",
    "parse_texture",
    "parse_geometry_name",
    "parse_conditions",
    "write_atomically",
    "is_no_regular_file",
    "unwritable_folder",
    "numbers_at_once",
    "decimal_point",
    "decimal_comma_in",
    "csv_form",
    "csv_separator",
    "filled_width",
    "named_separator",
    "network_file_system",
    "within",
    "spreadsheet_table",
    "csv_rows",
    "NOT_UTF8",
    "NUL_BYTES",
    "BINARY",
    "OTHER_KINDS",
    "kind_of_binary",
    "nul_problem",
    "NulBytesError",
    "decoding_problem",
    "utf16_without_mark",
    "utf8_of_utf16",
    "text_of",
]

_WAVELENGTH = re.compile(r"^\s*(?:R|r|nm)?\s*(\d{3}(?:\.\d+)?)\s*(?:nm)?\s*$")


@dataclass
class Reading:
    """One spectrum of one sample at one geometry, with where it came from (for messages);
    a file of L*a*b* alone gives no spectrum (None) until :func:`recovered_readings`."""

    where: str
    sample: str
    geometry: Geometry
    reflectance: np.ndarray | None
    lab: np.ndarray | None = None
    measured_at: datetime | None = None
    extras: dict[str, str] = field(default_factory=dict)


def parse_wavelength_header(
    path: str | PathLike,
    labels: Sequence[object],
    where: str,
    places: Sequence[str] | None = None,
) -> np.ndarray:
    """Wavelengths [nm] from column labels such as ``400``, ``R400`` or ``400nm``; checked to
    form a regular grid within 360–780 nm. A label that is none is named by its place in
    ``places`` (the file's own column, where the labels are some of its columns), else by its
    column among the labels."""
    values = []
    for i, label in enumerate(labels):
        match = _WAVELENGTH.match(str(label)) if label is not None else None
        if match is None:
            raise MeasurementFileError(
                path,
                f"expected a wavelength such as 'R400' or '400', got {label!r}",
                field=f"{where}, {places[i] if places else f'column {i + 1}'}",
            )
        values.append(float(match[1]))
    return checked_wavelengths(path, np.array(values), where)


def checked_wavelengths(path: str | PathLike, wavelengths: np.ndarray, where: str) -> np.ndarray:
    """``wavelengths`` [nm] of a file, checked to form a regular grid within 360–780 nm."""
    try:
        shape_of(wavelengths)
    except ValueError as error:
        raise MeasurementFileError(path, str(error), field=where) from None
    if wavelengths[0] < 360 or wavelengths[-1] > 780:
        raise MeasurementFileError(
            path,
            f"expected wavelengths within 360–780 nm, got {wavelengths[0]:g}–"
            f"{wavelengths[-1]:g} nm",
            field=where,
        )
    return wavelengths


def parse_number(path: str | PathLike, value: object, where: str) -> float:
    """A finite float from a cell, or a :class:`MeasurementFileError` naming the cell."""
    if isinstance(value, bool):
        raise MeasurementFileError(path, f"expected a number, got {value!r}", field=where)
    try:
        number = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        shown = "an empty cell" if value in (None, "") else repr(value)
        raise MeasurementFileError(path, f"expected a number, got {shown}", field=where) from None
    if not math.isfinite(number):
        raise MeasurementFileError(path, f"expected a finite number, got {value!r}", field=where)
    return number


def numbers_at_once(values: Sequence[object]) -> np.ndarray | None:
    """Cells as finite floats, parsed by numpy at once (as :func:`parse_number` parses each:
    a shop's history reads millions); None where one is not such a number, or is a bool."""
    if any(isinstance(v, bool) for v in values):
        return None
    try:
        numbers = np.array(values, dtype=float)
    except (TypeError, ValueError):
        return None
    return numbers if numbers.ndim == 1 and np.isfinite(numbers).all() else None


NOT_UTF8 = "not UTF-8 text; a spreadsheet saves a CSV as UTF-8 when asked for 'CSV UTF-8'"
"""What a CSV file in another encoding is told (a spreadsheet's default, Windows-1252, for
a shop named Müller)."""

NUL_BYTES = (
    "it holds NUL bytes, which no text file does: UTF-16 text without its byte-order mark? "
    "Save it as UTF-8, or as UTF-16 with its mark"
)
"""What a text file holding NUL bytes is told where it reads as UTF-16 without its mark
(:func:`utf16_without_mark`): read as UTF-8, a CSV whose header read "s a m p l e", or JSON
refused "Expecting property name" at column 2."""

BINARY = "binary content, not text"
"""What content holding NUL bytes is told where it does not read as UTF-16 text."""

OTHER_KINDS = {
    b"\x89PNG": "a PNG image",
    b"%PDF": "a PDF document",
    b"\xff\xd8\xff": "a JPEG image",
    b"GIF8": "a GIF image",
    b"\x1f\x8b": "a gzip archive",
    b"\xd0\xcf\x11\xe0": "an old binary Office file (.xls); export as .xlsx",
    b"SQLite format 3\x00": "a SQLite database",
}
"""Files that no reader takes, by their first bytes, and what each is called."""


def kind_of_binary(data: bytes) -> str | None:
    """What :data:`OTHER_KINDS` calls a file whose first bytes are ``data``, or None."""
    return next((kind for magic, kind in OTHER_KINDS.items() if data.startswith(magic)), None)


def utf16_without_mark(data: bytes) -> bool:
    """Whether ``data`` reads as UTF-16 text written without its byte-order mark: one byte of
    nearly every pair NUL and the other not, as in Latin text (a CSV of measurements, a shop
    named Müller); a database's empty pages are NUL in both."""
    pairs = len(data) // 2
    nuls = sorted(data[k : 2 * pairs : 2].count(0) for k in (0, 1))
    return pairs >= 2 and nuls[1] >= 0.9 * pairs and nuls[0] <= 0.1 * pairs


def nul_problem(data: bytes) -> str:
    """What content holding NUL bytes is told: :data:`NUL_BYTES` where it reads as UTF-16
    without its mark, else what :data:`OTHER_KINDS` calls it or :data:`BINARY`."""
    if utf16_without_mark(data):
        return NUL_BYTES
    kind = kind_of_binary(data)
    return f"this is {kind}, not text" if kind else BINARY


def decoding_problem(error: UnicodeDecodeError) -> str:
    """What text its encoding cannot read is told: UTF-16 (with its mark) cut inside a
    character, "not UTF-16 text (truncated data)"; where NULs lie among bytes that are not
    UTF-8, :func:`nul_problem` (UTF-16 without its mark with a character UTF-8 cannot read, a
    database); else :data:`NOT_UTF8`, with the decoder's reason."""
    if error.encoding.startswith("utf-16"):  # "not UTF-8 text" before
        return f"not UTF-16 text ({error.reason})"
    if isinstance(error.object, bytes) and b"\x00" in error.object:
        return nul_problem(error.object)
    return f"{NOT_UTF8} ({error.reason})"


class NulBytesError(UnicodeDecodeError):
    """Text that decoded but holds NUL bytes (:func:`nul_problem` says what it is); a
    :class:`UnicodeDecodeError`, for every reader of :func:`text_of` names the file where it
    meets one."""

    def __init__(self, encoding: str, text: str) -> None:
        data = text.encode("utf-8", "replace")
        start = len(text[: text.index("\x00")].encode("utf-8", "replace"))  # the NUL's byte
        problem = nul_problem(text.encode("latin-1", "replace"))  # UTF-16 read as UTF-8
        super().__init__(encoding, data, start, start + 1, problem)

    def __str__(self) -> str:
        return self.reason


UTF16_BOMS = (b"\xff\xfe", b"\xfe\xff")
"""The byte-order marks of UTF-16 text: a spreadsheet's "Unicode Text", tab-separated."""

_XML_ENCODING = re.compile(rb"""^(\s*<\?xml[^>]*?encoding\s*=\s*["'])[^"']*""")


def utf8_of_utf16(data: bytes) -> bytes:
    """UTF-16 text (with its mark) as UTF-8, an XML declaration's encoding made to say so:
    whatever a CxF3 file in UTF-16 declares, its parser reads the UTF-8 (declaring UTF-16 it
    had been refused in a copy, "encoding specified in XML declaration is incorrect", and a
    case history declaring UTF-8 was)."""
    return _XML_ENCODING.sub(rb"\1UTF-8", data.decode("utf-16").encode("utf-8"), count=1)


def text_encoding(path: str | PathLike) -> str:
    """The encoding to read a text file in: UTF-16 where it opens with that byte-order mark
    (a spreadsheet's "Unicode Text"), else UTF-8, a byte-order mark skipped. A pipe is UTF-8:
    its first bytes, once looked at, would be gone."""
    if is_no_regular_file(path):
        return "utf-8-sig"
    with open(path, "rb") as handle:
        return "utf-16" if handle.read(2) in UTF16_BOMS else "utf-8-sig"


STANDARD_STREAM = "-"
"""The file name that stands for standard input where a file is read and standard output
where a measurement is written, as most command-line tools take it: ``cat car.cxf |
flakelab inspect -``, ``… | flakelab weigh - --quantity 1l``, ``flakelab convert scan.xlsx -
--format csv | …``. Errors name it ``stdin`` or ``stdout``."""


_READ_STDIN: list = []
"""The standard input read already and what it held, where one was: it holds one file, and a
command given ``-`` twice (``compare - -``, ``correct - -r -``) met it empty the second time."""


def standard_input() -> bytes:
    """What is piped into standard input; refused where it is a terminal, where reading it
    would wait, silent, for a file typed by hand, and where it was read already."""
    if sys.stdin is None or sys.stdin.isatty():
        raise MeasurementFileError(
            "stdin",
            "a terminal, not a file: pipe the file into it ('… | flakelab inspect -'), or name "
            "the file",
        )
    if _READ_STDIN and _READ_STDIN[0] is sys.stdin:
        raise MeasurementFileError(
            "stdin", "read already for another of this command's files: - stands for one file"
        )
    data = sys.stdin.buffer.read()
    _READ_STDIN[:] = [sys.stdin, data]
    return data


def text_of(path: str | PathLike) -> str:
    """A text file's contents in :func:`text_encoding`'s encoding: a JSON or TOML file that
    Windows wrote is read as well as any, UTF-16 from PowerShell's ``>`` or UTF-8 with the
    byte-order mark of an older Notepad (both were refused, "Unexpected UTF-8 BOM").
    :data:`STANDARD_STREAM` reads standard input (:func:`standard_input`). Text holding NUL
    bytes raises :class:`NulBytesError`."""
    if os.fspath(path) == STANDARD_STREAM:
        data = standard_input()
        encoding = "utf-16" if data.startswith(UTF16_BOMS) else "utf-8-sig"
        text = data.decode(encoding)
    else:
        encoding = text_encoding(path)
        text = Path(path).read_text(encoding=encoding)
    if "\x00" in text:
        raise NulBytesError(encoding, text)
    return text


CSV_SEPARATORS = ",;\t"
"""A CSV file's cell separators: the comma, and the semicolon or tab of a spreadsheet in most
of Europe, where the comma is the decimal mark (:func:`decimal_point`)."""


_SEPARATOR_LINE = re.compile(r'"?sep=([,;\t])"?', re.IGNORECASE)


def named_separator(line: str) -> str | None:
    """The separator that a CSV file's first line names as Excel's hint does, ``sep=;``
    (instrument software writes it for Excel, which hides the line), else None. The file's
    header is the line after; before, the hint was taken for the header and every such file
    was refused "missing column 'sample'"."""
    found = _SEPARATOR_LINE.fullmatch(line.strip("\r\n "))
    return found and found.group(1)


def csv_separator(header: str) -> str | None:
    """The separator of a CSV file whose header line is ``header``: of
    :data:`CSV_SEPARATORS`, the one it holds most (no column name holds one); None where it
    holds none."""
    found = max(CSV_SEPARATORS, key=header.count)
    return found if found in header else None


def standard_of(measurements: Sequence[Measurement]) -> Measurement | None:
    """The measurement a file names its QC job's standard (an MA-T12 export's ``STANDARD:``
    row, a CxF3 document's one Object of ObjectType "Standard"), where it holds it; else
    None."""
    named = {m.metadata.get("standard") for m in measurements}
    standard = named.pop() if len(named) == 1 else None
    return next((m for m in measurements if standard and m.sample == standard), None)


def csv_rows(
    lines: Iterable[str], delimiter: str, refused: Callable[[int, str], Exception]
) -> Iterator[list[str]]:
    """The rows of CSV ``lines`` as :func:`csv.reader` splits them. A row it cannot split is
    raised as ``refused(row number, problem)`` makes it: a cell past csv's limit, which a
    quote left open reaches by swallowing every line after it (an internal error before), or
    a NUL."""
    reader = csv.reader(lines, delimiter=delimiter)
    for number in itertools.count(1):
        try:
            row = next(reader)
        except StopIteration:
            return
        except csv.Error as error:
            problem = str(error)
            if "field limit" in problem:
                problem = (
                    f"a cell longer than {csv.field_size_limit():,} characters (a quote left "
                    "open takes every line after it)"
                )
            raise refused(number, problem) from None
        if number == 1 and "\x00" in (header := "\t".join(row)):  # csv reads NULs as any
            raise refused(number, nul_problem(header.encode("latin-1", "replace")))
        yield row


def filled_width(header: Sequence[str]) -> int:
    """The columns of a CSV ``header`` up to its last named one: a spreadsheet whose sheet
    was once used further right writes ",,," at the end of every line, and such a file was
    refused ("column '' appears twice", "expected 43 columns, got 46")."""
    width = len(header)
    while width and not header[width - 1].strip():
        width -= 1
    return width


def within(row: list[str], width: int) -> list[str]:
    """``row`` cut to ``width`` cells where every cell past them is empty (the spreadsheet's
    trailing ",,," of :func:`filled_width`); else as it is, for its length to be refused."""
    if len(row) > width and not any(cell.strip() for cell in row[width:]):
        return row[:width]
    return row


def spreadsheet_table(
    lines: Iterable[str], refused: Callable[[int, str], Exception]
) -> tuple[str | None, list[str] | None, Iterator[tuple[int, list[str]]]]:
    """A CSV file's separator, header and rows, as a spreadsheet may have saved them: the
    separator a first line ``sep=;`` names (:func:`named_separator`, that line then left
    out), else the one its header holds most (:func:`csv_separator`; None where it holds
    none, the file then split at commas); the header up to its last named column
    (:func:`filled_width`), None where no line follows; and each row that is not blank,
    with its number (the header's is 1), cut to the header's width where only empty cells
    lie past it (:func:`within`). The measurement, case-history and manifest readers all
    read their CSV through it."""
    lines = iter(lines)
    first = next(lines, None)
    named = first is not None and named_separator(first)
    first = next(lines, None) if named else first
    separator = named or (None if first is None else csv_separator(first))
    rows = csv_rows(itertools.chain([] if first is None else [first], lines), separator or ",",
                    refused)  # fmt: skip
    header = next(rows, None)
    width = filled_width(header or [])

    def filled_rows() -> Iterator[tuple[int, list[str]]]:
        for number, row in enumerate(rows, start=2):
            row = within(row, width)
            if any(cell.strip() for cell in row):  # a spreadsheet's blank row, ",,,,"
                yield number, row

    return separator, header and header[:width], filled_rows()


def csv_form(decimal_comma: bool) -> tuple[str, str]:
    """The cell separator and encoding of a CSV written plain, or with ``decimal_comma`` as a
    spreadsheet in most of Europe opens it: semicolons, and a byte-order mark for it to take
    the file as UTF-8."""
    return (";", "utf-8-sig") if decimal_comma else (",", "utf-8")


def decimal_comma_in(cell: str) -> str:
    """A number written with a decimal comma (``0.25`` → ``0,25``), as :func:`decimal_point`
    reads it back."""
    return cell.replace(".", ",")


def decimal_point(cell: str) -> str:
    """A numeric cell with its decimal comma read as a point (``0,25`` → ``0.25``): a
    semicolon or tab separated file, as spreadsheets write it in most of Europe, leaves the
    comma free to be the decimal mark."""
    return cell.replace(",", ".")


def parse_lab(path: str | PathLike, values: Sequence[object], fields: Sequence[str]) -> np.ndarray:
    """Stored CIELAB ``[3]`` from three cells named by ``fields``: finite numbers within
    :data:`LAB_LIMIT`, or a :class:`MeasurementFileError` naming the cell."""
    lab = np.array([parse_number(path, v, f) for v, f in zip(values, fields, strict=True)])
    for value, where in zip(lab, fields, strict=True):
        if abs(value) > LAB_LIMIT:
            raise MeasurementFileError(
                path, f"expected a CIELAB value within ±{LAB_LIMIT:g}, got {value:g}", field=where
            )
    return lab


def parse_colour(
    path: str | PathLike,
    form: str,
    cells: Sequence[object],
    where: str,
    names: Sequence[str],
    conditions: Conditions = D65_10,
) -> np.ndarray:
    """A reading's colour stated in ``form`` (one of
    :data:`~flakelab.core.colorimetry.STATED_AS`) by three cells named ``names``, as L*a*b*
    ``[3]`` under ``conditions``; each cell checked and named, and the L*a*b* it gives."""
    fields = [f"{where}, {name}" for name in names]
    if form == "XYZ":
        values = np.array([parse_number(path, v, f) for v, f in zip(cells, fields, strict=True)])
    else:
        values = parse_lab(path, cells, fields)
    if form == "Lab":
        return values
    if form == "LCh" and values[1] < 0:
        raise MeasurementFileError(
            path, f"expected a chroma of 0 or more, got {values[1]:g}", field=fields[1]
        )
    lab = stated_to_Lab(form, values, conditions)
    return parse_lab(path, lab, [f"{where}, as L*a*b* {k}" for k in "LAB"])


STATED_ALIKE = 0.2
"""ΔE00 within which the forms a reading states its colour in (L*a*b* beside L*C*h° or XYZ, as
instruments export them) must agree: rounding each to one decimal stays within 0.1; columns
swapped or mislabelled do not."""


def agreed_colour(
    path: str | PathLike, stated: dict[str, np.ndarray], where: str
) -> np.ndarray | None:
    """The colour a reading states, as L*a*b* ``[3]``, by the forms it gives it in (``stated``,
    each named as the file names it, in the order of
    :data:`~flakelab.core.colorimetry.STATED_AS`): the first, every other agreeing with it to
    ΔE00 :data:`STATED_ALIKE`, else refused naming both; None where it states none."""
    if not stated:
        return None
    (first, lab), *others = stated.items()
    for name, other in others:
        difference = float(delta_E_CIE2000(lab, other))
        if difference > STATED_ALIKE:
            raise MeasurementFileError(
                path,
                f"its {name} read as L*a*b* {_shown(other)} lies ΔE00 {difference:.2f} from its "
                f"{first} {_shown(lab)}: one of them is wrong",
                field=where,
            )
    return lab


def _shown(lab: np.ndarray) -> str:
    return "(" + ", ".join(f"{v:.2f}" for v in lab) + ")"


def parse_texture(path: str | PathLike, value: object, where: str) -> float:
    """A texture reading from a cell: a finite number within :data:`TEXTURE_RANGE`, or a
    :class:`MeasurementFileError` naming the cell."""
    reading = parse_number(path, value, where)
    if outside(reading, TEXTURE_RANGE):
        low, high = TEXTURE_RANGE
        raise MeasurementFileError(
            path, f"expected a texture reading in [{low:g}, {high:g}], got {reading:g}", field=where
        )
    return reading


def parse_spectrum(
    path: str | PathLike, values: Sequence[object], wavelengths: np.ndarray, where: str
) -> np.ndarray:
    if len(values) != wavelengths.size:
        raise MeasurementFileError(
            path, f"expected {wavelengths.size} reflectance values, got {len(values)}", field=where
        )
    spectrum = numbers_at_once(values)
    if spectrum is None:  # the cell that stops it, named
        spectrum = np.array(
            [
                parse_number(path, v, f"{where}, {wl:g} nm")
                for v, wl in zip(values, wavelengths, strict=True)
            ]
        )
    low, high = REFLECTANCE_RANGE
    bad = np.flatnonzero(outside(spectrum, REFLECTANCE_RANGE))
    if bad.size:
        i = bad[0]
        raise MeasurementFileError(
            path,
            f"expected a reflectance factor in [{low}, {high}], got {spectrum[i]:g}",
            field=f"{where}, {wavelengths[i]:g} nm",
        )
    return spectrum


def parse_geometry_name(path: str | PathLike, value: object, where: str) -> Geometry:
    try:
        return Geometry.parse(str(value).strip() if value is not None else "")
    except ValueError as error:
        raise MeasurementFileError(path, str(error), field=where) from None


def parse_conditions(path: str | PathLike, text: str, where: str) -> Conditions:
    if not isinstance(text, str):  # a JSON number or list where the text belongs
        raise MeasurementFileError(
            path, f"expected illuminant/observer such as 'D65/10', got {text!r}", field=where
        )
    try:
        return Conditions.parse(text)
    except ValueError as error:
        raise MeasurementFileError(path, str(error), field=where) from None


def recovered_spectra(
    path: str | PathLike, lab: np.ndarray, places: Sequence[str], conditions: Conditions = D65_10
) -> np.ndarray:
    """Spectra ``[N, 31]`` on the storage grid recovered from colours ``lab [N, 3]`` under
    ``conditions`` (:func:`~flakelab.core.colorimetry.reflectance_from_Lab`), all at once; a
    colour no surface reflects, or one asking a reflectance factor no paint reaches, is
    refused naming its place in the file (``places``, one per colour)."""
    try:
        # near black an instrument's noise dips below 0, as its spectra would
        spectra = reflectance_from_Lab(lab, WAVELENGTHS, conditions, floor=REFLECTANCE_RANGE[0])
    except UnreachableColour as error:
        raise MeasurementFileError(path, str(error), field=places[error.position]) from None
    high = REFLECTANCE_RANGE[1]
    if (over := np.flatnonzero(outside(spectra, REFLECTANCE_RANGE).any(axis=1))).size:
        i = over[0]
        raise MeasurementFileError(
            path,
            f"L* {lab[i, 0]:g} asks a reflectance factor of {spectra[i].max():.3g}, over the "
            f"{high:g} any paint reaches near specular: the file is wrong, not the paint",
            field=places[i],
        )
    return spectra


def recovered_readings(
    path: str | PathLike, readings: list[Reading], conditions: Conditions
) -> list[Reading]:
    """``readings`` of L*a*b* alone, each with a spectrum recovered from its colour under
    ``conditions`` (:func:`recovered_spectra`); a colour no surface reflects is refused
    naming its reading."""
    lab = np.array([r.lab for r in readings], dtype=float).reshape(-1, 3)
    spectra = recovered_spectra(path, lab, [r.where for r in readings], conditions)
    return [replace(r, reflectance=R) for r, R in zip(readings, spectra, strict=True)]


def colour_alone(measurements: Sequence[Measurement]) -> bool:
    """Whether ``measurements`` are to be written as L*a*b* alone (their spectra recovered
    from it, which a file must not give as measured); one table holds one kind or the other
    (a CxF3 document holds both, Object by Object)."""
    alone = measurements[0].spectra_recovered
    if any(m.spectra_recovered != alone for m in measurements):
        raise ValueError(
            "expected measurements of one kind for one file: spectra measured, or L*a*b* "
            "alone, not both"
        )
    return alone


def assemble(
    path: str | PathLike,
    readings: Iterable[Reading],
    wavelengths: np.ndarray,
    *,
    instrument: str | None = None,
    lab_conditions: Conditions = D65_10,
    texture: dict[str, dict[str, float]] | None = None,
    metadata: dict[str, dict[str, str]] | None = None,
    spectra_recovered: bool = False,
) -> list[Measurement]:
    """Group readings by sample (file order) into measurements, checking that each sample has
    each geometry once and that stored L*a*b* is given for all of a sample's geometries or none;
    ``spectra_recovered`` where the readings' spectra were recovered from their L*a*b*."""
    groups: dict[str, list[Reading]] = {}
    for reading in readings:
        groups.setdefault(reading.sample, []).append(reading)
    if not groups:
        raise MeasurementFileError(path, "no measurements found (the data table is empty)")
    measurements = []
    for sample, rows in groups.items():
        seen: dict[Geometry, str] = {}
        for row in rows:
            if row.geometry in seen:
                raise MeasurementFileError(
                    path,
                    f"geometry {row.geometry.name} of sample {sample!r} appears twice "
                    f"(also at {seen[row.geometry]})",
                    field=row.where,
                )
            seen[row.geometry] = row.where
        labs = [r.lab for r in rows]
        if any(lab is None for lab in labs) and not all(lab is None for lab in labs):
            missing = next(r.where for r in rows if r.lab is None)
            raise MeasurementFileError(
                path, f"sample {sample!r} has L*a*b* for some geometries only", field=missing
            )
        sample_texture = (texture or {}).get(sample, {})
        unknown = [k for k in sample_texture if k not in TEXTURE_READINGS]
        if unknown:
            raise MeasurementFileError(
                path,
                f"expected texture readings among {', '.join(TEXTURE_READINGS)}, got {unknown}",
                field=f"sample {sample!r}",
            )
        dates = [r.measured_at for r in rows if r.measured_at is not None]
        measurements.append(
            Measurement(
                sample=sample,
                geometries=tuple(r.geometry for r in rows),
                wavelengths=wavelengths,
                reflectance=np.stack([r.reflectance for r in rows]),
                texture=sample_texture,
                instrument=instrument,
                measured_at=dates[0] if dates else None,
                stored_lab=None if labs[0] is None else np.stack(labs),  # type: ignore[arg-type]
                stored_lab_conditions=lab_conditions,
                metadata=(metadata or {}).get(sample, {}),
                spectra_recovered=spectra_recovered,
            )
        )
    return measurements


def read_json_file(path: str | PathLike, what: str, expected: str):
    """The parsed contents of the JSON file ``path`` (a ``what``: "recipe file"), or a
    :class:`~flakelab.errors.MeasurementFileError` naming it: missing, unreadable, or not JSON
    (``expected`` says what it should hold)."""
    try:
        text = text_of(path)
        if not text.strip():  # "Expecting value: line 1 column 1 (char 0)" before
            raise MeasurementFileError(path, f"empty file; expected {expected}")
        return json_value(text)
    except FlakelabError:
        raise
    except FileNotFoundError:
        raise MeasurementFileError(path, f"no such {what}") from None
    except IsADirectoryError:  # "[Errno 21] Is a directory: '/tmp'" before
        raise MeasurementFileError(path, f"a folder, not a {what}") from None
    except (UnicodeDecodeError, ValueError) as error:
        why = f"; this is {kind}" if (kind := other_format(path)) else f" ({error})"
        raise MeasurementFileError(path, f"expected {expected}{why}") from None
    except OSError as error:
        raise MeasurementFileError(path, f"expected {expected} ({error})") from None


_FORMAT_KINDS = {
    "mat12-xlsx": "an xlsx workbook, not JSON",
    "cxf": "a CxF3 file, not JSON",
    "csv": "a CSV file, not JSON",
}
"""What :func:`other_format` calls each format of :data:`flakelab.io.FORMATS` but JSON."""


def other_format(path: str | PathLike) -> str:
    """What a file given where JSON is read is instead, by its content: "a CxF3 file, not
    JSON" (a car's measurement given as ``--recipe``, a case history as ``--library``); ""
    where it is none flakelab reads."""
    from flakelab.io import detect_format  # the package, which imports this module

    try:
        if os.fspath(path) != STANDARD_STREAM:
            return _FORMAT_KINDS.get(detect_format(path), "")
        if not _READ_STDIN or _READ_STDIN[0] is not sys.stdin:
            return ""
        with tempfile.TemporaryDirectory() as folder:  # what was piped, judged as a file
            copy = Path(folder) / "stdin"
            copy.write_bytes(_READ_STDIN[1])
            return _FORMAT_KINDS.get(detect_format(copy), "")
    except FlakelabError:
        return ""


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def unwritable_folder(path: str | PathLike) -> str | None:
    """Why no file can be made at ``path``: "no folder F", or "folder F cannot be written";
    None where one can."""
    folder = Path(path).resolve().parent
    if not folder.is_dir():
        return f"no folder {folder}"
    if not os.access(folder, os.W_OK | os.X_OK):
        return f"folder {folder} cannot be written"
    return None


NETWORK_FILE_SYSTEMS = frozenset(
    {"nfs", "nfs4", "cifs", "smb3", "smbfs", "9p", "afs", "ceph", "glusterfs", "lustre",
     "fuse.sshfs", "fuse.glusterfs", "fuse.cephfs", "fuse.rclone"}
)  # fmt: skip
"""The file systems of a folder shared over a network (a NAS, another workplace's disk), as
Linux names them in ``/proc/self/mounts``."""


def network_file_system(
    path: str | PathLike, mounts: str | PathLike = "/proc/self/mounts"
) -> str | None:
    """The network file system ``path`` lies on (``nfs4``, ``cifs``, …), by the deepest mount
    point above it in ``mounts``; None on a local disk, or where the mounts cannot be read
    (not Linux)."""
    try:
        mounts = Path(mounts).read_text().splitlines()
    except OSError:
        return None
    target, deepest, kind = Path(path).resolve(), -1, None
    for fields in (line.split() for line in mounts):
        if len(fields) < 3:
            continue
        point = Path(re.sub(r"\\([0-7]{3})", lambda m: chr(int(m[1], 8)), fields[1]))  # \040
        if (point == target or point in target.parents) and len(point.parts) > deepest:
            deepest, kind = len(point.parts), fields[2]
    return kind if kind in NETWORK_FILE_SYSTEMS else None


def is_no_regular_file(path: str | PathLike) -> bool:
    """Whether what lies at ``path`` (through links) is there and no regular file nor folder:
    ``/dev/null``, ``/dev/stdout``, a named pipe. Such a file is written into, never renamed
    over, and is no database."""
    target = Path(path)
    return target.exists() and not target.is_file() and not target.is_dir()


def write_atomically(path: str | PathLike, write: Callable[[Path], None]) -> None:
    """Write through a temporary file beside ``path`` and rename it into place, so a failure
    never leaves a half-written file and never destroys the previous one.

    A link is written through: the file it names is replaced and the link stays. A file
    there keeps its permissions. What is no regular file (``/dev/null``, ``/dev/stdout``, a
    named pipe) is written into as it is: renamed over, it would be lost, and for a root user
    ``/dev/null`` with it."""
    target = Path(path)
    if not target.name or target.is_dir():
        raise IsADirectoryError(errno.EISDIR, "a folder, not a file to write", str(path))
    if is_no_regular_file(target):
        write(target)
        return
    target = Path(os.path.realpath(target))
    existed = target.exists()
    mode = stat.S_IMODE(target.stat().st_mode) if existed else 0o666 & ~_umask()
    try:
        # the name cut: with mkstemp's eight characters, a name near the file system's 255
        # would make the temporary one too long, and a name the file system takes refused
        handle, temporary = tempfile.mkstemp(prefix=f".{target.name[:100]}.", dir=target.parent)
    except OSError as error:  # named by the file asked for, not the temporary one
        raise OSError(error.errno, error.strerror, str(path)) from None
    os.close(handle)
    try:
        write(Path(temporary))
        os.chmod(temporary, mode)
        os.replace(temporary, target)
    except OSError as error:
        raise _unwritten(error, path, temporary, existed) from None
    finally:
        if os.path.exists(temporary):
            os.unlink(temporary)


def _unwritten(error: OSError, path: str | PathLike, temporary: str, existed: bool) -> OSError:
    """A failure met writing the temporary file (a full disk, a size limit) named by the file
    asked for, saying what is left there; one about another file keeps that file's name."""
    if error.filename not in (None, temporary) or error.strerror is None:
        return error
    left = "the file there is left as it was" if existed else "no file was written"
    return OSError(error.errno, f"{error.strerror} while writing it; {left}", str(path))
