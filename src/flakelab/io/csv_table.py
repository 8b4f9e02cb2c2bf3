"""CSV: a row per sample × geometry (the layout of ../shared/data), or a row per sample.

A row per reading: columns, in any order after the first two,

``sample``, ``geometry``          required; geometry as an ASTM name (``45as15``)
``R400`` … ``R700``               reflectance factor per wavelength [0–1]; any regular grid
``L``, ``a``, ``b``               optional stored L*a*b* under ``lab_conditions`` (default D65/10);
                                  also headed ``L*``, ``a*``, ``b*``
``L``, ``C``, ``h``               or L*C*h° [h in degrees] (``L*``, ``C*``, ``h°`` or ``hab``)
``X``, ``Y``, ``Z``               or XYZ [Y 0–100] under ``lab_conditions``
``instrument``, ``measured_at``   optional; ISO 8601 date-time, or ``22.11.2026 09:30``
``Sa15`` … ``G``                  optional texture readings; repeated on every row of a sample;
                                  also headed ``Sa 15°``, ``Si_45``
``lab_conditions``                optional, e.g. ``D65/10``

A row per sample (``wide``, as a spreadsheet of panels holds them): no ``geometry`` column;
each quantity above is headed with the geometry it was read at, either first, joined by a
space, an underscore, ``@``, ``:`` or nothing: ``L* 45as15``, ``45as15 L*``, ``R400_45as15``,
``h°45as110``. An aspecular angle alone (``L* 15°``, ``a*-15``, ``as25 b*``), as multi-angle
instruments head their readings, is taken at the 45° lamp
(:data:`~flakelab.core.geometry.LAMP_OF_AN_ASPECULAR_ANGLE`), and a note says so. A sample's
cells at a geometry it was not read at are left empty. Texture, ``instrument``,
``measured_at`` and ``lab_conditions`` are columns as above.

A sheet of an MA-T12 export saved as CSV (a spreadsheet saves the sheet it shows) is read as
the workbook's sheet is: its ``QC JOB:``, ``STANDARD:``, ``ILLUMINANT/OBSERVER:`` rows, then
``Name, Date/Time, Geometry`` for ``sample, measured_at, geometry``, and ``L* (D65/10)`` …
or wavelengths; rows are named as the spreadsheet numbers them.

A row may state its colour in several of these forms, as instruments export them; the first
(L*a*b*, then L*C*h°, then XYZ) is kept, and the others must agree with it to ΔE00
:data:`~flakelab.io.records.STATED_ALIKE` (:func:`~flakelab.io.records.agreed_colour`).

A file of a colour without spectra (an instrument that exports colour alone, a
paint maker's data sheet) is read with spectra recovered from its colour (one metamer of
many, :func:`~flakelab.core.colorimetry.reflectance_from_Lab`), and says so
(``Measurement.spectra_recovered``).

Lines starting with ``#`` are comments. Comma, semicolon or tab separated (detected); a
semicolon or tab separated file may write its numbers with a decimal comma (``0,2039``), as
spreadsheets do in most of Europe.
"""

from __future__ import annotations

import csv
import io
import re
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import datetime
from os import PathLike
from pathlib import Path

import numpy as np

from flakelab.core.colorimetry import D65_10, Conditions
from flakelab.core.geometry import LAMP_OF_AN_ASPECULAR_ANGLE, Geometry
from flakelab.core.measurement import TEXTURE_READINGS, Measurement
from flakelab.core.spectra import WAVELENGTHS
from flakelab.core.times import TIME_EXPECTED, read_time
from flakelab.errors import MeasurementFileError, Note
from flakelab.io.mat12_xlsx import (
    PREAMBLE_KEYS,
    ROW_KEYS,
    instrument_of_sheet,
    job_of,
    split_sheet,
)
from flakelab.io.records import (
    Reading,
    agreed_colour,
    assemble,
    colour_alone,
    csv_form,
    decimal_comma_in,
    decimal_point,
    decoding_problem,
    filled_width,
    parse_colour,
    parse_conditions,
    parse_geometry_name,
    parse_spectrum,
    parse_texture,
    parse_wavelength_header,
    recovered_readings,
    spreadsheet_table,
    within,
    write_atomically,
)

__all__ = ["read_csv", "write_csv"]

_COLOUR_COLUMNS = {
    "Lab": (("L", "L*"), ("a", "a*"), ("b", "b*")),
    "LCh": (("L", "L*"), ("C", "C*"), ("h", "h°", "hab")),
    "XYZ": (("X",), ("Y",), ("Z",)),
}
"""The headers each form of a stated colour is read under, coordinate by coordinate, in the
order of :data:`~flakelab.core.colorimetry.STATED_AS`."""

_COLOUR_NAMES = {name for form in _COLOUR_COLUMNS.values() for names in form for name in names}

_META = ("sample", "geometry", "instrument", "measured_at", "lab_conditions", *_COLOUR_NAMES)


def _colour_columns(
    path: str | PathLike, columns: dict[str, int], where: str, header: list[str]
) -> dict[str, list[int]]:
    """The columns of each form of colour the header states (L*a*b*, L*C*h°, XYZ), by the
    names of :data:`_COLOUR_COLUMNS`; a coordinate headed twice (``L`` and ``L*``), or colour
    columns no whole form uses (``C`` without ``h``), refused naming them."""
    headed: dict[str, list[str]] = {}
    for form, coordinates in _COLOUR_COLUMNS.items():
        headed[form] = []
        for names in coordinates:
            twice = [name for name in names if name in columns]
            if len(twice) > 1:
                raise MeasurementFileError(
                    path,
                    f"columns {header[columns[twice[0]]]!r} and {header[columns[twice[1]]]!r} "
                    "both give one value",
                    field=where,
                )  # fmt: skip
            headed[form] += twice
    forms = {
        form: [columns[name] for name in names]
        for form, names in headed.items()
        if len(names) == len(_COLOUR_COLUMNS[form])
    }
    used = {i for indices in forms.values() for i in indices}
    partial = [
        (form, names)
        for form, names in headed.items()
        if form not in forms and any(columns[name] not in used for name in names)
    ]
    if partial:
        form, names = max(partial, key=lambda p: len(p[1]))
        wanted = ", ".join(names[0] for names in _COLOUR_COLUMNS[form])
        raise MeasurementFileError(
            path,
            f"{'column' if len(names) == 1 else 'columns'} "
            f"{', '.join(header[columns[name]] for name in names)} without the rest "
            f"of a colour: {form} needs {wanted}",
            field=where,
        )
    return forms


def _conditions_named(
    path: str | PathLike,
    rows: list[tuple[int, list[str]]],
    column: int | None,
    stated: Conditions | None = None,
) -> Conditions:
    """The one ``lab_conditions`` the rows name (else those the header ``stated``, else
    D65/10); a row naming others than an earlier row is refused, naming both."""
    first: tuple[int, str] | None = None
    for number, row in rows if column is not None else ():
        named = row[column].strip() if column < len(row) else ""
        if named and first is None:
            first = number, named
        elif named and named != first[1]:
            raise MeasurementFileError(
                path,
                f"{named!r}, where row {first[0]} names {first[1]!r}: a file's colours are "
                "stated under one set of conditions",
                field=f"row {number}, lab_conditions",
            )
    if first is None:
        return stated or D65_10
    return parse_conditions(path, first[1], f"row {first[0]}, lab_conditions")


def _decimal_points(row: list[str], numeric: list[int]) -> list[str]:
    """A row with its numeric cells' decimal commas read as points (``0,25`` → ``0.25``)."""
    row = list(row)
    for i in numeric:
        if i < len(row):
            row[i] = decimal_point(row[i])
    return row


_ANGLE = r"[-+]?\d+(?:\.\d+)?"
_AT = rf"(?:\d+(?:\.\d+)?\s*)?(?i:as)\s*{_ANGLE}(?:\s*(?i:az)\s*{_ANGLE})?|{_ANGLE}\s*°?"
_QUANTITY = r"hab|h°|[LabCh]\*?|[XYZ]|R?\d{3}(?:\.\d+)?(?:\s*nm)?"
_AT_GEOMETRY = (
    re.compile(rf"^(?P<q>{_QUANTITY})[\s_@:]*(?P<g>{_AT})$"),
    re.compile(rf"^(?P<g>{_AT})[\s_@:]+(?P<q>{_QUANTITY})$"),
)
"""A column of the wide layout: a quantity (a colour coordinate of :data:`_COLOUR_COLUMNS` or
a wavelength) at a geometry, either first: ``L* 45as15``, ``L*15°``, ``a*_-15``, ``R400
45as15``, ``45as15 L*``."""

_QUANTITY_ALONE = re.compile(rf"^(?:{_QUANTITY})$")
_ROW_COLUMNS = ("sample", "instrument", "measured_at", "lab_conditions", "texture (Sa15 … G)")
"""The columns a wide file gives once per row (named in a message)."""

_TEXTURE_SPELT = re.compile(r"^(S[ai])[\s_]*(15|45|75)\s*°?$")
"""A sparkle reading headed with its lamp's angle apart (``Sa 15°``, ``Si_45``)."""


def _texture_named(header: str) -> str:
    """A header as :data:`~flakelab.core.measurement.TEXTURE_READINGS` names it where it heads a
    sparkle reading (``Sa 15°`` → ``Sa15``); any other as it stands."""
    spelt = _TEXTURE_SPELT.match(header)
    return f"{spelt[1]}{spelt[2]}" if spelt else header


_ASPECULAR_ALONE = re.compile(rf"^(?i:as)?\s*({_ANGLE})\s*°?$")


@dataclass(frozen=True)
class _Block:
    """Where a row gives one reading: at ``geometry`` (None: the one its ``geometry`` cell
    names), labelled as the header labels it; its reflectance columns and its colour's columns
    by form, and each column's name in messages."""

    geometry: Geometry | None
    label: str
    spectral: list[int]
    forms: dict[str, list[int]]
    names: dict[int, str]
    lamp_unsaid: bool = False

    @property
    def cells(self) -> list[int]:
        return [*self.spectral, *(i for indices in self.forms.values() for i in indices)]


def _split_wide(header: list[str]) -> dict[int, tuple[str, str]]:
    """The columns of the header that give a quantity at a geometry: index → (quantity,
    geometry as headed)."""
    found = {}
    for i, name in enumerate(header):
        if name in _META or name in TEXTURE_READINGS:
            continue
        match = next((m for p in _AT_GEOMETRY if (m := p.match(name))), None)
        if match is not None:
            found[i] = match["q"].strip(), match["g"].strip()
    return found


def _headed_geometry(path: str | PathLike, label: str, column: str) -> tuple[Geometry, bool]:
    """The geometry a wide column's label names, and whether it named an aspecular angle alone
    (taken at :data:`~flakelab.core.geometry.LAMP_OF_AN_ASPECULAR_ANGLE`)."""
    alone = _ASPECULAR_ALONE.match(label)
    try:
        if alone is not None:
            return Geometry(LAMP_OF_AN_ASPECULAR_ANGLE, float(alone[1])), True
        return Geometry.parse(label), False
    except ValueError as error:
        raise MeasurementFileError(path, str(error), field=f"header, {column}") from None


def _long_blocks(path: str | PathLike, header: list[str]) -> list[_Block]:
    """The one reading a row of the long layout gives."""
    columns = {h: i for i, h in enumerate(header)}
    spectral = [i for i, h in enumerate(header) if h not in _META and h not in TEXTURE_READINGS]
    names = dict(enumerate(header))
    return [_Block(None, "", spectral, _colour_columns(path, columns, "header", header), names)]


def _wide_blocks(
    path: str | PathLike, header: list[str], wide: dict[int, tuple[str, str]]
) -> list[_Block]:
    """The readings a row of the wide layout gives, one per geometry in the header's order;
    a column the layout does not read, or a geometry headed in two ways, refused by name."""
    loose = [
        h for i, h in enumerate(header)
        if i not in wide and (h in _COLOUR_NAMES or h not in _META and h not in TEXTURE_READINGS)
    ]  # fmt: skip
    if loose:
        quantity = _QUANTITY_ALONE.match(loose[0])
        raise MeasurementFileError(
            path,
            f"column {loose[0]!r} "
            + ("gives no geometry" if quantity else "is no quantity flakelab reads")
            + ": a file without a geometry column heads each quantity with its geometry, such "
            f"as 'L* 45as15', 'a* 15°' or 'R400 45as15', beside {', '.join(_ROW_COLUMNS)}",
            field="header",
        )
    quantities: dict[Geometry, dict[str, int]] = {}
    labels: dict[Geometry, str] = {}
    unsaid: set[Geometry] = set()
    for i, (quantity, label) in wide.items():
        geometry, lamp_unsaid = _headed_geometry(path, label, header[i])
        if geometry in labels and (geometry in unsaid) != lamp_unsaid:
            raise MeasurementFileError(
                path,
                f"{geometry.name} is headed both {labels[geometry]!r} and {label!r}, its lamp "
                "unsaid in one: name it alike in both",
                field=f"header, {header[i]}",
            )
        if quantity in quantities.setdefault(geometry, {}):
            first = header[quantities[geometry][quantity]]
            raise MeasurementFileError(
                path, f"columns {first!r} and {header[i]!r} both give one value", field="header"
            )
        quantities[geometry][quantity] = i
        labels.setdefault(geometry, label)
        if lamp_unsaid:
            unsaid.add(geometry)
    blocks = []
    for geometry, named in quantities.items():
        where = f"header, {labels[geometry]}"
        forms = _colour_columns(path, named, where, header)
        spectral = [i for q, i in named.items() if q not in _COLOUR_NAMES]
        names = {i: q for q, i in named.items()}
        blocks.append(
            _Block(geometry, labels[geometry], spectral, forms, names, geometry in unsaid)
        )
    return blocks


def _note_lamps_unsaid(path: str | PathLike, blocks: list[_Block]) -> None:
    """Say which of a wide file's geometries were headed by an aspecular angle alone, and
    read at :data:`~flakelab.core.geometry.LAMP_OF_AN_ASPECULAR_ANGLE`."""
    unsaid = [f"{b.label} as {b.geometry.name}" for b in blocks if b.lamp_unsaid]
    if unsaid:
        warnings.warn(
            f"{path}: aspecular angles alone are read at a "
            f"{LAMP_OF_AN_ASPECULAR_ANGLE:g}° lamp ({', '.join(unsaid)}), as multi-angle "
            "instruments name their readings",
            Note,
            stacklevel=4,
        )


def _grid(path: str | PathLike, blocks: list[_Block]) -> np.ndarray:
    """The wavelengths [nm] of the file's reflectance columns, one grid for every geometry
    (:data:`WAVELENGTHS` where it gives colour alone); a geometry without them, or on another
    grid, refused by name."""
    spectral = [block for block in blocks if block.spectral]
    if not spectral:
        return WAVELENGTHS
    grids = []
    for block in spectral:
        where = f"header, {block.label}" if block.geometry is not None else "header"
        labels = [block.names[i] for i in block.spectral]
        grids.append(parse_wavelength_header(
            path, labels, where, [f"column {i + 1}" for i in block.spectral]
        ))  # fmt: skip
        if grids[-1].shape != grids[0].shape or not np.allclose(grids[-1], grids[0]):
            raise MeasurementFileError(
                path,
                f"{block.label}'s reflectance columns lie on another wavelength grid than "
                f"{spectral[0].label}'s",
                field=where,
            )
    bare = next((block for block in blocks if not block.spectral), None)
    if bare is not None:
        raise MeasurementFileError(
            path,
            f"{bare.label} has no reflectance columns where {spectral[0].label} has: a file gives "
            "spectra at every geometry, or colour alone",
            field=f"header, {bare.label}",
        )
    return grids[0]


def read_csv(path: str | PathLike, text: str | None = None) -> list[Measurement]:
    """Read measurements from a CSV file in either layout above."""
    if text is None:
        try:
            text = Path(path).read_text(encoding="utf-8-sig")
        except UnicodeDecodeError as error:
            raise MeasurementFileError(path, decoding_problem(error)) from None
    lines = [
        line for line in text.splitlines() if line.strip() and not line.lstrip().startswith("#")
    ]

    def refused(number: int, problem: str) -> MeasurementFileError:
        return MeasurementFileError(path, problem, field=f"row {number}")

    delimiter, header, rows = spreadsheet_table(io.StringIO("\n".join(lines)), refused)
    if header is None:
        raise MeasurementFileError(path, "empty CSV file")
    sheet, stated = None, None
    if _opens_a_sheet(header):
        sheet, header, rows = _export_sheet(path, header, rows)
    if delimiter is None:
        raise MeasurementFileError(
            path, "no comma, semicolon or tab separated header", field="header"
        )
    header = [_texture_named(h.strip()) for h in header]
    if sheet is not None:
        header, stated = _sheet_header(path, header, sheet)
    columns = {h: i for i, h in enumerate(header)}
    wide = _checked_header(path, header, columns)
    blocks = _wide_blocks(path, header, wide) if wide else _long_blocks(path, header)
    if not any(block.cells for block in blocks):
        saved = "; a sheet saved alone: save its Spectral Data or Color Data sheet" if sheet else ""
        raise MeasurementFileError(
            path,
            "no reflectance columns such as R400, nor a colour: L, a, b (or L, C, h, or X, Y, Z)"
            + saved,
            field="header",
        )
    wavelengths = _grid(path, blocks)
    lab_alone = not any(block.spectral for block in blocks)  # spectra recovered from the colour
    if delimiter != ",":  # the comma is free to be the decimal mark
        texture_columns = [columns[k] for k in TEXTURE_READINGS if k in columns]
        numeric = [*(i for block in blocks for i in block.cells), *texture_columns]
        rows = ((number, _decimal_points(row, numeric)) for number, row in rows)
    rows = list(rows)
    lab_conditions = _conditions_named(path, rows, columns.get("lab_conditions"), stated)

    readings, texture, instruments = [], {}, set()
    for number, row in rows:
        where = f"row {number}"
        if len(row) != len(header):
            raise MeasurementFileError(
                path,
                f"expected {len(header)} columns, got {len(row)} (truncated line?)",
                field=where,
            )
        sample = row[columns["sample"]].strip()
        if not sample:
            raise MeasurementFileError(path, "empty sample name", field=f"{where}, sample")
        measured_at = _measured_at(path, row, columns, where)
        for k in TEXTURE_READINGS:
            if k in columns and row[columns[k]].strip():
                value = parse_texture(path, row[columns[k]], f"{where}, {k}")
                previous = texture.setdefault(sample, {}).setdefault(k, value)
                if previous != value:
                    raise MeasurementFileError(
                        path,
                        f"texture {k} of {sample!r} differs between rows ({previous} vs {value})",
                        field=f"{where}, {k}",
                    )
        if "instrument" in columns and row[columns["instrument"]].strip():
            instruments.add(row[columns["instrument"]].strip())
        read = len(readings)
        for block in blocks:
            if block.geometry is None:
                geometry = parse_geometry_name(path, row[columns["geometry"]], f"{where}, geometry")
                at = where
            elif any(row[i].strip() for i in block.cells):
                geometry, at = block.geometry, f"{where}, {block.label}"
            else:  # the sample was not read at this geometry
                continue
            readings.append(
                Reading(
                    where=at,
                    sample=sample,
                    geometry=geometry,
                    lab=_stated_colour(path, row, at, block, lab_alone, lab_conditions),
                    measured_at=measured_at,
                    reflectance=None
                    if lab_alone
                    else parse_spectrum(path, [row[i] for i in block.spectral], wavelengths, at),
                )
            )
        if len(readings) == read:
            raise MeasurementFileError(path, f"{sample!r} is read at no geometry", field=where)
    if lab_alone and readings:
        readings = recovered_readings(path, readings, lab_conditions)
    if sheet is not None:
        instruments = {instrument_of_sheet(sheet)}
    measurements = assemble(
        path,
        readings,
        wavelengths,
        lab_conditions=lab_conditions,
        texture=texture,
        instrument=instruments.pop() if len(instruments) == 1 else None,
        metadata={r.sample: job_of(sheet) for r in readings} if sheet else None,
        spectra_recovered=lab_alone,
    )
    _note_lamps_unsaid(path, blocks)
    return measurements


def _export_sheet(
    path: str | PathLike, first: list[str], rows: Iterator[tuple[int, list[str]]]
) -> tuple[dict[str, str], list[str], Iterator[tuple[int, list[str]]]]:
    """A sheet of an MA-T12 export saved as CSV (a spreadsheet saves the sheet it shows), read
    by :func:`~flakelab.io.records.spreadsheet_table` from its ``first`` row (``QC JOB:`` …):
    its preamble (``QC JOB:``, ``STANDARD:``, ``ILLUMINANT/OBSERVER:`` …), its header row
    (``Name, Date/Time, Geometry, …``) up to its last named column, and the rows after it,
    numbered as the spreadsheet shows them (the header is row 4)."""
    opening = [(1, first)]
    for number, row in rows:  # every preamble row once, then the header
        opening.append((number, row))
        if row[0].strip() == ROW_KEYS[0] or len(opening) > len(PREAMBLE_KEYS):
            break
    preamble, at = split_sheet([tuple(row) for _, row in opening])
    if at < 0:
        after = next((n for n, row in opening if not row[0].strip().endswith(":")), None)
        raise MeasurementFileError(
            path,
            f"an MA-T12 sheet's preamble ({first[0].strip()} …) without its header row "
            f"'{', '.join(ROW_KEYS)}, …'",
            field=f"row {after or opening[-1][0] + 1}",
        )
    header = opening[at][1]
    width = filled_width(header)
    return preamble, header[:width], ((number, within(row, width)) for number, row in rows)


def _opens_a_sheet(header: list[str]) -> bool:
    """Whether a CSV file's first row is an MA-T12 sheet's preamble (``QC JOB:`` …)."""
    first = header[0].strip() if header else ""
    return first.endswith(":") and first[:-1] in PREAMBLE_KEYS


_STATED_UNDER = re.compile(r"^(?P<name>.+?)\s*\((?P<conditions>[^()]+)\)$")
"""A sheet's colour column, headed with the conditions it is stated under: ``L* (D65/10)``."""


def _sheet_header(
    path: str | PathLike, header: list[str], sheet: dict[str, str]
) -> tuple[list[str], Conditions | None]:
    """An MA-T12 sheet's header as the layout above names its columns (``Name, Date/Time,
    Geometry`` → ``sample, measured_at, geometry``; ``L* (D65/10)`` → ``L*``), and the
    conditions its colour is stated under (its ``ILLUMINANT/OBSERVER:`` row, and those its
    colour columns name, which must agree); None where it states none."""
    if header[:3] != list(ROW_KEYS):
        raise MeasurementFileError(
            path, f"expected columns {', '.join(ROW_KEYS)}, got {header[:3]}", field="header"
        )
    key = "ILLUMINANT/OBSERVER"
    named = {f"preamble, {key}": sheet[key]} if sheet.get(key) else {}
    renamed = ["sample", "measured_at", "geometry"]
    for h in header[3:]:
        under = _STATED_UNDER.match(h)
        if under is not None and under["name"] in _COLOUR_NAMES:
            named[f"header, {h}"] = under["conditions"]
            h = under["name"]
        renamed.append(h)
    stated = {where: parse_conditions(path, text, where) for where, text in named.items()}
    first, conditions = next(iter(stated.items()), (None, None))
    other = next(((where, c) for where, c in stated.items() if c != conditions), None)
    if other is not None:
        raise MeasurementFileError(
            path,
            f"{other[1]}, where {first} states {conditions}: a file's colours are stated "
            "under one set of conditions",
            field=other[0],
        )
    return renamed, conditions


def _checked_header(
    path: str | PathLike, header: list[str], columns: dict[str, int]
) -> dict[int, tuple[str, str]]:
    """The columns at a geometry (:func:`_split_wide`) of a header that names its samples and
    each column once, and gives either a geometry column or columns at a geometry, not both
    (none where it gives the geometry column)."""
    if "sample" not in columns:
        found = f"columns: {', '.join(header[:6])}…"
        if "case_id" in columns:  # cases.exchange's first
            found = "this is a case history, which 'flakelab cases import' reads"
        raise MeasurementFileError(path, f"missing column 'sample' ({found})", field="header")
    if len(columns) != len(header):
        duplicate = next(h for h in header if header.count(h) > 1)
        raise MeasurementFileError(path, f"column {duplicate!r} appears twice", field="header")
    wide = _split_wide(header)
    if "geometry" in columns and wide:
        raise MeasurementFileError(
            path,
            f"a geometry column and columns at a geometry ({header[next(iter(wide))]!r}): a file "
            "gives a row per reading, or a row per sample",
            field="header",
        )
    if "geometry" not in columns and not wide:
        raise MeasurementFileError(
            path,
            f"missing column 'geometry', or columns at a geometry such as 'L* 45as15' (columns: "
            f"{', '.join(header[:6])}…)",
            field="header",
        )
    return wide


def _measured_at(
    path: str | PathLike, row: list[str], columns: dict[str, int], where: str
) -> datetime | None:
    cell = row[columns["measured_at"]] if "measured_at" in columns else ""
    if not cell.strip():
        return None
    try:
        return read_time(cell)
    except ValueError:
        raise MeasurementFileError(
            path, f"expected {TIME_EXPECTED}, got {cell!r}", field=f"{where}, measured_at"
        ) from None


def _stated_colour(
    path: str | PathLike,
    row: list[str],
    where: str,
    block: _Block,
    lab_alone: bool,
    conditions: Conditions,
) -> np.ndarray | None:
    """The colour a reading states (L*a*b* ``[3]``, see :func:`agreed_colour`), None where it
    states none; where the file gives colour alone, its first form's empty cell is refused."""
    given = {form: c for form, c in block.forms.items() if any(row[i].strip() for i in c)}
    if lab_alone and not given:  # the first form's empty cell, named
        given = dict([next(iter(block.forms.items()))])
    stated = {
        ", ".join(block.names[i] for i in c): parse_colour(
            path, form, [row[i] for i in c], where, [block.names[i] for i in c], conditions
        )
        for form, c in given.items()
    }
    return agreed_colour(path, stated, where)


def write_csv(
    measurements: list[Measurement],
    path: str | PathLike,
    *,
    decimal_comma: bool = False,
    wide: bool = False,
) -> None:
    """Write measurements in the CSV layout above (full float precision): a row per reading,
    or ``wide``, a row per sample with its L*a*b* and then its spectra at each geometry
    (``L* 45as15``, ``R400 45as15``), as a spreadsheet of panels holds them. With
    ``decimal_comma``, as a spreadsheet in most of Europe opens it: cells separated by
    semicolons, numbers with a decimal comma, a byte-order mark for its encoding.
    Measurements whose spectra were recovered from L*a*b* are written as they were read, L*a*b*
    alone: the spectra are not measurements."""
    wavelengths = measurements[0].wavelengths
    if any(not np.array_equal(m.wavelengths, wavelengths) for m in measurements):
        raise ValueError("expected all measurements on one wavelength grid for one CSV file")
    lab_alone = colour_alone(measurements)
    texture_keys = [k for k in TEXTURE_READINGS if any(k in m.texture for m in measurements)]
    with_lab = any(m.stored_lab is not None for m in measurements)
    bands = () if lab_alone else tuple(f"R{w:g}" for w in wavelengths)
    colour = ("L*", "a*", "b*") if with_lab else ()

    def number(value: float) -> str:
        text = repr(float(value))
        return decimal_comma_in(text) if decimal_comma else text

    def cells(m: Measurement, i: int | None) -> tuple[list[str], list[str]]:
        """The colour and the spectrum of ``m`` at its ``i``-th geometry (empty cells where it
        has none)."""
        if i is None:
            return [""] * len(colour), [""] * len(bands)
        known = with_lab and m.stored_lab is not None
        lab = [number(v) for v in m.stored_lab[i]] if known else [""] * len(colour)
        return lab, [number(v) for v in m.reflectance[i]] if bands else []

    def conditions(m: Measurement) -> list[str]:
        return [str(m.stored_lab_conditions) if m.stored_lab is not None else ""] * with_lab

    def rest(m: Measurement) -> list[str]:
        return [
            m.instrument or "",
            m.measured_at.isoformat() if m.measured_at else "",
            *(number(m.texture[k]) if k in m.texture else "" for k in texture_keys),
        ]

    tail = [*(["lab_conditions"] * with_lab), "instrument", "measured_at", *texture_keys]
    if wide:
        geometries = list(dict.fromkeys(g for m in measurements for g in m.geometries))
        header = ["sample"]
        header += [f"{q} {g.name}" for g in geometries for q in colour]
        header += [f"{q} {g.name}" for g in geometries for q in bands]
        table = [header + tail]
        for m in measurements:
            at = [
                cells(m, m.geometries.index(g) if g in m.geometries else None) for g in geometries
            ]
            lab = [c for lab, _ in at for c in lab]
            spectra = [c for _, spectrum in at for c in spectrum]
            table.append([m.sample, *lab, *spectra, *conditions(m), *rest(m)])
    else:
        table = [["sample", "geometry", *bands, *("L", "a", "b")[: len(colour)], *tail]]
        for m in measurements:
            for i, g in enumerate(m.geometries):
                lab, spectrum = cells(m, i)
                table.append([m.sample, g.name, *spectrum, *lab, *conditions(m), *rest(m)])

    separator, encoding = csv_form(decimal_comma)
    buffer = io.StringIO()
    csv.writer(buffer, delimiter=separator, lineterminator="\n").writerows(table)
    write_atomically(
        path, lambda temporary: temporary.write_text(buffer.getvalue(), encoding=encoding)
    )
