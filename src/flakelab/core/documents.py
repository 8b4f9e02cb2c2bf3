"""The JSON documents flakelab reads and writes, by the name in their ``format`` field: the
names in one place, and what a document is, for a message that names the file a command was
given by mistake (a recipe to ``inspect``, a measurement file to ``correct --recipe``). It
imports nothing but the standard library, like :mod:`flakelab.core.wording`."""

from __future__ import annotations

from numbers import Real

__all__ = [
    "LIBRARY_FORMAT",
    "LOTS_FORMAT",
    "MEASUREMENTS_FORMAT",
    "MODEL_FORMAT",
    "RECIPE_KIND",
    "SHOP_HABITS_FORMAT",
    "document_kind",
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
