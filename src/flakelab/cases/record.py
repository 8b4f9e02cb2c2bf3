"""A shop's own case from its readings: the target, the recipe sprayed and the spray-out.

This closes the colorist's loop (DESIGN.md §1, step 3): every spray-out that is measured
joins the case database, where the shop's habits, the adaptation and the next training
read it. The case keeps every geometry that both readings share, on the storage grid, so
that the model of each instrument whose geometries are among them learns from it: an MA-T12
spray-out serves the MA-T12 model and the five-angle model alike (``cases_at``).
"""

from __future__ import annotations

import hashlib
import json
import warnings
from collections.abc import Mapping
from datetime import UTC, datetime, timedelta

import numpy as np

from flakelab.cases.case import OUTCOMES, TEXT_LENGTHS, Case, CaseError, check_readings_kept
from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.geometry import (
    INSTRUMENT_GEOMETRIES,
    instrument_name,
    instrument_of,
    parse_geometries,
)
from flakelab.core.measurement import Measurement
from flakelab.core.times import shown_time, zoned_here
from flakelab.core.tolerance import Tolerance, failing_geometries, failures
from flakelab.core.wording import tidy_name
from flakelab.errors import Note
from flakelab.library.lots import TonerLot

__all__ = [
    "AUTO_OUTCOME",
    "case_from_readings",
    "judged_outcome",
    "reading_case_id",
    "shared_geometries",
]

AUTO_OUTCOME = "auto"
"""Outcome chosen by the tolerance: a passing spray-out is accepted, a failing one goes to
correction."""


def reading_case_id(
    target: np.ndarray, sprayout: np.ndarray, recipe: Mapping[str, float], shop: str
) -> str:
    """An id made from the case's content, so that the same spray-out recorded twice is
    refused by the database rather than stored twice."""
    digest = hashlib.sha256()
    for spectra in (target, sprayout):
        digest.update(np.round(spectra, 6).astype("<f8").tobytes())
    digest.update(json.dumps(sorted(recipe.items()), sort_keys=True).encode())
    digest.update(shop.encode())
    return f"shop-{digest.hexdigest()[:16]}"


def _tell_a_time_to_come(when: datetime, *, typed: bool, sample: str) -> None:
    """A :class:`~flakelab.errors.Note` where a case would be recorded more than a day from
    now (``typed``: at a time given, else at the spray-out's date): a year mistyped, or an
    instrument's clock set wrong. Such a case stays the newest, first in every list, and
    ``--since`` keeps it whatever the date."""
    if zoned_here(when) <= datetime.now(UTC) + timedelta(days=1):
        return
    said = (
        f"{shown_time(when)}, the time given, lies in the future (a year mistyped?): the "
        "case is recorded at it"
        if typed
        else f"{sample!r} was read at {shown_time(when)}, in the future (the instrument's "
        "clock?): the case is recorded at it; --at records it at another time"
    )
    warnings.warn(said, Note, stacklevel=3)


def judged_outcome(
    target: np.ndarray,
    sprayout: np.ndarray,
    geometries,
    tolerance: Tolerance,
    textures: tuple[Mapping[str, float], Mapping[str, float]] = ({}, {}),
) -> tuple[str, list[str]]:
    """``accepted`` when the spray-out passes ``tolerance`` at every geometry and at every
    texture reading it bounds that both ``textures`` (target's, spray-out's) hold, else
    ``corrected``; with what fails (geometries, then ``texture G``…), as ``compare`` says."""
    names = [g.name for g in geometries]
    _, _, passed = tolerance.judge(names, reflectance_to_Lab(target), reflectance_to_Lab(sprayout))
    failing = failures(failing_geometries(names, passed), tolerance.failing_texture(*textures))
    return ("corrected" if failing else "accepted"), failing


def shared_geometries(
    target: Measurement, sprayout: Measurement
) -> tuple[tuple[str, ...], str | None]:
    """The geometries both readings have, and the instrument whose set they are (told apart
    by the readings' instrument names where two share a set; None when none reads just
    these): in that instrument's export order, else in the target's."""
    names = tuple(g for g in target.geometry_names if g in set(sprayout.geometry_names))
    if not names:
        raise CaseError(
            f"spray-out: {sprayout.sample!r} shares no geometry with the target "
            f"{target.sample!r} ({', '.join(target.geometry_names)})"
        )
    makers = " ".join(r.instrument for r in (target, sprayout) if r.instrument)
    instrument = instrument_of(names, makers)
    return (INSTRUMENT_GEOMETRIES[instrument] if instrument else names), instrument


def case_from_readings(
    target: Measurement,
    sprayout: Measurement,
    recipe: Mapping[str, float],
    instrument: str | None = None,
    *,
    shop: str,
    outcome: str = AUTO_OUTCOME,
    tolerance: Tolerance | None = None,
    created_at: datetime | None = None,
    case_id: str | None = None,
    tins: Mapping[str, TonerLot] | None = None,
    colour_code: str = "",
) -> Case:
    """The case of one spray-out, read at every geometry both readings share, or at
    ``instrument``'s geometries alone when it is named.

    ``outcome`` is one of :data:`~flakelab.cases.case.OUTCOMES`, or ``auto`` to judge it
    against ``tolerance``. ``created_at`` defaults to when the spray-out was measured (the
    file's date), else now. ``tins`` (the shop's lots, by toner) gives the case the tins of
    its recipe's toners; ``colour_code`` the car maker's code for the car's colour.
    """
    check_readings_kept(target, sprayout)
    shop = tidy_name(shop)  # as the case stores it, for its id
    if instrument is None:
        names, instrument = shared_geometries(target, sprayout)
        named = target.instrument or sprayout.instrument or "unknown"
        instrument = instrument or named[: TEXT_LENGTHS["instrument"]]
    else:
        instrument = instrument_name(instrument)
        names = INSTRUMENT_GEOMETRIES[instrument]
    geometries = parse_geometries(names)
    spectra = {}
    for role, reading in (("target", target), ("spray-out", sprayout)):
        try:
            spectra[role] = reading.storage_spectra(names)
        except KeyError as error:
            raise CaseError(f"{role}: {error.args[0]}: the {instrument} reads them") from None
    if np.array_equal(spectra["target"], spectra["spray-out"]):
        raise CaseError(
            f"spray-out: {sprayout.sample!r} reads exactly as the target {target.sample!r}: the "
            "same reading twice (in one file, name the spray-out's sample)"
        )
    if outcome == AUTO_OUTCOME:
        if tolerance is None:
            raise CaseError("outcome: 'auto' needs a tolerance to judge the spray-out")
        textures = (target.texture, sprayout.texture)
        outcome, _ = judged_outcome(
            spectra["target"], spectra["spray-out"], geometries, tolerance, textures
        )
    elif outcome not in OUTCOMES:
        raise CaseError(
            f"outcome: expected {AUTO_OUTCOME} or one of {', '.join(OUTCOMES)}, got {outcome!r}"
        )
    when = created_at or sprayout.measured_at or datetime.now(UTC)
    _tell_a_time_to_come(when, typed=created_at is not None, sample=sprayout.sample)
    return Case(
        case_id=case_id or reading_case_id(spectra["target"], spectra["spray-out"], recipe, shop),
        geometries=geometries,
        recipe=recipe,
        target=spectra["target"],
        sprayout=spectra["spray-out"],
        target_texture=target.texture,
        sprayout_texture=sprayout.texture,
        instrument=instrument,
        shop=shop,
        outcome=outcome,
        created_at=when,
        tins={name: tin for name, tin in (tins or {}).items() if name in recipe},
        colour_code=colour_code,
        target_recovered=target.spectra_recovered,
        sprayout_recovered=sprayout.spectra_recovered,
    )
