"""The shop's mixing bank: toners a recipe may not use, being out of stock or not stocked at
all (``--without``). The search then matches with the others (its ``allowed`` mask), and a
correction neither adds them nor brings one of them in.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable, Sequence

import numpy as np
from numpy.typing import NDArray

from flakelab.errors import FlakelabError

__all__ = ["toners_allowed", "StockError", "check_toners"]


class StockError(FlakelabError):
    """A toner named as out of stock that the library does not hold."""


def toners_allowed(toners: Sequence[str], without: Iterable[str] = ()) -> NDArray[np.bool_]:
    """A mask over ``toners`` of those a recipe may use: every one but ``without``; a name
    that is not one of ``toners`` is an error naming the nearest that is."""
    without = list(without)
    check_toners(without, toners, "--without: ")
    return np.array([name not in without for name in toners], dtype=bool)


def check_toners(names: Iterable[str], toners: Sequence[str], where: str = "") -> None:
    """Refuse the first of ``names`` that is not one of ``toners`` (a library's), naming the
    nearest that is; ``where`` (a file, an option) begins the message."""
    for name in names:
        if name not in toners:
            near = difflib.get_close_matches(name, list(toners), n=1, cutoff=0.6)
            hint = f" (did you mean {near[0]!r}?)" if near else ""
            raise StockError(f"{where}{name!r} is not a toner of the library{hint}")
