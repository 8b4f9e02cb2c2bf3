"""The learned model's support: the recipes like those it learned from (DESIGN.md §6).

A recipe outside it (more than a solid, less effect toner than any effect paint the model
learned from, or a trace of a kind of effect toner) gets numbers the model guessed, which
the optimiser exploits: the search ranks such recipes after every recipe inside it and
says why (:mod:`flakelab.match.search`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from flakelab.match.settings import MatchSettings

__all__ = ["below_effect_floor", "outside_note", "outside_support", "trace_toners"]


def outside_support(x: NDArray, effect: NDArray, settings: MatchSettings) -> NDArray:
    """Recipes ``x[N, T]`` where the learned model never saw a case, and the optimiser finds
    its guesses:

    * between a solid and ``settings.effect_floor``, the least effect-toner share of the
      model's effect paints (``effect_share_floor`` in its training record): a DPP red solid
      matched with 3.9 % of red pearl, predicted within 0.3 ΔE00 and 1.3 off by the physics;
    * with a trace of a kind of effect toner (:func:`trace_toners`), which no formula of the
      world holds (:data:`~flakelab.match.settings.EFFECT_TRACE` says what it buys)."""
    return below_effect_floor(x, effect, settings) | trace_toners(x, effect, settings).any(-1)


def below_effect_floor(x: NDArray, effect: NDArray, settings: MatchSettings) -> NDArray:
    """Recipes ``x[N, T]`` between a solid and ``settings.effect_floor``: the part of
    :func:`outside_support` that the halving and the screen's ranking keep to as well. A
    trace of a kind of effect toner is judged at the end alone (and the swap stage tries the
    recipe without it): kept from the halving too, it moved the search's paths everywhere
    (the example's second and third candidates went from 0.24 and 0.32 to 0.42 and 0.52) for
    no pass its chance could see."""
    share = x[:, np.asarray(effect, bool)].sum(1)
    return (share > 0) & (share < settings.effect_floor)


def trace_toners(x: NDArray, effect: NDArray, settings: MatchSettings) -> NDArray:
    """Where recipes ``x[..., T]`` hold a kind of effect toner (``settings.effect_kinds``:
    aluminium, pearl) at less than ``settings.effect_trace`` of the recipe, all together:
    those toners ``[..., T]``. Without kinds (the physics alone, which has no support to
    keep to), none."""
    traces = np.zeros(np.shape(x), bool)
    if settings.effect_kinds is None:
        return traces
    kinds = np.where(np.asarray(effect, bool), np.asarray(settings.effect_kinds, dtype=str), "")
    for kind in set(kinds.tolist()) - {""}:
        members = kinds == kind
        share = x[..., members].sum(-1, keepdims=True)
        traces |= members & (x > 0) & (share < settings.effect_trace)
    return traces


def outside_note(x: NDArray, effect: NDArray, toners, settings: MatchSettings) -> str:
    """Why the best recipe ``x[T]`` lies outside the model's support (:func:`outside_support`)."""
    if below_effect_floor(x[None], effect, settings)[0]:
        share = x[effect].sum()
        return (
            f"the best recipe has {100 * share:.1f} % effect toners, less than any effect paint "
            f"the model learned from ({100 * settings.effect_floor:.0f} %): its numbers are "
            "extrapolated"
        )
    traces = ", ".join(
        f"{toners[i]} {100 * x[i]:.1f} %" for i in np.flatnonzero(trace_toners(x, effect, settings))
    )
    return (
        f"the best recipe holds a trace of effect toner ({traces}); no recipe the model "
        f"learned from held aluminium or pearl under {100 * settings.effect_trace:g} %: its "
        "numbers are extrapolated"
    )
