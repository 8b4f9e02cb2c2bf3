"""Toner-lot files: the shop's tins, their strengths and shades (:mod:`flakelab.library.lots`).

::

    {"format": "flakelab-toner-lots", "version": 2, "library": "flakelab demo",
     "lots": [{"toner": "Phthalo blue GS", "strength": 1.031, "strength_sd": 0.006,
               "lot": "B-2291", "panels": 1, "calibrated": "2026-11-29T10:12:00+00:00",
               "model_id": "demo-five-angle 65a5a7b88eab", "shade_nm": 0.8,
               "shade_sd_nm": 0.3},
              {"toner": "Al coarse bright", "strength": 0.975, ...}],
     "correlations": [{"a": ["Al coarse bright", "strength"],
                       "b": ["Phthalo blue GS", "strength"], "r": 0.93}],
     "misfit": [{"model_id": "demo-five-angle 65a5a7b88eab", "against": "model",
                 "chi2": 31.2, "dof": 13}]}

``correlations`` (version 3) are those between the tins' read quantities (log strength,
shade) that calibrating left (two tins read from one panel are read together); a pair not
listed is uncorrelated. ``misfit`` (version 3) is the χ² of the panels read so far about
their covariance, by model and by what they were read against, with its degrees of freedom.
Version 2 files have neither; version 1 files (before shades were read) are read with every
tin at the standard's shade.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import asdict, fields
from os import PathLike
from pathlib import Path

from flakelab.core.documents import LOTS_FORMAT
from flakelab.core.units import is_number
from flakelab.errors import FlakelabError
from flakelab.io.records import read_json_file, write_atomically
from flakelab.library import check_toners
from flakelab.library.lots import TonerLot, TonerLots

__all__ = ["LOTS_FORMAT", "read_lots", "write_lots", "lots_document", "lots_from_document"]

_VERSION = 3
_READS = (1, 2, 3)
_TEXT_FIELDS = ("toner", "lot", "calibrated", "model_id")
_NUMBER_FIELDS = ("strength", "strength_sd", "shade_nm", "shade_sd_nm")


def read_lots(path: str | PathLike, toners: Sequence[str] | None = None) -> TonerLots:
    """The lots of a toner-lot file; names the file, the lot and the field of any problem.
    With ``toners`` (a library's names), a tin of any other toner is refused, the nearest
    named."""
    path = Path(path)
    document = read_json_file(path, "toner-lot file", "a JSON toner-lot file")
    return lots_from_document(document, str(path), toners)


def lots_from_document(document, where: str, toners: Sequence[str] | None = None) -> TonerLots:
    """The lots of a toner-lot document (a file's JSON, or the database's copy), checked
    as :func:`read_lots` checks a file; ``where`` (the file, the shop) begins every message."""
    if not isinstance(document, dict) or document.get("format") != LOTS_FORMAT:
        raise FlakelabError(
            f"{where}: format: expected {LOTS_FORMAT!r} (a file 'flakelab lots calibrate' writes)"
        )
    if document.get("version") not in _READS:
        raise FlakelabError(
            f"{where}: version: expected {' or '.join(map(str, _READS))}, "
            f"got {document.get('version')!r}"
        )
    entries = document.get("lots")
    if not isinstance(entries, list):
        raise FlakelabError(f"{where}: lots: expected a list of lots")
    lots = [_lot(where, i, entry) for i, entry in enumerate(entries)]
    names = [lot.toner for lot in lots]
    if toners is not None:
        check_toners(names, toners, f"{where}: ")
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise FlakelabError(
            f"{where}: lots: more than one tin of {', '.join(twice)} (one per toner)"
        )
    library = document.get("library", "")
    if not isinstance(library, str):
        raise FlakelabError(f"{where}: library: expected a name, got {library!r}")
    top_level = {"format", "version", "library", "lots", "correlations", "misfit"}
    unknown = sorted(set(document) - top_level)
    if unknown:
        raise FlakelabError(f"{where}: {unknown[0]}: not a field of a toner-lot file")
    correlations = _correlations(where, document.get("correlations", []))
    misfit = _misfit(where, document.get("misfit", []))
    try:
        return TonerLots({lot.toner: lot for lot in lots}, library, correlations, misfit)
    except ValueError as error:
        raise FlakelabError(f"{where}: {error}") from None


def _entries(source: str, name: str, entries, keys: tuple[str, ...]):
    """Each entry of a file's list ``name`` with where it is, every one an object of
    ``keys`` exactly."""
    if not isinstance(entries, list):
        raise FlakelabError(f"{source}: {name}: expected a list")
    for index, entry in enumerate(entries):
        where = f"{source}: {name}[{index}]"
        if not isinstance(entry, dict) or set(entry) != set(keys):
            raise FlakelabError(f"{where}: expected an object with {', '.join(keys)}")
        yield where, entry


def _misfit(source: str, entries) -> dict:
    """The misfit of a file's ``misfit`` list, by (model id, read against), each once."""
    found = {}
    for where, entry in _entries(source, "misfit", entries, ("model_id", "against", "chi2", "dof")):
        key = (entry["model_id"], entry["against"])
        if not all(isinstance(v, str) for v in key):
            raise FlakelabError(f"{where}: model_id, against: expected text, got {key!r}")
        if not is_number(entry["chi2"]):
            raise FlakelabError(f"{where}: chi2: expected a number, got {entry['chi2']!r}")
        dof = entry["dof"]
        if not isinstance(dof, int) or isinstance(dof, bool):
            raise FlakelabError(f"{where}: dof: expected a whole number, got {dof!r}")
        if key in found:
            raise FlakelabError(f"{where}: {key[0]} read against the {key[1]}: listed twice")
        found[key] = (float(entry["chi2"]), dof)
    return found


def _correlations(source: str, entries) -> dict:
    """The correlations of a file's ``correlations`` list, each pair sorted, once."""
    found = {}
    for where, entry in _entries(source, "correlations", entries, ("a", "b", "r")):
        pair = []
        for side in ("a", "b"):
            quantity = entry[side]
            if not (isinstance(quantity, list) and len(quantity) == 2
                    and all(isinstance(v, str) for v in quantity)):  # fmt: skip
                raise FlakelabError(
                    f"{where}: {side}: expected [toner, 'strength' or 'shade'], got {quantity!r}"
                )
            pair.append(tuple(quantity))
        if not is_number(entry["r"]):
            raise FlakelabError(f"{where}: r: expected a number, got {entry['r']!r}")
        key = tuple(sorted(pair))
        if key in found or key[0] == key[1]:
            raise FlakelabError(f"{where}: {key[0]} and {key[1]}: a pair of two, listed once")
        found[key] = float(entry["r"])
    return found


def _lot(source: str, index: int, entry) -> TonerLot:
    where = f"{source}: lots[{index}]"
    if not isinstance(entry, dict):
        raise FlakelabError(f"{where}: expected an object with toner and strength")
    if isinstance(entry.get("toner"), str):
        where += f" ({entry['toner']})"
    known = {f.name for f in fields(TonerLot)}
    unknown = sorted(set(entry) - known)
    if unknown:
        raise FlakelabError(
            f"{where}: {unknown[0]}: not a field of a lot (expected {', '.join(sorted(known))})"
        )
    for name, value in entry.items():
        if name in _TEXT_FIELDS and not isinstance(value, str):
            raise FlakelabError(f"{where}: {name}: expected text, got {value!r}")
        if name == "panels" and not (isinstance(value, int) and not isinstance(value, bool)):
            raise FlakelabError(f"{where}: panels: expected a whole number, got {value!r}")
        if name in _NUMBER_FIELDS and not is_number(value):
            raise FlakelabError(f"{where}: {name}: expected a number, got {value!r}")
    if "toner" not in entry or "strength" not in entry:
        raise FlakelabError(f"{where}: expected both 'toner' and 'strength'")
    try:
        return TonerLot(**entry)
    except ValueError as error:
        raise FlakelabError(f"{where}: {error}") from None


def write_lots(lots: TonerLots, path: str | PathLike) -> None:
    """Write ``lots`` atomically, by toner name (:func:`read_lots` reads them)."""
    text = json.dumps(lots_document(lots), indent=1, ensure_ascii=False) + "\n"
    write_atomically(path, lambda temporary: temporary.write_text(text, encoding="utf-8"))


def lots_document(lots: TonerLots) -> dict:
    """The toner-lot document of ``lots`` (a file's JSON), by toner name."""
    return {
        "format": LOTS_FORMAT,
        "version": _VERSION,
        "library": lots.library,
        "lots": [asdict(lots.lots[name]) for name in sorted(lots.lots)],
        "correlations": [
            {"a": list(a), "b": list(b), "r": r} for (a, b), r in sorted(lots.correlations.items())
        ],
        "misfit": [
            {"model_id": model_id, "against": against, "chi2": chi2, "dof": dof}
            for (model_id, against), (chi2, dof) in sorted(lots.misfit.items())
        ],
    }
