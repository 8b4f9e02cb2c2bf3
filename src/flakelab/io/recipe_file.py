"""Recipe files: a JSON object toner name → grams, as weighed for one can.

::

    {"Al medium": 194.0, "Phthalo blue GS": 16.6, "Carbon black": 3.6}

Whether the toners belong to a library is the library's to say
(:meth:`~flakelab.library.toners.Library.fractions`).
"""

from __future__ import annotations

import json
import math
from os import PathLike
from pathlib import Path

from flakelab.errors import FlakelabError

__all__ = ["read_recipe"]


def read_recipe(path: str | PathLike) -> dict[str, float]:
    """Grams per toner from a recipe file; names the file and toner of any problem."""
    path = Path(path)
    try:
        grams = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise FlakelabError(f"{path}: no such recipe file") from None
    except (OSError, UnicodeDecodeError, ValueError) as error:
        raise FlakelabError(f"{path}: expected a JSON object toner → grams ({error})") from None
    if not isinstance(grams, dict) or not grams:
        raise FlakelabError(f"{path}: expected a JSON object toner → grams with at least one toner")
    for toner, amount in grams.items():
        if isinstance(amount, bool) or not isinstance(amount, int | float):
            raise FlakelabError(f"{path}: {toner}: expected grams as a number, got {amount!r}")
        if not math.isfinite(amount) or amount < 0:
            raise FlakelabError(f"{path}: {toner}: expected non-negative grams, got {amount!r}")
    if sum(grams.values()) <= 0:
        raise FlakelabError(f"{path}: the amounts sum to zero grams")
    return {str(toner): float(amount) for toner, amount in grams.items()}
