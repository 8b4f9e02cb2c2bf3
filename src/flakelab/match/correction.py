"""Correction: move a sprayed recipe onto the target (DESIGN.md §6).

The measured spray-out differs from the model's prediction for its recipe by an offset
(batch, application, model error). Assuming that offset stays for small recipe changes —
the model's local behaviour (its Jacobian) applied to the observed deviation — the corrected
recipe minimises the difference between target and *prediction + offset*:

* ``additions``: the can is already mixed; only non-negative grams of the recipe's toners
  can be added (the usual shop correction);
* ``reformulate``: new amounts of the same toners, mixed fresh.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from numpy.typing import NDArray

from flakelab.core.torch_colour import TorchColour
from flakelab.errors import FlakelabError

__all__ = ["correct", "Correction", "CORRECTION_MODES"]

CORRECTION_MODES = ("additions", "reformulate")


def _vector(forward, recipe: dict[str, float]) -> NDArray:
    index = {n: i for i, n in enumerate(forward.toners)}
    x = np.zeros(len(forward.toners))
    for name, amount in recipe.items():
        if name not in index:
            raise FlakelabError(f"recipe: toner {name!r} is unknown to the model")
        x[index[name]] = amount
    if x.sum() <= 0:
        raise FlakelabError("recipe: amounts sum to zero")
    return x / x.sum()


@dataclass(frozen=True)
class Correction:
    """The corrected recipe as fractions of its new total; ``added`` the additions per toner
    relative to the mixed can's content (``additions`` mode; empty when reformulating);
    ``expected_lab[G, 3]`` what the corrected spray-out should measure (prediction + offset)."""

    fractions: dict[str, float]
    added: dict[str, float]
    expected_lab: NDArray


def correct(
    forward,
    target: NDArray,
    recipe: dict[str, float],
    sprayed: NDArray,
    *,
    mode: str = "additions",
    steps: int = 300,
    max_addition: float = 0.5,
) -> Correction:
    """Correct ``recipe`` (fractions) after its spray-out measured ``sprayed`` [G, 31]; in
    ``additions`` mode every addition is ≥ 0 and at most ``max_addition`` of the can."""
    if mode not in CORRECTION_MODES:
        raise FlakelabError(f"--mode: expected one of {', '.join(CORRECTION_MODES)}, got {mode!r}")
    colour = TorchColour()
    x0 = torch.as_tensor(_vector(forward, recipe))[None]
    used = x0 > 0
    with torch.no_grad():
        R0, _ = forward(x0)
        offset = colour.lab(torch.as_tensor(sprayed)) - colour.lab(R0)[0]
    target_lab = colour.lab(torch.as_tensor(target))
    variable = torch.full_like(x0, -6.0 if mode == "additions" else 0.0).requires_grad_(True)
    if mode == "reformulate":
        with torch.no_grad():
            variable.copy_(torch.log(x0 + 1e-6))
    optimiser = torch.optim.Adam([variable], lr=0.05)

    def mixed() -> torch.Tensor:
        if mode == "reformulate":
            return torch.softmax(variable.masked_fill(~used, -1e4), dim=1)
        added = max_addition * torch.sigmoid(variable) * used
        return (x0 + added) / (1 + added.sum(1, keepdim=True))

    for _ in range(steps):
        optimiser.zero_grad()
        R, _ = forward(mixed())
        de = colour.delta_e94(target_lab, colour.lab(R)[0] + offset)
        (de.mean() + 0.5 * de.max()).backward()
        optimiser.step()
    with torch.no_grad():
        final = mixed()
        expected_lab = (colour.lab(forward(final)[0])[0] + offset).numpy()
    x = final.numpy()[0]
    fractions = {forward.toners[i]: float(x[i]) for i in np.argsort(-x) if x[i] > 1e-6}
    added = {}
    if mode == "additions":
        a = (max_addition * torch.sigmoid(variable) * used).detach().numpy()[0]
        added = {forward.toners[i]: float(a[i]) for i in np.flatnonzero(a > 1e-4)}
    return Correction(fractions, added, expected_lab)
