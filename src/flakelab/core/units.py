"""Amounts typed with a unit (``250g``, ``0.5 kg``, ``50cm``) → one number in a base unit."""

from __future__ import annotations

from collections.abc import Mapping
from numbers import Real

import numpy as np

__all__ = ["parse_amount", "is_number", "unit_of"]


def is_number(value: object) -> bool:
    """Whether a value read from a JSON or TOML file is a real number: JSON's ``true`` is a
    Python bool, which is an int, but not an amount."""
    if type(value) in (float, int):  # most of them, without the ABC's slower check
        return True
    return isinstance(value, Real) and not isinstance(value, bool)


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
