"""Recipe output: grams per toner for a can, at the scale's resolution, and what rounding costs.

The colour cost of rounding is the largest ΔE00 over geometries between the exact and the
weighed recipe, both predicted by the same forward model. The nearest grams (largest-remainder
rounding, so that the weighed amounts add up exactly to the can) are not always the closest
colour: 0.7 g of carbon black where 0.74 g was meant darkens a silver more than the tenth of
a gram of blue beside it can, and rounding that blue down as well keeps the hue. With a model,
:func:`weigh_for_colour` tries every rounding of each toner down or up to the scale (the
largest toner taking the balance, so the can stays whole) in one batch and keeps the one
whose colour is closest to the exact recipe's; the nearest grams are among those tried, so it
never costs more. Additions to a mixed can (:func:`weigh_additions`) are rounded the same way.

A shop orders its can by mass or by volume (:class:`Can`). By volume, each recipe weighs its
own: the toners' volumes add as they mix (mixing software assumes it), so V millilitres of a
recipe of mass shares wᵢ and densities ρᵢ weigh V / Σ wᵢ/ρᵢ grams.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E
from flakelab.core.units import parse_amount, unit_of
from flakelab.errors import FlakelabError
from flakelab.match.settings import SCALE_RESOLUTION_G

__all__ = [
    "RecipeLine",
    "Weighing",
    "Can",
    "order_can",
    "recipe_grams",
    "weigh",
    "check_scale",
    "check_resolution",
    "weigh_for_colour",
    "weigh_whole_can",
    "weigh_additions",
    "weigh_after_pouring",
    "pouring_order",
    "check_poured",
    "room_for_additions",
    "parse_quantity",
    "can_on_scale",
    "to_scale",
    "RecipeError",
    "ROUNDINGS_VARIED",
    "MAX_SCALE_STEPS",
]

MAX_SCALE_STEPS = 10**9
"""The most steps of its scale a can may take to weigh (100 t at 0.1 g): past it a quantity is
a typing error, and the rounding's integer arithmetic would overflow."""

ROUNDINGS_VARIED = 12
"""At most this many toners, the smallest in the can, are tried rounded both down and up
(2¹² roundings in one batch); the rest take their nearest grams."""


class RecipeError(FlakelabError):
    """An impossible quantity or resolution."""


@dataclass(frozen=True)
class RecipeLine:
    toner: str
    grams: float
    cumulative: float


@dataclass(frozen=True)
class Weighing:
    """What to weigh, and its colour cost: the largest ΔE00 over geometries between the
    weighed and the exact amounts (``rounding_de00``), and the same for the nearest grams
    (``nearest_de00``), both predicted by one model; ``lab_shift[G, 3]`` the weighed minus
    the exact amounts' CIELAB by that model. ``grams`` per toner; ``lines`` the recipe in
    pouring order, for a whole can (empty for additions)."""

    grams: dict[str, float]
    rounding_de00: float
    nearest_de00: float
    lab_shift: np.ndarray
    lines: list[RecipeLine]


METRIC_MASS = {"kg": 1000.0, "g": 1.0}
IMPERIAL_MASS = {"lb": 453.59237, "oz": 28.349523125}
"""Grams in each unit a can may be given in (NIST SP 811: the international pound)."""


VOLUME = {"ml": 1.0, "l": 1000.0, "pt": 473.176473, "qt": 946.352946, "gal": 3785.411784}
"""Millilitres in each unit a can may be ordered in by volume (NIST SP 811: US liquid pint,
quart and gallon)."""

QUANTITY_EXAMPLE = "250g, 0.5kg, 1lb or 0.5l"


def parse_quantity(text: str, option: str = "--quantity") -> float:
    """``250g``, ``0.5 kg``, ``1lb`` → grams."""
    units = METRIC_MASS | IMPERIAL_MASS
    return parse_amount(text, units, option, QUANTITY_EXAMPLE, RecipeError)


def is_volume(text: str) -> bool:
    """Whether a quantity is typed in a unit of volume (``0.5l``, ``500 ml``, ``1qt``)."""
    return bool(unit_of(text, VOLUME))


@dataclass(frozen=True)
class Can:
    """The can a shop mixes, as ordered (``quantity``) for a scale of ``resolution_g``: by
    mass, ``grams`` for every recipe; by volume, ``millilitres``, each recipe weighed from
    its toners' ``densities`` [g/mL] (module notes). ``option`` names it in messages."""

    quantity: str
    resolution_g: float
    grams: float | None = None
    millilitres: float | None = None
    densities: Mapping[str, float] = field(default_factory=dict, hash=False)
    option: str = "--quantity"

    def for_toners(self, library, names: Iterable[str]) -> Can:
        """A can by volume with the densities ``library`` gives the toners ``names`` its
        recipes may hold, checked that the scale weighs it whatever they hold; a can by mass
        unchanged."""
        if self.millilitres is None:
            return self
        densities = library.densities(names)
        can = replace(self, densities=densities)
        for density in {min(densities.values()), max(densities.values())}:
            can._on_scale(self.millilitres * density)
        return can

    def grams_for(self, fractions: Mapping[str, float]) -> float:
        """The can's grams for a recipe of mass shares ``fractions``, to the scale's step."""
        if self.grams is not None:
            return self.grams
        if missing := sorted(set(fractions) - set(self.densities)):
            raise RecipeError(f"{self.option} {self.quantity}: no density for {', '.join(missing)}")
        total = sum(fractions.values())
        specific_volume = sum(w / total / self.densities[n] for n, w in fractions.items())
        return self._on_scale(self.millilitres / specific_volume)

    def to_dict(self) -> dict[str, float]:
        """The can as ordered, by mass or by volume, and the scale's step."""
        if self.millilitres is None:
            return {"quantity_g": self.grams, "resolution_g": self.resolution_g}
        return {"quantity_ml": self.millilitres, "resolution_g": self.resolution_g}

    def _on_scale(self, grams: float) -> float:
        weighed = to_scale(grams, self.resolution_g)
        if weighed <= 0:
            _under_a_step(self.option, f"{self.quantity} ({grams:.3g} g)", self.resolution_g)
        check_scale(weighed, self.resolution_g, self.option)
        return weighed


def order_can(text: str, resolution_g: float, option: str = "--quantity") -> Can:
    """The can ``text`` orders, by mass (checked that the scale weighs it, as
    :func:`can_on_scale`) or by volume (its densities still to give:
    :meth:`Can.for_toners`); ``option`` names it in messages."""
    if is_volume(text):
        check_resolution(resolution_g)
        millilitres = parse_amount(text, VOLUME, option, QUANTITY_EXAMPLE, RecipeError)
        return Can(text, resolution_g, millilitres=millilitres, option=option)
    return Can(text, resolution_g, grams=can_on_scale(text, resolution_g, option), option=option)


def recipe_grams(
    text: str, resolution_g: float, library, fractions: Mapping[str, float], option: str
) -> float:
    """An amount of a recipe of mass shares ``fractions`` typed by mass or volume (``--left``,
    ``--most``), in grams to the scale's step: by volume, at the density its toners give
    in ``library``."""
    return order_can(text, resolution_g, option).for_toners(library, fractions).grams_for(fractions)


def can_on_scale(text: str, resolution_g: float, option: str = "--quantity") -> float:
    """The can ``text`` names, in grams, checked that a scale of ``resolution_g`` weighs it.
    A can in pounds or ounces is the nearest whole number of the scale's steps (a pound,
    453.59237 g, is 453.6 g on a 0.1 g scale); one in grams or kilograms must be one already,
    since a can typed finer than the scale reads is more likely a mistyped scale."""
    grams = parse_quantity(text, option)
    if unit_of(text, IMPERIAL_MASS):
        grams = to_scale(grams, resolution_g)
    if grams < resolution_g * (1 - 1e-9):  # "0.05 g is not a multiple of …" before
        _under_a_step(option, text, resolution_g)
    check_scale(grams, resolution_g, option)
    return grams


def _under_a_step(option: str, amount: str, resolution_g: float) -> None:
    advice = "; mix a larger can" if option == "--quantity" else ""
    raise RecipeError(f"{option}: {amount} is less than the scale's {resolution_g:g} g{advice}")


def to_scale(grams: float, resolution_g: float) -> float:
    """``grams`` as the nearest whole number of a scale's steps of ``resolution_g``."""
    check_resolution(resolution_g)
    return round(round(grams / resolution_g) * resolution_g, 9)


def check_resolution(resolution_g: float) -> None:
    """A :class:`RecipeError` unless the scale's resolution is a positive number of grams."""
    if not resolution_g > 0 or not np.isfinite(resolution_g):
        raise RecipeError(f"resolution: expected a positive number of grams, got {resolution_g}")


def check_scale(quantity_g: float, resolution_g: float, what: str = "quantity") -> int:
    """How many steps of a scale of ``resolution_g`` weigh a can of ``quantity_g``; a
    :class:`RecipeError` naming ``what`` where the scale cannot weigh it, before any search
    is made for it."""
    check_resolution(resolution_g)
    steps = quantity_g / resolution_g
    if not steps <= MAX_SCALE_STEPS:  # inf too: 1e308 g on a 0.1 g scale
        raise RecipeError(
            f"{what}: {quantity_g:g} g is more than {MAX_SCALE_STEPS:.0e} steps of the "
            f"scale's {resolution_g:g} g (a larger scale resolution weighs a larger can)"
        )
    if abs(steps - round(steps)) > 1e-6:
        raise RecipeError(
            f"{what}: {quantity_g:g} g is not a multiple of the scale's {resolution_g:g} g"
        )
    return round(steps)


def weigh(
    fractions: dict[str, float], quantity_g: float, resolution_g: float = SCALE_RESOLUTION_G
) -> list[RecipeLine]:
    """Grams per toner (largest first, the usual pouring order) summing to ``quantity_g``."""
    steps = check_scale(quantity_g, resolution_g)
    names = list(fractions)
    x = np.array([fractions[n] for n in names], dtype=float)
    x = x / x.sum()
    exact = x * steps
    units = np.floor(exact).astype(int)
    remainder = steps - units.sum()
    units[np.argsort(-(exact - units))[:remainder]] += 1
    if np.any(units == 0):
        small = [n for n, u in zip(names, units, strict=True) if u == 0]
        raise RecipeError(
            f"quantity: {quantity_g:g} g is too small to weigh {', '.join(small)} "
            f"at {resolution_g:g} g resolution; mix a larger can"
        )
    return pouring_order(
        {n: round(float(u) * resolution_g, 6) for n, u in zip(names, units, strict=True)}
    )


def weigh_for_colour(
    forward,
    fractions: dict[str, float],
    quantity_g: float,
    resolution_g: float = SCALE_RESOLUTION_G,
) -> Weighing:
    """:func:`weigh`, with each toner rounded down or up to the scale as the colour closest to
    the exact recipe's by ``forward`` asks (module notes)."""
    nearest = weigh(fractions, quantity_g, resolution_g)
    steps = check_scale(quantity_g, resolution_g)
    names = list(fractions)
    share = np.array([fractions[n] for n in names], dtype=float)
    exact = share / share.sum() * steps
    by_name = {line.toner: line.grams for line in nearest}
    nearest_units = np.array([round(by_name[n] / resolution_g) for n in names])
    units = _whole_can_roundings(exact, nearest_units, steps)
    best, cost, shift = _closest_colour(forward, names, exact, units)
    grams = {n: round(float(u) * resolution_g, 6) for n, u in zip(names, units[best], strict=True)}
    return Weighing(grams, float(cost[best]), float(cost[0]), shift, pouring_order(grams))


def weigh_whole_can(
    forward,
    fractions: dict[str, float],
    quantity_g: float,
    resolution_g: float = SCALE_RESOLUTION_G,
) -> Weighing:
    """:func:`weigh_for_colour` for a can of ``quantity_g`` grams mixed afresh, the traces
    under one scale step left out (a correction's reformulation, or any computed recipe, can
    carry amounts no scale weighs; under a whole step, rounding to the nearest could leave
    one at nothing)."""
    total = sum(fractions.values())
    kept = {n: v for n, v in fractions.items() if v / total * quantity_g >= resolution_g}
    return weigh_for_colour(forward, kept, quantity_g, resolution_g)


def weigh_additions(
    forward,
    can: dict[str, float],
    added: dict[str, float],
    resolution_g: float = SCALE_RESOLUTION_G,
) -> Weighing:
    """Grams to add to a mixed ``can`` (grams per toner) for ``added`` (each toner's
    addition as a share of the can), each rounded down or up to the scale as the colour
    closest to the exact additions' by ``forward`` asks; an addition rounded to nothing is
    left out."""
    names = list(dict.fromkeys([*can, *added]))
    total = sum(can.values())
    mixed = np.array([can.get(n, 0.0) for n in names])
    exact = np.array([added.get(n, 0.0) * total / resolution_g for n in names])
    nearest = np.round(exact)
    options = np.stack([np.floor(exact), np.ceil(exact)])
    units = _roundings(options, nearest, np.argsort(exact)[::-1][: np.count_nonzero(exact)])
    amounts = mixed / resolution_g + units  # in scale steps, the can and its additions
    best, cost, shift = _closest_colour(forward, names, mixed / resolution_g + exact, amounts)
    grams = {
        n: round(float(u) * resolution_g, 6)
        for n, u in zip(names, units[best], strict=True)
        if u > 0
    }
    return Weighing(grams, float(cost[best]), float(cost[0]), shift, [])


def weigh_after_pouring(
    forward,
    fractions: dict[str, float],
    quantity_g: float,
    poured: dict[str, float],
    resolution_g: float = SCALE_RESOLUTION_G,
) -> tuple[float, Weighing]:
    """What is still to pour for a can of ``quantity_g`` of ``fractions`` once ``poured``
    (grams per toner on the scale so far) are in it, and the can's size: where a toner ran
    over, the can grows to the least size, in whole steps of the scale, that holds it at the
    recipe's proportions, so that the colour is kept by pouring more of the others rather
    than lost. The rest is rounded as :func:`weigh_additions` rounds additions; ``lines``
    continue the scale's reading from what is poured."""
    steps = check_scale(quantity_g, resolution_g)
    if unknown := sorted(set(poured) - set(fractions)):
        raise RecipeError(
            f"--poured: {', '.join(unknown)} not in the recipe ({', '.join(fractions)}): "
            "scaling cannot take it out (correction.correct_what_was_poured dilutes it)"
        )
    check_poured(poured, resolution_g)
    total = sum(fractions.values())
    share = {n: v / total for n, v in fractions.items()}
    needed = max(g / share[n] / resolution_g for n, g in poured.items())
    if not needed <= MAX_SCALE_STEPS:  # a trace of the recipe poured by the gram; inf too
        over = max(poured, key=lambda n: poured[n] / share[n])
        raise RecipeError(
            f"--poured: {over}, {poured[over]:g} g, is {share[over]:.3g} of the recipe: the can "
            f"that holds it at the recipe's proportions is more than {MAX_SCALE_STEPS:.0e} steps "
            f"of the scale's {resolution_g:g} g; mix afresh"
        )
    grown = max(steps, int(np.ceil(round(needed, 6)))) * resolution_g
    check_scale(grown, resolution_g)
    in_can = sum(poured.values())
    added = {n: max(share[n] * grown - poured.get(n, 0.0), 0.0) / in_can for n in share}
    weighing = weigh_additions(forward, poured, added, resolution_g)
    lines = pouring_order(weighing.grams, start=in_can)
    return round(grown, 9), replace(weighing, lines=lines)


def room_for_additions(most_g: float, can_g: float, toners: int, resolution_g: float) -> float:
    """The share of a can of ``can_g`` that additions may come to together, so that it holds
    at most ``most_g`` (``--most``) even when each of ``toners`` weighed is rounded up a step
    on the scale; a :class:`RecipeError` where even no addition would fit."""
    needed = can_g + toners * resolution_g
    if not most_g >= needed:
        raise RecipeError(
            f"--most: {most_g:g} g cannot hold the can: it needs {needed:.1f} g ({can_g:.1f} g "
            f"and a scale step for each of its {toners} toners' rounding)"
        )
    return (most_g - needed) / can_g


def check_poured(poured: dict[str, float], resolution_g: float = SCALE_RESOLUTION_G) -> None:
    """A :class:`RecipeError` unless ``poured`` gives grams ≥ 0, more than none in all, and no
    more than a scale of ``resolution_g`` weighs (1e308 g overflowed the additions)."""
    if not poured or any(not (np.isfinite(g) and g >= 0) for g in poured.values()):
        raise RecipeError(f"--poured: expected grams ≥ 0 for at least one toner, got {poured}")
    in_all = sum(poured.values())
    if in_all <= 0:
        raise RecipeError("--poured: the amounts poured sum to zero grams")
    if not in_all / resolution_g <= MAX_SCALE_STEPS:  # inf too
        raise RecipeError(
            f"--poured: {in_all:g} g in all is more than {MAX_SCALE_STEPS:.0e} steps of the "
            f"scale's {resolution_g:g} g"
        )


def _whole_can_roundings(exact: np.ndarray, nearest: np.ndarray, steps: int) -> np.ndarray:
    """Integer amounts ``[N, k]`` (the nearest first) summing to ``steps``: each toner but
    the largest rounded down or up (at least one step), the largest taking the balance."""
    largest = int(np.argmax(exact))
    options = np.stack([np.floor(exact), np.ceil(exact)]).clip(min=1)
    others = [i for i in np.argsort(exact) if i != largest]
    units = _roundings(options, nearest, others)
    units[:, largest] = steps - (units.sum(1) - units[:, largest])
    return units[units[:, largest] >= 1]


def _roundings(options: np.ndarray, nearest: np.ndarray, varied) -> np.ndarray:
    """Every choice between ``options[0]`` and ``options[1]`` for the first
    :data:`ROUNDINGS_VARIED` toners of ``varied``, the others at ``nearest``; the nearest
    rounding first, no row twice."""
    varied = np.asarray(varied, dtype=int)[:ROUNDINGS_VARIED]
    bits = (np.arange(2 ** len(varied))[:, None] >> np.arange(len(varied))) & 1
    units = np.repeat(nearest[None].astype(float), len(bits), axis=0)
    units[:, varied] = options[bits, varied]
    units = np.unique(units, axis=0)
    return np.concatenate([nearest[None], units[np.any(units != nearest, axis=1)]])


def _closest_colour(forward, names: list[str], exact: np.ndarray, amounts: np.ndarray):
    """The row of ``amounts[N, k]`` (any units) whose colour by ``forward`` is closest to
    that of ``exact[k]``, each row's cost (the largest ΔE00 over geometries), and the chosen
    row's CIELAB minus the exact amounts'."""
    from flakelab.match.judging import evaluate_recipes

    columns = [list(forward.toners).index(n) for n in names]
    x = np.zeros((1 + len(amounts), len(forward.toners)))
    x[:, columns] = np.concatenate([exact[None], amounts])
    R, _ = evaluate_recipes(forward, x / x.sum(1, keepdims=True))
    lab = reflectance_to_Lab(R)
    cost = delta_E(lab[:1], lab[1:]).max(axis=1)
    best = int(np.argmin(cost))
    return best, cost, lab[1 + best] - lab[0]


def pouring_order(grams: dict[str, float], start: float = 0.0) -> list[RecipeLine]:
    """The largest toner first, with the scale's running total from ``start``."""
    order = sorted(grams, key=lambda n: -grams[n])
    running = start + np.cumsum([grams[n] for n in order])
    return [
        RecipeLine(n, grams[n], round(float(c), 6)) for n, c in zip(order, running, strict=True)
    ]
