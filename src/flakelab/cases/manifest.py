"""A shop's spray-out history from its own instrument files, through a manifest.

A shop that has been measuring its cars and spray-outs keeps the instrument's exports (MA-T12
xlsx, CxF3, CSV, JSON) and the recipes it mixed. A manifest lists them, one spray-out per
row, and ``flakelab cases record-all`` records every row as ``flakelab cases record`` would:
in one transaction, or not at all.

Manifest columns (CSV with a header, separated by commas, or by semicolons or tabs as a
spreadsheet in most of Europe saves it; file paths relative to the manifest's folder):

=================  ====================================================================
``target``         measurement file of the car (required)
``recipe``         recipe file ``{toner: grams}`` that was sprayed (required)
``sprayed``        measurement file of the spray-out (required)
``sample``         the car's sample in a multi-sample file (default: the file's first)
``sprayed_sample`` the spray-out's sample (default: the file's first)
``shop``           the shop (default: the command's ``--shop``)
``outcome``        ``auto`` (judged against the tolerance), ``accepted``, ``corrected``
                   or ``rejected`` (default ``auto``)
``at``             when the spray-out was made, ISO 8601 or ``22.11.2026 09:30``, local
                   time without a zone (default: the spray-out file's date)
``case_id``        the case's id (default: made from the readings, recipe and shop)
``lots``           the shop's toner-lot file when it was sprayed (``flakelab lots``): the
                   case records the tins of its recipe's toners (default: none)
``colour_code``    the car maker's code for the car's colour, as on its plate ('Toyota
                   1G3'; default: none)
=================  ====================================================================
"""

from __future__ import annotations

from collections.abc import Iterable
from datetime import datetime
from os import PathLike
from pathlib import Path

from flakelab.cases.case import Case
from flakelab.cases.record import AUTO_OUTCOME, case_from_readings
from flakelab.core.measurement import Measurement
from flakelab.core.times import TIME_EXPECTED, read_time, zoned_here
from flakelab.core.tolerance import Tolerance
from flakelab.errors import FlakelabError
from flakelab.io import pick_sample, read_measurements, read_recipe
from flakelab.io.lots_file import read_lots
from flakelab.io.records import (
    decoding_problem,
    spreadsheet_table,
    text_encoding,
)
from flakelab.library import Library
from flakelab.library.lots import TonerLot, TonerLots

__all__ = ["MANIFEST_COLUMNS", "ManifestError", "cases_from_manifest", "read_manifest"]

MANIFEST_COLUMNS = (
    "target",
    "recipe",
    "sprayed",
    "sample",
    "sprayed_sample",
    "shop",
    "outcome",
    "at",
    "case_id",
    "lots",
    "colour_code",
)
REQUIRED_COLUMNS = ("target", "recipe", "sprayed")


class ManifestError(FlakelabError):
    """A manifest that is wrong: names the file, row, column and problem."""


def read_manifest(path: str | PathLike) -> list[tuple[int, dict[str, str]]]:
    """The manifest's rows ``(row number, {column: cell})``, blank rows skipped; the header
    must name the required columns and no unknown one."""
    path = Path(path)
    try:
        text = path.read_text(encoding=text_encoding(path))  # UTF-16: "Unicode Text"
    except FileNotFoundError:
        raise ManifestError(f"{path}: no such manifest file") from None
    except UnicodeDecodeError as error:
        raise ManifestError(f"{path}: {decoding_problem(error)}") from None
    except OSError as error:
        raise ManifestError(f"{path}: cannot be read as a CSV manifest ({error})") from None

    def refused(number: int, problem: str) -> ManifestError:
        return ManifestError(f"{path}: row {number}: {problem}")

    _, header, rows = spreadsheet_table(text.splitlines(), refused)
    header = [cell.strip() for cell in header or []]
    unknown = [c for c in header if c not in MANIFEST_COLUMNS]
    missing = [c for c in REQUIRED_COLUMNS if c not in header]
    twice = sorted({c for c in header if header.count(c) > 1})
    if unknown or missing or twice:
        found = {"missing": missing, "unknown": unknown, "twice": twice}
        wrong = [f"{name} {columns}" for name, columns in found.items() if columns]
        raise ManifestError(
            f"{path}: row 1: expected a header with {', '.join(REQUIRED_COLUMNS)} and any of "
            f"{', '.join(MANIFEST_COLUMNS[3:])}, each once ({', '.join(wrong)})"
        )
    entries = []
    for number, row in rows:
        if len(row) != len(header):
            raise ManifestError(
                f"{path}: row {number}: expected {len(header)} cells, got {len(row)}"
            )
        cells = {c: v.strip() for c, v in zip(header, row, strict=True)}
        for column in REQUIRED_COLUMNS:
            if not cells[column]:
                raise ManifestError(f"{path}: row {number}: {column}: expected a file, got none")
        entries.append((number, cells))
    if not entries:
        raise ManifestError(f"{path}: no spray-outs after the header")
    return entries


def cases_from_manifest(
    path: str | PathLike,
    library: Library,
    *,
    tolerance: Tolerance,
    shop: str = "unknown",
    instrument: str | None = None,
    rows: Iterable[tuple[int, dict[str, str]]] | None = None,
) -> list[tuple[int, Case]]:
    """Every row's number and case (:func:`~flakelab.cases.record.case_from_readings`); the
    first problem names the manifest, row and column, and no case is returned. Two rows with
    the same readings, recipe and shop are refused. ``rows`` are the manifest's, as
    :func:`read_manifest` gives them (read here when None; a caller may pass them through a
    progress bar)."""
    path = Path(path)
    files: dict[Path, list[Measurement]] = {}  # a car's file serves several rows, read once
    lot_files: dict[Path, TonerLots] = {}  # so does a lot file

    def named_file(where: str, cell: str) -> Path:
        if "\x00" in cell:  # the operating system's own words are "embedded null byte"
            raise ManifestError(f"{where}: {cell!r}: a file name cannot hold a NUL character")
        return path.parent / cell

    def reading(where: str, file: str, sample: str) -> Measurement:
        name = named_file(where, file)
        try:
            if name not in files:
                files[name] = read_measurements(name)
            return pick_sample(files[name], sample or None, name)
        except (FlakelabError, OSError, KeyError, ValueError) as error:
            raise ManifestError(f"{where}: {error}") from None

    def tins(where: str, file: str) -> dict[str, TonerLot] | None:
        if not file:
            return None
        name = named_file(where, file)
        try:
            if name not in lot_files:
                lot_files[name] = read_lots(name, library.names)
        except (FlakelabError, OSError) as error:
            raise ManifestError(f"{where}: {error}") from None
        return dict(lot_files[name].lots)

    cases: list[tuple[int, Case]] = []
    first_row: dict[str, int] = {}
    for number, cells in read_manifest(path) if rows is None else rows:
        where = f"{path}: row {number}"
        target = reading(f"{where}: target", cells["target"], cells.get("sample", ""))
        sprayed = reading(f"{where}: sprayed", cells["sprayed"], cells.get("sprayed_sample", ""))
        recipe = named_file(f"{where}: recipe", cells["recipe"])
        try:
            grams = read_recipe(recipe)
            fractions = library.fractions(grams)
        except (FlakelabError, ValueError) as error:
            raise ManifestError(f"{where}: recipe: {error}") from None
        when = _time(where, cells.get("at", ""))
        poured_from = tins(f"{where}: lots", cells.get("lots", ""))
        try:
            case = case_from_readings(
                target,
                sprayed,
                {n: f for n, f in zip(library.names, fractions.tolist(), strict=True) if f},
                instrument,
                shop=cells.get("shop") or shop,
                outcome=cells.get("outcome") or AUTO_OUTCOME,
                tolerance=tolerance,
                created_at=when,
                case_id=cells.get("case_id") or None,
                tins=poured_from,
                colour_code=cells.get("colour_code", ""),
            )
        except (FlakelabError, ValueError) as error:
            raise ManifestError(f"{where}: {error}") from None
        if case.case_id in first_row:
            raise ManifestError(
                f"{where}: case {case.case_id}: the same readings, recipe and shop as row "
                f"{first_row[case.case_id]} (or the same case_id)"
            )
        first_row[case.case_id] = number
        cases.append((number, case))
    return cases


def _time(where: str, cell: str) -> datetime | None:
    if not cell:
        return None
    try:
        when = read_time(cell)
    except ValueError:
        raise ManifestError(f"{where}: at: expected {TIME_EXPECTED}, got {cell!r}") from None
    return zoned_here(when)
