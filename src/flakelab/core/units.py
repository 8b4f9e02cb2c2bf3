"""Amounts typed with a unit (``250g``, ``0.5 kg``, ``50cm``) → one number in a base unit."""

from __future__ import annotations

from collections.abc import Mapping
from numbers import Real

import numpy as np

__all__ = ["parse_amount", "is_number", "unit_of", "check_mass_fractions", "FRACTION_SUM_TOLERANCE"]

FRACTION_SUM_TOLERANCE = 1e-4
"""How far a recipe's mass fractions may sum from one, or fall below zero, before a forward
model refuses them [-]. A float32 recipe, or one rounded to the scale and divided by the can,
stays far inside; grams or percent are far outside, and a learned model predicted them without
a word far outside its cases (a blue metallic's 250 g recipe 26–117 ΔE00 from its fractions',
the same recipe times 1.5 7–28; ``tests/test_match.py -k grams_are_refused``)."""


def is_number(value: object) -> bool:
    """Whether a value read from a JSON or TOML file is a real number: JSON's ``true`` is a
    Python bool, which is an int, but not an amount."""
    if type(value) in (float, int):  # most of them, without the ABC's slower check
        return True
    return isinstance(value, Real) and not isinstance(value, bool)


def check_mass_fractions(fractions: np.ndarray, error: type[Exception] = ValueError) -> None:
    """Refuse recipes ``fractions[N, T]`` that are not mass fractions: each row finite, none
    below zero and summing to one (within :data:`FRACTION_SUM_TOLERANCE`), naming the first
    row that is not."""
    x = np.atleast_2d(fractions)
    sums = x.sum(axis=1)
    off = np.abs(sums - 1.0)
    if (
        off.max(initial=0.0) <= FRACTION_SUM_TOLERANCE
        and x.min(initial=0.0) >= -FRACTION_SUM_TOLERANCE
    ):
        return  # 9 ms for 200,000 recipes of 35 toners: under 2 % of predicting them
    bad = ~(off <= FRACTION_SUM_TOLERANCE) | (x.min(axis=1) < -FRACTION_SUM_TOLERANCE)
    row = int(np.argmax(bad))
    if not np.isfinite(sums[row]):
        problem = "holds an amount that is not a number"
    elif x[row].min() < -FRACTION_SUM_TOLERANCE:
        problem = f"has a negative amount ({x[row].min():g})"
    else:
        problem = f"sums to {sums[row]:g}, not 1"
    raise error(
        f"fractions: row {row} {problem}: a recipe's amounts are mass fractions of the can "
        "(divide grams by the can's total)"
    )


def unit_of(text: str, units: Mapping[str, float]) -> str:
    """The unit among ``units`` that ``text`` is typed in (the longest that ends it, case
    and spaces aside), else ``""``."""
    value = text.strip().lower().replace(" ", "")
    return max((u for u in units if value.endswith(u)), key=len, default="")


def parse_amount(
    text: str,
    units: Mapping[str, float],
    option: str,
    example: str,
    error: type[Exception] = ValueError,
) -> float:
    """``text`` in any of ``units`` (name → factor to the base unit; a bare number is in the
    base unit) as a positive finite number, else ``error`` naming ``option``."""
    value = text.strip().lower().replace(" ", "")
    unit = unit_of(value, units)
    try:
        amount = float(value[: len(value) - len(unit)]) * units.get(unit, 1.0)
    except ValueError:
        # "1,5kg": a decimal comma, or a thousands separator ("1,000g")? Not guessed: said
        point = "; write a decimal point, not a comma" if "," in value else ""
        raise error(f"{option}: expected an amount like {example}, got {text!r}{point}") from None
    if not np.isfinite(amount) or amount <= 0:
        raise error(f"{option}: expected a positive amount, got {text!r}")
    return amount
