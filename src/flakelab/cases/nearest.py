"""The shop's own formulas first: the recorded cases whose spray-outs lie closest to a car.

A shop's case database holds every recipe it sprayed and what the panel then read. Before a
search, a colorist looks there: a recipe that already gave a panel near this colour, sprayed
with the shop's own guns and toner batches, is the surest start (the paint makers' formula
retrieval works so on their own databases). The spray-out, not the car it was mixed for,
is what the recipe is known to give, so cases are ranked by how far their spray-out lies
from the target: the worst geometry's share of the tolerance's limit (ΔE00 with its kL,
kC, kH, and any component limits), every case in one colour computation. Colour alone
ranks them; each case's texture difference is reported beside it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime
from typing import Any

import numpy as np
from numpy.typing import NDArray
from sqlalchemy import Engine

from flakelab.cases.case import Case, CaseError
from flakelab.cases.database import cases_by_rows, stored_sprayouts
from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.measurement import TEXTURE_READINGS
from flakelab.core.tolerance import Tolerance

__all__ = [
    "NearCase",
    "nearest_cases",
    "nearest_stored_cases",
    "recorded_recipes",
    "texture_delta",
]


@dataclass(frozen=True)
class NearCase:
    """A recorded ``case`` and how far it lies from the target: its spray-out's ΔE00 per
    geometry (``sprayout_de00``) and worst share of the tolerance's limit (``share``;
    ``passes`` where every geometry is within it), and its own car's ΔE00 from the target
    (``target_de00``); the spray-out's texture minus the target's, where both were read."""

    case: Case
    sprayout_de00: NDArray
    share: float
    passes: bool
    target_de00: NDArray
    texture_delta: dict[str, float]

    def to_dict(self) -> dict[str, Any]:
        case, names = self.case, self.case.geometry_names
        return {
            "case_id": case.case_id,
            "shop": case.shop,
            "colour_code": case.colour_code,
            "created_at": case.created_at.isoformat(),
            "outcome": case.outcome,
            "instrument": case.instrument,
            "synthetic": case.synthetic,
            "recipe": {name: round(share, 6) for name, share in case.recipe.items()},
            "sprayout_de00": dict(zip(names, self.sprayout_de00.round(3).tolist(), strict=True)),
            "sprayout_de00_max": round(float(self.sprayout_de00.max()), 3),
            "worst_geometry": names[int(np.argmax(self.sprayout_de00))],
            "limit_share_max": round(self.share, 3),
            "passes": self.passes,
            "target_de00_max": round(float(self.target_de00.max()), 3),
            "texture_delta": {k: round(v, 3) for k, v in self.texture_delta.items()},
        }


def nearest_cases(
    target: NDArray,
    cases: Sequence[Case],
    tolerance: Tolerance,
    count: int = 5,
    target_texture: dict[str, float] | None = None,
) -> list[NearCase]:
    """The ``count`` cases whose spray-outs lie closest to ``target`` (reflectance
    ``[G, 31]`` at the cases' geometries, in their order), nearest first, judged by
    ``tolerance``; ``target_texture`` gives the texture differences where the cases have
    texture readings too."""
    if not cases:
        raise CaseError("no cases to search")
    geometries = cases[0].geometry_names
    if any(c.geometry_names != geometries for c in cases):
        raise CaseError("nearest_cases: expected every case at the same geometries")
    sprayouts = np.stack([c.sprayout for c in cases])
    order, judged = _ranked(target, sprayouts, geometries, tolerance, count)
    return _near(target, [cases[i] for i in order], judged, tolerance, target_texture)


def nearest_stored_cases(
    engine: Engine,
    target: NDArray,
    geometries: tuple[str, ...],
    tolerance: Tolerance,
    count: int = 5,
    *,
    shop: str | None = None,
    colour_code: str | None = None,
    since: datetime | None = None,
    target_texture: dict[str, float] | None = None,
) -> tuple[list[NearCase], int]:
    """:func:`nearest_cases` among a database's cases (``shop``'s, for ``colour_code``, made
    at or after ``since``, where given) read at ``geometries``, reading only their spray-outs
    and then the ``count`` cases found; and how many were searched (none found where none was
    read there)."""
    row_ids, sprayouts = stored_sprayouts(
        engine, tuple(geometries), shop=shop, colour_code=colour_code, since=since
    )
    if not row_ids:
        return [], 0
    order, judged = _ranked(target, sprayouts, tuple(geometries), tolerance, count)
    found = cases_by_rows(engine, [row_ids[i] for i in order])
    chosen = [case.at_geometries(geometries) for case in found]
    return _near(target, chosen, judged, tolerance, target_texture), len(row_ids)


def recorded_recipes(found: Sequence[NearCase], toners: Sequence[str]) -> dict[str, NDArray]:
    """The recipes of the cases ``found``, by case id, as mass fractions over ``toners``: those
    whose every toner is among them (a recipe without one of its toners is not that
    recipe)."""
    return {
        near.case.case_id: np.array([near.case.recipe.get(t, 0.0) for t in toners])
        for near in found
        if set(near.case.recipe) <= set(toners)
    }


def _ranked(target, sprayouts: NDArray, geometries, tolerance: Tolerance, count: int):
    """The ``count`` spray-outs ``[N, G, 31]`` nearest ``target`` by the worst geometry's
    share of ``tolerance``'s limit (one colour computation for all), and their ΔE00, share
    and verdict, in that order."""
    target_lab = reflectance_to_Lab(np.asarray(target, dtype=float))
    de00, dLCH, passed = tolerance.judge(geometries, target_lab, reflectance_to_Lab(sprayouts))
    shares = tolerance.share_of_limit(geometries, de00=de00, dLCH=dLCH).max(axis=1)
    order = np.argsort(shares, kind="stable")[:count]
    return order, (de00[order], shares[order], passed[order].all(axis=1))


def _near(target, cases: list[Case], judged, tolerance: Tolerance, target_texture):
    """:class:`NearCase` of each case with its ``judged`` spray-out, and its own car's ΔE00
    from the target."""
    de00, shares, passes = judged
    geometries = cases[0].geometry_names
    target_lab = reflectance_to_Lab(np.asarray(target, dtype=float))
    cars = reflectance_to_Lab(np.stack([case.target for case in cases]))
    cars_de00 = tolerance.judge(geometries, target_lab, cars)[0]
    return [
        NearCase(
            case,
            de00[k],
            float(shares[k]),
            bool(passes[k]),
            cars_de00[k],
            texture_delta(case.sprayout_texture, target_texture or {}),
        )  # fmt: skip
        for k, case in enumerate(cases)
    ]


def texture_delta(sprayout: dict[str, float], target: dict[str, float]) -> dict[str, float]:
    """The spray-out's (or any sample's) texture readings minus the target's, where both
    have them."""
    return {k: sprayout[k] - target[k] for k in TEXTURE_READINGS if k in sprayout and k in target}
