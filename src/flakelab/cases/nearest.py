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
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flakelab.cases.case import Case, CaseError
from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.measurement import TEXTURE_READINGS
from flakelab.core.tolerance import Tolerance

__all__ = ["NearCase", "nearest_cases"]


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
    target_lab = reflectance_to_Lab(np.asarray(target, dtype=float))
    sprayouts = reflectance_to_Lab(np.stack([c.sprayout for c in cases]))
    de00, dLCH, passed = tolerance.judge(geometries, target_lab, sprayouts)
    shares = tolerance.share_of_limit(geometries, de00=de00, dLCH=dLCH).max(axis=1)
    order = np.argsort(shares, kind="stable")[:count]
    cars = reflectance_to_Lab(np.stack([cases[i].target for i in order]))
    cars_de00 = tolerance.judge(geometries, target_lab, cars)[0]
    return [
        NearCase(
            cases[i],
            de00[i],
            float(shares[i]),
            bool(passed[i].all()),
            cars_de00[k],
            _texture_delta(cases[i].sprayout_texture, target_texture or {}),
        )
        for k, i in enumerate(order)
    ]


def _texture_delta(sprayout: dict[str, float], target: dict[str, float]) -> dict[str, float]:
    """The spray-out's texture readings minus the target's, where both have them."""
    return {k: sprayout[k] - target[k] for k in TEXTURE_READINGS if k in sprayout and k in target}
