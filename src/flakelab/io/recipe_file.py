"""Recipe files: a JSON object toner name → grams, as weighed for one can.

::

    {"Al medium": 194.0, "Phthalo blue GS": 16.6, "Carbon black": 3.6}

Whether the toners belong to a library is the library's to say
(:meth:`~flakelab.library.toners.Library.fractions`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from os import PathLike
from pathlib import Path

from flakelab.core.documents import RECIPE_KIND, document_kind
from flakelab.core.units import is_number
from flakelab.errors import FlakelabError
from flakelab.io.records import read_json_file, write_atomically

__all__ = ["read_recipe", "write_recipe"]


def read_recipe(path: str | PathLike) -> dict[str, float]:
    """Grams per toner from a recipe file; names the file and toner of any problem."""
    path = Path(path)
    grams = read_json_file(path, "recipe file", "a JSON object toner → grams")
    if not isinstance(grams, dict) or not grams:
        raise FlakelabError(f"{path}: expected a JSON object toner → grams with at least one toner")
    kind = document_kind(grams)
    if kind not in ("", RECIPE_KIND):
        raise FlakelabError(f"{path}: expected a JSON object toner → grams; this is {kind}")
    for toner, amount in grams.items():
        if not is_number(amount):
            raise FlakelabError(f"{path}: {toner}: expected grams as a number, got {amount!r}")
        if not math.isfinite(amount) or amount < 0:
            raise FlakelabError(f"{path}: {toner}: expected non-negative grams, got {amount!r}")
    total = sum(grams.values())
    if total <= 0:
        raise FlakelabError(f"{path}: the amounts sum to zero grams")
    if not math.isfinite(total):  # each finite, their sum past 1.8e308
        raise FlakelabError(f"{path}: the amounts sum to more grams than a number holds")
    return {str(toner): float(amount) for toner, amount in grams.items()}


def write_recipe(grams: Mapping[str, float], path: str | PathLike) -> None:
    """Write grams per toner, heaviest first, atomically (:func:`read_recipe` reads it)."""
    if not grams or any(not math.isfinite(g) or g < 0 for g in grams.values()):
        raise FlakelabError(f"{path}: expected non-negative grams for at least one toner")
    ordered = {name: round(float(g), 6) for name, g in sorted(grams.items(), key=lambda t: -t[1])}
    text = json.dumps(ordered, indent=1, ensure_ascii=False) + "\n"
    write_atomically(path, lambda temporary: temporary.write_text(text, encoding="utf-8"))
