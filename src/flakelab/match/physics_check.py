"""The physics check: the library's physics where the learned model is unsure (DESIGN.md §3).

Where the networks of the shipped ensemble disagree on a recipe by more than
:data:`~flakelab.match.settings.MODEL_SPREAD_NOTICE` ΔE00 at some geometry, the cases taught
the model little about such a paint, and its recipes pass their first spray a quarter (at the
MA-T12) to a third (at the five-angle) less often. There (over :func:`check_over`: 1.0 at the
MA-T12's twelve geometries) the library's physics answers in its place, as DESIGN.md §3's
hybrid does for a toner with too few cases: the search refines its best recipes through it
(:func:`flakelab.match.search.match`, ``MatchSettings.physics_check``), and the correction
corrects through it (:func:`flakelab.match.correction.correct`, ``physics_check``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from flakelab.core.geometry import instrument_of
from flakelab.library.toners import Library
from flakelab.match.judging import recipe_spread
from flakelab.match.settings import MODEL_SPREAD_NOTICE, PHYSICS_CHECK_OVER

__all__ = [
    "is_unsure",
    "check_over",
    "needs_physics",
    "physics_for",
    "checked_forward",
    "disagreement_words",
]


def is_unsure(spread: NDArray | None) -> bool:
    """Whether an ensemble's disagreement ``spread`` (ΔE00 per geometry; None: one network,
    or the physics) exceeds :data:`~flakelab.match.settings.MODEL_SPREAD_NOTICE` somewhere."""
    return _exceeds(spread, MODEL_SPREAD_NOTICE)


def check_over(geometries) -> float:
    """The ensemble's spread (ΔE00) over which the library's physics checks a model read at
    ``geometries``: :data:`~flakelab.match.settings.PHYSICS_CHECK_OVER` of their instrument,
    else :data:`~flakelab.match.settings.MODEL_SPREAD_NOTICE`."""
    return PHYSICS_CHECK_OVER.get(instrument_of(geometries), MODEL_SPREAD_NOTICE)


def needs_physics(spread: NDArray | None, geometries) -> bool:
    """Whether an ensemble's disagreement ``spread`` (ΔE00 per geometry of ``geometries``;
    None: one network, or the physics) exceeds :func:`check_over` somewhere."""
    return _exceeds(spread, check_over(geometries))


def _exceeds(spread: NDArray | None, threshold: float) -> bool:
    return spread is not None and float(np.max(spread)) > threshold


def disagreement_words(spread: NDArray, geometries, recipe: str) -> str:
    """How far the ensemble's networks disagree on ``recipe`` (its words), at the worst of
    the ``geometries`` by ``spread`` (ΔE00 per geometry), as the notes of the search and the
    correction begin."""
    worst = int(np.argmax(spread))
    return (
        f"the model's networks disagree on {recipe} by {spread[worst]:.2f} ΔE00 at "
        f"{geometries[worst]}"
    )


def physics_for(forward, library: Library | None):
    """The library's physics at ``forward``'s geometries, for the shop's tins where
    ``forward`` is (:class:`~flakelab.match.lots.WithLots`), or None: no ``library``, or a
    forward whose toners are not the library's (a Kubelka–Munk solid)."""
    if library is None or tuple(forward.toners) != tuple(library.names):
        return None
    from flakelab.match.forward import PhysicsForward
    from flakelab.match.lots import WithLots  # which builds on the correction, and it on this

    physics = PhysicsForward(library, forward.geometries)
    if isinstance(forward, WithLots):
        return WithLots(physics, forward.strength, forward.shade, library)
    return physics


def checked_forward(forward, library: Library | None, x: NDArray) -> tuple[object, NDArray | None]:
    """The forward model to predict recipe ``x[T]`` (or recipes ``x[N, T]``, which one model
    must compare) and their neighbours with, and the ensemble's disagreement on ``x`` (ΔE00
    per geometry, the worst recipe's at each) where that sent it to the library's physics:
    ``forward`` itself and None where the model is sure enough of ``x`` (:func:`needs_physics`),
    is one network, or the physics cannot stand in (:func:`physics_for`)."""
    if getattr(forward, "members", 1) < 2:
        return forward, None
    spread = np.atleast_2d(recipe_spread(forward, x)).max(axis=0)
    physics = physics_for(forward, library) if needs_physics(spread, forward.geometries) else None
    return (forward, None) if physics is None else (physics, spread)
