"""A shop's habits, read from its case history by the physics of application.

Every shop sprays a little differently from the cases a model learned: its gun, pressure and
viscosity lay a little more or less film, its flakes a little flatter or less flat, and its
instrument reads a little high or low. Over many spray-outs these habits show as an offset
between what was measured and what the model predicts for the recipe that was mixed, in the
directions the physics says each habit moves each recipe's colour
(:mod:`flakelab.physics.application`): film build changes how a low-hiding colour covers,
flake spread a metallic's flop, the instrument's gain every lightness alike.

The habits θ = (relative film build, log flake-spread scale, relative instrument gain) are
the generalised least-squares fit of every case's L*a*b* offset at every geometry,
offset_i = f_i(θ) + e_i, with f_i(θ) the L*a*b* change the physics predicts for recipe i
sprayed at θ, and e_i ~ N(0, S_i Σ_a S_iᵀ + (σ_p² + σ_n²) I): the spray's own application
(one sigma :data:`~flakelab.physics.application.FILM_BUILD_SD`,
:data:`~flakelab.physics.application.SPREAD_SD`, sensitivities S_i), the batches' and the
model's error and the reading (:data:`~flakelab.match.settings.PERSISTENT_SD`,
:data:`~flakelab.match.settings.NOISE_SD`). f is not linear over a few sigmas of film build:
Gauss–Newton relinearises it at θ. Standard errors are the sandwich (robust) estimate,
since the persistent offsets are heavy-tailed, not Gaussian, each case's score freed of its
own leverage (Bell and McCaffrey's CR2, :func:`_small_sample_sandwich`). The estimate is then
combined with a prior, no habits ± :data:`PRIOR_SD`, by precisions: a small shop's poorly
read film build is drawn towards none.

Where a model was adapted to the shop, it learned the habits already: measured against it,
they come out near zero. The correction and the matcher take them as the shop's mean
application (:meth:`ShopHabits.offset`): a spray-out's offset along them persists at the next
spray.

Habits change (a new gun, painter or instrument). :func:`habits_drift` scans every split
of a shop's cases in time order for the one where the earlier and later habits differ most
(:func:`change_scan`, all splits from one pass of cumulative sums) and flags a habit whose
two sides differ by more than :data:`DRIFT_Z` standard errors of the difference.

A sandwich variance is itself read from the cases, and from few of them where a habit shows in
few: film build shows only in colours that hide the primer incompletely, a tenth of the cases,
so 41 cases may hold four cases' worth of its information. Such a variance runs small: each of
those few cases pulls the fit towards itself (its leverage), and the variance is read from few
values, so a difference divided by it is Student's t, not normal. Each side's variance is
freed of the leverage and given Bell and McCaffrey's degrees of freedom (exact for a mean: n −
1); the two sides' are joined by Welch–Satterthwaite, and z is reported as the normal deviate
of the same tail probability (:func:`normal_equivalent`). The scan, which reads every split
from cumulative sums, cannot follow each split's leverage: it takes the plain sandwich and
Satterthwaite's degrees of freedom, the effective number of cases (Σhᵢ)²/Σhᵢ² of the cases'
information hᵢ along the habit, to choose the split, and the split chosen is read in full.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from datetime import UTC, datetime
from os import PathLike

import numpy as np
from numpy.typing import NDArray
from scipy import stats
from sqlalchemy import Engine, select

from flakelab.cases.database import DatabaseError, reading_rows, write_transaction
from flakelab.cases.schema import HabitsRow
from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E
from flakelab.core.documents import SHOP_HABITS_FORMAT
from flakelab.core.units import is_number
from flakelab.core.wording import counted, database_label
from flakelab.errors import FlakelabError, MeasurementFileError
from flakelab.io.records import read_json_file, write_atomically
from flakelab.library.toners import Library
from flakelab.match.mixups import SPRAYOUT_MISMATCH, sprayout_mismatch
from flakelab.match.settings import NOISE_SD, PERSISTENT_SD

__all__ = [
    "ShopHabits",
    "HABITS_FORMAT",
    "MIN_HABIT_CASES",
    "PRIOR_SD",
    "HABITS",
    "estimate_habits",
    "screened_habits",
    "habits_fit",
    "habits_drift",
    "CLEAR_Z",
    "DRIFT_Z",
    "MIN_DRIFT_CASES",
    "MIN_SEGMENT_CASES",
    "change_scan",
    "normal_equivalent",
    "read_habits",
    "write_habits",
    "save_habits",
    "stored_habits",
    "list_habits",
]

HABITS_FORMAT = SHOP_HABITS_FORMAT
"""The ``format`` of a habits file: the JSON of :meth:`ShopHabits.report` with ``shop``."""

MIN_HABIT_CASES = 20
"""Fewer spray-outs than this cannot tell three habits from one batch's or spray's accident."""

HABITS = ("film_build", "flake_spread", "instrument_gain")
"""The habits' names in :meth:`ShopHabits.report`, in the order of ``theta``."""

PRIOR_SD = np.array([0.10, 0.10, 0.01])
"""How far a shop's habits may lie from the model's cases before any of its spray-outs are
read (film build, log flake spread, instrument gain): a tenth more or less film or flake
spread, a per cent of gain. With few spray-outs the film build, which only low-hiding
colours show, is drawn towards none; with hundreds the prior weighs nothing."""

_STEP = np.array([0.01, 0.01, 0.001])
"""Central-difference steps for the habits' Jacobian (film, log spread, gain)."""

_ITERATIONS = 4
"""Gauss–Newton steps: the estimate settles to 10⁻⁴ in two or three."""

_CASES_AT_ONCE = 2048
"""Spray-outs whose Gauss–Newton terms one physics call computes: their 7 applications
each, held at once, took a shop's history of 30,000 spray-outs to 1.7 GB."""

_SHOWN = 1e-12
"""A habit whose information is below this share of the largest is not shown by the
spray-outs (flake spread in a shop of solids: exactly none)."""


@dataclass(frozen=True)
class ShopHabits:
    """A shop's habits against a model: ``theta`` = (relative film build, log flake-spread
    scale, relative instrument gain), ``standard_error`` of each, from ``cases`` spray-outs,
    measured against the model named ``model``. ``changed_since``: the time (ISO 8601) from
    which those cases showed other habits (:func:`habits_drift`), None where none was seen.
    ``cases_with_tins``: how many of the cases were read at the standard tins, recording the
    tins they were poured from (:func:`~flakelab.match.lots.at_standard_tins`): habits so
    read are the shop's against the model at the standard tins, as ``match --lots``
    predicts."""

    theta: NDArray
    standard_error: NDArray
    cases: int
    model: str = ""
    shop: str | None = None
    changed_since: str | None = None
    cases_with_tins: int = 0

    @classmethod
    def none(cls) -> ShopHabits:
        """A shop that sprays and reads as the model's cases did."""
        return cls(np.zeros(3), np.zeros(3), 0)

    @classmethod
    def from_report(cls, report: dict) -> ShopHabits:
        """The habits :meth:`report` gave (checked by the reader that hands it over)."""
        spread = report["flake_spread"]
        theta = np.array([report["film_build"], np.log1p(spread), report["instrument_gain"]])
        # a habit its spray-outs did not show has no standard error (null): infinite; so has
        # one whose standard error is wider than the values it may take
        se = np.array([report[f"{habit}_se"] for habit in HABITS], dtype=float)
        shown = se <= [_RANGE_WIDTH[habit] for habit in HABITS]  # False for NaN
        se = np.where(shown, se, np.inf) / [1, 1 + spread, 1]
        return cls(
            theta,
            se,
            int(report["cases"]),
            report.get("model") or "",
            report.get("shop"),
            report.get("changed_since"),
            int(report.get("cases_with_tins") or 0),  # habits read before stop 77 have none
        )

    @property
    def film_build(self) -> float:
        """Relative film build: 0.05 is 5 % more film than the model's cases."""
        return float(self.theta[0])

    @property
    def flake_spread(self) -> float:
        """Relative spread of the flakes' orientation: −0.04 is 4 % flatter."""
        return float(np.expm1(self.theta[1]))

    @property
    def instrument_gain(self) -> float:
        """Relative gain of the shop's instrument: 0.005 reads 0.5 % high."""
        return float(self.theta[2])

    def report(self) -> dict:
        """The habits and their standard errors as the CLI and the JSON report them."""
        se = [_finite_or_none(v) for v in self.standard_error * [1, np.exp(self.theta[1]), 1]]
        return {
            "film_build": self.film_build,
            "film_build_se": se[0],
            "flake_spread": self.flake_spread,
            "flake_spread_se": se[1],
            "instrument_gain": self.instrument_gain,
            "instrument_gain_se": se[2],
            "cases": self.cases,
            "model": self.model,
            "shop": self.shop,
            "changed_since": self.changed_since,
            "cases_with_tins": self.cases_with_tins,
        }

    def describe(self) -> str:
        """The habits in a colorist's words, with their standard errors."""
        r = self.report()
        spread = "flatter" if self.flake_spread < 0 else "less flat"
        words = (
            ("film build", f"{self.film_build:+.1%}", "{:.1%}", r["film_build_se"]),
            ("flakes", f"{abs(self.flake_spread):.1%}", "{:.1%} " + spread, r["flake_spread_se"]),
            ("instrument reads", f"{self.instrument_gain:+.2%}", "{:.2%}", r["instrument_gain_se"]),
        )
        parts = [
            f"{name} not shown by these spray-outs"
            if se is None
            else f"{name} {value} ± " + error.format(se)
            for name, value, error, se in words
        ]
        return f"{', '.join(parts)} ({self.cases} spray-outs)"

    def learned_by(self, forward) -> bool:
        """Whether ``forward``'s model, other than the one these habits were read against, was
        adapted to the shop's cases (``model adapt --shop``, ``train --adapt``) or from that
        model (:func:`~flakelab.models.training.adapt_model` records both): its network has
        learned the habits, and adding them again counts them twice. On 500 fresh cases of
        the habits shop (film +5 %, flakes 4 % flatter, gain +0.5 %) the shipped model errs
        by ΔE00 1.04, 0.62 with the habits read from 2,000 others, 0.65 adapted to them
        (``model adapt``), and 1.03 adapted with the habits added again."""
        adaptation = adaptation_of(forward)
        if not adaptation or self.model == forward.model_id:
            return False
        to_shop = self.shop is not None and adaptation.get("shop") == self.shop
        return to_shop or adaptation.get("from") == self.model

    def offset(
        self, library: Library, fractions: NDArray, reflectance: NDArray, geometries
    ) -> NDArray:
        """L*a*b* change ``[F, G, 3]`` that these habits make to recipes ``fractions[F, T]``
        whose model prediction is ``reflectance[F, G, 31]``: the physics' change of colour
        between the habits' and the nominal application, plus the instrument's gain on the
        prediction."""
        return _offsets(self.theta[None], library, fractions, reflectance, geometries)[0]


def _finite_or_none(value: float) -> float | None:
    """A standard error as a report gives it: None (JSON null) for a habit not shown."""
    return float(value) if np.isfinite(value) else None


def _offsets(thetas: NDArray, library: Library, x: NDArray, R: NDArray, geometries) -> NDArray:
    """``[P, F, G, 3]`` L*a*b* changes for P habit vectors at once (one physics call). An
    application the vectors share (they differ in the instrument's gain alone, or none at
    all) is sprayed once: a Gauss–Newton step's seven vectors spray five or six."""
    from flakelab.physics.application import sprayed_lab  # numba: only where habits are fitted

    film = np.concatenate([[1.0], 1 + thetas[:, 0]])  # the nominal application first
    spread = np.concatenate([[1.0], np.exp(thetas[:, 1])])
    sprayed, which = np.unique(np.stack([film, spread], 1), axis=0, return_inverse=True)
    lab = sprayed_lab(library, x, geometries, sprayed[:, 0], sprayed[:, 1])[which.ravel()]
    gained = reflectance_to_Lab(R[None] * (1 + thetas[:, 2, None, None, None]))
    return lab[1:] - lab[:1] + gained - reflectance_to_Lab(R)


def adaptation_of(forward) -> dict | None:
    """What ``forward``'s model records of its adaptation (``shop``, and the model it came
    ``from``: :func:`~flakelab.models.training.adapt_model`), None where it was not adapted
    (the physics alone is never)."""
    model = getattr(forward, "model", None)
    return model.adaptation if model is not None else None


def estimate_habits(
    forward,
    library: Library,
    fractions: NDArray,
    sprayouts: NDArray,
    *,
    persistent_sd: float = PERSISTENT_SD,
    noise_sd: float = NOISE_SD,
    prior_sd: NDArray | None = PRIOR_SD,
) -> ShopHabits:
    """The habits of the shop whose recipes ``fractions[N, T]`` (in ``forward``'s toner
    order) measured ``sprayouts[N, G, 31]``, against ``forward``'s predictions (module
    notes), drawn towards none by ``prior_sd`` (:data:`PRIOR_SD`; None: no prior)."""
    return _estimate(forward, library, fractions, sprayouts, persistent_sd, noise_sd, prior_sd)[0]


def screened_habits(
    forward, library: Library, fractions: NDArray, sprayouts: NDArray, *, prior_sd=PRIOR_SD
) -> tuple[ShopHabits, NDArray]:
    """:func:`estimate_habits` of the spray-outs ``sprayouts[N, G, 31]`` of recipes
    ``fractions[N, T]`` that are not mix-ups, and which ``[N]`` are: those further than
    :data:`~flakelab.match.mixups.SPRAYOUT_MISMATCH` (ΔE00, worst geometry) from the
    model's prediction moved by the habits all of them show (another panel's reading, recipe
    or target), which would pull the habits, not a shop's way of spraying. Three white panels
    given as the spray-outs of three of 500 generated cases moved the instrument's gain read
    from them from +0.15 % ± 0.07 to +0.76 % ± 0.44 (stop 66). Where every one is a mix-up
    the habits of all are returned, for the caller to refuse."""
    habits = estimate_habits(forward, library, fractions, sprayouts, prior_sd=prior_sd)
    mismatch = sprayout_mismatch(forward, fractions, sprayouts, habits, library)
    mixed_up = mismatch.max(axis=1) > SPRAYOUT_MISMATCH
    if mixed_up.any() and not mixed_up.all():
        kept = ~mixed_up
        habits = estimate_habits(
            forward, library, fractions[kept], sprayouts[kept], prior_sd=prior_sd
        )
    return habits, mixed_up


def _estimate(
    forward,
    library: Library,
    fractions: NDArray,
    sprayouts: NDArray,
    persistent_sd: float = PERSISTENT_SD,
    noise_sd: float = NOISE_SD,
    prior_sd: NDArray | None = PRIOR_SD,
) -> tuple[ShopHabits, NDArray]:
    """:func:`estimate_habits`, and the degrees of freedom of each habit's variance
    (:func:`_small_sample_sandwich`, :func:`normal_equivalent`)."""
    theta, covariance, dof, _, _ = _gauss_newton(
        forward, library, fractions, sprayouts, persistent_sd, noise_sd
    )
    if prior_sd is not None:
        theta, covariance = _with_prior(theta, covariance, np.asarray(prior_sd, float))
    habits = ShopHabits(
        theta, np.sqrt(np.diag(covariance)), len(fractions), getattr(forward, "model_id", "")
    )
    return habits, dof


def _gauss_newton(
    forward,
    library: Library,
    fractions: NDArray,
    sprayouts: NDArray,
    persistent_sd: float = PERSISTENT_SD,
    noise_sd: float = NOISE_SD,
) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray]:
    """The habits' GLS estimate θ without a prior, its sandwich covariance and each habit's
    degrees of freedom (:func:`_small_sample_sandwich`), with the model's prediction
    ``R[N, G, 31]`` and the spray-outs' L*a*b* offsets from it ``[N, G·3]`` that they were
    read from. Fewer than :data:`MIN_HABIT_CASES` spray-outs are refused."""
    from flakelab.match.judging import evaluate_recipes  # torch: only where a model predicts

    N = len(fractions)
    if N < MIN_HABIT_CASES:
        raise FlakelabError(
            f"shop habits: {N} spray-outs; at least {MIN_HABIT_CASES} are needed to tell "
            "the shop's habits from one spray's accident"
        )
    R = evaluate_recipes(forward, fractions)[0]
    offset = (reflectance_to_Lab(sprayouts) - reflectance_to_Lab(R)).reshape(N, -1)
    theta = np.zeros(3)
    for _ in range(_ITERATIONS):
        score, information = _case_terms(
            theta, library, fractions, R, offset, forward.geometries, persistent_sd, noise_sd
        )
        H = information.sum(0)
        step = _shown_inverse(H)[0] @ score.sum(0)
        theta = theta + step
    covariance, dof = _small_sample_sandwich(information, score - information @ step)
    return theta, covariance, dof, R, offset


def _case_terms(
    theta: NDArray,
    library: Library,
    fractions: NDArray,
    R: NDArray,
    offset: NDArray,
    geometries,
    persistent_sd: float = PERSISTENT_SD,
    noise_sd: float = NOISE_SD,
) -> tuple[NDArray, NDArray]:
    """Each case's share of the Gauss–Newton step from ``theta`` (module notes): its score
    Sᵢᵀ Cᵢ⁻¹ rᵢ ``[N, 3]`` and information Sᵢᵀ Cᵢ⁻¹ Sᵢ ``[N, 3, 3]``, for the L*a*b*
    ``offset[N, G·3]`` of its spray-out from the model's prediction ``R``. Sums over any
    run of cases give that run's step, so every split of the cases is read from one pass;
    they are computed :data:`_CASES_AT_ONCE` cases at a time."""
    from flakelab.physics.application import FILM_BUILD_SD, SPREAD_SD

    # θ itself and θ ± one step along each habit, in one physics call a run
    thetas = np.concatenate([theta[None], theta + np.diag(_STEP), theta - np.diag(_STEP)])
    spray_var = np.array([FILM_BUILD_SD, SPREAD_SD, 0.0]) ** 2
    residual_var = persistent_sd**2 + noise_sd**2

    def terms_of(run: slice) -> tuple[NDArray, NDArray]:
        f = _offsets(thetas, library, fractions[run], R[run], geometries)
        f = f.reshape(7, f.shape[1], -1)
        S = ((f[1:4] - f[4:7]) / (2 * _STEP[:, None, None])).transpose(1, 2, 0)  # [N, D, 3]
        C = np.einsum("ndk,k,nek->nde", S, spray_var, S) + residual_var * np.eye(S.shape[1])
        weighted = np.linalg.solve(C, S)  # C⁻¹S
        score = np.einsum("ndk,nd->nk", weighted, offset[run] - f[0])
        return score, np.einsum("ndk,ndl->nkl", S, weighted)

    runs = [
        terms_of(slice(i, i + _CASES_AT_ONCE)) for i in range(0, len(fractions), _CASES_AT_ONCE)
    ]
    return np.concatenate([s for s, _ in runs]), np.concatenate([i for _, i in runs])


def _small_sample_sandwich(information: NDArray, scores: NDArray) -> tuple[NDArray, NDArray]:
    """The sandwich covariance with each case's score freed of its own leverage, and each
    habit's Bell–McCaffrey degrees of freedom, from the cases' ``information`` Bᵢ ``[N, 3,
    3]`` and ``scores`` sᵢ ``[N, 3]`` at the estimate (Bell & McCaffrey 2002, "CR2"; the
    degrees of freedom as Imbens & Kolesár 2016 write them).

    A case that carries much of a habit's information pulls the fit towards itself, so its
    residual, and the plain sandwich, run small: (1 − leverage)⁻¹ in variance. In whitened
    coordinates, with M_i = H^-1/2 B_i H^-1/2 (H = ΣB_i) the case's leverage, its score
    becomes H^1/2 (I − M_i)^-1/2 H^-1/2 s_i (the D×D adjustment of the whitened residual,
    pushed through the case's design to 3×3), which makes the sandwich unbiased under the
    working covariance. Its variance of habit j is then Σ λ_k χ²₁ with λ the eigenvalues of
    GᵀG = diag(a_i) − Q Qᵀ, a_i = wᵀ(I − M_i)⁻¹M_i w, rows q_i = (I − M_i)^-1/2 M_i w,
    w = H^-1/2 e_j, and its degrees of freedom (Σλ)²/Σλ² are read from traces in O(N).
    A case that alone shows a habit (leverage 1) is fitted exactly and adds nothing; a
    habit no case shows has an infinite variance and NaN degrees of freedom."""
    H_inv, shown = _shown_inverse(information.sum(0))
    value, vector = np.linalg.eigh(H_inv)
    root = (vector * np.sqrt(value.clip(0))[None]) @ vector.T  # H^-1/2 on the habits shown
    leverage, U = np.linalg.eigh(root @ information @ root)  # M_i = U_i diag(λ_i) U_iᵀ
    free = 1 - leverage.clip(0, 1)
    fitted = free < 1e-12
    free = np.where(fitted, 1.0, free)  # the fitted directions are zeroed below
    inv_root_free = np.where(fitted, 0.0, free**-0.5)
    along = np.einsum("nki,kj->nij", U, root)  # U_iᵀ H^-1/2: [N, eigen, coordinate]
    adjusted = np.einsum("nji,ni->nj", U, inv_root_free * np.einsum("nij,nj->ni", along, scores))
    covariance = _unshown_infinite(root @ (adjusted.T @ adjusted) @ root, shown)
    odds = np.where(fitted, 0.0, leverage / free)  # λ/(1 − λ)
    a = np.einsum("ni,nij->nj", odds, along**2)
    q = np.einsum("nci,ni,nij->ncj", U, leverage * inv_root_free, along)  # [N, coord, habit]
    qq = (q**2).sum(1)
    trace = a.sum(0) - qq.sum(0)
    trace_of_square = (
        (a**2).sum(0) - 2 * (a * qq).sum(0) + (np.einsum("nij,nkj->jik", q, q) ** 2).sum((1, 2))
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        dof = np.where(shown & (trace_of_square > 0), trace**2 / trace_of_square, np.nan)
    return covariance, dof


def _shown_inverse(H: NDArray) -> tuple[NDArray, NDArray]:
    """The inverse of information ``H[..., 3, 3]`` over the habits the spray-outs show, zero
    for those they do not (``shown[..., 3]``): a shop of solids shows no flake spread, and
    its H has a row and column of zeros there. A habit that is not shown is read as none."""
    d = np.diagonal(H, axis1=-2, axis2=-1)
    shown = d > _SHOWN * d.max(-1, keepdims=True)
    both = shown[..., :, None] & shown[..., None, :]
    # the block of habits shown, with the identity for the others, is block-diagonal
    inverse = np.linalg.inv(np.where(both, H, np.eye(H.shape[-1])))
    return np.where(both, inverse, 0.0), shown


def _unshown_infinite(covariance: NDArray, shown: NDArray) -> NDArray:
    """``covariance[..., 3, 3]`` with an infinite variance for each habit not ``shown``."""
    eye = np.eye(covariance.shape[-1], dtype=bool)
    return np.where(eye & ~shown[..., None, :], np.inf, covariance)


def _with_prior(theta: NDArray, covariance: NDArray, prior_sd: NDArray):
    """The estimate ``theta`` (``covariance``) combined with the prior N(0, diag(prior_sd²))
    by their precisions (the Gaussian posterior's mean and covariance)."""
    precision = _shown_inverse(np.where(np.isinf(covariance), 0.0, covariance))[0]
    posterior = np.linalg.inv(precision + np.diag(prior_sd**-2.0))
    return posterior @ precision @ theta, posterior


CLEAR_Z = 2.0
"""A habit whose estimate lies within this many standard errors of none (about 95 % of a
Gaussian's draws) is not clear from the spray-outs: its sign may be their noise. The matcher
still aims off for the estimate as read (:meth:`ShopHabits.offset`)."""


def habit_meaning(key: str, value: float, se: float | None) -> str:
    """What the estimate ``value`` ± ``se`` of the habit ``key`` (``film_build``,
    ``flake_spread``, ``instrument_gain``) says in a colorist's words; nothing where no
    spray-out moved with it (``se`` None) or where it lies within :data:`CLEAR_Z` standard
    errors of none."""
    if se is None:
        return "not shown by these spray-outs"
    if abs(value) <= CLEAR_Z * se:
        return f"not clear from these spray-outs (within {CLEAR_Z:g} s.e. of none)"
    return {
        "film_build": f"{'more' if value > 0 else 'less'} film than the model's cases",
        "flake_spread": f"flakes lie {'flatter' if value < 0 else 'less flat'}",
        "instrument_gain": f"the instrument reads {'high' if value > 0 else 'low'}",
    }[key]


DRIFT_Z = 4.5
"""A habit whose earlier and later sides differ by more than this many standard errors of
the difference (read as Student's t, module notes) has changed over the cases (a new gun,
painter or instrument). The scan takes the largest of every split, so the bar sits well
above the usual 3: the largest |z| of 40 steady shops of 1,000 cases was 4.00 (``python
benchmarks/habits_drift.py``, 2026-11-28, stop 60)."""


MIN_DRIFT_CASES = 100
"""Fewer spray-outs than this are not searched for a change: with 20 a side the habits and
their errors are read from few cases' worth of information (the largest |z| of 80 steady
shops split in halves: 3.13 at 40 cases, 2.28 at 100; ``python benchmarks/habits_drift.py
--cases 40,100 --repeats 40 --at 0.5``, 2026-11-28, stop 60; 3.22 and 2.31 before each
side was freed of its cases' leverage)."""

MIN_SEGMENT_CASES = 40
"""The fewest spray-outs on either side of a change the scan considers: each side's habits
and their sandwich errors must be read from enough cases to be trusted."""


def habits_drift(
    forward,
    library: Library,
    fractions: NDArray,
    sprayouts: NDArray,
    *,
    minimum: int = MIN_DRIFT_CASES,
    split: int | None = None,
) -> dict:
    """Whether the habits changed over cases given in time order, and where: the split of
    the cases at which the earlier and later habits differ most (:func:`change_scan`, whose
    ``splits`` and ``z`` come back as ``scan``; or the given ``split``), the habits on either
    side read in full, and for each habit the difference in standard errors (``z``) and
    whether it exceeds :data:`DRIFT_Z`. Fewer than ``minimum`` cases are refused."""
    if len(fractions) < minimum:
        raise FlakelabError(
            f"shop habits: {counted(len(fractions), 'spray-out')}; at least {minimum} are needed "
            "to tell whether the habits changed"
        )
    scan = None
    if split is None:
        splits, scanned = change_scan(forward, library, fractions, sprayouts)
        split = int(splits[np.abs(scanned).max(1).argmax()])
        scan = {"splits": splits, "z": scanned}
    (early, n_early), (late, n_late) = (
        _estimate(forward, library, fractions[side], sprayouts[side], prior_sd=None)
        for side in (slice(None, split), slice(split, None))
    )
    v_early, v_late = early.standard_error**2, late.standard_error**2
    z, dof = normal_equivalent(late.theta - early.theta, v_early, n_early, v_late, n_late)
    changed = np.abs(z) > DRIFT_Z
    return {
        "split": split,
        "early": early,
        "late": late,
        "z": z,
        "dof": dof,
        "changed": changed,
        "scan": scan,
    }


def _effective_cases(total: NDArray, total_of_squares: NDArray) -> NDArray:
    """Kish's effective number of cases (Σhᵢ)²/Σhᵢ² from the sums of the cases' information
    hᵢ along each habit and of its squares: Satterthwaite's degrees of freedom of a variance
    summed from them. NaN for a habit no case shows."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(total_of_squares > 0, total**2 / total_of_squares, np.nan)


def normal_equivalent(
    difference: NDArray, v_early: NDArray, n_early: NDArray, v_late: NDArray, n_late: NDArray
) -> tuple[NDArray, NDArray]:
    """The ``difference`` of two sides' habits as the normal deviate z with the tail
    probability of its Student's t, and the t's degrees of freedom (module notes): the
    sides' variances ``v`` with ``n`` degrees of freedom each are joined by Welch–Satterthwaite,
    ν = (v₁ + v₂)² / (v₁²/n₁ + v₂²/n₂). A habit not shown on a side (infinite variance) has
    z = 0; a t so far out that its tail underflows keeps its value."""
    with np.errstate(invalid="ignore", divide="ignore"):
        total = v_early + v_late
        dof = total**2 / (v_early**2 / n_early + v_late**2 / n_late)
        t = np.where(np.isfinite(total), difference / np.sqrt(total), 0.0)
    tail = stats.t.sf(np.abs(t), np.where(np.isfinite(dof), dof, np.inf))
    z = np.where(tail > 0, np.copysign(stats.norm.isf(tail), t), t)
    return z, dof


def change_scan(
    forward,
    library: Library,
    fractions: NDArray,
    sprayouts: NDArray,
    least: int = MIN_SEGMENT_CASES,
) -> tuple[NDArray, NDArray]:
    """Every split of cases in time order, ``least`` or more (at most half) on either side,
    and for each the difference of the later and earlier habits in standard errors, as
    normal deviates ``z[K, 3]`` (:func:`normal_equivalent`). Each side's habits are one
    Gauss–Newton step from those of all the cases, with sandwich errors: the cases' terms
    are summed once, cumulatively, so all N splits cost one fit."""
    N = len(fractions)
    least = min(least, N // 2)
    pooled, _, _, R, offset = _gauss_newton(forward, library, fractions, sprayouts)
    g, B = _case_terms(pooled, library, fractions, R, offset, forward.geometries)
    h = np.diagonal(B, axis1=1, axis2=2)
    terms = (
        g,
        B,
        np.einsum("nj,nk->njk", g, g),
        np.einsum("nj,nkl->njkl", g, B),
        np.einsum("njm,nkl->njmkl", B, B),
        h,
        h**2,
    )
    prefix = [np.concatenate([np.zeros((1, *t.shape[1:])), np.cumsum(t, 0)]) for t in terms]
    splits = np.arange(least, N - least + 1)
    t_early, v_early, n_early = _segment_fits([p[splits] for p in prefix])
    t_late, v_late, n_late = _segment_fits([p[-1] - p[splits] for p in prefix])
    z, _ = normal_equivalent(t_late - t_early, v_early, n_early, v_late, n_late)
    return splits, z


def _segment_fits(sums: list[NDArray]) -> tuple[NDArray, NDArray, NDArray]:
    """The Gauss–Newton step ``[K, 3]``, its sandwich variances ``[K, 3]`` and their
    effective cases ``[K, 3]`` of K runs of cases from their summed terms
    (:func:`change_scan`): Σ(gᵢ − Bᵢt)(gᵢ − Bᵢt)ᵀ expanded in the sums of gᵢgᵢᵀ, gᵢ⊗Bᵢ and
    Bᵢ⊗Bᵢ; the effective cases from those of the information's diagonal hᵢ and hᵢ²."""
    g, B, gg, gB, BB, h, hh = sums
    H_inv, shown = _shown_inverse(B)
    t = np.einsum("kij,kj->ki", H_inv, g)
    cross = np.einsum("kjil,kl->kji", gB, t)
    meat = gg - cross - cross.transpose(0, 2, 1) + np.einsum("kjmil,km,kl->kji", BB, t, t)
    covariance = _unshown_infinite(H_inv @ meat @ H_inv.transpose(0, 2, 1), shown)
    return t, np.diagonal(covariance, axis1=1, axis2=2), _effective_cases(h, hh)


def habits_fit(
    forward, library: Library, habits: ShopHabits, fractions: NDArray, sprayouts: NDArray
) -> dict:
    """How far the habits explain a shop's spray-outs (``fractions[N, T]`` measured
    ``sprayouts[N, G, 31]``), per geometry: the mean ΔE00 of the spray-outs from the model's
    prediction alone and with the habits' offset, and the mean L*a*b* offset measured and
    the habits' mean offset. On the cases the habits were read from, the ΔE00 with them is
    optimistic by about 3 parameters in N·G·3 values: little."""
    from flakelab.match.forward import film_of  # torch: only where a model predicts
    from flakelab.match.judging import evaluate_recipes

    R = evaluate_recipes(forward, fractions)[0]
    predicted, measured = reflectance_to_Lab(R), reflectance_to_Lab(sprayouts)
    offset = habits.offset(library, film_of(forward, fractions), R, forward.geometries)
    return {
        "geometries": [str(g) for g in forward.geometries],
        "cases": len(fractions),
        "de00_model": delta_E(measured, predicted).mean(0),
        "de00_habits": delta_E(measured, predicted + offset).mean(0),
        "offset_measured": (measured - predicted).mean(0),
        "offset_habits": offset.mean(0),
    }


def write_habits(habits: ShopHabits, path: str | PathLike) -> None:
    """Write ``habits`` as a JSON habits file (atomically)."""
    document = {"format": HABITS_FORMAT, "version": 1, **habits.report()}
    write_atomically(path, lambda p: p.write_text(json.dumps(document, indent=2) + "\n"))


def read_habits(path: str | PathLike) -> ShopHabits:
    """A habits file written by :func:`write_habits` (``flakelab cases habits --out``)."""
    document = read_json_file(path, "habits file", "a JSON habits file")
    if not isinstance(document, dict) or document.get("format") != HABITS_FORMAT:
        raise MeasurementFileError(path, f"expected {HABITS_FORMAT!r}", field="format")
    if found := _report_problem(document):
        raise MeasurementFileError(path, found[1], field=found[0])
    return ShopHabits.from_report(document)


def _report_problem(report: dict) -> tuple[str, str] | None:
    """The first field of a habits report (a file's, or one stored in the database) that
    holds what :meth:`ShopHabits.from_report` cannot take, and why; None where all can."""
    for key, low, high in _RANGES:
        value = report.get(key)
        if key not in report:
            return key, "missing"
        if key.endswith("_se") and value is None:
            continue  # a habit its spray-outs did not show
        if not is_number(value) or not np.isfinite(value):
            return key, f"expected a finite number, got {value!r}"
        if not low <= value <= high:
            bounds = f"{low} or more" if high == np.inf else f"{low} to {high}"
            return key, f"expected {bounds}, got {value}"
    for key in ("model", "shop", "changed_since"):
        value = report.get(key)
        if value is not None and not isinstance(value, str):
            return key, f"expected text, got {value!r}"
    tinned = report.get("cases_with_tins", 0)
    whole = isinstance(tinned, int) and not isinstance(tinned, bool)
    if not whole or not 0 <= tinned <= report["cases"]:
        return "cases_with_tins", (
            f"expected a whole number from 0 to the cases ({report['cases']}), got {tinned!r}"
        )
    if report.get("changed_since") is not None:
        try:
            datetime.fromisoformat(report["changed_since"])
        except ValueError:
            return "changed_since", f"expected an ISO 8601 time, got {report['changed_since']!r}"
    return None


_RANGES = (
    ("film_build", -0.5, 0.5),
    ("flake_spread", -0.5, 0.5),
    ("instrument_gain", -0.1, 0.1),
    ("film_build_se", 0, np.inf),
    ("flake_spread_se", 0, np.inf),
    ("instrument_gain_se", 0, np.inf),
    ("cases", 0, np.inf),
)
"""The fields of a habits report and the values a habits file may give them."""

_RANGE_WIDTH = {key: high - low for key, low, high in _RANGES if key in HABITS}
"""The width of the values each habit may take: a standard error wider says nothing."""


def save_habits(engine: Engine, habits: ShopHabits, instrument: str) -> None:
    """Store ``habits`` (of a named shop) in the database; earlier readings are kept."""
    if not habits.shop:
        raise FlakelabError("shop habits: name the shop whose habits are stored (--shop)")
    doing = f"store the habits of shop {habits.shop!r}"
    with write_transaction(engine, doing, "nothing was stored") as session:
        session.add(
            HabitsRow(
                shop=habits.shop,
                model=habits.model,
                instrument=instrument,
                report=habits.report(),
                created_at=datetime.now(UTC),
            )
        )


def stored_habits(engine: Engine, shop: str, model: str = "") -> ShopHabits:
    """The latest habits stored for ``shop``: those measured against ``model`` when there
    are any, else the latest against any model (check :attr:`ShopHabits.model`)."""
    with reading_rows(engine, HabitsRow, "habits of shop", "shop") as session:
        rows = session.scalars(
            select(HabitsRow).where(HabitsRow.shop == shop).order_by(HabitsRow.id.desc())
        ).all()
    if not rows:
        raise FlakelabError(
            f"{database_label(engine)}: no habits stored for shop {shop!r}; read them from its "
            f"cases with flakelab cases habits CASES --shop {shop!r} --save"
        )
    row = next((r for r in rows if r.model == model), rows[0])
    return ShopHabits.from_report(_stored_report(engine, row))


def list_habits(engine: Engine) -> list[dict]:
    """The latest stored habits of every shop, with when they were read."""
    with reading_rows(engine, HabitsRow, "habits of shop", "shop") as session:
        rows = session.scalars(select(HabitsRow).order_by(HabitsRow.id)).all()
        latest = {r.shop: r for r in rows}
        return [
            _stored_report(engine, r)
            | {"shop": r.shop, "instrument": r.instrument, "created_at": r.created_at.isoformat()}
            for r in latest.values()
        ]


def _stored_report(engine: Engine, row: HabitsRow) -> dict:
    """A stored habits row's report, checked as a habits file's is (another tool or a hand
    may have written it): a :class:`DatabaseError` names the shop, the row and the field."""
    report = row.report
    found = (
        ("report", f"expected a habits report (a JSON object), got {report!r:.40}")
        if not isinstance(report, dict)
        else _report_problem(report)
    )
    if found:
        raise DatabaseError(
            f"{database_label(engine)}: habits of shop {row.shop!r} (row {row.id}): {found[0]}: "
            f"{found[1]}; the database is left as it is"
        )
    return report
