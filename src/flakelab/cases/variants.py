"""The variants of a colour code: the shop's cars of one code grouped by how they read.

One maker's code is not one colour. Plants, years, paint batches and the spray line make
it a little lighter, bluer or coarser from car to car, by more than a refinish tolerance,
and the paint makers' retrieval shows each code's variants (their "variant chips") for the
colorist to pick the one nearest the car. A shop's own cases hold the same knowledge: the
cars of a code it has painted, as its instrument read them, and the recipe sprayed on each.

Here the cars of a code are covered by as few variants as the greedy rule finds (set cover:
the car within reach of the most cars not yet covered, again and again), such that every car
lies within ``within`` of the tolerance's limit of its variant's centre car, at every
geometry; each car then joins the variant whose centre lies nearest. Each variant is shown
by its centre (the car whose furthest member lies nearest), its offset from the main variant
(the most cars), and the recorded recipe whose spray-out lies nearest its centre.

The generated world's cars of one formulation (factory batches, spray line, instrument
noise; 40 cars, 8 formulations, seed 5) lie a median 0.6-1.5 of the refinish limit apart, so
one formulation's cars needed 3-7 variants within 1.0 of it, 1-2 within 2.0: as a real code
needs its variant chips.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flakelab.cases.case import Case, CaseError
from flakelab.cases.nearest import NearCase, nearest_cases, texture_delta
from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.measurement import Measurement
from flakelab.core.spectra import WAVELENGTHS
from flakelab.core.tolerance import Tolerance

__all__ = [
    "ColourVariant",
    "car_from_centres",
    "colour_variants",
    "covering_centres",
    "pairwise_reach",
    "worst_shares",
    "variant_chips",
]

ROWS_AT_ONCE = 256
"""The most cars compared with the cars after them at once: small blocks of rows leave the
pairs judged twice (below the diagonal) few."""

PAIRS_AT_ONCE = 2**18
"""Pairs of cars judged at once: bounds the pairwise colour computation's memory (pairs ×
geometries ΔE00 and its temporaries, about 0.3 GB at five geometries), however many cars a
code has: a fixed block of rows took 1.75 GB for 5,000 cars."""


@dataclass(frozen=True)
class ColourVariant:
    """Cars of one colour code around one car, ``centre`` (the one whose furthest member lies
    nearest; ``spread``: that member's share of the tolerance's limit from it);
    ``offset_de00`` and ``offset_dLCH`` its ΔE00 and (ΔL*, ΔC*, ΔH*) per geometry from the
    main variant's centre (zero for the main one), ``offset_texture`` its texture readings
    minus that car's, where both were read; ``recipe`` the recorded case whose spray-out lies
    nearest the centre car."""

    cases: tuple[Case, ...]
    centre: Case
    spread: float
    offset_de00: NDArray
    offset_dLCH: NDArray
    recipe: NearCase
    offset_texture: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        names = self.centre.geometry_names
        worst = int(np.argmax(self.offset_de00))
        return {
            "cases": len(self.cases),
            "case_ids": [case.case_id for case in self.cases],
            "centre_case_id": self.centre.case_id,
            "spread": round(self.spread, 3),
            "offset_de00": dict(zip(names, self.offset_de00.round(3).tolist(), strict=True)),
            "offset_de00_max": round(float(self.offset_de00[worst]), 3),
            "offset_geometry": names[worst],
            "offset_dLCH": dict(
                zip(("dL", "dC", "dH"), self.offset_dLCH[worst].round(3).tolist(), strict=True)
            ),
            "offset_texture": {k: round(v, 3) for k, v in self.offset_texture.items()},
            "recipe": self.recipe.to_dict(),
        }


def worst_shares(
    Lab_a: NDArray, Lab_b: NDArray, geometries: Sequence[str], tolerance: Tolerance
) -> NDArray[np.float64]:
    """Each car of CIELAB ``Lab_a`` ``[A, G, 3]`` against each of ``Lab_b`` ``[B, G, 3]``: the
    worst geometry's share of ``tolerance``'s limit, ``[A, B]``, judged ``A × B`` pairs at
    once (callers keep that to about :data:`PAIRS_AT_ONCE`)."""
    de00, dLCH, _ = tolerance.judge(geometries, Lab_a[:, None], Lab_b[None, :])
    return tolerance.share_of_limit(geometries, de00=de00, dLCH=dLCH).max(axis=-1)


def pairwise_reach(
    Lab: NDArray,
    geometries: Sequence[str],
    tolerance: Tolerance,
    within: float,
    progress: Callable[[int], None] | None = None,
) -> NDArray[np.bool_]:
    """Whether each two cars of CIELAB ``[N, G, 3]`` lie within ``within`` of ``tolerance``'s
    limit of each other, ``[N, N]``: a byte a pair (a code of 20,000 cars, 0.4 GB; their
    shares, 3.2 GB), the shares judged again where the cover and the centres need them.
    CIEDE2000 and the magnitudes of ΔL*, ΔC*, ΔH* that the limits bound are the same whichever
    car of a pair is the standard, so each pair is judged once (N (N + 1) / 2 pairs, told to
    ``progress`` block by block)."""
    n = len(Lab)
    reach = np.empty((n, n), dtype=bool)
    rows_at_once = max(1, min(ROWS_AT_ONCE, PAIRS_AT_ONCE // max(n, 1)))
    for start in range(0, n, rows_at_once):
        rows = slice(start, start + rows_at_once)
        block = worst_shares(Lab[rows], Lab[start:], geometries, tolerance) <= within
        reach[rows, start:] = block
        reach[start:, rows] = block.T
        if progress is not None:
            height = block.shape[0]  # its rows' pairs with themselves and the cars after
            progress(height * (n - start) - height * (height - 1) // 2)
    return reach


def colour_variants(
    cases: Sequence[Case],
    tolerance: Tolerance,
    within: float = 1.0,
    progress: Callable[[int], None] | None = None,
) -> list[ColourVariant]:
    """The variants of ``cases`` (one colour code's, read at the same geometries): every car
    within ``within`` of ``tolerance``'s limit of its variant's centre car, as few variants as
    the greedy cover finds; most cars first (the main variant), then newest first; each
    variant's cases newest first. ``progress`` is told the pairs of cars judged
    (:func:`pairwise_reach`)."""
    if not cases:
        raise CaseError("no cases to group into variants")
    if not within > 0:
        raise CaseError(f"within: expected a share of the tolerance's limit above 0, got {within}")
    geometries = cases[0].geometry_names
    if any(c.geometry_names != geometries for c in cases):
        raise CaseError("colour_variants: expected every case at the same geometries")
    Lab = reflectance_to_Lab(np.stack([c.target for c in cases]))

    def shares_of(rows: NDArray, columns: NDArray) -> NDArray:
        return worst_shares(Lab[rows], Lab[columns], geometries, tolerance)

    reach = pairwise_reach(Lab, geometries, tolerance, within, progress)
    chips = covering_centres(reach, shares_of)
    nearest_chip = _nearest_chip(len(cases), chips, shares_of)
    groups = [np.flatnonzero(nearest_chip == k) for k in range(len(chips))]
    groups = [g for g in groups if g.size]  # two chips alike would leave one empty
    newest = np.array([c.created_at.timestamp() for c in cases])
    groups.sort(key=lambda g: (-len(g), -newest[g].max()))
    centred = [_centre(group, reach, shares_of) for group in groups]
    del reach  # N² bytes, needed no more
    centres = [centre for centre, _ in centred]
    de00, dLCH, _ = tolerance.judge(geometries, Lab[centres[0]], Lab[centres])
    variants = []
    for k, (group, (centre, spread)) in enumerate(zip(groups, centred, strict=True)):
        members = [cases[i] for i in sorted(group, key=lambda i: -newest[i])]
        variants.append(
            ColourVariant(
                cases=tuple(members),
                centre=cases[centre],
                spread=spread,
                offset_de00=de00[k],
                offset_dLCH=dLCH[k],
                recipe=nearest_cases(cases[centre].target, members, tolerance, count=1)[0],
                offset_texture=texture_delta(
                    cases[centre].target_texture, cases[centres[0]].target_texture
                ),
            )
        )
    return variants


def car_from_centres(
    variants: Sequence[ColourVariant], car: NDArray, tolerance: Tolerance
) -> tuple[NDArray, NDArray, NDArray]:
    """How far a car in the booth (reflectance ``[G, 31]`` at the variants' geometries) lies
    from each variant's centre car, the centre the standard: ΔE00 ``[V, G]``, the worst
    geometry's share of ``tolerance``'s limit ``[V]``, and whether it passes ``[V]``."""
    geometries = variants[0].centre.geometry_names
    centres = reflectance_to_Lab(np.stack([v.centre.target for v in variants]))
    de00, dLCH, passed = tolerance.judge(geometries, centres, reflectance_to_Lab(car)[None])
    shares = tolerance.share_of_limit(geometries, de00=de00, dLCH=dLCH).max(axis=1)
    return de00, shares, passed.all(axis=1)


SharesOf = Callable[[NDArray[np.intp], NDArray[np.intp]], NDArray[np.float64]]
"""The worst share of the limit of each car of ``rows`` against each of ``columns``."""


def covering_centres(reach: NDArray[np.bool_], shares_of: SharesOf) -> list[int]:
    """Cars (indices of ``reach``, :func:`pairwise_reach`) such that every car lies within
    reach of one: greedy set cover, each time the car within reach of the most cars not yet
    covered, on a tie the one nearest them: the least sum of their shares, judged again
    (``shares_of``) for the tied cars alone (Chvátal 1979: at most 1 + ln N times the fewest
    there are)."""
    left = np.ones(len(reach), dtype=bool)
    centres: list[int] = []
    cars = np.arange(len(reach))
    while left.any():  # in blocks of rows: no [N, N] temporary for each centre
        gain = np.concatenate(
            [np.count_nonzero(reach[rows] & left, axis=1) for rows in _blocks(cars, len(cars))]
        )
        best = np.flatnonzero(gain == gain.max())
        centre = int(best[0])
        if best.size > 1:
            near = np.flatnonzero(left & _reached_by(reach, best))
            nearness = np.concatenate(
                [
                    np.where(reach[np.ix_(rows, near)], shares_of(rows, near), 0.0).sum(axis=1)
                    for rows in _blocks(best, len(near))
                ]
            )
            centre = int(best[np.argmin(nearness)])
        centres.append(centre)
        left &= ~reach[centre]
    return centres


def _reached_by(reach: NDArray[np.bool_], rows: NDArray[np.intp]) -> NDArray[np.bool_]:
    """Whether any car of ``rows`` reaches each car, ``[N]``."""
    reached = np.zeros(len(reach), dtype=bool)
    for block in _blocks(rows, len(reach)):
        reached |= reach[block].any(axis=0)
    return reached


def _nearest_chip(n: int, chips: Sequence[int], shares_of: SharesOf) -> NDArray[np.intp]:
    """For each of the ``n`` cars, the chip (index into ``chips``) nearest it, the first on a
    tie."""
    cars, chips = np.arange(n), np.asarray(chips)
    return np.concatenate(
        [np.argmin(shares_of(rows, chips), axis=1) for rows in _blocks(cars, len(chips))]
    )


def _centre(
    group: NDArray[np.intp], reach: NDArray[np.bool_], shares_of: SharesOf
) -> tuple[int, float]:
    """The car of ``group`` whose furthest member lies nearest, the first on a tie, and that
    member's share. Every member lies within reach of the chip the group gathered around, so
    the cars that reach the whole group (that chip among them) are the only ones judged:
    every other car's furthest member lies beyond reach. A group that none reaches whole (its
    chip went to another chip alike) is judged whole."""
    whole = np.concatenate(
        [reach[np.ix_(rows, group)].all(axis=1) for rows in _blocks(group, len(group))]
    )
    candidates = group[whole] if whole.any() else group
    furthest = np.concatenate(
        [shares_of(rows, group).max(axis=1) for rows in _blocks(candidates, len(group))]
    )
    k = int(np.argmin(furthest))
    return int(candidates[k]), float(furthest[k])


def chip_name(colour_code: str, number: int) -> str:
    """The sample name of a code's variant chip: ``'GEN 001 #2'``."""
    return f"{colour_code} #{number}"


def variant_chips(
    variants: Sequence[ColourVariant], colour_code: str, tolerance: Tolerance, within: float
) -> list[Measurement]:
    """The shop's variant chips of ``colour_code``: each variant's centre car as the
    instrument read it (reflectance and texture), named by :func:`chip_name` in the order of
    ``variants``, for a QC program or ``compare``/``match`` to take as standards. Its metadata
    (kept by CxF3 and JSON) say which cars it stands for and the recorded recipe nearest it
    (mass fractions, as the case recorded them)."""
    synthetic = any(case.synthetic for v in variants for case in v.cases)
    chips = []
    for k, variant in enumerate(variants, 1):
        centre, recipe = variant.centre, variant.recipe.case
        meta = {
            "colour_code": colour_code,
            "variant": str(k),
            "variants": str(len(variants)),
            "cars": str(len(variant.cases)),
            "spread": f"{variant.spread:.3f}",
            "centre_case_id": centre.case_id,
            "recipe_case_id": recipe.case_id,
            "recipe": json.dumps(recipe.recipe),
            "tolerance": tolerance.name,
            "within": f"{within:g}",
            "synthetic": "1" if synthetic else "0",
        }
        chips.append(
            Measurement(
                chip_name(colour_code, k),
                geometries=centre.geometries,
                wavelengths=WAVELENGTHS,
                reflectance=centre.target,
                texture=centre.target_texture,
                instrument=centre.instrument,
                measured_at=centre.created_at,
                metadata=meta,
                **centre.as_read("target"),
            )
        )
    return chips


def _blocks(rows: NDArray[np.intp], columns: int) -> list[NDArray[np.intp]]:
    """``rows`` of a matrix of ``columns`` columns, in blocks of about :data:`PAIRS_AT_ONCE`
    elements."""
    return np.array_split(rows, max(1, -(-len(rows) * columns // PAIRS_AT_ONCE)))
