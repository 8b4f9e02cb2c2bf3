"""Case histories as files: CSV (one row per case) and CxF3 (two samples per case).

CSV columns: ``case_id, shop, instrument, conditions, outcome, synthetic, created_at,
recipe`` (JSON object toner → amount), ``geometries`` (the case's, names joined by ``;``),
where any case records the car maker's colour code ``colour_code`` (empty for a case that
records none), where any case records the tins it was poured from ``tins`` (JSON object
toner → ``{lot, strength, shade_nm}``, empty for a case that records none), then each role's
readings: ``target:<geometry>:<nm>`` reflectance factors for every geometry of the file and
band (400–700 nm, 10 nm) where any case measured its target, ``target:<geometry>:L``, ``:a``
and ``:b`` (its L*a*b* in D65/10) where any case knows its target by its colour alone (a
case fills one or the other), the same for ``sprayout``, then ``target:<reading>`` and
``sprayout:<reading>`` texture readings (empty when not measured). So a shop whose
instrument exports colour alone writes a history of L*a*b* columns alone, and a reading
known by its colour is read with its spectrum recovered from it, flagged
(:attr:`~flakelab.cases.case.Case.target_recovered`). A file of stop 101 gave such a reading
as its recovered spectrum, flagged by a ``target_recovered`` (``sprayout_recovered``) column
of 0/1 after the tins; it is read as it was. A file may hold cases
read at different geometry sets (an MA-T12's and a five-angle instrument's): its columns
are every geometry any case was read at, and a case's cells at geometries it was not read
at are empty. A file saved by a spreadsheet in most of Europe, separated by semicolons (or
tabs) with decimal commas in its readings, is read as well.

CxF3: each case is two multi-angle samples, ``<case_id>/target`` and ``<case_id>/sprayout``;
the case's fields ride as ``meta:`` tags on the target (``tins`` as the CSV's cell;
``colour_code`` where the case records one). A reading known by its L*a*b* alone is
written as its ColorCIELab in D65/10 alone, as it was read.

Readers check every row and name the file, row and column of the first problem; nothing is
returned from a bad file.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Callable, Iterable, Iterator
from datetime import datetime
from functools import cache
from operator import attrgetter, itemgetter
from os import PathLike
from pathlib import Path
from typing import NamedTuple

import numpy as np

from flakelab.cases.case import Case, CaseError, check_readings_kept, tin_fields
from flakelab.core.defaults import DEFAULT_CONDITIONS
from flakelab.core.documents import json_value
from flakelab.core.measurement import TEXTURE_READINGS, Measurement
from flakelab.core.spectra import WAVELENGTHS
from flakelab.core.times import TIME_EXPECTED, read_time
from flakelab.errors import FlakelabError, MeasurementFileError, shown
from flakelab.io import STANDARD_STREAM
from flakelab.io.cxf import read_cxf, write_cxf
from flakelab.io.records import (
    csv_form,
    decimal_comma_in,
    decimal_point,
    decoding_problem,
    is_no_regular_file,
    numbers_at_once,
    recovered_spectra,
    spreadsheet_table,
    text_encoding,
    write_atomically,
)

__all__ = ["read_cases", "write_cases", "is_case_file", "check_case_file_suffix", "CASE_FIELDS"]

CXF_SUFFIXES = (".cxf", ".xml")
CASE_FILE_SUFFIXES = (".csv", *CXF_SUFFIXES)

PIPED_CASES = (
    "-: cases are read from a case file (CSV or CxF3) or a database named, not from standard "
    "input; save what is piped to a file (a file named - by its path, ./-)"
)
"""What ``-`` is told where cases are read: it was "no such file", or "no such case file or
database"."""

CASE_FIELDS = (
    "case_id",
    "shop",
    "instrument",
    "conditions",
    "outcome",
    "synthetic",
    "created_at",
    "recipe",
    "geometries",
)

CODE_FIELD = "colour_code"
"""The first optional column after :data:`CASE_FIELDS`: each case's colour code."""

TINS_FIELD = "tins"
"""The second optional column after :data:`CASE_FIELDS`: the tins each case was poured
from."""

RECOVERED_FIELDS = ("target_recovered", "sprayout_recovered")
"""The third and fourth optional columns of a file of stop 101, read and no longer written:
whether each case's target (spray-out) was known by its L*a*b* alone
(:attr:`~flakelab.cases.case.Case.target_recovered`), 1 or 0, its spectra the recovered."""

OPTIONAL_FIELDS = (CODE_FIELD, TINS_FIELD)
"""The columns after :data:`CASE_FIELDS` a file has, in this order, where any of its cases
records what they hold."""

ROLES = ("target", "sprayout")
"""A case's two readings, as its columns name them."""

READING_CELLS = {"spectra": tuple(str(int(w)) for w in WAVELENGTHS), "colour": ("L", "a", "b")}
"""The cells of one reading at one geometry, by the form a file gives it in: its reflectance
factors band by band [nm], or its L*a*b* in D65/10 (a reading known by its colour alone)."""

MEASURED = tuple((role, "spectra") for role in ROLES)
"""The reading blocks of a file of measured readings alone: each role's spectra."""

_FLAGS = {"0": False, "1": True}


def _tins_cell(case: Case) -> str:
    """A case's tins as its file writes them: a JSON object, empty where it records none."""
    return json.dumps({k: tin_fields(t) for k, t in case.tins.items()}) if case.tins else ""


class _Optional(NamedTuple):
    """An optional column: its cell of a case, whether the case records what it holds, and
    that in words."""

    cell: Callable[[Case], str]
    held: Callable[[Case], object]
    words: str


_OPTIONAL = {
    CODE_FIELD: _Optional(
        attrgetter("colour_code"), attrgetter("colour_code"), "records its colour code"
    ),
    TINS_FIELD: _Optional(_tins_cell, attrgetter("tins"), "records its tins"),
}
"""Each of :data:`OPTIONAL_FIELDS`: what a case writes in it and when it needs it."""


class CaseFileError(FlakelabError):
    """A case file that is wrong: names the file, row, column and problem."""


@cache
def _header(
    geometries: tuple[str, ...],
    optional: tuple[str, ...] = (),
    blocks: tuple[tuple[str, str], ...] = MEASURED,
) -> tuple:
    """Column names for one geometry set, with the ``optional`` columns (of
    :data:`OPTIONAL_FIELDS`, or of a file of stop 101 :data:`RECOVERED_FIELDS` too, in that
    order) and the readings' ``blocks`` (role, form) (cached: every row of a file checks
    against it)."""
    readings = _block_columns(blocks, geometries)
    texture = [f"{role}:{t}" for role in ROLES for t in TEXTURE_READINGS]
    return (*CASE_FIELDS, *optional, *readings, *texture)


def _block_columns(blocks: tuple[tuple[str, str], ...], geometries: tuple[str, ...]) -> list[str]:
    return [
        f"{role}:{g}:{cell}" for role, form in blocks for g in geometries
        for cell in READING_CELLS[form]
    ]  # fmt: skip


def _optional_columns(cases: list[Case]) -> tuple[str, ...]:
    """The optional columns a file of ``cases`` has: those that any of them records."""
    return tuple(f for f in OPTIONAL_FIELDS if any(_OPTIONAL[f].held(c) for c in cases))


def _reading_blocks(cases: list[Case]) -> tuple[tuple[str, str], ...]:
    """The readings' blocks a file of ``cases`` has, role by role: its spectra where any case
    measured it, its colour where any case knows it by its L*a*b* alone."""
    blocks = []
    for role in ROLES:
        known = [c.known_by_colour(role) for c in cases]
        blocks += [(role, "spectra")] * (not all(known)) + [(role, "colour")] * any(known)
    return tuple(blocks)


def is_case_file(path: str | PathLike) -> bool:
    """Whether a path names a case file (CSV or CxF3) by its suffix."""
    return Path(path).suffix.lower() in CASE_FILE_SUFFIXES


OTHER_FORMAT_SUFFIXES = (".txt", ".tsv", ".json", ".toml", ".xlsx", ".xls", ".pt", ".npz",
                         ".png", ".pdf", ".svg")  # fmt: skip
"""Suffixes of other formats, which a file of cases or a database is not named: ``cases
generate --out cases.txt`` wrote a SQLite database under that name."""


def check_cases_or_database_name(path: str | PathLike, option: str) -> None:
    """Refuse a name ``path`` of another format where a case file or a database is written:
    any name but a case file's (:data:`CASE_FILE_SUFFIXES`) is a database."""
    suffix = Path(path).suffix.lower()
    if suffix in OTHER_FORMAT_SUFFIXES:
        raise CaseFileError(
            f"{option}: {path}: a case file is named {', '.join(CASE_FILE_SUFFIXES)} (CSV or "
            f"CxF3) and any other name is a SQLite database; {suffix} would hold a database"
        )


def check_case_file_suffix(path: str | PathLike, *, decimal_comma: bool = False) -> None:
    """A case file to write is named .csv, .cxf or .xml (its format is read from the name);
    one with a ``decimal_comma`` is a CSV."""
    if not is_case_file(path):
        raise CaseFileError(
            f"{path}: expected a case file named {', '.join(CASE_FILE_SUFFIXES)} "
            f"(CSV or CxF3), got the suffix {Path(path).suffix!r}"
        )
    if decimal_comma and Path(path).suffix.lower() in CXF_SUFFIXES:
        raise CaseFileError(f"{path}: a decimal comma is for a CSV file; CxF3 writes points")


def write_cases(
    cases: Iterable[Case],
    path: str | PathLike,
    *,
    geometries: tuple[str, ...] | None = None,
    tins: bool | None = None,
    codes: bool = False,
    decimal_comma: bool = False,
    progress: Callable[[], None] | None = None,
) -> None:
    """Write cases as CSV or CxF3 (by extension), atomically. Given the CSV's
    ``geometries`` (their columns, in order) and whether it has a ``tins`` column (and a
    colour codes' one, with ``codes``), the cases are written as they come (a generator's:
    none held); else they are read first.
    With ``decimal_comma``, a CSV is a European spreadsheet's: cells separated by semicolons,
    readings with a decimal comma, a byte-order mark for its encoding. ``progress`` is
    called for each case of a CSV written."""
    check_case_file_suffix(path, decimal_comma=decimal_comma)
    streamed = geometries is not None and tins is not None
    if Path(path).suffix.lower() in CXF_SUFFIXES or not streamed:
        cases = list(cases)
        if not cases:
            raise CaseFileError(f"{path}: expected at least one case to write, got none")
    if Path(path).suffix.lower() in CXF_SUFFIXES:
        write_cxf([m for c in cases for m in _as_measurements(c)], path)
        return
    if streamed:  # a generator's: its cases' readings measured
        optional, blocks = (CODE_FIELD,) * codes + (TINS_FIELD,) * tins, MEASURED
    else:
        geometries = tuple(dict.fromkeys(g for c in cases for g in c.geometry_names))
        optional, blocks = _optional_columns(cases), _reading_blocks(cases)
    readings = len(CASE_FIELDS) + len(optional)  # the first cell of the readings

    separator, encoding = csv_form(decimal_comma)

    def write(temporary: Path) -> None:  # row by row, not the whole text first
        with temporary.open("w", encoding=encoding, newline="") as handle:
            writer = csv.writer(handle, delimiter=separator)
            writer.writerow(_header(geometries, optional, blocks))
            written = 0
            for case in cases:
                if streamed:
                    _check_columns_hold(path, case, geometries, optional)
                row = _csv_row(case, geometries, optional, blocks)
                if decimal_comma:
                    row[readings:] = [decimal_comma_in(cell) for cell in row[readings:]]
                writer.writerow(row)
                written += 1
                if progress is not None:
                    progress()
        if not written:  # the temporary file is removed: nothing written
            raise CaseFileError(f"{path}: expected at least one case to write, got none")

    write_atomically(path, write)


def _check_columns_hold(path, case: Case, geometries: tuple[str, ...], optional: tuple[str, ...]):
    """A case streamed into a CSV of ``geometries`` and ``optional`` columns is one its
    columns hold whole."""
    beyond = [g for g in case.geometry_names if g not in geometries]
    unheld = [o.words for f, o in _OPTIONAL.items() if f not in optional and o.held(case)]
    unheld += [f"knows its {role} by its L*a*b* alone" for role in ROLES
               if case.known_by_colour(role)]  # fmt: skip
    what = f"read at {', '.join(beyond)}" if beyond else next(iter(unheld), None)
    if what:
        raise CaseFileError(f"{path}: case {case.case_id!r} {what}, which its columns do not hold")


def _csv_row(
    case: Case,
    geometries: tuple[str, ...],
    optional: tuple[str, ...],
    blocks: tuple[tuple[str, str], ...] = MEASURED,
) -> list[str]:
    """A case's row of a case file of ``geometries``, ``optional`` columns and readings'
    ``blocks``: each reading in the form it was read, the other's cells empty."""
    return [
        case.case_id,
        case.shop,
        case.instrument,
        case.conditions,
        case.outcome,
        "1" if case.synthetic else "0",
        case.created_at.isoformat(),
        json.dumps(case.recipe),
        ";".join(case.geometry_names),
        *(_OPTIONAL[f].cell(case) for f in optional),
        *(cell for role, form in blocks for cell in _reading_cells(case, role, form, geometries)),
        *(_fmt(case.target_texture.get(t)) for t in TEXTURE_READINGS),
        *(_fmt(case.sprayout_texture.get(t)) for t in TEXTURE_READINGS),
    ]


def _reading_cells(case: Case, role: str, form: str, geometries: tuple[str, ...]) -> list[str]:
    """A case's cells of its ``role`` reading in ``form`` at the file's ``geometries``: its
    reflectance factors, or its L*a*b* in D65/10 where it knows the reading by its colour
    alone; empty where it was not read so, or not at that geometry."""
    empty = [""] * len(READING_CELLS[form])
    read = case.as_read(role)
    if (form == "colour") != bool(read):
        return empty * len(geometries)
    values = read["stored_lab"] if read else getattr(case, role)
    own = dict(zip(case.geometry_names, values.tolist(), strict=True))  # floats: formatted faster
    return [
        cell for g in geometries for cell in ([f"{v:.6g}" for v in own[g]] if g in own else empty)
    ]


def _fmt(value: float | None) -> str:
    return "" if value is None else f"{value:.6g}"


def read_cases(path: str | PathLike, progress: Callable[[], None] | None = None) -> list[Case]:
    """All cases of a CSV or CxF3 case file; ``progress`` is called for each line of a CSV
    file read."""
    if str(path) == STANDARD_STREAM:
        raise CaseFileError(PIPED_CASES)
    path = Path(path)
    if not path.exists():
        raise CaseFileError(f"{path}: no such file")
    if path.is_dir():  # "Is a directory" before
        raise CaseFileError(f"{path}: a folder, not a case file")
    if path.suffix.lower() in CXF_SUFFIXES:
        return _from_measurements(path, read_cxf(path))
    try:  # row by row: 30,000 cases as one list of cells took 1.45 GB
        with path.open(encoding=text_encoding(path), newline="") as handle:
            lines = handle if progress is None else _told(handle, progress)
            return _cases_from_lines(path, lines)
    except UnicodeDecodeError as error:
        raise CaseFileError(f"{path}: {decoding_problem(error)}") from None


def _told(lines: Iterable[str], progress: Callable[[], None]) -> Iterator[str]:
    for line in lines:
        progress()
        yield line


def count_lines(path: str | PathLike) -> int | None:
    """The lines of a CSV case file, counted in its bytes, as :func:`read_cases` tells them
    (for a progress bar: 0.1 s for 100 MB); None for a CxF3 file, one that cannot be read,
    or a pipe (``/dev/stdin``, ``<(…)``), whose lines counting would consume."""
    if Path(path).suffix.lower() in CXF_SUFFIXES or is_no_regular_file(path):
        return None
    try:
        with open(path, "rb") as handle:
            return sum(chunk.count(b"\n") for chunk in iter(lambda: handle.read(1 << 20), b""))
    except OSError:
        return None


def _cases_from_lines(path: Path, lines: Iterable[str]) -> list[Case]:
    """A case file's cases, separated by commas, or by semicolons or tabs as a spreadsheet
    in most of Europe saves them, with the decimal comma it then uses."""

    def refused(number: int, problem: str) -> CaseFileError:
        return CaseFileError(f"{path}: row {number}: {problem}")

    separator, header, rows = spreadsheet_table(lines, refused)
    separator = separator or ","
    if not header:  # "row 1: expected a header starting with case_id, …" before
        raise CaseFileError(f"{path}: empty file; expected a case history's header and rows")
    if header[: len(CASE_FIELDS)] != list(CASE_FIELDS):
        raise CaseFileError(
            f"{path}: row 1: expected a header starting with {', '.join(CASE_FIELDS)} "
            "(separated by commas, semicolons or tabs)"
        )
    geometries, blocks = _file_geometries(path, header)
    layout = _Layout(header, geometries, blocks, decimal_comma=separator != ",")
    read = [(number, _case_from_row(path, number, layout, row)) for number, row in rows]
    _recover_colours(path, read)
    cases, rows_of = [], {}
    for number, fields in read:
        case = _case_of(f"{path}: row {number}", fields)
        if case.case_id in rows_of:
            raise CaseFileError(
                f"{path}: row {number}: case_id: {case.case_id!r} is also row "
                f"{rows_of[case.case_id]}'s; a case id names one case"
            )
        rows_of[case.case_id] = number
        cases.append(case)
    if not cases:
        raise CaseFileError(f"{path}: no cases after the header")
    return cases


class _Layout:
    """A case file's columns: its header, its geometries and readings' blocks, and the
    cells of each block for a row's geometries, taken from a row at once (found once per set
    of geometries)."""

    def __init__(
        self,
        header: list[str],
        geometries: tuple[str, ...],
        blocks: tuple[tuple[str, str], ...] = MEASURED,
        *,
        decimal_comma: bool = False,
    ) -> None:
        self.header, self.geometries, self.decimal_comma = header, geometries, decimal_comma
        self.blocks = blocks
        self._index = {column: i for i, column in enumerate(header)}
        self._cells: dict = {}

    def cells(self, role: str, form: str, geometries: tuple[str, ...]):
        """The column names of ``role``'s reading in ``form`` at ``geometries``, geometry by
        geometry, and a function that takes their cells from a row."""
        key = (role, form, geometries)
        if key not in self._cells:
            names = _block_columns(((role, form),), geometries)
            self._cells[key] = names, itemgetter(*(self._index[n] for n in names))
        return self._cells[key]


def _file_geometries(path: Path, header: list[str]) -> tuple[tuple[str, ...], tuple]:
    """The geometries and readings' blocks whose columns the header holds, checked to be
    every column they need, and each role to be given in some form."""
    columns = [c.split(":") for c in header[len(CASE_FIELDS) :] if c.count(":") == 2]
    geometries = tuple(dict.fromkeys(g for role, g, _ in columns if role in ROLES))
    forms = {(role, "colour" if cell in READING_CELLS["colour"] else "spectra")
             for role, _, cell in columns}  # fmt: skip
    blocks = tuple(
        (role, form) for role in ROLES for form in READING_CELLS if (role, form) in forms
    )
    absent = [role for role in ROLES if not any(r == role for r, _ in blocks)]
    if absent and geometries:
        raise CaseFileError(
            f"{path}: row 1: no {absent[0]} readings: expected {absent[0]}:<geometry>:<nm> "
            f"reflectance columns, or {absent[0]}:<geometry>:L, :a and :b"
        )
    optional = tuple(f for f in (*OPTIONAL_FIELDS, *RECOVERED_FIELDS) if f in header)
    expected = _header(geometries, optional, blocks or MEASURED)
    if tuple(header) != expected:
        missing = [c for c in expected if c not in header]
        extra = [c for c in header if c not in expected]
        wrong = [f"{len(missing)} missing, e.g. {missing[:3]}"] if missing else []
        wrong += [f"{len(extra)} unexpected, e.g. {extra[:3]}"] if extra else []
        wrong = wrong or ["in another order"]
        raise CaseFileError(
            f"{path}: row 1: expected the columns of geometries {';'.join(geometries) or 'none'}"
            f" ({'; '.join(wrong)})"
        )
    return geometries, blocks


def _case_from_row(path: Path, number: int, layout: _Layout, row: list[str]) -> dict:
    """A row's case, as the fields of a :class:`Case`; a reading known by its colour is given
    as its L*a*b* ``[G, 3]`` under ``colours`` (its spectrum recovered for the whole file at
    once, :func:`_recover_colours`)."""
    where = f"{path}: row {number}"
    header, columns = layout.header, layout.geometries
    if len(row) != len(header):
        raise CaseFileError(f"{where}: expected {len(header)} columns, got {len(row)}")
    cells = dict(zip(header, row, strict=True))
    geometries = tuple(g for g in cells["geometries"].split(";") if g)
    unknown = [g for g in geometries if g not in columns]
    if unknown or not geometries:
        raise CaseFileError(
            f"{where}: geometries: expected some of the file's {';'.join(columns)}, "
            f"got {cells['geometries']!r}"
        )
    others = tuple(g for g in columns if g not in geometries)
    unread = [c for c in _block_columns(layout.blocks, others) if cells[c].strip()]
    if unread:
        raise CaseFileError(
            f"{where}: {unread[0]}: a value at a geometry the row's geometries "
            f"({cells['geometries']}) do not list; leave it empty"
        )

    def number_of(column: str) -> float:
        try:
            value = float(decimal_point(cells[column]) if layout.decimal_comma else cells[column])
        except ValueError:
            raise CaseFileError(
                f"{where}: {column}: expected a number, got {cells[column]!r}"
            ) from None
        if not math.isfinite(value):
            raise CaseFileError(f"{where}: {column}: expected a finite number")
        return value

    def values(role: str, form: str) -> np.ndarray:
        names, cells_of = layout.cells(role, form, geometries)
        read = cells_of(row)
        found = numbers_at_once([decimal_point(c) for c in read] if layout.decimal_comma else read)
        if found is None:  # the cell that stops them, named
            found = np.array([number_of(name) for name in names])
        return found.reshape(len(geometries), len(READING_CELLS[form]))

    def given(role: str, form: str) -> bool:
        if (role, form) not in layout.blocks:
            return False
        return any(c.strip() for c in layout.cells(role, form, geometries)[1](row))

    def texture(role: str) -> dict[str, float]:
        return {t: number_of(f"{role}:{t}") for t in TEXTURE_READINGS if cells[f"{role}:{t}"]}

    recipe = _recipe_field(f"{where}: recipe", cells["recipe"])
    tins = _tins_field(f"{where}: tins", cells.get(TINS_FIELD, ""))
    created = _date_field(f"{where}: created_at", cells["created_at"])
    for flag in ("synthetic", *RECOVERED_FIELDS):
        if cells.get(flag, "0") not in _FLAGS:
            raise CaseFileError(f"{where}: {flag}: expected 0 or 1, got {cells[flag]!r}")
    readings: dict = {"colours": {}}
    for role in ROLES:
        by_colour = given(role, "colour")
        if by_colour and given(role, "spectra"):
            raise CaseFileError(
                f"{where}: {role}: given as reflectance factors and as L*a*b*; a reading is "
                "read in one form, measured or known by its colour alone"
            )
        flag = f"{role}_recovered"
        if flag in cells and (role, "colour") in layout.blocks and _FLAGS[cells[flag]] != by_colour:
            raise CaseFileError(
                f"{where}: {flag}: {cells[flag]}, where the {role} is given as "
                f"{'L*a*b*' if by_colour else 'reflectance factors'}"
            )
        if by_colour or (role, "spectra") not in layout.blocks:  # an empty colour, named
            readings["colours"][role] = values(role, "colour")
        else:
            readings[role] = values(role, "spectra")
        readings[flag] = by_colour or _FLAGS[cells.get(flag, "0")]
    return dict(
        case_id=cells["case_id"],
        geometries=geometries,
        recipe=recipe,
        **readings,
        target_texture=texture("target"),
        sprayout_texture=texture("sprayout"),
        instrument=cells["instrument"],
        shop=cells["shop"],
        conditions=cells["conditions"],
        outcome=cells["outcome"],
        synthetic=_FLAGS[cells["synthetic"]],
        created_at=created,
        tins=tins,
        colour_code=cells.get(CODE_FIELD, ""),
    )


def _recover_colours(path: Path, rows: list[tuple[int, dict]]) -> None:
    """Give each reading the rows know by its colour (``fields["colours"]``) its spectrum,
    recovered from its L*a*b* in D65/10, all at once (:func:`~flakelab.io.records.
    recovered_spectra`); a colour no surface reflects is refused naming its row, role and
    geometry."""
    known = [(number, fields, role, lab) for number, fields in rows
             for role, lab in fields.pop("colours").items()]  # fmt: skip
    if not known:
        return
    lab = np.concatenate([k[3] for k in known])
    places = [f"row {number}: {role}:{g}" for number, fields, role, _ in known
              for g in fields["geometries"]]  # fmt: skip
    try:
        spectra = recovered_spectra(path, lab, places)
    except MeasurementFileError as error:  # a case file's error, as its others
        raise CaseFileError(str(error)) from None
    start = 0
    for _, fields, role, colour in known:
        fields[role] = spectra[start : start + len(colour)]
        start += len(colour)


def _case_of(where: str, fields: dict) -> Case:
    try:
        return Case(**fields)
    except (CaseError, ValueError) as error:
        raise CaseFileError(f"{where}: {error}") from None


def _recipe_field(where: str, text: str) -> dict:
    """A case's recipe as its file writes it: a JSON object toner → amount."""
    try:
        recipe = json_value(text)
    except ValueError:
        recipe = None
    if not isinstance(recipe, dict):
        raise CaseFileError(f"{where}: expected a JSON object toner → amount, got {shown(text)}")
    return recipe


def _tins_field(where: str, text: str) -> dict:
    """A case's tins as its file writes them (:func:`_tins_cell`): none where empty."""
    if not text.strip():
        return {}
    try:
        tins = json_value(text)
    except ValueError:
        tins = None
    if not isinstance(tins, dict):
        raise CaseFileError(
            f"{where}: expected a JSON object toner → {{lot, strength, shade_nm}}, got "
            f"{shown(text)}"
        )
    return tins


def _date_field(where: str, text: str) -> datetime:
    try:
        return read_time(text)
    except ValueError:
        raise CaseFileError(f"{where}: expected {TIME_EXPECTED}, got {text!r}") from None


def _as_measurements(case: Case) -> tuple[Measurement, Measurement]:
    meta = {
        "case_id": case.case_id,
        "shop": case.shop,
        "conditions": case.conditions,
        "outcome": case.outcome,
        "synthetic": "1" if case.synthetic else "0",
        "created_at": case.created_at.isoformat(),
        "recipe": json.dumps(case.recipe),
        **({TINS_FIELD: _tins_cell(case)} if case.tins else {}),
        **({CODE_FIELD: case.colour_code} if case.colour_code else {}),
    }
    common = {
        "geometries": case.geometries,
        "wavelengths": WAVELENGTHS,
        "instrument": case.instrument,
    }
    return (
        Measurement(
            f"{case.case_id}/target",
            reflectance=case.target,
            texture=case.target_texture,
            metadata=meta,
            **common,
            **case.as_read("target"),
        ),
        Measurement(
            f"{case.case_id}/sprayout",
            reflectance=case.sprayout,
            texture=case.sprayout_texture,
            metadata={"case_id": case.case_id},
            **common,
            **case.as_read("sprayout"),
        ),
    )


def _from_measurements(path: Path, measurements: list[Measurement]) -> list[Case]:
    by_name = {m.sample: m for m in measurements}
    sprayed = [n.removesuffix("/sprayout") for n in by_name if n.endswith("/sprayout")]
    orphan = next((case_id for case_id in sprayed if f"{case_id}/target" not in by_name), None)
    if orphan is not None:
        raise CaseFileError(
            f"{path}: sample '{orphan}/sprayout': no matching '{orphan}/target' sample"
        )
    cases = []
    for name, target in by_name.items():
        if not name.endswith("/target"):
            continue
        case_id = name[: -len("/target")]
        sprayout = by_name.get(f"{case_id}/sprayout")
        where = f"{path}: sample {name!r}"
        if sprayout is None:
            raise CaseFileError(f"{where}: no matching '{case_id}/sprayout' sample")
        try:
            check_readings_kept(target, sprayout)
        except CaseError as error:  # a shop's history of colours alone
            raise CaseFileError(f"{path}: {error}") from None
        meta = target.metadata
        missing = [k for k in ("recipe", "outcome", "created_at") if k not in meta]
        if missing:
            raise CaseFileError(f"{where}: missing meta tags {missing}")
        recipe = _recipe_field(f"{where}: meta tag recipe", meta["recipe"])
        created = _date_field(f"{where}: meta tag created_at", meta["created_at"])
        tins = _tins_field(f"{where}: meta tag tins", meta.get(TINS_FIELD, ""))
        try:
            cases.append(
                Case(
                    case_id=case_id,
                    geometries=target.geometries,
                    recipe=recipe,
                    target=target.reflectance,
                    sprayout=sprayout.reflectance,
                    target_texture=target.texture,
                    sprayout_texture=sprayout.texture,
                    instrument=target.instrument or "unknown",
                    shop=meta.get("shop", "unknown"),
                    conditions=meta.get("conditions", DEFAULT_CONDITIONS),
                    outcome=meta["outcome"],
                    synthetic=meta.get("synthetic") == "1",
                    created_at=created,
                    tins=tins,
                    colour_code=meta.get(CODE_FIELD, ""),
                    target_recovered=target.spectra_recovered,
                    sprayout_recovered=sprayout.spectra_recovered,
                )
            )
        except (CaseError, ValueError) as error:
            raise CaseFileError(f"{where}: {error}") from None
    if not cases:
        raise CaseFileError(f"{path}: no '<case>/target' samples: not a case history")
    return cases
