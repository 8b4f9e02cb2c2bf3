"""Recipe search: from a target measurement to ranked candidate formulations (DESIGN.md §6).

1. **Screen**, one batch of restarts with a square-root sparsity penalty: free ones (one from
   each effect toner with every toner allowed, two solid ones with every pigment) and one per
   effect base (each effect toner alone and each pair, pigments free). Their best solutions
   say which effect toners and pigments the target needs (:func:`_importance`).
2. **Subsets** (smart pruning, not enumeration of the library): every combination of the
   free restarts' three most important effect toners (a pearl over an aluminium base takes
   all three) × every combination of up to ``max_pigments`` of their most important
   pigments; each of the best effect bases × combinations of its own important pigments.
3. **Optimise** all subsets at once (one batch through the forward model, autograd, Adam on
   masked softmax logits: amounts stay non-negative and sum to the can), by successive
   halving: a third of the steps on every subset, the rest on the ``refine_keep`` best.
   The steps follow two tangents, retaken every few steps: the metamerism index's
   (:class:`~flakelab.match.objective.MetamerismTangent`) and, through new toners, the
   physics ratio's (:class:`~flakelab.match.forward.HeldJacobian`); rows are ranked exactly.
4. **Swap** (local search over toner sets), only when the best recipe still uses more than
   ``swap_above`` of the tolerance's limit somewhere (ΔE00 0.6 for the default ΔE00 ≤ 1.0):
   every set one move from the best few recipes — a toner swapped for
   another of its kind, or a pigment added — optimised from its parent's amounts. The
   screen's importance misses a pigment whose job a near neighbour does almost as well (a
   bronze tinted with quinacridone magenta, matched with quinacridone red: off by 0.68 ΔE00,
   0.19 once the swap finds the magenta).
5. **Judge** with the numbers the colorist sees — CIEDE2000 per geometry, texture
   differences, the tolerance — plus a small penalty per toner, and return the best distinct
   candidates (:mod:`flakelab.match.judging`).
6. **Physics check**, only where the learned model's ensemble disagrees on the best candidate
   by more than :func:`~flakelab.match.physics_check.check_over` (0.5 ΔE00, 1.0 at the
   MA-T12's twelve geometries): there its cases were too few, so the best few candidates are
   refined over their own toners through the library's physics, which then judges every
   candidate (DESIGN.md §3's hybrid; :data:`~flakelab.match.settings.PHYSICS_CHECK`;
   :mod:`flakelab.match.physics_check`).

Every stage aims at the colorist's tolerance: the optimiser's loss and the judging's score
count each geometry's error as a share of its limit, with the tolerance's kL, kC, kH
(:mod:`flakelab.match.objective`).

Throughout, a recipe outside the learned model's **support** — more than a solid, less effect
toner than any effect paint it learned from (``effect_share_floor`` in its training record)
— ranks after every recipe inside it, in the halving and in the judging; so, in the judging,
does a recipe with a trace of a kind of effect toner (aluminium in a pearl, under
:data:`~flakelab.match.settings.EFFECT_TRACE`). The swap stage also tries such a recipe
made solid, or without its traces: there the model's numbers are guesses that the optimiser
exploits (:mod:`flakelab.match.support`).
"""

from __future__ import annotations

import itertools
import time
from dataclasses import replace

import numpy as np
import torch
from numpy.typing import NDArray

from flakelab.core.difference import (
    is_metamer,
    travel_off_specular,
    worst_light,
    worst_per_light,
)
from flakelab.core.measurement import (
    TEXTURE_READINGS,
    Measurement,
    daylight_estimate_note,
    recovered_note,
)
from flakelab.core.tolerance import (
    Tolerance,
    tolerance_preset,
)
from flakelab.core.torch_colour import TorchColour
from flakelab.errors import FlakelabError
from flakelab.match.adam import TensorAdam
from flakelab.match.forward import film_of, stepping
from flakelab.match.judging import (
    Candidate,
    MatchResult,
    assess,
    evaluate_recipes,
    judge,
    recipe_vector,
)
from flakelab.match.objective import OBJECTIVE_DEFAULT, MatchObjective, MetamerismTangent
from flakelab.match.physics_check import (
    disagreement_words,
    is_unsure,
    needs_physics,
    physics_for,
)
from flakelab.match.settings import MODEL_SPREAD_NOTICE, MatchSettings, without_metamerism
from flakelab.match.stock import toners_allowed
from flakelab.match.support import below_effect_floor, outside_note, outside_support, trace_toners

__all__ = [
    "MatchSettings",
    "match",
    "MatchError",
    "SOLID_TEXTURE",
    "model_risk",
    "target_spectra",
    "unused_geometries",
    "left_out_note",
]


IMPORTANCE_FLOOR = 0.02
"""A toner whose removal from the screen's solutions raises the loss (ΔE94 units) by less
than this is not worth a refinement."""


SOLID_TEXTURE = {"G": 0.4, "SG": 0.05}
"""A target whose graininess and sparkle grade both read below these has no flakes: it is
a solid, matched with pigments alone. In the generated world solids read 0 and 0, effect
paints at least G 0.83 and SG 0.11 (3,000 formulations, seed 3); left to effect toners too,
4 of 30 solid targets (white-based pastels) took 56–70 % of them, 1.7–2.7 ΔE00 off the car's
paint by the physics."""


class MatchError(FlakelabError):
    """A target or library the matcher cannot work with."""


def _masked_softmax(logits: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    return torch.softmax(logits.masked_fill(~mask, -1e4), dim=1)


def _loss(
    forward,
    objective: MatchObjective,
    x: torch.Tensor,
    target_lab: torch.Tensor,
    target_texture: torch.Tensor | None,
    settings: MatchSettings,
    tangent: MetamerismTangent | None = None,
) -> torch.Tensor:
    """The search's loss ``[N]`` of amounts ``x[N, T]``; with a ``tangent``, its metamerism
    term followed along that (an optimiser's step), else exact."""
    risky = settings.model_risk and getattr(forward, "members", 1) > 1
    R, texture, members = forward.with_members(x) if risky else (*forward(x), None)
    if tangent is None:
        loss = objective.recipe_loss(target_lab, R)
    else:
        loss = objective.colour_loss(target_lab, R) + tangent(R)
    if target_texture is not None and texture is not None:
        loss = loss + settings.texture_weight * (texture[:, -2:] - target_texture[-2:]).abs().sum(1)
    if risky:
        loss = loss + settings.model_risk * model_risk(objective, members)
    return loss


def model_risk(colour: TorchColour, R: torch.Tensor) -> torch.Tensor:
    """Differentiable: how far an ensemble's members, with reflectances ``R[K, N, G, 31]``,
    disagree: the root mean square over members of each one's ΔE94 from their mean
    (log-reflectance average, as the ensemble predicts), averaged over geometries, ``[N]``.
    Where the members disagree the cases taught the model little, and the optimiser, free to
    go there, finds the model's errors in its favour (``benchmarks/matched_error.py``)."""
    mean = torch.exp(torch.log(R).mean(dim=0))
    de2 = colour.delta_e94_squared(colour.lab(mean)[None], colour.lab(R))
    return torch.sqrt(de2.mean(dim=0)).mean(dim=1)


def _optimise(
    forward, objective, logits, mask, target_lab, target_texture, settings, steps, sparsity
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Adam on the logits of every row at once; returns the logits, amounts and losses (the
    last exact: the steps follow the tangents that ``settings`` ask for)."""
    logits = logits.clone().requires_grad_(True)
    optimiser = TensorAdam(logits, lr=0.08, fused=True)
    tangent = (
        MetamerismTangent(objective, settings.metamerism_every)
        if objective.metamerism is not None and settings.metamerism_every > 1
        else None
    )
    step_forward = stepping(forward, settings.physics_every)
    for _ in range(steps):
        x = _masked_softmax(logits, mask)
        loss = _loss(step_forward, objective, x, target_lab, target_texture, settings, tangent)
        if sparsity:
            loss = loss + sparsity * torch.sqrt(x + 1e-4).sum(1)
        optimiser.step(loss.sum())
    with torch.no_grad():
        x = _masked_softmax(logits, mask)
        loss = _loss(forward, objective, x, target_lab, target_texture, settings)
        return logits.detach(), x, loss


def _screen(
    forward, objective, allowed, effect, target_lab, target_texture, settings, generator, bases
) -> tuple[NDArray, NDArray, list[tuple[int, ...] | None]]:
    """Restarts, all in one batch (a step costs about the same for 20 rows as for 140):

    * free: one from each effect toner, every toner allowed, and two solid starts, every
      pigment allowed;
    * with ``bases``, one per effect base — each effect toner alone and each pair — with
      every pigment free. The free restarts drift to blends of half a dozen aluminiums that
      the refinement's few effect toners cannot rebuild (and the learned model never saw);
      these search the space the recipes live in.

    Returns amounts ``[R, T]``, losses ``[R]`` and each row's effect base (None: free)."""
    T = len(forward.toners)
    effects = np.flatnonzero(effect & allowed)
    starts = [*effects, None, None]
    rows: list[tuple[int, ...] | None] = [None] * len(starts)
    # solid starts search solids: free to take effect toners, they drift into traces of them
    # that the learned model never saw (outside its support, ranked last)
    pigments = allowed & ~effect
    solid = pigments if pigments.any() else allowed
    masks = [allowed] * len(effects) + [solid, solid]
    if bases:
        for base in (c for size in (1, 2) for c in itertools.combinations(effects, size)):
            rows.append(base)
            masks.append(allowed & (~effect | np.isin(np.arange(T), base)))
    mask = np.stack(masks)
    logits = 0.3 * torch.randn(len(rows), T, generator=generator, dtype=forward.dtype) - 2.0
    for row, i in enumerate(starts):
        if i is not None:
            logits[row, i] = 2.0
    based = np.array([base is not None for base in rows])
    logits[torch.as_tensor(based[:, None] & mask & effect[None])] = 2.0
    _, x, loss = _optimise(
        forward,
        objective,
        logits,
        torch.as_tensor(mask),
        target_lab,
        target_texture,
        settings,
        settings.screen_steps,
        settings.sparsity,
    )
    return x.numpy().astype(float), loss.numpy(), rows


def _refine(
    forward, objective, init, mask, effect, target_lab, target_texture, settings
) -> torch.Tensor:
    """Successive halving: a third of ``refine_steps`` on every subset, the rest on the
    ``refine_keep`` best so far (a subset far behind after a third rarely wins; the batch
    shrinks and the search's time with it), those outside the model's support last."""
    first = settings.refine_steps // 3
    logits, x, _ = _optimise(
        forward, objective, init, mask, target_lab, target_texture, settings, first, 0.0
    )
    # ranked as they would be weighed: an amount under ``min_amount`` is dropped, and a
    # subset whose loss rests on such traces must not push out one that does not
    mask = _prune(x, mask, settings.min_amount)
    with torch.no_grad():
        pruned = x * mask
        pruned = pruned / pruned.sum(1, keepdim=True)
        loss = _loss(forward, objective, pruned, target_lab, target_texture, settings)
    outside = below_effect_floor(pruned.numpy(), effect, settings)
    keep = torch.as_tensor(np.lexsort((loss.numpy(), outside))[: settings.refine_keep])
    _, x, _ = _optimise(
        forward,
        objective,
        logits[keep],
        mask[keep],
        target_lab,
        target_texture,
        settings,
        settings.refine_steps - first,
        0.0,
    )
    return x


def _prune(x: torch.Tensor, mask: torch.Tensor, min_amount: float) -> torch.Tensor:
    """``mask`` without the toners under ``min_amount`` in ``x`` (the largest always kept)."""
    largest = torch.nn.functional.one_hot(x.argmax(1), x.shape[1]).bool()
    return mask & ((x >= min_amount) | largest)


def _subsets(
    x_screen: NDArray, importance: NDArray, effect: NDArray, settings: MatchSettings
) -> list[tuple[int, ...]]:
    """Toner sets to refine, from the screen's best solutions ``x_screen[S, T]`` and each
    toner's ``importance[S, T]`` in them (:func:`_importance`)."""
    importance = importance.max(0)
    ranked = [i for i in np.argsort(-importance) if importance[i] > IMPORTANCE_FLOOR]
    effects = [i for i in ranked if effect[i]][: settings.top_effects]
    pigments = [i for i in ranked if not effect[i]][: settings.top_pigments]
    bases: list[tuple[int, ...]] = [()] if x_screen[:, effect].sum(1).min() < 0.05 else []
    for size in range(1, len(effects) + 1):
        bases += list(itertools.combinations(effects, size))
    subsets = []
    for base in bases or [()]:
        for size in range(0 if base else 1, settings.max_pigments + 1):
            subsets += [base + combo for combo in itertools.combinations(pigments, size)]
    # each screen solution's own toners too, so that the screen's best is always reachable
    subsets += [_support(row, effect, settings) for row in x_screen]
    return list(dict.fromkeys(tuple(sorted(s)) for s in subsets if s))


def _importance(forward, objective, x_best, target_lab, target_texture, settings) -> NDArray:
    """How much each toner matters to each of the screen's best solutions ``x_best[S, T]``:
    the rise in loss ``[S, T]`` when it is taken out (the rest renormalised). Amount alone
    misses a tint: 0.2 % of a red pigment can carry a whole colour in a silver metallic,
    where the aluminiums are tens of per cent and interchangeable."""
    S, T = x_best.shape
    rows, toners = np.nonzero(x_best > 1e-4)
    without = x_best[rows].copy()
    without[np.arange(rows.size), toners] = 0.0
    without /= without.sum(axis=1, keepdims=True)
    with torch.no_grad():
        losses = _loss(
            forward,
            objective,
            torch.as_tensor(np.concatenate([x_best, without]), dtype=forward.dtype),
            target_lab,
            target_texture,
            settings,
        ).numpy()
    importance = np.zeros((S, T))
    importance[rows, toners] = losses[S:] - losses[rows]
    return importance


def _base_subsets(
    bases: list[tuple[int, ...]], importance: NDArray, effect: NDArray, settings: MatchSettings
) -> list[tuple[int, ...]]:
    """Each effect base of the base screen's best rows with every combination of that row's
    most important pigments (``importance[B, T]``)."""
    subsets = []
    for base, row in zip(bases, importance, strict=True):
        ranked = [i for i in np.argsort(-row) if row[i] > IMPORTANCE_FLOOR and not effect[i]]
        pigments = ranked[: settings.max_pigments]
        for size in range(len(pigments) + 1):
            subsets += [
                tuple(sorted(base + combo)) for combo in itertools.combinations(pigments, size)
            ]
    return subsets


STARTING_PIGMENT_LEVELS = (0.003, 0.02, 0.08)
"""Amounts of each pigment in the generic starts of a subset (trace tint to strong colour)."""


def _starts(
    forward, objective, x_best, subset_mask, effect, target_lab, target_texture, settings
) -> torch.Tensor:
    """Starting logits ``[N, T]`` for each subset: the best, by loss, of the screen's best
    solutions restricted to it and generic starts with every pigment at one of
    :data:`STARTING_PIGMENT_LEVELS`. One start for all would leave a subset far from its own
    optimum (a trace of black from a screen solution without black starts at tens of per cent)
    and successive halving would drop it before it got there."""
    N, T = subset_mask.shape
    restricted = (x_best[:, None, :] + 1e-3) * subset_mask[None]
    pigments = subset_mask & ~effect[None]
    effects = subset_mask & effect[None]
    generic = []
    for level in STARTING_PIGMENT_LEVELS:
        x = np.where(pigments, level, 0.0)
        rest = (1.0 - x.sum(1, keepdims=True)).clip(0.05, None)
        n_effects = effects.sum(1, keepdims=True)
        x = x + np.where(effects, rest / np.maximum(n_effects, 1), 0.0)
        generic.append(x)
    candidates = np.concatenate([restricted, np.stack(generic)])
    candidates /= candidates.sum(2, keepdims=True)
    flat = candidates.reshape(-1, T)
    with torch.no_grad():
        loss = _loss(
            forward,
            objective,
            torch.as_tensor(flat, dtype=forward.dtype),
            target_lab,
            target_texture,
            settings,
        ).numpy()
    choice = loss.reshape(len(candidates), N).argmin(0)
    return torch.as_tensor(np.log(candidates[choice, np.arange(N)] + 1e-6), dtype=forward.dtype)


def _recorded_starts(starts: NDArray, allowed: NDArray, effect: NDArray, settings) -> NDArray:
    """Recipes ``starts[K, T]`` as a search may use them: each recipe's allowed toners, every
    trace of a tint kept (the screen's own rows keep those ≥ 1 %), the largest
    ``max_pigments`` pigments, renormalised; a recipe left with none is not used."""
    rows = []
    for recipe in np.where(allowed, starts, 0.0):
        used = [i for i in np.argsort(-recipe, kind="stable") if recipe[i] > 0]
        kept = [i for i in used if effect[i]] + [i for i in used if not effect[i]][
            : settings.max_pigments
        ]
        if kept:
            row = np.zeros_like(recipe)
            row[kept] = recipe[kept] / recipe[kept].sum()
            rows.append(row)
    return np.array(rows).reshape(len(rows), starts.shape[1])


def _refined_recorded(
    forward, objective, recorded, effect, target_lab, target_texture, settings
) -> torch.Tensor:
    """Each of the ``recorded`` recipes (:func:`_recorded_starts`) refined from itself over its
    own toners, in a batch of their own: beside the search's subsets they would change which
    of those successive halving keeps."""
    init = torch.as_tensor(np.log(recorded + 1e-6), dtype=forward.dtype)
    mask = torch.as_tensor(recorded > 0)
    return _refine(forward, objective, init, mask, effect, target_lab, target_texture, settings)


def _support(x: NDArray, effect: NDArray, settings: MatchSettings) -> tuple[int, ...]:
    """The toners a screen solution uses (≥ 1 %): at most ``top_effects`` effect toners and
    ``max_pigments`` pigments, the largest amounts."""
    order = [i for i in np.argsort(-x) if x[i] >= 0.01]
    effects = [i for i in order if effect[i]][: settings.top_effects]
    pigments = [i for i in order if not effect[i]][: settings.max_pigments]
    return tuple(sorted(effects) + sorted(pigments))


def target_spectra(target, forward) -> tuple[NDArray, dict[str, float], str]:
    """Reflectance ``[G, 31]`` of the target at the forward model's geometries."""
    if isinstance(target, np.ndarray):
        return target, {}, "target"
    names = [g.name for g in target.geometries]
    missing = [g for g in forward.geometries if g not in names]
    if missing:
        raise MatchError(
            f"{target.sample}: geometries {', '.join(missing)} missing: the model "
            f"({forward.name}) needs {', '.join(forward.geometries)}"
        )
    return target.storage_spectra(forward.geometries), dict(target.texture), target.sample


def unused_geometries(target, forward) -> list[str]:
    """The geometries a target measurement reads that the forward model does not predict."""
    if isinstance(target, np.ndarray):
        return []
    return [g for g in target.geometry_names if g not in forward.geometries]


def left_out_note(unused: list[str], forward, job: str) -> list[str]:
    """A note naming the target's geometries ``unused`` that the ``job`` leaves out (none:
    no note)."""
    if not unused:
        return []
    return [
        f"left out of the {job}: the target's {', '.join(unused)}; the model predicts "
        f"{', '.join(forward.geometries)}"
    ]


def match(*args, **kwargs) -> MatchResult:
    """Ranked candidate recipes for a target; see :func:`_match` (run on one thread: the
    batches are small, and a second thread only adds contention)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return _match(*args, **kwargs)
    finally:
        torch.set_num_threads(threads)


def _match(
    target,
    forward,
    effect: NDArray | None = None,
    *,
    tolerance: Tolerance | None = None,
    settings: MatchSettings | None = None,
    allowed: NDArray | None = None,
    habits=None,
    library=None,
    starts: NDArray | None = None,
) -> MatchResult:
    """Ranked candidate recipes for ``target`` (a Measurement or reflectance ``[G, 31]``).

    ``effect[T]`` marks effect toners (aluminium, pearls); ``allowed[T]`` restricts the
    toners the search may use (default: all), and so does ``settings.without``. With the
    shop's ``habits`` (:class:`~flakelab.match.habits.ShopHabits`, and the ``library``
    whose physics says what they do) every candidate is aimed off for them, and its numbers
    are what the shop should measure. The search aims at ``tolerance`` (default ΔE00 ≤ 1.0
    at every geometry, the harness's criterion) and judges by it
    (:class:`~flakelab.match.objective.MatchObjective`). ``starts[K, T]`` are recipes to
    judge as they are and to refine as well, each from itself (the shop's recorded recipes
    nearest the car, which a colorist would start from; :func:`_recorded_starts`).
    """
    start = time.perf_counter()
    settings = _settled(settings or MatchSettings(), forward)
    if getattr(target, "spectra_recovered", False):
        settings = without_metamerism(settings)
    tolerance = tolerance or tolerance_preset(OBJECTIVE_DEFAULT)
    T = len(forward.toners)
    effect = np.zeros(T, bool) if effect is None else np.asarray(effect, bool)
    allowed = np.ones(T, bool) if allowed is None else np.asarray(allowed, bool)
    allowed = allowed & toners_allowed(forward.toners, settings.without)
    if not allowed.any():
        raise MatchError("library: no toners to match with (--without leaves none)")
    spectra, texture, name = target_spectra(target, forward)
    objective, target_lab, target_texture = _aimed_at(
        forward, spectra, texture, tolerance, settings
    )
    solid = None
    if (allowed & ~effect).any():  # pigments to match with
        solid = _solid_reason(texture, target_lab.numpy(), forward.geometries, settings)
    if solid:
        allowed = allowed & ~effect
    generator = torch.Generator().manual_seed(settings.seed)
    # 1. screen, and the toner subsets its best rows suggest
    novel = np.array([n in forward.novel for n in forward.toners])
    x_screen, screen_loss, bases = _screen_known_first(
        forward, objective, allowed, novel, effect, target_lab, target_texture, settings, generator
    )
    x_best, subsets = _subsets_to_refine(forward, objective, x_screen, screen_loss, bases,
                                         effect, target_lab, target_texture, settings)  # fmt: skip
    # 2.–3. refine every subset in one batch, then only the most promising
    subset_mask = np.zeros((len(subsets), T), bool)
    for row, subset in enumerate(subsets):
        subset_mask[row, list(subset)] = True
    init = _starts(
        forward, objective, x_best, subset_mask, effect, target_lab, target_texture, settings
    )
    x_refined = _refine(
        forward,
        objective,
        init,
        torch.as_tensor(subset_mask),
        effect,
        target_lab,
        target_texture,
        settings,
    )
    x = _weighable(x_refined.numpy().astype(float), settings)
    candidates = judge(forward, x, effect, spectra, texture, tolerance, settings)
    swapped = 0
    if candidates and (
        candidates[0].limit_share.max() > settings.swap_above or not candidates[0].in_support
    ):
        # 4. swap: one move from the best few recipes
        x_swapped, swapped = _swapped(forward, objective, candidates, allowed & ~novel, effect,
                                      target_lab, target_texture, settings)  # fmt: skip
        if swapped:
            x = np.concatenate([x, x_swapped])
            candidates = judge(forward, x, effect, spectra, texture, tolerance, settings)
    recorded = np.zeros((0, T))
    if starts is not None:
        recorded = _recorded_starts(np.asarray(starts, float), allowed, effect, settings)
    if len(recorded):  # after the search's own stages, which they leave as they were
        x_from_recorded = _refined_recorded(
            forward, objective, recorded, effect, target_lab, target_texture, settings
        )
        # each recorded recipe as it is, too: a colorist may mix it unchanged
        from_recorded = np.concatenate([x_from_recorded.numpy().astype(float), recorded])
        x = np.concatenate([x, _weighable(from_recorded, settings)])
        candidates = judge(forward, x, effect, spectra, texture, tolerance, settings)
    learned_best = candidates[0] if candidates else None
    if (physics := _physics_check(forward, library, learned_best, settings)) is not None:
        # 6. the model unsure of its best: the physics refines the best few and judges all
        candidates = _physics_checked(
            physics, candidates, effect, spectra, texture, tolerance, settings
        )
        forward = physics
    habits_note = None
    if habits is not None and candidates:
        candidates, habits_note = _aimed_off(
            forward, candidates, effect, spectra, texture, tolerance, settings, habits, library
        )
    notes = _match_notes(target, forward, candidates, effect, solid, habits_note, tolerance,
                         texture, target_texture is not None, settings, learned_best,
                         checked=physics is not None)  # fmt: skip
    return MatchResult(
        name,
        tuple(forward.geometries),
        candidates,
        tolerance.name,
        time.perf_counter() - start,
        len(subsets) + len(recorded) + swapped,
        notes,
        tolerance.texture_limits(),
        forward.model_id,
    )


def _settled(settings: MatchSettings, forward) -> MatchSettings:
    """``settings`` with what they leave to the model filled in from it: the least effect
    share of its training recipes and its effect toners' kinds."""
    if settings.effect_floor is None:
        settings = replace(settings, effect_floor=getattr(forward, "effect_share_floor", 0.0))
    if settings.effect_kinds is None and getattr(forward, "effect_kinds", None):
        settings = replace(settings, effect_kinds=tuple(forward.effect_kinds))
    return settings


def _aimed_at(forward, spectra, texture, tolerance, settings):
    """What a search through ``forward`` aims at: its objective for the target's ``spectra``
    (:class:`~flakelab.match.objective.MatchObjective`), the target's L*a*b* by it, and the
    target's ``texture`` readings as the model's outputs (:func:`_texture_readings`)."""
    objective = MatchObjective(
        forward.geometries, tolerance, forward.dtype, spectra, settings.metamerism, settings.lights
    )
    target_lab = objective.lab(torch.as_tensor(spectra))
    return objective, target_lab, _texture_readings(texture, forward.dtype)


def _texture_readings(texture: dict | None, dtype) -> torch.Tensor | None:
    """The target's texture readings in :data:`TEXTURE_READINGS` order, or None unless it
    carries every one of them."""
    if not texture or not all(k in texture for k in TEXTURE_READINGS):
        return None
    return torch.as_tensor([texture[k] for k in TEXTURE_READINGS], dtype=dtype)


def _subsets_to_refine(
    forward, objective, x_screen, screen_loss, bases, effect, target_lab, target_texture, settings
) -> tuple[NDArray, list[tuple[int, ...]]]:
    """The screen's best rows ``[B, T]`` and the toner subsets drawn from them: the best free
    rows' most important toners, and the best effect bases, each with its own most
    important pigments."""
    # those outside the model's support after every one inside it: a near-black target's
    # best free rows can all be black with a trace of aluminium, and the solid restarts
    # must still seed the refinement
    outside = below_effect_floor(x_screen, effect, settings)
    free = np.array([base is None for base in bases])
    best = _ranked(np.flatnonzero(free), screen_loss, outside)[:3]
    top = _ranked(np.flatnonzero(~free), screen_loss, outside)[: settings.top_bases]
    x_best = x_screen[np.concatenate([best, top])]
    importance = _importance(forward, objective, x_best, target_lab, target_texture, settings)
    n = best.size
    subsets = _subsets(x_best[:n], importance[:n], effect, settings)
    subsets += _base_subsets([bases[i] for i in top], importance[n:], effect, settings)
    return x_best, list(dict.fromkeys(subsets))


def _screen_known_first(forward, objective, allowed, novel, effect, target_lab, target_texture,
                        settings, generator):  # fmt: skip
    """Step 1, the screen: one restart per effect toner, plus solid starts. Toners new to the
    learned model (physics-scaled, slower) join only when the known ones cannot get close."""
    args = (effect, target_lab, target_texture, settings, generator)
    x, loss, bases = _screen(forward, objective, allowed & ~novel, *args,
                             bases=settings.top_bases > 0)  # fmt: skip
    if novel.any() and float(loss.min()) > settings.novel_threshold:
        x_all, loss_all, bases_all = _screen(forward, objective, allowed, *args, bases=False)
        x, loss = np.concatenate([x, x_all]), np.concatenate([loss, loss_all])
        bases = bases + bases_all
    return x, loss, bases


def _swapped(forward, objective, candidates, allowed, effect, target_lab, target_texture,
             settings) -> tuple[NDArray, int]:  # fmt: skip
    """Step 4, the swap: every recipe one move (a toner in, out or exchanged) from the best
    few ``candidates``, refined; and how many were tried."""
    parents = np.array([recipe_vector(forward, c.fractions) for c in candidates])
    neighbours, init = _neighbours(parents[: settings.swap_from], allowed, effect, settings)
    if not neighbours:
        return np.zeros((0, len(forward.toners))), 0
    x = _refine(
        forward,
        objective,
        torch.as_tensor(np.log(init + 1e-6), dtype=forward.dtype),
        torch.as_tensor(init > 0),
        effect,
        target_lab,
        target_texture,
        settings,
    )
    return _weighable(x.numpy().astype(float), settings), len(neighbours)


def _match_notes(target, forward, candidates, effect, solid, habits_note, tolerance,
                 texture: dict | None, texture_read: bool, settings,
                 learned_best: Candidate | None, checked: bool) -> list[str]:  # fmt: skip
    """What a match says beside its candidates: the geometries it left out, a solid, the
    shop's habits, and of the best candidate whether it lies outside the model's support,
    fails, is a metamer, was judged without the target's ``texture`` or holds no effect toner
    where that texture reads flakes; and whether the model was unsure of the best it found,
    ``learned_best``, and whether the physics then ``checked`` it (:func:`_unsure_note`)."""
    notes = left_out_note(unused_geometries(target, forward), forward, "match")
    if note := recovered_note(target) if isinstance(target, Measurement) else None:
        notes.append(
            f"{note}: the search weighed no metamerism index against it (the instrument's "
            "spectral export would let it prefer the car's own pigments to a metamer)"
        )
        if estimate := daylight_estimate_note(target):
            notes.append(estimate)
    if solid:
        notes.append(f"{solid}: a solid, matched with pigments alone")
    if habits_note:
        notes.append(habits_note)
    if not candidates:
        return notes
    best = candidates[0]
    if not best.in_support:
        notes.append(
            outside_note(recipe_vector(forward, best.fractions), effect, forward.toners, settings)
        )
    if not best.passes:
        notes.append(
            "no candidate passes the tolerance: best achievable shown; fails at "
            + ", ".join(best.failures())
        )
    if note := _metamer_note(best, settings):
        notes.append(note)
    if note := _unsure_note(learned_best, checked):
        notes.append(note)
    flakes = any(v > 0 for v in best.texture.values())
    if tolerance.texture is not None and not texture_read and flakes:
        notes.append(
            f"the target carries no texture readings: {tolerance.name}'s texture limits are "
            "not judged (read it with an instrument that measures sparkle and graininess)"
        )
    if note := _flakes_unmatched_note(texture, best, effect, forward):
        notes.append(note)
    return notes


def _reads_flakes(texture: dict | None) -> bool | None:
    """Whether a target's texture reads flakes: one of :data:`SOLID_TEXTURE`'s readings at
    or over its limit; None where it lacks one of them."""
    texture = texture or {}
    if not all(k in texture for k in SOLID_TEXTURE):
        return None
    return not all(texture[k] < limit for k, limit in SOLID_TEXTURE.items())


def _flakes_unmatched_note(texture: dict | None, best: Candidate, effect, forward) -> str | None:
    """A note where the target's texture reads flakes (:data:`SOLID_TEXTURE`) and the best
    candidate holds no effect toner: a paint the model knows nothing like, or none of the
    library's effect toners searched. A white pearl (a pearl in a white ground) was one until
    the shipped models learned white pearls (stop 108): the learned search offered a white
    solid that failed the graininess, where the physics matched the pearl."""
    if not _reads_flakes(texture):
        return None
    if recipe_vector(forward, best.fractions)[np.asarray(effect, bool)].any():
        return None
    G, SG = texture["G"], texture["SG"]
    return (
        f"the target's texture reads flakes (G {G:.2f}, SG {SG:.2f}), yet the best candidate "
        "holds no effect toner: the model may know no paint like it, or the effect toners "
        "were left out; a search by the physics alone (match --physics) may find its effect "
        "pigment"
    )


def _solid_reason(
    texture: dict | None, lab: NDArray, geometries, settings: MatchSettings
) -> str | None:
    """Why a target is a solid, or None: its texture readings show no flakes
    (:data:`SOLID_TEXTURE`), or, read without them, its colour ``lab[G, 3]`` at
    ``geometries`` travels less than ``settings.solid_travel`` over those
    ``settings.solid_travel_from`` or more from specular
    (:data:`~flakelab.match.settings.SOLID_TRAVEL`)."""
    flakes = _reads_flakes(texture)
    if flakes is False:
        G, SG = texture["G"], texture["SG"]
        return f"the target's texture reads no flakes (G {G:.2f}, SG {SG:.2f})"
    if flakes:
        return None
    if lab.shape[0] < 2:  # one geometry: no travel to read
        return None
    travel = float(travel_off_specular(lab, geometries, settings.solid_travel_from))
    if travel < settings.solid_travel:
        return (
            f"the target has no texture readings and its colour travels {travel:.2f} ΔE00 over "
            f"its geometries {settings.solid_travel_from:g}° or more from specular, under the "
            f"{settings.solid_travel:g} of a paint with flakes (a white pearl can travel as "
            "little: if the paint sparkles, match it with --solid-travel 0)"
        )
    return None


def _metamer_note(best: Candidate, settings: MatchSettings) -> str | None:
    """A note when the best candidate is a metamer of the target: its index over
    :data:`~flakelab.core.difference.METAMERISM_NOTICE` under some test light."""
    if not is_metamer(best.metamerism):
        return None
    # the index as the candidate's report gives it (to the thousandth), as the table shows it
    light, worst = worst_light(worst_per_light(best.metamerism))
    advice = (
        "the search did not weigh it: --metamerism 0"
        if not settings.metamerism
        else f"--metamerism {settings.metamerism:g} weighed it; a larger weight, or the car's "
        "own pigments in the library, may find a recipe that matches under both"
    )
    return (
        f"the best recipe is a metamer of the target: its metamerism index under {light} is "
        f"{worst:.2f} at worst, so it matches in daylight and not under that light ({advice})"
    )


def _unsure(best: Candidate | None) -> bool:
    """Whether the model's ensemble :func:`~flakelab.match.physics_check.is_unsure` of the
    ``best`` candidate."""
    return best is not None and is_unsure(best.spread)


def _unsure_note(best: Candidate | None, checked: bool) -> str | None:
    """A note when the model's ensemble is :func:`_unsure` of the ``best`` candidate: the cases
    taught it little about such a paint, and its recipe passes its first spray a quarter to a
    third less often (:data:`~flakelab.match.settings.MODEL_SPREAD_NOTICE`); and whether the
    physics then ``checked`` the candidates (:func:`_physics_checked`)."""
    if not _unsure(best):
        return None
    disagree = (
        f"{disagreement_words(best.spread, best.geometries, 'its best recipe')}, over the "
        f"{MODEL_SPREAD_NOTICE:g} beyond which its recipes pass their first spray a quarter to "
        "a third less often: the cases taught it little about paints like this one"
    )
    if checked:
        return (
            f"{disagree}, so the library's physics refined its best recipes and predicts every "
            "candidate shown (--no-physics-check keeps the model's); spray a test card before "
            "mixing the can"
        )
    return f"{disagree}; spray a test card before mixing the can, or compare match --physics"


def _physics_check(forward, library, best: Candidate | None, settings: MatchSettings):
    """The library's physics (:func:`~flakelab.match.physics_check.physics_for`) as the
    matcher predicts with it where the learned model's ensemble disagrees on its ``best``
    candidate by over :func:`~flakelab.match.physics_check.check_over`, or None: the model
    sure enough, ``settings.physics_check`` 0, or no physics to stand in."""
    checking = settings.physics_check and best is not None
    if not (checking and needs_physics(best.spread, forward.geometries)):
        return None
    return physics_for(forward, library)


def _physics_checked(
    physics, candidates, effect, spectra, texture, tolerance, settings
) -> list[Candidate]:
    """The learned search's ``candidates`` judged by the library's ``physics``, beside its
    best ``settings.physics_check`` refined over their own toners through it: where the
    networks disagree, the cases were too few, and the physics answers (DESIGN.md §3;
    :data:`~flakelab.match.settings.PHYSICS_CHECK`). Refining from the learned recipes adds
    0.1–0.3 s at the median, where a whole search through the physics (``match --physics``)
    took 2.7–2.8 s at the harness's median (docs/matching.md)."""
    objective, target_lab, target_texture = _aimed_at(
        physics, spectra, texture, tolerance, settings
    )
    x = np.array([recipe_vector(physics, c.fractions) for c in candidates])
    best = _recorded_starts(x[: settings.physics_check], np.ones(len(x[0]), bool), effect, settings)
    refined = _refined_recorded(
        physics, objective, best, effect, target_lab, target_texture, settings
    )
    x = np.concatenate([_weighable(refined.numpy().astype(float), settings), x])
    return judge(physics, x, effect, spectra, texture, tolerance, settings)


def _ranked(rows: NDArray, loss: NDArray, outside: NDArray) -> NDArray:
    """``rows`` by ``loss``, those ``outside`` the model's support last."""
    return rows[np.lexsort((loss[rows], outside[rows]))]


def _weighable(x: NDArray, settings: MatchSettings) -> NDArray:
    """Amounts ``[N, T]`` without the traces under ``min_amount``, renormalised."""
    x = np.where(x < settings.min_amount, 0.0, x)
    return x / x.sum(axis=1, keepdims=True)


SWAP_ADDED_AMOUNT = 0.01
"""Starting amount of a pigment added to a recipe by the swap stage."""


def _neighbours(
    parents: NDArray, candidates: NDArray, effect: NDArray, settings: MatchSettings
) -> tuple[list[tuple[int, ...]], NDArray]:
    """Toner sets one move from each recipe ``parents[K, T]`` and their starting amounts
    ``[N, T]``: each toner swapped for a ``candidates`` toner of its kind (effect or pigment)
    at the same amount; below ``max_pigments``, each candidate pigment added at
    :data:`SWAP_ADDED_AMOUNT`; and a recipe outside the model's support made solid (its
    effect toners dropped) and without its traces of a kind of effect toner
    (:func:`~flakelab.match.support.trace_toners`)."""
    sets: dict[tuple[int, ...], NDArray] = {}
    for parent in parents[outside_support(parents, effect, settings)]:
        for kept in (
            np.where(effect, 0.0, parent),
            np.where(trace_toners(parent, effect, settings), 0.0, parent),
        ):
            if kept.any():
                sets.setdefault(tuple(np.flatnonzero(kept > 0)), kept / kept.sum())
    for parent in parents:
        support = np.flatnonzero(parent > 0)
        for i in support:
            for j in np.flatnonzero(candidates & (effect == effect[i]) & (parent == 0)):
                x = parent.copy()
                x[j], x[i] = x[i], 0.0
                sets.setdefault(tuple(np.flatnonzero(x > 0)), x)
        room = np.count_nonzero(parent[~effect]) < settings.max_pigments
        for j in np.flatnonzero(candidates & ~effect & (parent == 0) & room):
            x = parent.copy()
            x[j] = SWAP_ADDED_AMOUNT
            sets.setdefault(tuple(np.flatnonzero(x > 0)), x / x.sum())
    return list(sets), np.array(list(sets.values()))


def _aimed_off(
    forward, candidates, effect, spectra, texture, tolerance, settings, habits, library
) -> tuple[list[Candidate], str]:
    """``candidates`` aimed off for the shop's ``habits`` and judged by what the shop should
    measure (:func:`~flakelab.match.correction.aim_off`), and a note of how many moved. Each
    keeps its unaimed recipe where that scores better with the habits' offset: the aim-off
    weighs colour and metamerism, the judge texture too."""
    # the correction builds on the search
    from flakelab.match.correction import AIM_OFF_FLOOR, aim_off

    x = np.array([recipe_vector(forward, c.fractions) for c in candidates])
    aimed = aim_off(
        forward, spectra, x, habits, library, tolerance=tolerance,
        metamerism=settings.metamerism, lights=settings.lights,
    )[0]  # fmt: skip
    both, K = np.concatenate([_weighable(aimed, settings), x]), len(x)
    predicted = evaluate_recipes(forward, both)
    offset = habits.offset(library, film_of(forward, both), predicted[0], forward.geometries)
    assessed = assess(forward, both, spectra, texture, tolerance, settings, offset, predicted)
    score = assessed.score
    rows = np.arange(K) + K * (score[K:] < score[:K])  # the unaimed row where it does better
    chosen = both[rows]
    was_aimed = np.abs(chosen - x).max(axis=1) > 1e-9  # renormalising moves ulps
    moved = int(was_aimed.sum())
    if moved == 0:
        note = (
            "not aimed off for the shop's habits: they move no candidate by "
            f"{AIM_OFF_FLOOR:g} ΔE00 or more, or aiming it scored worse ({habits.describe()})"
        )
    else:
        some = "" if moved == K else f" ({moved} of {K} candidates)"
        note = f"aimed off for the shop's habits{some}: {habits.describe()}"
    judged = judge(
        forward, chosen, effect, spectra, texture, tolerance, settings, was_aimed,
        assessed.rows(rows),
    )  # fmt: skip
    return judged, note
