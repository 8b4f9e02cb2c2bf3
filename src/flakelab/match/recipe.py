"""Recipe output: grams per toner for a can, at the scale's resolution, and what rounding costs.

Rounding uses the largest-remainder method, so the weighed amounts add up exactly to the can;
the colour cost of rounding is the largest ΔE00 over geometries between the exact and the
rounded recipe, both predicted by the same forward model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E
from flakelab.core.units import parse_amount
from flakelab.errors import FlakelabError

__all__ = ["RecipeLine", "weigh", "rounding_cost", "parse_quantity", "RecipeError"]


class RecipeError(FlakelabError):
    """An impossible quantity or resolution."""


@dataclass(frozen=True)
class RecipeLine:
    toner: str
    grams: float
    cumulative: float


def parse_quantity(text: str) -> float:
    """``250g``, ``0.5 kg``, ``1lb`` → grams."""
    units = {"kg": 1000.0, "g": 1.0, "lb": 453.59237, "oz": 28.349523125}
    return parse_amount(text, units, "--quantity", "250g or 0.5kg", RecipeError)


def weigh(
    fractions: dict[str, float], quantity_g: float, resolution_g: float = 0.1
) -> list[RecipeLine]:
    """Grams per toner (largest first, the usual pouring order) summing to ``quantity_g``."""
    if resolution_g <= 0 or not np.isfinite(resolution_g):
        raise RecipeError(f"resolution: expected a positive number of grams, got {resolution_g}")
    steps = quantity_g / resolution_g
    if abs(steps - round(steps)) > 1e-6:
        raise RecipeError(
            f"quantity: {quantity_g:g} g is not a multiple of the scale's {resolution_g:g} g"
        )
    names = list(fractions)
    x = np.array([fractions[n] for n in names], dtype=float)
    x = x / x.sum()
    exact = x * round(steps)
    units = np.floor(exact).astype(int)
    remainder = int(round(steps)) - units.sum()
    units[np.argsort(-(exact - units))[:remainder]] += 1
    if np.any(units == 0):
        small = [n for n, u in zip(names, units, strict=True) if u == 0]
        raise RecipeError(
            f"quantity: {quantity_g:g} g is too small to weigh {', '.join(small)} "
            f"at {resolution_g:g} g resolution; mix a larger can"
        )
    order = np.argsort(-units, kind="stable")
    grams = units[order] * resolution_g
    return [
        RecipeLine(names[i], round(float(g), 6), round(float(c), 6))
        for i, g, c in zip(order, grams, np.cumsum(grams), strict=True)
    ]


def rounding_cost(forward, fractions: dict[str, float], lines: list[RecipeLine]) -> float:
    """Largest ΔE00 over geometries between the exact and the weighed recipe."""
    from flakelab.match.search import evaluate_recipes

    index = {n: i for i, n in enumerate(forward.toners)}
    x = np.zeros((2, len(forward.toners)))
    for name, value in fractions.items():
        x[0, index[name]] = value
    total = sum(line.grams for line in lines)
    for line in lines:
        x[1, index[line.toner]] = line.grams / total
    R, _ = evaluate_recipes(forward, x / x.sum(1, keepdims=True))
    lab = reflectance_to_Lab(R)
    return float(delta_E(lab[0], lab[1]).max())
