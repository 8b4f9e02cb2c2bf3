"""flakelab's JSON measurement document (lossless for everything a Measurement holds).

::

    {"format": "flakelab-measurements", "version": 1,
     "measurements": [{
        "sample": "...", "instrument": "...", "measured_at": "2024-05-29T19:02:51",
        "wavelengths": [400, 410, ...],
        "lab_conditions": "D65/10",
        "geometries": [{"name": "45as15", "reflectance": [...], "lab": [L, a, b]}, ...],
        "texture": {"Sa15": 12.1, ...}, "metadata": {"key": "value"}}]}
"""

from __future__ import annotations

import json
from datetime import datetime
from os import PathLike
from typing import Any

from flakelab.core.defaults import DEFAULT_CONDITIONS
from flakelab.core.documents import MEASUREMENTS_FORMAT, document_kind, json_value
from flakelab.core.measurement import Measurement
from flakelab.errors import MeasurementFileError
from flakelab.io.records import (
    NulBytesError,
    Reading,
    assemble,
    parse_conditions,
    parse_geometry_name,
    parse_lab,
    parse_spectrum,
    parse_texture,
    parse_wavelength_header,
    text_of,
    write_atomically,
)

__all__ = ["read_json", "write_json", "FORMAT_NAME"]

FORMAT_NAME = MEASUREMENTS_FORMAT
FORMAT_VERSION = 1


def _require(path: str | PathLike, mapping: Any, key: str, kind: type, where: str) -> Any:
    if not isinstance(mapping, dict):
        raise MeasurementFileError(
            path, f"expected an object, got {type(mapping).__name__}", field=where
        )
    if key not in mapping:
        raise MeasurementFileError(path, f"missing key {key!r}", field=where)
    value = mapping[key]
    if not isinstance(value, kind):
        raise MeasurementFileError(
            path,
            f"expected {kind.__name__}, got {type(value).__name__}",
            field=f"{where}.{key}" if where else key,
        )
    return value


def read_json(path: str | PathLike, text: str | None = None) -> list[Measurement]:
    """Read a flakelab JSON measurement document."""
    try:
        document = json_value(text_of(path) if text is None else text)
    except json.JSONDecodeError as error:
        raise MeasurementFileError(
            path, f"invalid JSON ({error.msg})", field=f"line {error.lineno}, column {error.colno}"
        ) from None
    except NulBytesError as error:
        raise MeasurementFileError(path, f"not a measurement file: {error}") from None
    except UnicodeDecodeError as error:  # the CLI said it naming no file
        encoding = "UTF-16" if error.encoding.startswith("utf-16") else "UTF-8"
        where = f"{error.reason} at byte {error.start + 1}"
        raise MeasurementFileError(path, f"not {encoding} text ({where})") from None
    if not isinstance(document, dict) or document.get("format") != FORMAT_NAME:
        kind = document_kind(document)
        raise MeasurementFileError(
            path,
            f"expected a JSON object with format {FORMAT_NAME!r}"
            + (f"; this is {kind}" if kind else ""),
        )
    if document.get("version", FORMAT_VERSION) != FORMAT_VERSION:  # a later flakelab's file
        raise MeasurementFileError(
            path,
            f"expected version {FORMAT_VERSION} (the one this flakelab reads), "
            f"got {document['version']!r}",
            field="version",
        )
    items = _require(path, document, "measurements", list, "")
    results: list[Measurement] = []
    for n, item in enumerate(items):
        where = f"measurements[{n}]"
        sample = _require(path, item, "sample", str, where)
        wavelengths = parse_wavelength_header(
            path, _require(path, item, "wavelengths", list, where), f"{where}.wavelengths"
        )
        readings = []
        geometries = _require(path, item, "geometries", list, where)
        if not geometries:
            raise MeasurementFileError(
                path, "expected at least one geometry", field=f"{where}.geometries"
            )
        for k, g in enumerate(geometries):
            gw = f"{where}.geometries[{k}]"
            geometry = parse_geometry_name(path, _require(path, g, "name", str, gw), f"{gw}.name")
            values = _require(path, g, "reflectance", list, gw)
            lab = g.get("lab")
            if lab is not None:
                if not isinstance(lab, list) or len(lab) != 3:
                    raise MeasurementFileError(path, "expected [L, a, b]", field=f"{gw}.lab")
                lab = parse_lab(path, lab, [f"{gw}.lab[{i}]" for i in range(3)])
            readings.append(
                Reading(
                    where=gw,
                    sample=sample,
                    geometry=geometry,
                    lab=lab,
                    reflectance=parse_spectrum(path, values, wavelengths, f"{gw}.reflectance"),
                )
            )
        measured_at = item.get("measured_at")
        try:
            moment = datetime.fromisoformat(measured_at) if measured_at else None
        except (TypeError, ValueError):
            raise MeasurementFileError(
                path,
                f"expected an ISO 8601 date-time, got {measured_at!r}",
                field=f"{where}.measured_at",
            ) from None
        for r in readings:
            r.measured_at = moment
        texture = item.get("texture") or {}
        if not isinstance(texture, dict):
            raise MeasurementFileError(path, "expected an object", field=f"{where}.texture")
        texture = {k: parse_texture(path, v, f"{where}.texture.{k}") for k, v in texture.items()}
        conditions = parse_conditions(
            path, item.get("lab_conditions", DEFAULT_CONDITIONS), f"{where}.lab_conditions"
        )
        metadata = item.get("metadata") or {}
        if not isinstance(metadata, dict):
            raise MeasurementFileError(path, "expected an object", field=f"{where}.metadata")
        instrument = item.get("instrument")
        if instrument is not None and not isinstance(instrument, str):
            raise MeasurementFileError(
                path,
                f"expected a text, got {type(instrument).__name__}",
                field=f"{where}.instrument",
            )
        results += assemble(
            path,
            readings,
            wavelengths,
            instrument=instrument,
            lab_conditions=conditions,
            texture={sample: texture},
            metadata={sample: {k: str(v) for k, v in metadata.items()}},
        )
    if not results:
        raise MeasurementFileError(path, "no measurements", field="measurements")
    return results


def measurement_to_dict(m: Measurement) -> dict[str, Any]:
    geometries = []
    for i, g in enumerate(m.geometries):
        entry: dict[str, Any] = {"name": g.name, "reflectance": m.reflectance[i].tolist()}
        if m.stored_lab is not None:
            entry["lab"] = m.stored_lab[i].tolist()
        geometries.append(entry)
    return {
        "sample": m.sample,
        "instrument": m.instrument,
        "measured_at": m.measured_at.isoformat() if m.measured_at else None,
        "wavelengths": m.wavelengths.tolist(),
        "lab_conditions": str(m.stored_lab_conditions),
        "geometries": geometries,
        "texture": dict(m.texture),
        "metadata": dict(m.metadata),
    }


def write_json(measurements: list[Measurement], path: str | PathLike) -> None:
    document = {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "measurements": [measurement_to_dict(m) for m in measurements],
    }
    text = json.dumps(document, indent=1, ensure_ascii=False)
    write_atomically(path, lambda temporary: temporary.write_text(text, encoding="utf-8"))
