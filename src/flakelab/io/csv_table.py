"""CSV: one row per sample × geometry (the layout of spreadsheets and of ../shared/data).

Columns, in any order after the first two:

``sample``, ``geometry``          required; geometry as an ASTM name (``45as15``)
``R400`` … ``R700``               reflectance factor per wavelength [0–1]; any regular grid
``L``, ``a``, ``b``               optional stored L*a*b* under ``lab_conditions`` (default D65/10);
                                  also headed ``L*``, ``a*``, ``b*``
``L``, ``C``, ``h``               or L*C*h° [h in degrees] (``L*``, ``C*``, ``h°`` or ``hab``)
``X``, ``Y``, ``Z``               or XYZ [Y 0–100] under ``lab_conditions``
``instrument``, ``measured_at``   optional; ISO 8601 date-time, or ``22.11.2026 09:30``
``Sa15`` … ``G``                  optional texture readings; repeated on every row of a sample
``lab_conditions``                optional, e.g. ``D65/10``

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
from os import PathLike
from pathlib import Path

import numpy as np

from flakelab.core.colorimetry import D65_10, Conditions
from flakelab.core.measurement import TEXTURE_READINGS, Measurement
from flakelab.core.spectra import WAVELENGTHS
from flakelab.core.times import TIME_EXPECTED, read_time
from flakelab.errors import MeasurementFileError
from flakelab.io.records import (
    NOT_UTF8,
    Reading,
    agreed_colour,
    assemble,
    colour_alone,
    csv_form,
    decimal_comma_in,
    decimal_point,
    parse_colour,
    parse_conditions,
    parse_geometry_name,
    parse_spectrum,
    parse_texture,
    parse_wavelength_header,
    recovered_readings,
    spreadsheet_table,
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


def _colour_columns(path: str | PathLike, columns: dict[str, int]) -> dict[str, list[int]]:
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
                    path, f"columns {twice[0]!r} and {twice[1]!r} both give one value",
                    field="header",
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
            f"{'column' if len(names) == 1 else 'columns'} {', '.join(names)} without the rest "
            f"of a colour: {form} needs {wanted}",
            field="header",
        )
    return forms


def _conditions_named(
    path: str | PathLike, rows: list[tuple[int, list[str]]], column: int | None
) -> Conditions:
    """The one ``lab_conditions`` the rows name (D65/10 where none); a row naming others than
    an earlier row is refused, naming both."""
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
        return D65_10
    return parse_conditions(path, first[1], f"row {first[0]}, lab_conditions")


def _decimal_points(row: list[str], numeric: list[int]) -> list[str]:
    """A row with its numeric cells' decimal commas read as points (``0,25`` → ``0.25``)."""
    row = list(row)
    for i in numeric:
        if i < len(row):
            row[i] = decimal_point(row[i])
    return row


def read_csv(path: str | PathLike, text: str | None = None) -> list[Measurement]:
    """Read measurements from a CSV file in the layout above."""
    if text is None:
        try:
            text = Path(path).read_text(encoding="utf-8-sig")
        except UnicodeDecodeError as error:
            raise MeasurementFileError(path, f"{NOT_UTF8} ({error.reason})") from None
    lines = [
        line for line in text.splitlines() if line.strip() and not line.lstrip().startswith("#")
    ]

    def refused(number: int, problem: str) -> MeasurementFileError:
        return MeasurementFileError(path, problem, field=f"row {number}")

    delimiter, header, rows = spreadsheet_table(io.StringIO("\n".join(lines)), refused)
    if header is None:
        raise MeasurementFileError(path, "empty CSV file")
    if delimiter is None:
        raise MeasurementFileError(
            path, "no comma, semicolon or tab separated header", field="header"
        )
    header = [h.strip() for h in header]
    columns = {h: i for i, h in enumerate(header)}
    for required in ("sample", "geometry"):
        if required not in columns:
            found = f"columns: {', '.join(header[:6])}…"
            if "case_id" in columns and "sample" not in columns:  # cases.exchange's first
                found = "this is a case history, which 'flakelab cases import' reads"
            raise MeasurementFileError(
                path, f"missing column {required!r} ({found})", field="header"
            )
    if len(columns) != len(header):
        duplicate = next(h for h in header if header.count(h) > 1)
        raise MeasurementFileError(path, f"column {duplicate!r} appears twice", field="header")
    spectral = [i for i, h in enumerate(header) if h not in _META and h not in TEXTURE_READINGS]
    forms = _colour_columns(path, columns)
    if not spectral and not forms:
        raise MeasurementFileError(
            path,
            "no reflectance columns such as R400, nor a colour: L, a, b (or L, C, h, or X, Y, Z)",
            field="header",
        )
    names = {form: ", ".join(header[i] for i in indices) for form, indices in forms.items()}
    lab_alone = not spectral  # spectra recovered from the colour (a metamer of many)
    wavelengths = (
        WAVELENGTHS
        if lab_alone
        else parse_wavelength_header(
            path, [header[i] for i in spectral], "header", [f"column {i + 1}" for i in spectral]
        )
    )
    if delimiter != ",":  # the comma is free to be the decimal mark
        stated = [i for indices in forms.values() for i in indices]
        numeric = [*spectral, *stated, *(columns[k] for k in TEXTURE_READINGS if k in columns)]
        rows = ((number, _decimal_points(row, numeric)) for number, row in rows)
    rows = list(rows)
    lab_conditions = _conditions_named(path, rows, columns.get("lab_conditions"))

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
        geometry = parse_geometry_name(path, row[columns["geometry"]], f"{where}, geometry")
        given = {form: c for form, c in forms.items() if any(row[i].strip() for i in c)}
        if lab_alone and not given:  # the first form's empty cell, named
            given = dict([next(iter(forms.items()))])
        stated = {
            names[form]: parse_colour(
                path, form, [row[i] for i in c], where, [header[i] for i in c], lab_conditions
            )
            for form, c in given.items()
        }
        lab = agreed_colour(path, stated, where)
        measured_at = None
        if "measured_at" in columns and row[columns["measured_at"]].strip():
            try:
                measured_at = read_time(row[columns["measured_at"]])
            except ValueError:
                raise MeasurementFileError(
                    path,
                    f"expected {TIME_EXPECTED}, got {row[columns['measured_at']]!r}",
                    field=f"{where}, measured_at",
                ) from None
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
        readings.append(
            Reading(
                where=where,
                sample=sample,
                geometry=geometry,
                lab=lab,
                measured_at=measured_at,
                reflectance=None
                if lab_alone
                else parse_spectrum(path, [row[i] for i in spectral], wavelengths, where),
            )
        )
    if lab_alone and readings:
        readings = recovered_readings(path, readings, lab_conditions)
    return assemble(
        path,
        readings,
        wavelengths,
        lab_conditions=lab_conditions,
        texture=texture,
        instrument=instruments.pop() if len(instruments) == 1 else None,
        spectra_recovered=lab_alone,
    )


def write_csv(
    measurements: list[Measurement], path: str | PathLike, *, decimal_comma: bool = False
) -> None:
    """Write measurements in the CSV layout above (full float precision); with
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
    header = ["sample", "geometry", *(f"R{w:g}" for w in wavelengths if not lab_alone)]
    header += ["L", "a", "b", "lab_conditions"] if with_lab else []
    header += ["instrument", "measured_at", *texture_keys]

    def number(value: float) -> str:
        text = repr(float(value))
        return decimal_comma_in(text) if decimal_comma else text

    separator, encoding = csv_form(decimal_comma)
    buffer = io.StringIO()
    writer = csv.writer(buffer, delimiter=separator, lineterminator="\n")
    writer.writerow(header)
    for m in measurements:
        for i, g in enumerate(m.geometries):
            spectrum = () if lab_alone else m.reflectance[i]
            row: list[object] = [m.sample, g.name, *(number(v) for v in spectrum)]
            if with_lab:
                lab = m.stored_lab[i] if m.stored_lab is not None else ("", "", "")
                row += [*(number(v) if v != "" else "" for v in lab)]
                row += [str(m.stored_lab_conditions) if m.stored_lab is not None else ""]
            row += [m.instrument or "", m.measured_at.isoformat() if m.measured_at else ""]
            row += [number(m.texture[k]) if k in m.texture else "" for k in texture_keys]
            writer.writerow(row)
    write_atomically(
        path, lambda temporary: temporary.write_text(buffer.getvalue(), encoding=encoding)
    )
