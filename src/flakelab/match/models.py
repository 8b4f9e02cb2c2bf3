"""Which forward model answers for a library and instrument."""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np

from flakelab.errors import Note
from flakelab.library.toners import Library, did_you_mean
from flakelab.match.forward import HybridForward, LearnedForward, stand_ins
from flakelab.models.network import MIN_CASES, ForwardModel, ModelError

__all__ = [
    "forward_for",
    "MIN_CASES",
    "effect_kinds",
    "effect_mask",
    "novel_toners",
    "toner_standing",
    "unused_toners",
]


EFFECT_KINDS = ("aluminium", "pearl")
"""The library's kinds of effect toner."""


def effect_kinds(library: Library, toners) -> tuple[str, ...]:
    """Each of ``toners``' kind of effect toner ("aluminium", "pearl"; "" for a pigment)."""
    kinds = {t.name: t.kind for t in library.toners}
    return tuple(kinds.get(n) if kinds.get(n) in EFFECT_KINDS else "" for n in toners)


def effect_mask(library: Library, toners) -> np.ndarray:
    """Which of ``toners`` are effect toners (:func:`effect_kinds`)."""
    return np.array(effect_kinds(library, toners)) != ""


def unused_toners(library: Library, model: ForwardModel) -> list[str]:
    """The model's toners the library lacks: the matcher never uses them."""
    return [n for n in model.toners if n not in library.names]


def _toner_difference(library: Library, model: ForwardModel) -> str:
    """How a library's toner list differs from a model's, for a message."""
    new = [n for n in library.names if n not in model.toners]
    gone = unused_toners(library, model)
    parts = [f"{len(new)} of the library's are not in the model (e.g. {new[:3]})"] if new else []
    parts += (
        [f"{len(gone)} of the model's are not in the library (e.g. {gone[:3]})"] if gone else []
    )
    return "differ in toners: " + "; ".join(parts)


def novel_toners(library: Library, model: ForwardModel) -> list[str]:
    """The library's toners the matcher predicts as new: those the model learned from too
    few cases, and those it was not trained with."""
    return [n for n in library.names if n in model.new_toners or n not in model.toners]


def toner_standing(library: Library, model: ForwardModel) -> list[dict]:
    """How ``model`` knows each of ``library``'s toners: the cases it learned it from (None
    where its training record gives none), "learned", "new" (too few cases) or "added" (not
    among the model's toners: added to the library since), and the known toner a new or an
    added one stands in as (:func:`stand_ins`)."""
    counts = model.info.get("toner_cases", {})
    novel = novel_toners(library, model)
    proxies = stand_ins(library, novel)
    rows = []
    for toner in library.toners:
        known = toner.name in model.toners
        standing = "learned" if toner.name not in novel else "new" if known else "added"
        rows.append(
            {
                "toner": toner.name,
                "kind": toner.kind,
                "cases": counts.get(toner.name) if known else 0,
                "standing": standing,
                "stands_in_as": proxies.get(toner.name),
            }
        )
    return rows


def forward_for(model: ForwardModel, library: Library) -> LearnedForward:
    """The learned model, or the hybrid for the library's toners the model has too few
    cases of, or none: a toner added to the library after the model was trained is such a
    new toner (DESIGN.md §3), with a note. A model that knows under half of the library's
    toners is one of another library, and refused."""
    unknown = [n for n in library.names if n not in model.toners]
    if len(unknown) * 2 > len(library.names):
        raise ModelError(
            f"library {library.name!r} and model {model.info.get('name', '?')} "
            f"{_toner_difference(library, model)}; train a model for this library"
        )
    if unknown:
        _tell_unknown(library, model, unknown)
    novel = novel_toners(library, model)
    if novel:
        forward = HybridForward(model, library, novel)
    else:
        forward = LearnedForward(model, library.names)
    forward.effect_kinds = effect_kinds(library, forward.toners)
    return forward


def _tell_unknown(library: Library, model: ForwardModel, unknown: Sequence[str]) -> None:
    """A note naming the library's toners the model was not trained with, each with the
    model's toner it may be a misspelling of."""
    missing = unused_toners(library, model)
    named = ", ".join(f"{n!r}{did_you_mean(n, missing)}" for n in unknown)
    warnings.warn(
        f"library {library.name!r}: {len(unknown)} toner(s) the model "
        f"{model.info.get('name', '?')} was not trained with, predicted as new toners (physics "
        f"scaling around the learned base, flagged on each recipe): {named}",
        Note,
        stacklevel=3,
    )
