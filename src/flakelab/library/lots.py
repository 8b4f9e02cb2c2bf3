"""The shop's toner lots: how strong each tin it pours from is, and its shade, against the
model's standard.

No two batches of a toner are alike: the generated world draws each batch's tinting strength
× N(1, 3 %) (issue 4 finds 0.02–0.04 realistic), and a recipe matched on the model's
standard lots comes out of the shop's tins that much off. Paint makers' systems let a shop
read each new tin's strength from a spray-out of a known mix (its tinting strength, after
ISO 787-24's reduction with white) and weigh recipes for it. A lot's strength multiplies its
toner's amount in the film, as a batch does in the world's physics
(:func:`~flakelab.physics.layer.layer_from_fractions`): 1.03 means 3 % more colour per gram.
A pigment's batch differs in shade too (ISO 787-24 and ASTM D387 judge it beside strength):
its absorption band sits a little off the standard's, as the world's batches drift, and a
tin's ``shade_nm`` is that shift along the wavelength axis (+1 nm: its colour a little
towards the longer wavelengths). :mod:`flakelab.match.lots` reads both from spray-outs and
predicts with them.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

__all__ = ["LOT_SHADE_SD_NM", "LOT_STRENGTH_SD", "MAX_SHADE_NM", "TonerLot", "TonerLots"]

LOT_STRENGTH_SD = 0.03
"""Prior standard deviation of a tin's relative strength before any spray-out of it was
read: the batch-to-batch spread of issue 4's realistic range (0.02–0.04) and of the
generated world (``WorldSettings.batch_strength_sd``). Calibrations are read in its log."""

LOT_SHADE_SD_NM = 1.5
"""Prior standard deviation of a pigment tin's shade [nm] before any spray-out of it was read:
the generated world's batch hue drift (``WorldSettings.batch_hue_shift_nm``); a shop whose
supplier certifies its batches' shade closer would set it so."""

MAX_SHADE_NM = 10.0
"""The largest shade a tin may be read at [nm]: a batch further off is another pigment."""


@dataclass(frozen=True)
class TonerLot:
    """One tin's relative strength ``strength`` ± ``strength_sd`` (1 ± 0.03 before any
    spray-out) and shade ``shade_nm`` ± ``shade_sd_nm`` (0 ± 1.5 nm; a pigment's only),
    read from ``panels`` spray-outs against model ``model_id`` on ``calibrated`` (ISO 8601),
    for the tin numbered ``lot``."""

    toner: str
    strength: float = 1.0
    strength_sd: float = LOT_STRENGTH_SD
    lot: str = ""
    panels: int = 0
    calibrated: str = ""
    model_id: str = ""
    shade_nm: float = 0.0
    shade_sd_nm: float = LOT_SHADE_SD_NM

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
        if not (math.isfinite(self.shade_nm) and abs(self.shade_nm) <= MAX_SHADE_NM):
            raise ValueError(
                f"shade_nm: expected −{MAX_SHADE_NM:g} to {MAX_SHADE_NM:g} nm, "
                f"got {self.shade_nm!r}"
            )
        if not (math.isfinite(self.shade_sd_nm) and 0 < self.shade_sd_nm <= MAX_SHADE_NM):
            raise ValueError(
                f"shade_sd_nm: expected more than 0 and at most {MAX_SHADE_NM:g} nm, "
                f"got {self.shade_sd_nm!r}"
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

    def shades(self, names: Sequence[str]) -> NDArray:
        """Shade ``[T]`` [nm] of each toner of ``names`` (0 where no tin is read)."""
        return np.array([self.lots[n].shade_nm if n in self.lots else 0.0 for n in names])

    def shade_prior(self, names: Sequence[str]) -> tuple[NDArray, NDArray]:
        """Shade and its standard deviation ``[T]`` [nm] as a calibration starts from them:
        the tin's last reading, or the standard ± :data:`LOT_SHADE_SD_NM`."""
        sd = [self.lots[n].shade_sd_nm if n in self.lots else LOT_SHADE_SD_NM for n in names]
        return self.shades(names), np.array(sd)

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
