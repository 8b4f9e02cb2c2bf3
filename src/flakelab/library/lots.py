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

__all__ = [
    "LOT_SHADE_SD_NM",
    "LOT_STRENGTH_SD",
    "MAX_SHADE_NM",
    "QUANTITIES",
    "READ_AGAINST",
    "READ_TOGETHER",
    "Quantity",
    "TonerLot",
    "TonerLots",
]

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

READ_TOGETHER = 0.5
"""The correlation of two tins' strengths, as read, beyond which a report says that the
readings told their ratio rather than each: a panel of two tins tells how strong one is
against the other far better than how strong either is (the learned model sees proportions)."""


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

    @property
    def shade_read(self) -> bool:
        """Whether the tin's shade was read: it stands off the standard's prior (an effect
        toner's never does, nor a pigment's read for its strength alone)."""
        return not (self.shade_nm == 0 and self.shade_sd_nm == LOT_SHADE_SD_NM)


TIN_KNOWLEDGE = ("none", "calibrated", "referenced", "known")
"""What a shop knows of the tins its recipes are poured from, one vocabulary for the cases it
records (``flakelab cases generate --tins``) and the harness's shop (``flakelab match evaluate
--lots``): nothing, every tin taken at the standard (``none``, as most shops); each tin's
strength and shade read from a calibration panel against the model's prediction of it
(``calibrated``, as ``flakelab lots calibrate`` reads) or against the paint maker's reading of
the same panel from its standard tins (``referenced``); or the tins' own strengths and shades
(``known``, the limit that calibration approaches)."""

TINS_READ = ("calibrated", "referenced")
"""The :data:`TIN_KNOWLEDGE` in which a shop reads its tins from calibration panels."""

READ_AGAINST = ("model", "standard")
"""What a panel is read against: the model's prediction of it, or the paint maker's reading
of it from the standard tins (whose covariance holds no model error)."""

QUANTITIES = ("strength", "shade")
"""What a tin is read for; a calibration's parameters are each tin's log strength and shade,
in this order (:meth:`TonerLots.covariance`)."""

Quantity = tuple[str, str]
"""One read quantity of one tin: (toner, ``"strength"`` or ``"shade"``)."""


@dataclass(frozen=True)
class TonerLots:
    """The shop's tins by toner name; a toner without one pours at the standard (1.0). The
    ``correlations`` between the tins' read quantities (log strength, shade), by pair, sorted
    within it: two tins read from the same panel are read together, and a later panel of one
    tells about the other (:func:`~flakelab.match.lots.calibrate_lots`). A pair not listed is
    uncorrelated. ``misfit`` holds, by (model id, what the panels were read against), the
    χ² of every panel read so far about its covariance and its degrees of freedom: a
    calibration scales its panels' covariance by the shop's pooled ratio, not by its own
    panels' alone (:func:`~flakelab.match.lots.calibrate_lots`)."""

    lots: Mapping[str, TonerLot] = field(default_factory=dict)
    library: str = ""
    correlations: Mapping[tuple[Quantity, Quantity], float] = field(default_factory=dict)
    misfit: Mapping[tuple[str, str], tuple[float, int]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for (model_id, against), (chi2, dof) in self.misfit.items():
            if against not in READ_AGAINST:
                raise ValueError(
                    f"misfit: against: expected one of {', '.join(READ_AGAINST)}, got {against!r}"
                )
            if not (math.isfinite(chi2) and chi2 >= 0 and isinstance(dof, int) and dof >= 0):
                raise ValueError(
                    f"misfit ({model_id}, {against}): expected χ² ≥ 0 and a whole number of "
                    f"degrees of freedom, got {chi2!r} and {dof!r}"
                )
        for (a, b), r in self.correlations.items():
            for toner, quantity in (a, b):
                if toner not in self.lots:
                    raise ValueError(f"correlations: {toner!r} has no tin in the file")
                if quantity not in QUANTITIES:
                    raise ValueError(
                        f"correlations: {quantity!r}: expected one of {', '.join(QUANTITIES)}"
                    )
            if not a < b:
                raise ValueError(f"correlations: {a} and {b}: expected a pair sorted, once")
            if not (math.isfinite(r) and -1 < r < 1):
                raise ValueError(f"correlations: {a} and {b}: expected −1 < r < 1, got {r!r}")
        if self.correlations:
            names = sorted(self.lots)
            try:
                np.linalg.cholesky(self.covariance(names))
            except np.linalg.LinAlgError:
                raise ValueError(
                    "correlations: they cannot all hold at once (the covariance they make is "
                    "not positive definite)"
                ) from None

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

    def read_with(self, name: str, threshold: float = READ_TOGETHER) -> list[str]:
        """The toners whose tins' strengths are correlated with ``name``'s beyond
        ``threshold``: read together with it, their ratio surer than either."""
        return sorted(
            b[0] if a[0] == name else a[0]
            for (a, b), r in self.correlations.items()
            if name in (a[0], b[0]) and a[1] == b[1] == "strength" and abs(r) >= threshold
        )

    def covariance(self, names: Sequence[str]) -> NDArray:
        """Covariance ``[2T, 2T]`` of the log strengths and then the shades of ``names``' tins,
        as a calibration starts from it: :meth:`prior`'s and :meth:`shade_prior`'s deviations
        with :attr:`correlations` between them."""
        sd = np.concatenate([self.prior(names)[1], self.shade_prior(names)[1]])
        index = {(n, q): i * len(names) + k for i, q in enumerate(QUANTITIES)
                 for k, n in enumerate(names)}  # fmt: skip
        r = np.eye(2 * len(names))
        for (a, b), value in self.correlations.items():
            if a in index and b in index:
                r[index[a], index[b]] = r[index[b], index[a]] = value
        return r * np.outer(sd, sd)

    def without(self, names: Iterable[str]) -> TonerLots:
        """These lots without the tins of ``names`` (new tins start from the standard,
        correlated with none)."""
        gone = set(names)
        return TonerLots(
            {n: lot for n, lot in self.lots.items() if n not in gone},
            self.library,
            {
                pair: r
                for pair, r in self.correlations.items()
                if pair[0][0] not in gone and pair[1][0] not in gone
            },  # fmt: skip
            self.misfit,
        )

    def replaced(
        self, lots: Iterable[TonerLot], covariance: NDArray | None = None,
        names: Sequence[str] = (),
    ) -> TonerLots:  # fmt: skip
        """These lots, with ``lots`` read anew; with a calibration's ``covariance`` ``[2T, 2T]``
        over ``names``' log strengths and shades, the correlations it holds between the tins
        on file replace those of ``names``' tins (the rest stay)."""
        merged = {**self.lots, **{lot.toner: lot for lot in lots}}
        if covariance is None:
            return TonerLots(merged, self.library, self.correlations, self.misfit)
        read = set(names)
        kept = {pair: r for pair, r in self.correlations.items()
                if pair[0][0] not in read and pair[1][0] not in read}  # fmt: skip
        correlations = {**kept, **_correlations(covariance, names, merged)}
        return TonerLots(merged, self.library, correlations, self.misfit)

    def with_misfit(self, model_id: str, against: str, chi2: float, dof: int) -> TonerLots:
        """These lots with the panels' misfit to model ``model_id`` read ``against`` (one of
        :data:`READ_AGAINST`) grown by ``chi2`` over ``dof`` more degrees of freedom."""
        before = self.misfit.get((model_id, against), (0.0, 0))
        misfit = {**self.misfit, (model_id, against): (before[0] + chi2, before[1] + dof)}
        return TonerLots(self.lots, self.library, self.correlations, misfit)


CORRELATION_KEPT = 1e-6
"""The smallest correlation a lot file keeps; a smaller one is taken as none (dropping more
could leave the matrix of those kept not positive definite)."""


def _correlations(
    covariance: NDArray, names: Sequence[str], lots: Mapping[str, TonerLot]
) -> dict[tuple[Quantity, Quantity], float]:
    """The correlations of ``covariance`` ``[2T, 2T]`` (``names``' log strengths, then shades)
    between quantities of tins in ``lots``, by sorted pair, those of at least
    :data:`CORRELATION_KEPT`."""
    keys = [(n, q) for q in QUANTITIES for n in names]
    sd = np.sqrt(np.diag(covariance))
    r = covariance / np.outer(sd, sd)
    found = {}
    for i, j in zip(*np.triu_indices(len(keys), k=1), strict=True):
        a, b = sorted((keys[i], keys[j]))
        if a[0] in lots and b[0] in lots and abs(r[i, j]) >= CORRELATION_KEPT:
            found[a, b] = round(float(r[i, j]), 9)
    return found
