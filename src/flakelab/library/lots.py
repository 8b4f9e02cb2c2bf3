"""The shop's toner lots: how strong each tin it pours from is, against the model's standard.

No two batches of a toner are alike: the generated world draws each batch's tinting strength
× N(1, 3 %) (issue 4 finds 0.02–0.04 realistic), and a recipe matched on the model's
standard lots comes out of the shop's tins that much off. Paint makers' systems let a shop
read each new tin's strength from a spray-out of a known mix (its tinting strength, after
ISO 787-24's reduction with white) and weigh recipes for it. A lot's strength multiplies its
toner's amount in the film, as a batch does in the world's physics
(:func:`~flakelab.physics.layer.layer_from_fractions`): 1.03 means 3 % more colour per gram.
:mod:`flakelab.match.lots` reads the strengths from spray-outs and predicts with them.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

__all__ = ["LOT_STRENGTH_SD", "TonerLot", "TonerLots"]

LOT_STRENGTH_SD = 0.03
"""Prior standard deviation of a tin's relative strength before any spray-out of it was
read: the batch-to-batch spread of issue 4's realistic range (0.02–0.04) and of the
generated world (``WorldSettings.batch_strength_sd``). Calibrations are read in its log."""


@dataclass(frozen=True)
class TonerLot:
    """One tin's relative strength ``strength`` ± ``strength_sd`` (1 ± 0.03 before any
    spray-out), read from ``panels`` spray-outs against model ``model_id`` on ``calibrated``
    (ISO 8601), for the tin numbered ``lot``."""

    toner: str
    strength: float = 1.0
    strength_sd: float = LOT_STRENGTH_SD
    lot: str = ""
    panels: int = 0
    calibrated: str = ""
    model_id: str = ""

    def __post_init__(self) -> None:
        if not self.toner:
            raise ValueError("toner: expected a name")
        if not (math.isfinite(self.strength) and 0.5 <= self.strength <= 2.0):
            raise ValueError(
                f"strength: expected 0.5–2 (against the standard), got {self.strength!r}"
            )
        if not (math.isfinite(self.strength_sd) and 0 < self.strength_sd <= 1):
            raise ValueError(
                f"strength_sd: expected more than 0 and at most 1, got {self.strength_sd!r}"
            )
        if self.panels < 0:
            raise ValueError(f"panels: expected 0 or more, got {self.panels!r}")


@dataclass(frozen=True)
class TonerLots:
    """The shop's tins by toner name; a toner without one pours at the standard (1.0)."""

    lots: Mapping[str, TonerLot] = field(default_factory=dict)
    library: str = ""

    @classmethod
    def of(cls, lots: Iterable[TonerLot], library: str = "") -> TonerLots:
        return cls({lot.toner: lot for lot in lots}, library)

    def strengths(self, names: Sequence[str]) -> NDArray:
        """Relative strength ``[T]`` of each toner of ``names`` (1.0 where no tin is read)."""
        return np.array([self.lots[n].strength if n in self.lots else 1.0 for n in names])

    def prior(self, names: Sequence[str]) -> tuple[NDArray, NDArray]:
        """Log strength and its standard deviation ``[T]`` each, as a calibration starts from
        them: the tin's last reading, or the standard ± :data:`LOT_STRENGTH_SD`."""
        mean = np.log(self.strengths(names))
        sd = np.array(
            [
                self.lots[n].strength_sd / self.lots[n].strength
                if n in self.lots
                else LOT_STRENGTH_SD
                for n in names
            ]
        )
        return mean, sd

    def replaced(self, lots: Iterable[TonerLot]) -> TonerLots:
        """These lots, with ``lots`` read anew."""
        return TonerLots({**self.lots, **{lot.toner: lot for lot in lots}}, self.library)
