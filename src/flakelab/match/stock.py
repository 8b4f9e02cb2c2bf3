"""The shop's mixing bank: toners a recipe may not use, being out of stock or not stocked at
all (``--without``). The search then matches with the others (its ``allowed`` mask), and a
correction neither adds them nor brings one of them in.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np
from numpy.typing import NDArray

from flakelab.library import check_toners

__all__ = ["toners_allowed"]


def toners_allowed(toners: Sequence[str], without: Iterable[str] = ()) -> NDArray[np.bool_]:
    """A mask over ``toners`` of those a recipe may use: every one but ``without``; a name
    that is not one of ``toners`` is an error naming the nearest that is."""
    without = list(without)
    check_toners(without, toners, "--without: ")
    return np.array([name not in without for name in toners], dtype=bool)
