"""Mix-ups: a spray-out far from what its recipe predicts (DESIGN.md §1, steps 3 and 4).

A spray-out read from another panel, a recipe written down wrongly or a target picked from
the wrong file lies further from its recipe's prediction than any spray-out the model never
saw: :data:`SPRAYOUT_MISMATCH` bounds how far a shop's own may lie. The correction asks
about one (:func:`~flakelab.match.correction.mismatch_note`), the habits leave them out
(:func:`~flakelab.match.habits.screened_habits`), and a recorded or imported case is checked
as it joins the database (:func:`recorded_checks`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E
from flakelab.errors import FlakelabError

if TYPE_CHECKING:
    from flakelab.library.toners import Library
    from flakelab.match.habits import ShopHabits

__all__ = [
    "SPRAYOUT_MISMATCH",
    "is_mismatched",
    "mismatch_message",
    "recorded_checks",
    "recorded_mismatch",
    "sprayout_mismatch",
]

SPRAYOUT_MISMATCH = 5.0
"""Worst-geometry ΔE00 between a spray-out and its recipe's prediction beyond which it is
taken for a likely mix-up (module notes): on 500 generated spray-outs the shipped
five-angle model never saw (``flakelab cases generate --n 500 --seed 987``) that worst
geometry read a median 0.79, 2.55 at the 99th percentile and 4.39 at most (stop 66). A
spray-out farther off is more likely another panel's, recipe's or target's, and the
correction would take its whole offset as the shop's."""


def sprayout_mismatch(
    forward,
    fractions: NDArray,
    sprayouts: NDArray,
    habits: ShopHabits | None = None,
    library: Library | None = None,
) -> NDArray:
    """ΔE00 ``[N, G]`` of spray-outs ``sprayouts[N, G, 31]`` from the prediction of the
    recipes ``fractions[N, T]`` they were mixed from, moved by the shop's ``habits`` (given
    the ``library``): what :data:`SPRAYOUT_MISMATCH` bounds."""
    # torch's import: not for a bare record
    from flakelab.match.forward import film_of
    from flakelab.match.judging import evaluate_recipes

    R = evaluate_recipes(forward, fractions)[0]
    predicted = reflectance_to_Lab(R)
    if habits is not None:
        film = film_of(forward, fractions)
        predicted = predicted + habits.offset(library, film, R, forward.geometries)
    return delta_E(predicted, reflectance_to_Lab(sprayouts))


def mismatch_message(de00: float, geometry: str) -> str:
    """What a spray-out ``de00`` (worst, at ``geometry``) from its recipe's prediction, beyond
    :data:`SPRAYOUT_MISMATCH`, asks of the colorist."""
    return (
        f"the spray-out is ΔE00 {de00:.1f} from what the recipe predicts at {geometry} "
        f"(spray-outs the model never saw stay within ΔE00 {SPRAYOUT_MISMATCH:g}): check that "
        "the spray-out, the recipe and the target belong together"
    )


CHECKED_AT_ONCE = 4096
"""Recorded cases :func:`recorded_mismatch` checks at once."""


def recorded_mismatch(
    forward, library: Library, cases: list, habits: ShopHabits | None = None
) -> tuple[NDArray, NDArray]:
    """:func:`sprayout_mismatch` of recorded ``cases`` (:class:`~flakelab.cases.case.Case`),
    each read at every one of ``forward``'s geometries (among others): each one's worst ΔE00
    ``[N]`` and the index of its geometry in ``forward.geometries``. In chunks of
    :data:`CHECKED_AT_ONCE` cases: a shop's history of 30,000 at once peaked 175 MB higher."""
    from flakelab.cases.case import cases_at
    from flakelab.match.lots import poured_from
    from flakelab.models.training import case_arrays

    worst, where = [], []
    for start in range(0, len(cases), CHECKED_AT_ONCE):
        chunk = cases_at(cases[start : start + CHECKED_AT_ONCE], forward.geometries)
        data = case_arrays(chunk, library.names)
        poured = poured_from(forward, library, data.strength, data.shade)  # the tins they record
        de = sprayout_mismatch(poured, data.x, data.R, habits, library)
        worst.append(de.max(axis=1))
        where.append(de.argmax(axis=1))
    return np.concatenate(worst), np.concatenate(where)


def recorded_checks(
    cases: list, library: Library, engine=None
) -> tuple[list[dict | None], str | None]:
    """Each recorded case's spray-out against its recipe's prediction (:func:`recorded_
    mismatch`) by the current model for its shop (in ``engine``, else the shipped) of an
    instrument that reads it, the default one where it can, moved by the shop's habits stored
    against that model: ``{de00, geometry, model, habits}``, None where no model reads the
    case; and why the rest went unchecked (no model for the library, a damaged one, a toner it
    lacks), else None. It only advises, after the cases are stored, and so refuses nothing."""
    from flakelab.core.geometry import DEFAULT_INSTRUMENT, INSTRUMENT_GEOMETRIES
    from flakelab.match.models import forward_for
    from flakelab.models.registry import serving_model, serving_version

    checks: list[dict | None] = [None] * len(cases)
    forwards: dict[tuple, object] = {}  # each model loaded once: shops without one share it
    for instrument in sorted(INSTRUMENT_GEOMETRIES, key=lambda k: k != DEFAULT_INSTRUMENT):
        rows = [
            i
            for i, c in enumerate(cases)
            if checks[i] is None and c.reads(INSTRUMENT_GEOMETRIES[instrument])
        ]
        for shop in sorted({cases[i].shop for i in rows}):
            mine = [i for i in rows if cases[i].shop == shop]
            try:
                serving = engine and serving_version(engine, instrument, shop)
                if (instrument, serving) not in forwards:
                    model = serving_model(engine, instrument, serving)
                    forwards[instrument, serving] = forward_for(model, library)
                forward = forwards[instrument, serving]
            except FlakelabError as error:
                return checks, str(error)
            habits = _stored_habits(engine, shop, forward.model_id)
            try:
                worst, where = recorded_mismatch(forward, library, [cases[i] for i in mine], habits)
            except FlakelabError as error:  # a toner the library lacks
                return checks, str(error)
            for i, de, g in zip(mine, worst, where, strict=True):
                checks[i] = {
                    "de00": round(float(de), 3),
                    "geometry": forward.geometries[g],
                    "model": forward.model_id,
                    "habits": habits is not None,
                }
    return checks, None


def is_mismatched(check: dict | None) -> bool:
    """Whether a :func:`recorded_checks` entry lies beyond :data:`SPRAYOUT_MISMATCH`."""
    return check is not None and check["de00"] > SPRAYOUT_MISMATCH


def _stored_habits(engine, shop: str, model_id: str) -> ShopHabits | None:
    """The habits stored for ``shop`` against the model ``model_id``, else None."""
    from flakelab.match.habits import stored_habits

    if engine is None:
        return None
    try:
        found = stored_habits(engine, shop, model_id)
    except FlakelabError:  # none stored for the shop
        return None
    return found if found.model == model_id else None
