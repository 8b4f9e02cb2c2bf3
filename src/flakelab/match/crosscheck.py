"""A match's candidates predicted at the target's geometries that its model left out.

An MA-T12 reads twelve geometries; the default five-angle model predicts five of them, and
searches there (``benchmarks/instrument_choice.py``: its recipes pass at twelve geometries
at least as often as the MA-T12 model's own). The colorist still wants to know how each
candidate will look at the other seven: a model that predicts them (the MA-T12 one) says so,
clearly apart from the numbers the search used.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.tolerance import Tolerance, failing_geometries
from flakelab.match.judging import Candidate, evaluate_recipes, geometry_rows, recipe_vector
from flakelab.match.search import unused_geometries

__all__ = ["LeftOut", "predict_left_out", "expected_left_out"]


@dataclass(frozen=True)
class LeftOut:
    """One candidate at the geometries its own model left out, as ``model`` (its
    description; ``model_id``, which model file) predicts it."""

    model: str
    model_id: str
    geometries: tuple[str, ...]
    lab: NDArray
    dLCH: NDArray
    de00: NDArray
    passed: NDArray

    @property
    def failing(self) -> list[str]:
        return failing_geometries(self.geometries, self.passed)

    def to_dict(self) -> dict[str, Any]:
        rows = geometry_rows(self.geometries, self.lab, self.dLCH, self.de00)
        for row, ok in zip(rows.values(), self.passed, strict=True):
            row["pass"] = bool(ok)
        return {
            "model": self.model,
            "model_id": self.model_id,
            "passes": not self.failing,
            "failing_geometries": self.failing,
            "geometries": rows,
        }


def _predicted_lab(other, recipes: list[dict[str, float]], geometries: list[str]) -> NDArray:
    """CIELAB ``[recipes, geometries, 3]`` of ``recipes`` as ``other`` predicts them."""
    R, _ = evaluate_recipes(other, np.array([recipe_vector(other, r) for r in recipes]))
    return reflectance_to_Lab(R[:, [list(other.geometries).index(g) for g in geometries]])


def _left_out(other, geometries: list[str], lab, dlch, de00, passed) -> LeftOut:
    return LeftOut(
        other.name, getattr(other, "model_id", other.name), tuple(geometries), lab, dlch, de00,
        passed,
    )  # fmt: skip


def predict_left_out(
    candidates: list[Candidate], target, forward, other, tolerance: Tolerance
) -> list[LeftOut]:
    """Each of ``candidates`` (matched through ``forward``) predicted by ``other`` at the
    geometries of the ``target`` measurement that ``forward`` left out and ``other``
    predicts, judged against ``tolerance``. Empty when there are none."""
    left_out = [g for g in unused_geometries(target, forward) if g in other.geometries]
    if not left_out or not candidates:
        return []
    target_lab = reflectance_to_Lab(target.storage_spectra(left_out))
    lab = _predicted_lab(other, [c.fractions for c in candidates], left_out)
    de00, dlch, passed = tolerance.judge(left_out, target_lab[None], lab)  # [candidates, G]
    return [
        _left_out(other, left_out, lab[k], dlch[k], de00[k], passed[k])
        for k in range(len(candidates))
    ]


def expected_left_out(
    target,
    sprayed,
    before: dict[str, float],
    after: dict[str, float],
    forward,
    other,
    tolerance: Tolerance,
) -> tuple[NDArray, LeftOut] | None:
    """A correction's expected result at the geometries of the ``target`` reading that
    ``forward`` left out, where ``other`` predicts and the ``sprayed`` reading measured: the
    spray-out as measured there, moved by what ``other`` predicts the change of recipe from
    ``before`` to ``after`` does. The whole offset there is taken to persist (splitting off
    this spray's application would need the correction's model of those geometries).
    Returns the spray-out's ΔE00 there and the expected result; None where there are none."""
    read = set(sprayed.geometry_names)
    left_out = [
        g for g in unused_geometries(target, forward) if g in other.geometries and g in read
    ]
    if not left_out:
        return None
    target_lab = reflectance_to_Lab(target.storage_spectra(left_out))
    sprayed_lab = reflectance_to_Lab(sprayed.storage_spectra(left_out))
    lab_before, lab_after = _predicted_lab(other, [before, after], left_out)
    expected = sprayed_lab + lab_after - lab_before
    sprayed_de00, _, _ = tolerance.judge(left_out, target_lab, sprayed_lab)
    de00, dlch, passed = tolerance.judge(left_out, target_lab, expected)
    return sprayed_de00, _left_out(other, left_out, expected, dlch, de00, passed)
