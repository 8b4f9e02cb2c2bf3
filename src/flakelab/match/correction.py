"""Correction: move a sprayed recipe onto the target (DESIGN.md §6).

The measured spray-out differs from the model's prediction for its recipe by an offset
(batch, application, model error). Assuming that offset stays for small recipe changes —
the model's local behaviour (its Jacobian) applied to the observed deviation — the corrected
recipe minimises the difference between target and *prediction + offset*:

* ``additions``: the can is already mixed; only non-negative grams can be added (the usual
  shop correction);
* ``reformulate``: new amounts, mixed fresh.

Only part of the offset persists. The toner batches and the model's own error stay; the
spray's film build and flake orientation and the instrument's noise are drawn afresh at the
next spray, and correcting for them adds them back with the opposite sign. Given the library,
the physics tells the two apart: how film build and flake spread move this recipe's colour
(:mod:`flakelab.physics.application`) spans the directions a spray's
application can take, and the offset is split as the posterior means of a linear-Gaussian
model, offset = Σₖ aₖ·sₖ + p + n, with aₖ ~ N(0, 1) one-sigma application deviations along
the sensitivities sₖ, p ~ N(0, σ_p²) the persistent offset and n ~ N(0, σ_n²) noise, every
geometry and L*a*b* component alike: p̂ = σ_p²·C⁻¹·offset, â = Sᵀ·C⁻¹·offset,
C = S·Sᵀ + (σ_p² + σ_n²)·I. Without the library (or with an explicit ``offset_weight``) the
whole offset is weighted by one share, ``offset_weight`` (a shrinkage estimate).
``benchmarks/correction.py`` measures what each choice buys.

A shop with habits of its own (:mod:`flakelab.match.habits`: its film build, flake alignment
and instrument differ from the model's cases) sprays about its own mean, not the model's:
the habits' offset at the recipe persists, and only the deviation from it is split.
:func:`aim_off` uses the same optimisation before the first spray, to aim a recipe matched
by the model off for the habits.

When the recipe's own toners cannot move the colour where it must go (a one-toner silver
that came out too blue), one more toner may join: the few whose first-order effect on the
loss is most favourable are tried in the same batch, and one is kept only when it lowers the
loss by more than :data:`EXTRA_TONER_GAIN`.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
import torch
from numpy.typing import NDArray

from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import (
    delta_E,
    is_metamer,
    metamerism_indices,
    worst_light,
    worst_per_light,
)
from flakelab.core.tolerance import Tolerance, tolerance_preset
from flakelab.errors import FlakelabError
from flakelab.library.toners import Library
from flakelab.match.adam import TensorAdam
from flakelab.match.forward import film_of, stepping
from flakelab.match.judging import evaluate_recipes, recipe_spread
from flakelab.match.mixups import SPRAYOUT_MISMATCH, mismatch_message, sprayout_mismatch
from flakelab.match.objective import OBJECTIVE_DEFAULT, MatchObjective
from flakelab.match.physics_check import check_over, checked_forward, disagreement_words
from flakelab.match.settings import (
    EXTRA_TONERS_TRIED,
    MODEL_SD,
    NOISE_SD,
    PERSISTENT_SD,
    SCALE_RESOLUTION_G,
    MatchSettings,
)
from flakelab.match.stock import toners_allowed
from flakelab.physics.application import (
    APPLICATION_PARAMETERS,
    FILM_BUILD_SD,
    SPREAD_SD,
    sprayed_lab,
)

if TYPE_CHECKING:
    from flakelab.match.habits import ShopHabits
    from flakelab.match.recipe import Weighing

__all__ = [
    "aim_off",
    "AIM_OFF_FLOOR",
    "correct",
    "correct_what_was_poured",
    "PouredCorrection",
    "Correction",
    "CORRECTION_MODES",
    "OFFSET_WEIGHT",
    "PERSISTENT_SD",
    "MODEL_SD",
    "NOISE_SD",
    "metamerism_note",
    "mismatch_note",
    "physics_checked_note",
    "unreached_note",
    "model_persistent_sd",
    "split_offset",
    "application_sensitivities",
]

CORRECTION_MODES = ("additions", "reformulate")

OFFSET_WEIGHT = 0.7
"""Share of a spray-out's offset from the model assumed to persist at the next spray, when
the physics cannot split it (no library given)."""

EXTRA_TONER_GAIN = 0.15
"""Loss (:meth:`~flakelab.match.objective.MatchObjective.loss`) a toner new to the recipe must save
to join."""

NEW_TONER_START = 0.002

AIM_STEPS = 60
"""Adam steps of :func:`aim_off`: a small move from a recipe already matched. On 12 targets
of the habits shop, sprayed at its mean, 0 / 30 / 60 / 150 / 300 steps landed at worst-
geometry ΔE00 1.51 / 0.95 / 0.85 / 0.85 / 0.85 in 0.06 / 0.11 / 0.25 / 0.49 s, weighing the
metamerism index (stop 65; at colour alone, stop 62: 1.51 / 0.93 / 0.84 / 0.83 / 0.83); in a
shop with mild habits 30 targets landed at 0.42 / 0.30 / 0.28 / 0.29 after 0 / 30 / 60 / 150
(``benchmarks/aim_off.py [--world-habits 1.015,0.99,0.0015 --targets 30]``). Adam's first
steps can overshoot (five candidates' loss was higher after 10 steps than at the start in 6
of 10 mild-shop matches, 2 of 12 in the habits shop), but a learning rate warmed up over 10
or 20 steps, doubled with the warm-up, or halved landed no nearer than this one after 60
steps (stop 65: 0.857–0.908 against 0.851 in the habits shop, 0.284–0.302 against 0.283 in
the mild one)."""

AIM_OFF_FLOOR = 0.05
"""Worst-geometry ΔE00 that the habits' offset at a recipe must reach for :func:`aim_off` to
move it: under an instrument's own repeatability (0.02–0.10) a reading could not tell the
aimed recipe from the unaimed one, and Adam's first steps are as long for a small offset as
for a large one. In the ordinary shop (habits read from 500 of its cases: film −0.1 % ± 1.7,
gain +0.10 % ± 0.08) the offsets at 146 candidates of 30 targets were 0.023 at most; aimed
off anyway, their predictions moved by a median 0.075 and came no nearer the target (worst
geometry −0.007 on average, farther for half of them), at 0.08 s a match. In the habits
shop the offsets were 1.5 (median), 1.9 at most, and aiming off took the worst geometry
0.69 nearer (``benchmarks/aim_off.py --offsets --targets 30``, stop 63)."""


def mismatch_note(
    forward,
    recipe: dict[str, float],
    sprayed: NDArray,
    habits: ShopHabits | None = None,
    library: Library | None = None,
) -> str | None:
    """What to tell the colorist when the spray-out ``sprayed[G, 31]`` lies further from the
    prediction of the ``recipe`` it was mixed from (moved by the shop's ``habits``, given the
    ``library``) than :data:`SPRAYOUT_MISMATCH`."""
    x = _vector(forward, recipe)[None]
    de = sprayout_mismatch(forward, x, np.asarray(sprayed)[None], habits, library)[0]
    worst = int(np.argmax(de))
    if de[worst] <= SPRAYOUT_MISMATCH:
        return None
    return (
        f"{mismatch_message(de[worst], forward.geometries[worst])}; the correction takes that "
        "offset as the can's own"
    )


def unreached_note(
    tolerance: Tolerance, failing: list[str], expected_de00: NDArray, mode: str
) -> str | None:
    """What to tell the colorist when the corrected spray-out is still expected to fail the
    ``tolerance`` at the ``failing`` geometries (ΔE00 ``expected_de00[G]``)."""
    if not failing:
        return None
    further = (
        "additions cannot take colour out of the can: --mode reformulate mixes it afresh, or "
        if mode == "additions"
        else ""
    )
    return (
        f"the correction is expected to leave the spray-out failing {tolerance.name} at "
        f"{', '.join(failing)} (ΔE00 {np.max(expected_de00):.2f} at worst): {further}match "
        "the target again (flakelab match) for another recipe"
    )


def physics_checked_note(
    correction: Correction | PouredCorrection, unsure_of: str = "the sprayed recipe"
) -> str | None:
    """A note where the library's physics made the ``correction`` in the learned model's
    place, its networks unsure of what ``unsure_of`` names
    (:func:`~flakelab.match.physics_check.checked_forward`); None where it did not."""
    spread = correction.model_spread
    if spread is None:
        return None
    geometries = correction.predicted_by.geometries
    return (
        f"{disagreement_words(spread, geometries, unsure_of)}, over "
        f"{check_over(geometries):.1f}: the cases taught it little about paints like this one, so "
        "the library's physics made the correction and predicts its figures "
        "(--no-physics-check keeps the model's)"
    )


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
    ``expected_lab[G, 3]`` what the corrected spray-out should measure (prediction + the
    persistent offset); ``new_toner`` the toner that joined the recipe, if one did;
    ``application`` the spray-out's estimated application deviation (relative film build,
    relative flake spread), when the physics split the offset; ``metamerism`` the expected
    metamerism index (:func:`_spectral_ratio`)."""

    fractions: dict[str, float]
    added: dict[str, float]
    expected_lab: NDArray
    new_toner: str | None = None
    application: dict[str, float] | None = None
    # the corrected spray-out's expected metamerism index against the target, per test
    # illuminant and geometry (reported whether or not the correction weighed it)
    metamerism: dict[str, NDArray] | None = None
    # the forward model whose predictions these are: the one given, or the library's physics
    # where the ensemble disagreed on the sprayed recipe by ``model_spread`` (ΔE00 per
    # geometry; None where it did not stand in) (:mod:`flakelab.match.physics_check`)
    predicted_by: object = None
    model_spread: NDArray | None = None
    # how far the ensemble of ``predicted_by`` disagrees on the corrected recipe (ΔE00 per
    # geometry; None for one network or the physics): how far to trust ``expected_lab``
    expected_spread: NDArray | None = None


def split_offset(
    offset: NDArray,
    sensitivity: NDArray,
    persistent_sd: float | NDArray = PERSISTENT_SD,
    noise_sd: float = NOISE_SD,
) -> tuple[NDArray, NDArray]:
    """The persistent part ``[G, 3]`` of a spray-out's L*a*b* ``offset`` from the model, and
    its application deviations ``[K]`` in sigmas, given the L*a*b* change of one sigma of each
    application parameter ``sensitivity[K, G, 3]`` (posterior means; module notes).
    ``persistent_sd`` is one σ_p, or one per geometry and component ``[G, 3]``."""
    S = sensitivity.reshape(len(sensitivity), -1).T
    prior = np.broadcast_to(np.square(persistent_sd), offset.shape).reshape(-1)
    C = S @ S.T + np.diag(prior + noise_sd**2)
    w = np.linalg.solve(C, offset.reshape(-1))
    return (prior * w).reshape(offset.shape), S.T @ w


def model_persistent_sd(forward, x: NDArray, model_sd: float) -> float | NDArray:
    """σ_p per geometry and L*a*b* component ``[G, 3]`` for recipe ``x[T]``: the prior's
    σ_p widened by ``model_sd`` times the ensemble's members' standard deviation there, where
    the model's own error (which persists) is likely larger; σ_p alone for one network."""
    if not model_sd or getattr(forward, "members", 1) < 2:
        return PERSISTENT_SD
    members = reflectance_to_Lab(forward.member_reflectance(x[None]))[:, 0]
    return np.sqrt(PERSISTENT_SD**2 + (model_sd * members.std(axis=0)) ** 2)


def application_sensitivity(library: Library, x: NDArray, geometries) -> NDArray:
    """L*a*b* change ``[2, G, 3]`` of recipe ``x[T]`` per one sigma of film build and of
    flake spread (:func:`application_sensitivities` of one recipe)."""
    return application_sensitivities(library, x[None], geometries)[0]


def application_sensitivities(library: Library, x: NDArray, geometries) -> NDArray:
    """L*a*b* change ``[N, 2, G, 3]`` of each recipe ``x[N, T]`` per one sigma of film build
    and of flake spread: half the difference between sprays one sigma either side (the
    library's physics, one call)."""
    film = np.array([1 + FILM_BUILD_SD, 1 - FILM_BUILD_SD, 1.0, 1.0])
    spread = np.exp([0.0, 0.0, SPREAD_SD, -SPREAD_SD])
    lab = sprayed_lab(library, x, geometries, film, spread).reshape(2, 2, len(x), -1, 3)
    return np.moveaxis((lab[:, 0] - lab[:, 1]) / 2, 1, 0)


def _spectral_ratio(sprayed: NDArray, predicted: NDArray) -> NDArray:
    """What the spray-out measured over what the model predicted for its recipe, wavelength by
    wavelength ``[G, 31]``. A corrected recipe's spectra are expected at its prediction times
    this ratio, as its colour is at its prediction plus the offset that persists: the
    metamerism index, which the multiplicative correction of ISO 18314-4 already makes blind
    to a difference in strength, is taken on them. With no change the expected index is the
    spray-out's own."""
    return np.asarray(sprayed, float) / np.maximum(np.asarray(predicted, float), 1e-6)


def metamerism_note(sprayed: dict[str, NDArray], expected: dict[str, NDArray]) -> str | None:
    """What to tell the colorist when the corrected spray-out is still expected to be a
    metamer of the target (:func:`~flakelab.core.difference.is_metamer`, under some test light,
    given the indices per light and geometry of the spray-out and of the correction)."""
    if not is_metamer(expected):
        return None
    # the figures as the report gives them (to the thousandth), so that note and report agree
    light, after = worst_light(worst_per_light(expected))
    before = worst_per_light(sprayed)[light]
    return (
        f"the spray-out is a metamer of the target: under {light} its metamerism index is "
        f"{before:.2f} at worst (ΔE00 once the daylight difference is corrected) "
        f"and the correction is expected to leave {after:.2f}: this recipe's pigments (and the "
        "one toner a correction may add) cannot match it under that light; match the target "
        "again (flakelab match) for a recipe of the car's own pigments"
    )


def _predicted(objective, forward, x, target_lab, offset, ratio):
    """Predicted reflectances ``[N, G, 31]`` of mixes ``x[N, T]``, their expected L*a*b*
    (prediction plus ``offset``) and their loss ``[N]``: the colour's, plus the metamerism
    index of the prediction times the spectral ``ratio`` where the objective weighs it (None:
    the prediction's own index)."""
    R = forward(x)[0]
    if objective.metamerism is None:
        lab = objective.lab(R) + offset
        return R, lab, objective.loss(target_lab, lab)
    if ratio is None:
        lab, metamerism = objective.lab_and_metamerism_loss(R)
    else:
        lab, metamerism = objective.lab(R), objective.metamerism_loss(R * ratio)
    lab = lab + offset
    return R, lab, objective.loss(target_lab, lab) + metamerism


def _extra_candidates(
    forward, objective, x0, target_lab, offset, ratio, count, allowed
) -> list[int]:  # fmt: skip
    """Toners outside the recipe, ``allowed`` and known to the learned model, whose small
    addition lowers the loss fastest (the directional derivative of the renormalised mix,
    one backward pass)."""
    known = np.array([n not in forward.novel for n in forward.toners])
    candidates = np.flatnonzero((x0[0].numpy() == 0) & known & allowed)
    if not count or not candidates.size:
        return []
    x = x0.clone().requires_grad_(True)
    _predicted(objective, forward, x, target_lab, offset, ratio)[2].sum().backward()
    g = x.grad[0]
    slope = (g - (g * x0[0]).sum()).numpy()
    steepest = candidates[np.argsort(slope[candidates])][:count]
    return [int(j) for j in steepest if slope[j] < 0]


def correct(
    forward,
    target: NDArray,
    recipe: dict[str, float],
    sprayed: NDArray,
    *,
    mode: str = "additions",
    steps: int = 300,
    max_addition: float = 0.5,
    max_total: float | None = None,
    library: Library | None = None,
    offset_weight: float | None = None,
    persistent_sd: float | None = None,
    noise_sd: float = NOISE_SD,
    extra_toners: int = EXTRA_TONERS_TRIED,
    habits: ShopHabits | None = None,
    model_sd: float = MODEL_SD,
    tolerance: Tolerance | None = None,
    metamerism: float = MatchSettings.metamerism,
    lights: tuple[str, ...] | None = None,
    physics_every: int = MatchSettings.physics_every,
    without: Collection[str] = (),
    physics_check: bool = True,
) -> Correction:
    """Correct ``recipe`` (fractions) after its spray-out measured ``sprayed`` [G, 31]; in
    ``additions`` mode every addition is ≥ 0 and at most ``max_addition`` of the can, and
    all of them together at most ``max_total`` of it (None: no bound but each one's);
    ``extra_toners`` toners outside the recipe are tried (0: the recipe's toners only).
    With ``library`` (in the model's toner order) the offset is split by the physics of the
    spray's application (σ_p widened by ``model_sd`` times an ensemble's disagreement,
    unless ``persistent_sd`` fixes it); ``offset_weight`` weights the whole offset instead.
    With the shop's ``habits`` (:func:`~flakelab.match.habits.estimate_habits`) the
    application is split about the shop's mean: the habits' part of the offset persists.
    The corrected recipe aims at ``tolerance`` (default ΔE00 ≤ 1.0 at every geometry) and
    weighs its expected ``metamerism`` index under the test ``lights`` (default A, F11 and
    LED-B3), as the search does. Its optimiser holds what it differentiates by finite
    differences ``physics_every`` steps, as the search's does
    (:func:`~flakelab.match.forward.stepping`). Toners ``without`` (out of stock) are
    neither added nor brought in; a reformulation leaves them out. With ``physics_check`` and
    the ``library``, where the model's ensemble is unsure of the sprayed recipe the library's
    physics corrects in its place (:func:`~flakelab.match.physics_check.checked_forward`)."""
    if mode not in CORRECTION_MODES:
        raise FlakelabError(f"--mode: expected one of {', '.join(CORRECTION_MODES)}, got {mode!r}")
    if max_total is not None and not max_total >= 0:
        raise FlakelabError(f"max_total: expected a share ≥ 0 of the can, got {max_total}")
    if offset_weight is not None and not 0.0 <= offset_weight <= 1.0:
        raise FlakelabError(f"--offset-weight: expected 0 to 1, got {offset_weight}")
    x_recipe = _vector(forward, recipe)
    disagreement = None  # the ensemble's, where the physics stands in for it
    if physics_check:
        forward, disagreement = checked_forward(forward, library, x_recipe)
    objective = MatchObjective(
        forward.geometries, tolerance, forward.dtype, target, metamerism, lights
    )
    allowed = toners_allowed(forward.toners, without)
    if mode == "reformulate" and not (allowed & (x_recipe > 0)).any():
        raise FlakelabError("--without: leaves none of the recipe's toners to reformulate with")
    x0 = torch.as_tensor(x_recipe, dtype=forward.dtype)[None]
    with torch.no_grad():
        R0, _ = forward(x0)
        measured = objective.lab(torch.as_tensor(sprayed, dtype=forward.dtype))
        raw = (measured - objective.lab(R0)[0]).double().numpy()
    ratio = _spectral_ratio(sprayed, R0[0].double().numpy())
    application = None
    if library is None or offset_weight is not None:
        persistent = (OFFSET_WEIGHT if offset_weight is None else offset_weight) * raw
    else:
        mean = np.zeros(2) if habits is None else habits.theta[:2]
        expected = np.zeros_like(raw)
        film = film_of(forward, x_recipe[None])  # where the spray's application acts
        if habits is not None:
            R = R0.double().numpy()
            expected = habits.offset(library, film, R, forward.geometries)[0]
        sensitivity = application_sensitivity(library, film[0], forward.geometries)
        if persistent_sd is None:
            persistent_sd = model_persistent_sd(forward, x_recipe, model_sd)
        persistent, sigmas = split_offset(raw - expected, sensitivity, persistent_sd, noise_sd)
        persistent = persistent + expected
        film, spread = mean + sigmas * [FILM_BUILD_SD, SPREAD_SD]
        application = dict(
            zip(APPLICATION_PARAMETERS, (float(film), float(np.expm1(spread))), strict=True)
        )
    corrected = _recipe_for_offset(
        forward,
        objective,
        target,
        x_recipe,
        persistent,
        mode,
        steps,
        AdditionBounds(max_addition, max_total),
        extra_toners,
        application,
        ratio,
        lights,
        physics_every,
        allowed,
    )
    return replace(
        corrected,
        predicted_by=forward,
        model_spread=disagreement,
        expected_spread=recipe_spread(forward, _vector(forward, corrected.fractions)),
    )


def aim_off(
    forward,
    target: NDArray,
    recipes: NDArray,
    habits: ShopHabits,
    library: Library,
    *,
    steps: int = AIM_STEPS,
    tolerance: Tolerance | None = None,
    floor: float = AIM_OFF_FLOOR,
    metamerism: float = MatchSettings.metamerism,
    lights: tuple[str, ...] | None = None,
) -> tuple[NDArray, NDArray]:
    """The recipes ``[K, T]`` that land on ``target`` [G, 31] when sprayed and read with the
    shop's ``habits``, and what they should then measure (L*a*b* ``[K, G, 3]``): each of
    ``recipes[K, T]`` (matches by the model, which knows no habits) reformulated with its own
    toners for the habits' offset at it, which persists as a correction's persistent offset
    does, aimed at ``tolerance`` and weighing the prediction's ``metamerism`` index under the
    test ``lights``, as the search does. A recipe where that offset stays under ``floor``
    (ΔE00) at every geometry is left as it is."""
    R = evaluate_recipes(forward, recipes)[0]
    expected = habits.offset(library, film_of(forward, recipes), R, forward.geometries)
    predicted = reflectance_to_Lab(R)
    x, lab = np.array(recipes, float), predicted + expected
    moved = delta_E(predicted, lab).max(axis=1) >= floor
    if not moved.any() or not steps:
        return x, lab
    objective = MatchObjective(
        forward.geometries, tolerance, forward.dtype, target, metamerism, lights
    )
    x0 = torch.as_tensor(x[moved], dtype=forward.dtype)
    target_lab = objective.lab(torch.as_tensor(target, dtype=forward.dtype))
    offset = torch.as_tensor(expected[moved], dtype=forward.dtype)
    aimed, _, aimed_lab, _, _ = _optimise(
        objective,
        forward,
        x0,
        x0 > 0,
        target_lab,
        offset,
        None,  # the index of the prediction itself
        "reformulate",
        steps,
        AdditionBounds(0.0),
        MatchSettings.physics_every,
    )
    x[moved], lab[moved] = aimed.double().numpy(), aimed_lab.double().numpy()
    return x, lab


def _recipe_for_offset(
    forward,
    objective: MatchObjective,
    target: NDArray,
    x_recipe: NDArray,
    persistent: NDArray,
    mode: str,
    steps: int,
    bounds: AdditionBounds,
    extra_toners: int,
    application: dict[str, float] | None,
    spectral_ratio: NDArray,
    lights: tuple[str, ...] | None,
    physics_every: int,
    allowed: NDArray,
) -> Correction:
    """The recipe near ``x_recipe`` whose prediction plus the ``persistent`` L*a*b* offset
    ``[G, 3]`` best matches ``target`` by ``objective``, with at most one toner joining
    it, ``allowed[T]`` toners only changed; its expected spectra are its prediction times
    ``spectral_ratio``."""
    x0 = torch.as_tensor(x_recipe, dtype=forward.dtype)[None]
    offset = torch.as_tensor(persistent, dtype=forward.dtype)
    ratio = torch.as_tensor(spectral_ratio, dtype=forward.dtype)
    target_lab = objective.lab(torch.as_tensor(target, dtype=forward.dtype))
    extra = _extra_candidates(
        forward, objective, x0, target_lab, offset, ratio, extra_toners, allowed
    )
    used = ((x0 > 0) & torch.as_tensor(allowed)).repeat(1 + len(extra), 1)
    used[torch.arange(1, 1 + len(extra)), extra] = True
    final, added, lab, loss, R = _optimise(
        objective,
        forward,
        x0,
        used,
        target_lab,
        offset,
        ratio,
        mode,
        steps,
        bounds,
        physics_every,
    )
    loss[1:] += EXTRA_TONER_GAIN
    row = int(np.argmin(loss))
    x = final[row].double().numpy()
    fractions = {forward.toners[i]: float(x[i]) for i in np.argsort(-x) if x[i] > 1e-6}
    additions = {}
    if mode == "additions":
        a = added[row].double().numpy()
        additions = {forward.toners[i]: float(a[i]) for i in np.flatnonzero(a > 1e-4)}
    expected = R[row].double().numpy() * spectral_ratio
    return Correction(
        fractions,
        additions,
        lab[row].double().numpy(),
        forward.toners[extra[row - 1]] if row else None,
        application,
        metamerism_indices(target, expected, tests=lights),
    )


def _optimise(
    objective, forward, x0, used, target_lab, offset, ratio, mode, steps, bounds, every
):  # fmt: skip
    """Adam over every row of ``used[N, T]`` at once, each from ``x0`` (one row, or one per
    row): new amounts of the used toners (``reformulate``) or additions to ``x0``; returns
    the mixes ``[N, T]``, the additions, L*a*b* with ``offset``, the loss ``[N]`` (with the
    metamerism of the predictions times the spectral ``ratio`` (None: of the predictions),
    where the objective weighs it) and the predicted reflectances. The steps hold a
    finite-difference Jacobian ``every`` steps (:func:`~flakelab.match.forward.stepping`);
    the result is exact."""
    if mode == "reformulate":
        start = torch.where(x0 > 0, x0, torch.full_like(x0, NEW_TONER_START))
        variable = torch.log(start).expand(len(used), -1).clone().requires_grad_(True)
    else:
        variable = torch.full(used.shape, -6.0, dtype=forward.dtype).requires_grad_(True)
    optimiser = TensorAdam(variable, lr=0.05)

    def additions() -> torch.Tensor:
        return bounds.apply(torch.sigmoid(variable) * used)

    def mixed() -> torch.Tensor:
        if mode == "reformulate":
            return torch.softmax(variable.masked_fill(~used, -1e4), dim=1)
        added = additions()
        return (x0 + added) / (1 + added.sum(1, keepdim=True))

    step_forward = stepping(forward, every)
    for _ in range(steps):
        _, _, loss = _predicted(objective, step_forward, mixed(), target_lab, offset, ratio)
        optimiser.step(loss.sum())
    with torch.no_grad():
        final = mixed()
        R, lab, loss = _predicted(objective, forward, final, target_lab, offset, ratio)
        return final, additions().detach(), lab, loss.numpy(), R


@dataclass(frozen=True)
class AdditionBounds:
    """How much a correction may add, as shares of the can: ``each`` toner at most, and all
    together at most ``total`` (None: no bound but each one's), which a can's size sets."""

    each: float = 0.5
    total: float | None = None

    def apply(self, levels: torch.Tensor) -> torch.Tensor:
        """Additions ``[N, T]`` from ``levels`` in 0–1: each scaled to ``each``, and a row
        over ``total`` scaled down whole, so its proportions (the colour's direction) stay."""
        added = self.each * levels
        if self.total is None:
            return added
        total = torch.as_tensor(self.total, dtype=added.dtype)
        # a row of nothing (no toner it may add) stays nothing, even at a total of 0
        return added * total / added.sum(1, keepdim=True).clamp(min=max(self.total, 1e-12))


@dataclass(frozen=True)
class PouredCorrection:
    """:func:`correct_what_was_poured`'s answer: the ``weighing`` of all still to pour
    (``lines`` in pouring order from what is in the can) and the grams the can then
    ``holds``, the ΔE00 per geometry by which it is expected to miss the recipe
    (``expected_de00``) and whether each passes (``passes``); the same ΔE00 had the rest been
    poured as planned (``as_planned_de00``), and the grams of that can (``as_planned``)."""

    weighing: Weighing
    holds: dict[str, float]
    expected_de00: NDArray
    passes: NDArray
    as_planned: dict[str, float]
    as_planned_de00: NDArray
    # the forward model whose predictions these are: the one given, or the library's physics
    # where the ensemble disagreed on the can or the recipe by ``model_spread`` (ΔE00 per
    # geometry; None where it did not stand in) (:mod:`flakelab.match.physics_check`)
    predicted_by: object = None
    model_spread: NDArray | None = None


def correct_what_was_poured(
    forward,
    fractions: dict[str, float],
    quantity_g: float,
    poured: dict[str, float],
    resolution_g: float = SCALE_RESOLUTION_G,
    tolerance: Tolerance | None = None,
    most_g: float | None = None,
    library: Library | None = None,
    physics_check: bool = True,
) -> PouredCorrection:
    """What to pour into a can that holds a toner outside the recipe (``poured``, grams per
    toner; poured by mistake) or too much of one of its own: the rest of the recipe's
    ``quantity_g`` as planned, plus additions, each at most half the can again, that bring
    the can's predicted colour back to the recipe's (:func:`correct`, aimed at the recipe's
    own prediction: no spray-out has measured the can, so no offset is split off), judged by
    ``tolerance`` (default :data:`~flakelab.match.objective.OBJECTIVE_DEFAULT`). With
    ``most_g`` the can holds at most that many grams once weighed, and the additions are
    scaled down together to fit (:func:`~flakelab.match.recipe.room_for_additions`). A toner
    the recipe lacks is never added to, only diluted: where even then the can misses, it is
    better mixed afresh. With ``physics_check`` and the ``library``, where the model's
    ensemble is unsure of the can or of the recipe, the library's physics predicts both and
    dilutes in its place (:func:`~flakelab.match.physics_check.checked_forward`)."""
    from flakelab.match.recipe import (
        check_poured,
        check_scale,
        pouring_order,
        room_for_additions,
        weigh_additions,
    )

    check_scale(quantity_g, resolution_g)
    check_poured(poured, resolution_g)
    tolerance = tolerance or tolerance_preset(OBJECTIVE_DEFAULT)
    total = sum(fractions.values())
    planned = {n: v / total * quantity_g for n, v in fractions.items()}
    can = {n: max(planned.get(n, 0.0), poured.get(n, 0.0)) for n in {*planned, *poured}}
    in_can, mixed = sum(poured.values()), sum(can.values())
    room = None if most_g is None else room_for_additions(most_g, mixed, len(can), resolution_g)
    x = np.stack([_vector(forward, fractions), _vector(forward, can)])
    forward, spread = checked_forward(forward, library, x) if physics_check else (forward, None)
    R, _ = evaluate_recipes(forward, x)
    recipe_lab, can_lab = reflectance_to_Lab(R)
    strays = [n for n in poured if n not in fractions]  # never poured again
    correction = correct(
        forward, R[0], can, R[1], offset_weight=1.0, extra_toners=0, tolerance=tolerance,
        max_total=room, without=strays, physics_check=False,
    )  # fmt: skip
    to_pour = {
        n: (can[n] - poured.get(n, 0.0) + correction.added.get(n, 0.0) * mixed) / in_can
        for n in can
    }
    weighing = weigh_additions(forward, poured, to_pour, resolution_g)
    held = {n: poured.get(n, 0.0) + weighing.grams.get(n, 0.0) for n in can}
    R_held, _ = evaluate_recipes(forward, _vector(forward, held)[None])
    miss, _, passes = tolerance.judge(forward.geometries, recipe_lab, reflectance_to_Lab(R_held[0]))
    lines = pouring_order(weighing.grams, start=in_can)
    return PouredCorrection(
        replace(weighing, lines=lines), held, miss, passes, can, delta_E(recipe_lab, can_lab),
        forward, spread,
    )  # fmt: skip
