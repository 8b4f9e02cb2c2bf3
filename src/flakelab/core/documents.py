"""The JSON documents flakelab reads and writes, by the name in their ``format`` field: the
names in one place, and what a document is, for a message that names the file a command was
given by mistake (a recipe to ``inspect``, a measurement file to ``correct --recipe``), and
how their text is parsed (:func:`json_value`, :func:`toml_value`), for files and the case
database's JSON columns alike. It imports nothing but the standard library, like
:mod:`flakelab.core.wording`."""

from __future__ import annotations

import json
import tomllib
from numbers import Real

__all__ = [
    "LIBRARY_FORMAT",
    "LOTS_FORMAT",
    "MEASUREMENTS_FORMAT",
    "MODEL_FORMAT",
    "RECIPE_KIND",
    "SHOP_HABITS_FORMAT",
    "document_kind",
    "json_value",
    "toml_value",
]

MEASUREMENTS_FORMAT = "flakelab-measurements"
LIBRARY_FORMAT = "flakelab-library"
LOTS_FORMAT = "flakelab-toner-lots"
SHOP_HABITS_FORMAT = "flakelab-shop-habits"
MODEL_FORMAT = "flakelab-model"
"""The ``format`` of the description inside a model file (:mod:`flakelab.models.files`)."""

RECIPE_KIND = "a recipe file, toner → grams (--recipe)"
"""What :func:`document_kind` calls a recipe file, which names no format."""

_KINDS = {
    MEASUREMENTS_FORMAT: "a measurement file",
    LIBRARY_FORMAT: "a toner library (--library)",
    LOTS_FORMAT: "a file of the shop's tins (--lots)",
    SHOP_HABITS_FORMAT: "a shop's habits (--habits)",
}


def document_kind(document: object) -> str:
    """What a parsed JSON ``document`` is, as a message names it ("a toner library
    (--library)"), by its ``format``, else by its shape: a recipe file (toner → grams), a
    report of ``match --json``; "" where it is none of them."""
    if not isinstance(document, dict) or not document:
        return ""
    if isinstance(document.get("format"), str):
        return _KINDS.get(document["format"], "")
    if {"target", "candidates"} <= document.keys():
        return "a report of 'flakelab match --json' ('match --recipe-out' writes a recipe file)"
    if all(isinstance(v, Real) and not isinstance(v, bool) for v in document.values()):
        return RECIPE_KIND
    return ""


def json_value(text: str):
    """``json.loads``. JSON nested deeper than Python's recursion reaches (a damaged or
    hostile file: ``[[[[…`` a hundred thousand deep) is refused as any JSON that does not
    parse, a :class:`json.JSONDecodeError`; it was an internal error, RecursionError.
    Integers past 64 bits are read as doubles (:func:`_number_of_integer`)."""
    try:
        return json.loads(text, parse_int=_number_of_integer)
    except RecursionError:
        raise json.JSONDecodeError("nested too deeply to be read", text, 0) from None


def toml_value(text: str) -> dict:
    """``tomllib.loads``, where arrays nested deeper than Python's recursion reaches are a
    :class:`tomllib.TOMLDecodeError` as any TOML that does not parse (as :func:`json_value`),
    and integers past 64 bits are doubles (:func:`_number_of_integer`)."""
    try:
        return _without_huge_integers(tomllib.loads(text))
    except RecursionError:
        raise tomllib.TOMLDecodeError("nested too deeply to be read") from None
    except tomllib.TOMLDecodeError:
        raise
    except ValueError as error:  # an integer of over 4,300 digits, past what Python converts
        raise tomllib.TOMLDecodeError(str(error).partition(";")[0]) from None


_INT64_DIGITS = 18
"""Every integer of this many digits fits a signed 64-bit integer (2⁶³ − 1 has 19)."""


def _number_of_integer(text: str) -> int | float:
    """An integer as a JSON or TOML file writes it: a Python int where it fits 64 bits, else
    the double it names (infinity past a double's range), as JavaScript and most tools that
    write JSON read it; each field's check of a finite number then judges it. A Python int
    past 64 bits was an internal error wherever numpy met it (``np.isfinite``: "not
    supported for the input types") or a float was made of it (OverflowError)."""
    return int(text) if len(text.lstrip("+-")) <= _INT64_DIGITS else float(text)


def _without_huge_integers(value):
    """``value`` (parsed TOML, whose integers Python reads at any size) with each integer
    past 64 bits a double (:func:`_number_of_integer`)."""
    if isinstance(value, dict):
        return {k: _without_huge_integers(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_without_huge_integers(v) for v in value]
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) >= 10**_INT64_DIGITS:
        return _number_of_integer(str(value))
    return value
