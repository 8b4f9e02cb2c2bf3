"""Evaluation harness: hidden targets in the generator's world, matched, sprayed, judged.

For each hidden formulation: the target is that paint sprayed with the factory's batches and
application and measured, spectra and texture readings; the matcher proposes a recipe; the
recipe is "sprayed" with the shop's batches and a fresh application, measured and judged
(ΔE00 ≤ 1.0 at every geometry, or another tolerance, which the matcher and the correction
then aim at too, its texture limits included); a failed spray gets one correction and is
sprayed again. Whatever the tolerance, the report says how many first spray-outs keep within
the refinish tolerance's texture limits. The oracle is the hidden
formulation itself sprayed and judged the same way — the limit that spray and measurement
noise set. The respray is the car's own paint (the factory's batches) sprayed again: what a
correction that removed every batch difference would still face, each spray's application.
Novel-toner targets each contain one toner the learned model never saw. Recipes are sprayed
as computed, or, given a scale, as a shop weighs them (rounded to its resolution). A shop
whose instrument exports L*a*b* alone is run too: the matcher and the correction then read
every target and spray-out by its colour, their spectra recovered from it.

The issue's figures come from a real shop's world. Two calmer worlds (:data:`HARNESS_WORLDS`)
say where the rest is lost: with the paper's "standardised pigments" no batch differs from
another; in the controlled world nothing varies but the instrument's reading, so what fails
there fails through the matcher and its model alone.
"""

from __future__ import annotations

import copy
import time
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from flakelab.cases.generator import SHOP_WITH_HABITS, Variation, World, WorldSettings
from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E, metamerism_indices, worst_light
from flakelab.core.geometry import DEFAULT_INSTRUMENT
from flakelab.core.measurement import TEXTURE_READINGS, Measurement, known_by_colour
from flakelab.core.spectra import WAVELENGTHS
from flakelab.core.tolerance import REFINISH_TEXTURE, Tolerance, tolerance_preset
from flakelab.library.lots import TIN_KNOWLEDGE, TINS_READ
from flakelab.match.correction import correct
from flakelab.match.habits import ShopHabits
from flakelab.match.judging import recipe_vector
from flakelab.match.lots import WithLots, calibrate_lots, calibration_recipes
from flakelab.match.objective import OBJECTIVE_DEFAULT
from flakelab.match.recipe import Can, weigh_whole_can
from flakelab.match.search import MatchError, MatchSettings, match
from flakelab.match.settings import without_metamerism

__all__ = [
    "evaluate_matching",
    "harness_match",
    "harness_trials",
    "harness_world",
    "HARNESS_WORLDS",
    "SUCCESS_DE00",
    "Trial",
    "as_weighed",
    "trial",
    "worst_de00",
    "worst_metamerism",
    "worst_share",
    "recipe_vector",
]

SUCCESS_DE00 = 1.0
"""A spray-out succeeds when ΔE00 ≤ this at every geometry (the preset ``de00-1.0``)."""

_NO_BATCHES = {"batch_strength_sd": 0.0, "batch_hue_shift_nm": 0.0}
HARNESS_WORLDS = {
    "shop": {},
    "standard-pigments": _NO_BATCHES,
    "controlled": {**_NO_BATCHES, "film_build_sd": 0.0, "spread_sd": 0.0},
    "shop-with-habits": SHOP_WITH_HABITS,
}
"""The harness's worlds, as changes to the generator's settings: a real shop's (batches and
application vary); the hybrid paper's "standardised pigments" (its 85 % first shot: no batch
differs from another, each spray's application still varies); controlled (only the
instrument's reading varies); a real shop with habits of its own (``SHOP_WITH_HABITS``),
which the model learns by adaptation (``flakelab model adapt``)."""


def harness_world(library, instrument: str = DEFAULT_INSTRUMENT, name: str = "shop") -> World:
    """The generator's world for the harness named ``name`` (:data:`HARNESS_WORLDS`)."""
    if name not in HARNESS_WORLDS:
        raise MatchError(f"--world: expected one of {', '.join(HARNESS_WORLDS)}, got {name!r}")
    return World(library, instrument, replace(WorldSettings(), **HARNESS_WORLDS[name]))


def worst_de00(a, b) -> float:
    """The largest ΔE00 over geometries between two readings ``[G, 31]``."""
    return float(delta_E(reflectance_to_Lab(a), reflectance_to_Lab(b)).max())


@dataclass
class Trial:
    """One hidden formulation in the shop's world: the target as measured on the car (the
    factory's batches ``car`` and application), the shop's own batches, and one random stream per
    spray-out (the first, its correction, the oracle, the car's paint again), so that no
    spray depends on another."""

    world: World
    target: NDArray
    car: Variation
    shop: Variation
    streams: list[np.random.Generator]
    texture: dict[str, float] = field(default_factory=dict)  # the target's readings

    def measurement(self) -> Measurement:
        """The target as the shop's instrument gives it: spectra and texture readings."""
        geometries = self.world.geometries
        return Measurement("target", geometries, WAVELENGTHS, self.target, texture=self.texture)

    @cached_property
    def target_by_colour(self) -> Measurement:
        """The target as an instrument that exports L*a*b* alone gives it: its spectra
        recovered from its colour (:func:`~flakelab.core.measurement.known_by_colour`)."""
        return known_by_colour(self.measurement())

    def read(self, texture: bool = True, colour_alone: bool = False) -> Measurement:
        """The target as the matcher reads it: without its texture readings unless
        ``texture``; with ``colour_alone``, known by its L*a*b* alone."""
        read = self.target_by_colour if colour_alone else self.measurement()
        return read if texture else replace(read, texture={})

    def as_read(self, reading: NDArray, colour_alone: bool) -> NDArray:
        """A spray-out's ``reading`` ``[G, 31]`` as the shop's instrument gives it: with
        ``colour_alone``, the spectra recovered from its L*a*b*."""
        if not colour_alone:
            return reading
        sprayed = Measurement("sprayed", self.world.geometries, WAVELENGTHS, reading)
        return known_by_colour(sprayed).reflectance

    def spray(
        self, x: NDArray, stream: np.random.Generator, batches: Variation | None = None
    ) -> NDArray:
        """``x`` mixed from the shop's batches (or ``batches``), sprayed once and measured
        ``[G, 31]``."""
        return self.sprayed(x, stream, batches)[0]

    def sprayed(
        self, x: NDArray, stream: np.random.Generator, batches: Variation | None = None
    ) -> tuple[NDArray, dict[str, float]]:
        """:meth:`spray`'s reading and the same spray-out's texture readings, one spot's
        (:meth:`World.measure_texture <flakelab.cases.generator.World.measure_texture>`)."""
        batches = batches or self.shop
        film, spread = self.world.application(1, stream)
        variation = Variation(batches.strength, batches.hue_shift, film, spread)
        R, texture = self.world.appearance(x[None], variation)
        reading = self.world.measure(R, stream)[0]
        # the texture noise from a child stream: the spray's colour stays as it was
        return reading, texture_reading(self.world, texture, stream.spawn(1)[0])

    def panels(self, x: NDArray) -> NDArray:
        """Recipes ``x[N, T]`` mixed from the shop's tins, each sprayed once and measured
        ``[N, G, 31]``, from a stream of their own (:func:`calibration_stream`): the shop's
        calibration panels."""
        stream = calibration_stream(self)
        film, spread = self.world.application(len(x), stream)
        tins = Variation(
            np.repeat(self.shop.strength, len(x), axis=0),
            np.repeat(self.shop.hue_shift, len(x)),
            film,
            spread,
        )
        return self.world.measure(self.world.appearance(x, tins)[0], stream)

    def unsprayed(self, x: NDArray) -> NDArray:
        """``x`` mixed from the shop's batches at the shop's mean application, read without
        noise ``[G, 31]``: a spray-out without its own application and instrument noise."""
        mean = self.world.nominal(1, at_shop=True)
        variation = replace(mean, strength=self.shop.strength, hue_shift=self.shop.hue_shift)
        R = self.world.appearance(x[None], variation)[0][0]
        return R * (1 + self.world.settings.shop_gain)


def trial(world: World, x_hidden: NDArray, rng: np.random.Generator) -> Trial:
    oem, shop = world.variation(1, rng, at_shop=False), world.variation(1, rng)
    streams = rng.spawn(3)
    # the respray's stream comes from the oracle's, so that adding it changed no other spray
    streams.append(streams[2].spawn(1)[0])
    R_target, texture = world.appearance(x_hidden[None], oem)
    target = world.measure(R_target, rng)[0]
    # the target's texture noise from a child of the first spray's stream: a child of rng
    # would move every later target's streams (rng.spawn counts its children)
    readings = texture_reading(world, texture, streams[0].spawn(1)[0])
    return Trial(world, target, oem, shop, streams, readings)


def standard_panels(world: World, panels: NDArray, seed: int) -> NDArray:
    """The paint maker's readings ``[N, G, 31]`` of calibration ``panels[N, T]``, each sprayed
    once from its standard tins at the factory's application: the same for every trial, from
    a stream of ``seed``'s that no trial draws from."""
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(2**31 - 1,)))
    film, spread = world.application(len(panels), rng, at_shop=False)
    standard = world.nominal(len(panels))
    tins = replace(standard, film=film, spread=spread)
    return world.measure(world.appearance(panels, tins)[0], rng)


def calibration_stream(t: Trial) -> np.random.Generator:
    """A stream for ``t``'s calibration panels that no other spray of the trial draws from:
    a child of the first spray's stream by a key that counted spawning never reaches, so
    that calibrating changes none of the other sprays."""
    seeds = t.streams[0].bit_generator.seed_seq
    return np.random.default_rng(
        np.random.SeedSequence(seeds.entropy, spawn_key=(*seeds.spawn_key, 2**31 - 1))
    )


def texture_reading(world: World, texture: NDArray, rng: np.random.Generator) -> dict[str, float]:
    """One reading, by name, of one coating's expected texture readings ``[1, 8]``."""
    readings = world.measure_texture(texture, rng)[0]
    return dict(zip(TEXTURE_READINGS, readings.tolist(), strict=True))


def worst_metamerism(a: NDArray, b: NDArray, lights: tuple[str, ...] | None = None) -> float:
    """The largest metamerism index of reading ``b`` ``[G, 31]`` against ``a`` over test
    ``lights`` (default A, F11, LED-B3) and geometries
    (:func:`~flakelab.core.difference.metamerism_indices`)."""
    return worst_light(metamerism_indices(a, b, tests=lights))[1]


FAMILY_FIGURES = {
    "first_shot_success": "first",
    "after_one_correction": "corrected",
    "oracle_success": "oracle",
    "respray_success": "respray",
}
"""The harness's rates reported per paint family, and the trial's figure each counts."""
CHANCES = {
    "first_shot_chance": "first_chance",
    "after_one_correction_chance": "corrected_chance",
    "oracle_chance": "oracle_chance",
}
"""With resprays, the chances reported (per paint family too), and the trial's figure each
averages. After one correction: 1 where the first spray passed, else the chance that the
corrected recipe's spray passes (the correction made from that first spray-out)."""


def _by_family(rows: list[dict], share, mean) -> dict[str, dict]:
    """The targets of each paint family among ``rows``, their rates (:data:`FAMILY_FIGURES`,
    :data:`CHANCES`; a family's first shot judged against its own oracle) and the families of
    their first recipes (``matched_as``: a pearl matched by aluminium alone, …)."""
    families = sorted({r["family"] for r in rows})
    report = {}
    for f in families:
        mine = [r for r in rows if r["family"] == f]
        rates = {name: share(mine, key) for name, key in FAMILY_FIGURES.items()}
        chances = {name: mean(mine, key) for name, key in CHANCES.items()}
        matched = Counter(r["matched_family"] for r in mine)
        report[f] = {"targets": len(mine), **rates, **chances, "matched_as": dict(matched)}
    return report


def _mean_or_none(values) -> float | None:
    values = [v for v in values if v is not None]
    return float(np.mean(values)) if values else None


def _median(values) -> float | None:
    values = list(values)
    return float(np.median(values)) if values else None


def _percentile(values, q: float) -> float | None:
    """The ``q``-th percentile of ``values``; None where there are none (a harness of new-toner
    targets alone has no known target's figures)."""
    values = list(values)
    return float(np.percentile(values, q)) if values else None


def worst_share(tolerance: Tolerance, geometries, a: NDArray, b: NDArray) -> float:
    """How far reading ``b`` ``[G, 31]`` is from passing ``tolerance`` against ``a``: the
    largest share of a limit over geometries (≤ 1 passes)."""
    de00, dlch, _ = tolerance.judge(geometries, reflectance_to_Lab(a), reflectance_to_Lab(b))
    return float(tolerance.share_of_limit(geometries, de00=de00, dLCH=dlch).max())


def as_weighed(forward, fractions: dict[str, float], scale: Can | None) -> dict[str, float]:
    """``fractions`` as a shop mixes them: weighed for the can ``scale`` orders on its scale,
    rounded for colour, traces under a step left out
    (:func:`~flakelab.match.recipe.weigh_whole_can`); unchanged without a scale."""
    if scale is None:
        return fractions
    can = scale.grams_for(fractions)
    grams = weigh_whole_can(forward, fractions, can, scale.resolution_g).grams
    total = sum(grams.values())
    return {name: g / total for name, g in grams.items() if g > 0}


def harness_trials(
    world: World, targets: int, seed: int, novel: tuple[str, ...] = (), novel_targets: int = 0
) -> Iterator[tuple[NDArray, Trial]]:
    """The harness's hidden formulations ``[T]`` and their trials, as
    :func:`evaluate_matching` draws them from ``seed``: ``targets`` of the toners the model
    knows, then (with ``novel`` toners) ``novel_targets`` that each hold one of them."""
    rng = np.random.default_rng(seed)
    names = list(world.library.names)
    # hidden formulations draw only on toners the model knows (a new toner is added below)
    known = world.without(novel)
    for x in known.formulations(targets, rng):
        yield x, trial(world, x, rng)
    if not (novel and novel_targets):
        return
    for x in known.formulations(novel_targets, rng):
        x[names.index(novel[int(rng.integers(len(novel)))])] = np.exp(
            rng.uniform(np.log(0.01), np.log(0.08))
        )
        x = x / x.sum()
        yield x, trial(world, x, rng)


def shop_forward(
    t: Trial, forward, lots: str, panels: NDArray | None, standards=None, library=None
):
    """``forward`` as trial ``t``'s shop predicts with it, knowing ``lots`` of its tins
    (:data:`~flakelab.library.lots.TIN_KNOWLEDGE`; ``none``: the issue's figures), and the
    RMS of its tins' strengths' and its pigments' shades' errors (None at the standard).
    ``panels`` are the calibration recipes (:func:`~flakelab.match.lots.calibration_recipes`),
    one of each toner sprayed from the trial's tins; ``standards`` their readings from the
    standard tins (one spray each, at the factory, the same for every trial). ``library``
    is the shop's, through whose physics it reads its tins and moves their shades (the
    world's unless given: ``benchmarks/physics_check.py --tins-read-off`` gives one off by
    a lot)."""
    if lots == "none":
        return forward, None
    library = t.world.library if library is None else library
    order = [list(library.names).index(n) for n in forward.toners]
    true = t.shop.strength[0][order]
    # the world's batches drift every pigment's absorption alike (World.layer)
    true_shade = np.where(library.effect[order], 0.0, t.shop.hue_shift[0])
    strength, shade = true, true_shade
    if lots in TINS_READ:
        found = calibrate_lots(forward, library, panels, t.panels(panels), standards=standards)
        read = dict(zip(found.toners, zip(found.strength, found.shade, strict=True), strict=True))
        strength, shade = np.array([read.get(n, (1.0, 0.0)) for n in forward.toners]).T
    pigments = ~library.effect[order]
    error = {
        "strength": float(np.sqrt(np.mean((strength - true) ** 2))),
        "shade_nm": float(np.sqrt(np.mean((shade - true_shade)[pigments] ** 2))),
    }
    return WithLots(forward, strength, shade, library), error


def harness_match(
    t: Trial, forward, effect, settings, habits, tolerance, target_texture=True, colour_alone=False
):
    """The harness's match of trial ``t``'s target, and its latency in seconds: the target
    read (:meth:`Trial.read`: without its texture readings unless ``target_texture``, by its
    L*a*b* alone with ``colour_alone``) and matched."""
    start = time.perf_counter()
    result = match(
        t.read(target_texture, colour_alone),
        forward,
        effect,
        tolerance=tolerance,
        settings=settings,
        habits=habits,
        library=t.world.library,
    )
    return result, time.perf_counter() - start


def _one(
    t: Trial, x_hidden, forward, effect, settings, habits, tolerance, scale, target_texture=True,
    resprays=0, lots="none", panels=None, standards=None, colour_alone=False,
) -> dict:  # fmt: skip
    world = t.world
    forward, lot_error = shop_forward(t, forward, lots, panels, standards)
    first_rng, correction_rng, oracle_rng, respray_rng = t.streams

    def share(sprayed: tuple[NDArray, dict]) -> float:
        reading, texture = sprayed
        colour = worst_share(tolerance, forward.geometries, t.target, reading)
        return max([colour, *tolerance.texture_share(t.texture, texture).values()])

    def texture_share(sprayed: tuple[NDArray, dict]) -> float:  # by refinish's limits
        return max(REFINISH_TEXTURE.share(t.texture, sprayed[1]).values(), default=0.0)

    result, latency = harness_match(
        t, forward, effect, settings, habits, tolerance, target_texture, colour_alone
    )
    # the correction, too, reads what the instrument gives; no metamerism index against a metamer
    aim = without_metamerism(settings) if colour_alone else settings
    best = result.candidates[0]
    mixed = as_weighed(forward, best.fractions, scale)
    x = recipe_vector(forward, mixed)
    first = t.sprayed(x, first_rng)
    first_share = corrected_share = share(first)
    corrected_metamerism, corrected_again, correction_checked = None, [True], False
    if first_share > 1.0:
        correction = correct(
            forward,
            t.read(colour_alone=colour_alone).reflectance,
            mixed,
            t.as_read(first[0], colour_alone),
            mode="reformulate",
            library=world.library,
            habits=habits,
            tolerance=tolerance,
            metamerism=aim.metamerism,
            lights=aim.lights,
            physics_every=settings.physics_every,
            without=settings.without,
            physics_check=bool(settings.physics_check),
        )
        correction_checked = correction.model_spread is not None
        x_corrected = recipe_vector(forward, as_weighed(forward, correction.fractions, scale))
        corrected = t.sprayed(x_corrected, correction_rng)
        corrected_share = share(corrected)
        corrected_metamerism = worst_metamerism(t.target, corrected[0], settings.lights)
        # children of the correction's stream: no other spray changes
        corrected_again = [
            share(t.sprayed(x_corrected, s)) <= 1.0 for s in correction_rng.spawn(resprays)
        ]
    oracle = t.sprayed(x_hidden, oracle_rng)
    respray_share = share(t.sprayed(x_hidden, respray_rng, batches=t.car))
    # the first recipe and the hidden formula sprayed again, each pair from one stream (the
    # same application and reading: a paired comparison); the streams are children of the
    # respray's, drawn after it, so no other spray changes
    again = respray_rng.spawn(resprays)
    first_again = [share(t.sprayed(x, copy.deepcopy(s))) <= 1.0 for s in again]
    oracle_again = [share(t.sprayed(x_hidden, s)) <= 1.0 for s in again]
    return {
        "first_de00": worst_de00(t.target, first[0]),
        "first_metamerism": worst_metamerism(t.target, first[0], settings.lights),
        "corrected_metamerism": corrected_metamerism,
        "oracle_metamerism": worst_metamerism(t.target, oracle[0], settings.lights),
        "oracle_de00": worst_de00(t.target, oracle[0]),
        "first_texture": texture_share(first),
        "oracle_texture": texture_share(oracle),
        "first": first_share,
        # the first recipe from the shop's tins at its mean application, read without noise:
        # what the search and its model left, apart from the spray's own luck
        "first_unsprayed": worst_share(tolerance, forward.geometries, t.target, t.unsprayed(x)),
        "corrected": min(first_share, corrected_share),
        "oracle": share(oracle),
        "respray": respray_share,
        "first_or_respray": min(first_share, respray_share),
        "first_chance": float(np.mean(first_again)) if resprays else None,
        "corrected_chance": float(np.mean(corrected_again)) if resprays else None,
        "oracle_chance": float(np.mean(oracle_again)) if resprays else None,
        "latency_s": latency,
        "lot_error": lot_error,
        "predicted_de00": float(best.de00.max()),
        # an ensemble's disagreement on the first recipe, at its worst geometry (None: one network,
        # or the library's physics, which predicts where the ensemble disagreed)
        "predicted_spread": None if best.spread is None else float(best.spread.max()),
        "physics_checked": result.model_id != forward.model_id,
        # the physics corrected the failed first shot, the ensemble unsure of its recipe
        "correction_physics_checked": correction_checked,
        "family": str(world.library.paint_families(x_hidden[None])[0]),
        # the first recipe's family: what the matcher made of the target
        "matched_family": str(world.library.paint_families(x[None])[0]),
        # the car's paint holds a toner the shop is out of (settings.without)
        "needs_missing": bool(
            any(x_hidden[list(world.library.names).index(n)] > 0 for n in settings.without)
        ),
    }


def evaluate_matching(
    world: World,
    forward,
    effect,
    *,
    targets: int = 200,
    seed: int = 4242,
    novel: tuple[str, ...] = (),
    novel_targets: int = 0,
    settings: MatchSettings | None = None,
    habits: ShopHabits | None = None,
    tolerance: Tolerance | None = None,
    scale: Can | None = None,
    target_texture: bool = True,
    resprays: int = 0,
    lots: str = "none",
    colour_alone: bool = False,
    progress: Callable[[], None] | None = None,
    per_target: bool = False,
) -> dict:
    """The harness's figures (issue 5); ``world`` generates and sprays in the shop's world.
    With a ``scale`` (the can a shop orders, on its scale) every recipe is sprayed as
    weighed for it (:func:`as_weighed`), the correction's too; without, as computed.
    With the shop's ``habits`` every match is aimed off for them and the
    correction splits the offset about them. Sprays are judged by ``tolerance`` (default
    :data:`~flakelab.match.objective.OBJECTIVE_DEFAULT`), which the matcher and the
    correction aim at. Without ``target_texture`` the matcher reads each target without its
    texture readings, as from a file that lacks them; the sprays are judged as ever. With
    ``colour_alone`` the shop's instrument exports L*a*b* alone: the matcher and the
    correction read each target and spray-out by its colour (D65/10), their spectra
    recovered from it (:meth:`Trial.read`), and weigh no metamerism index; the sprays are
    judged as ever, their metamerism against the car's measured spectra.

    With ``resprays`` = K, each target's first recipe and its hidden formula are sprayed K
    more times, in pairs that share their application and reading: ``first_shot_chance`` and
    ``oracle_chance`` are the chances that a spray passes, averaged over the targets. A
    target's one first spray passes or fails by its own application's luck; the chance
    averages that out, so two matchers (or paint families) compare with a fraction of the
    noise of one spray each. With ``per_target`` the report keeps every target's trial
    (``per_target``: the targets, then those with a new toner), for paired comparisons of
    two runs on the same seed. With ``targets`` 0 the new-toner targets are judged alone
    (a toner being brought in): the figures of the known targets are then None. ``lots``
    says what the shop knows of its tins (:data:`~flakelab.library.lots.TIN_KNOWLEDGE`).

    A Ctrl-C (KeyboardInterrupt) once a target is judged ends the run there: the report is
    that of the targets judged (``targets``), with the counts asked for (``targets_asked``,
    ``novel_targets_asked``)."""
    settings = settings or MatchSettings()
    tolerance = tolerance or tolerance_preset(OBJECTIVE_DEFAULT)
    if lots not in TIN_KNOWLEDGE:
        raise MatchError(f"--lots: expected one of {', '.join(TIN_KNOWLEDGE)}, got {lots!r}")
    panels = standards = None
    if lots in TINS_READ:
        panels = calibration_recipes(forward, world.library)
    if lots == "referenced":
        standards = standard_panels(world, panels, seed)
    rows, novel_rows = [], []
    try:
        for i, (x, t) in enumerate(harness_trials(world, targets, seed, novel, novel_targets)):
            row = _one(
                t, x, forward, effect, settings, habits, tolerance, scale, target_texture,
                resprays, lots, panels, standards, colour_alone,
            )  # fmt: skip
            (rows if i < targets else novel_rows).append(row)
            if progress:
                progress()
    except KeyboardInterrupt:  # a Ctrl-C ends the run early: the figures of the targets judged
        if not (rows or novel_rows):
            raise
        interrupted = {"targets_asked": targets, "novel_targets_asked": novel_targets}
    else:
        interrupted = {}

    def share(rs, key):
        return float(np.mean([r[key] <= 1.0 for r in rs])) if rs else None

    def mean(rs, key):  # a chance over the resprays, averaged over targets
        return float(np.mean([r[key] for r in rs])) if rs and resprays else None

    def ratio(rate, limit):
        return rate / limit if rate is not None and limit else None

    oracle, novel_oracle = share(rows, "oracle"), share(novel_rows, "oracle")
    first, corrected = share(rows, "first"), share(rows, "corrected")
    novel_first, novel_corrected = share(novel_rows, "first"), share(novel_rows, "corrected")
    latency = np.array([r["latency_s"] for r in rows + novel_rows])
    return {
        "targets": len(rows),
        **interrupted,
        "seed": seed,
        "tolerance": tolerance.name,
        "weighed": scale and scale.to_dict(),
        "first_shot_success": first,
        # the first recipes' colour without their spray's noise (``Trial.unsprayed``)
        "first_shot_unsprayed": share(rows, "first_unsprayed"),
        "novel_toner_first_shot_unsprayed": share(novel_rows, "first_unsprayed"),
        "without": list(settings.without),
        # the targets whose paint holds a toner out of stock, and how they fared
        "needing_missing_targets": sum(r["needs_missing"] for r in rows),
        "needing_missing_first_shot": share([r for r in rows if r["needs_missing"]], "first"),
        "needing_missing_after_one_correction": share(
            [r for r in rows if r["needs_missing"]], "corrected"
        ),
        "novel_needing_missing_targets": sum(r["needs_missing"] for r in novel_rows),
        "novel_needing_missing_first_shot": share(
            [r for r in novel_rows if r["needs_missing"]], "first"
        ),
        "by_family": _by_family(rows, share, mean),
        "novel_by_family": _by_family(novel_rows, share, mean),
        "targets_read_texture": target_texture,
        "targets_read_colour_alone": colour_alone,
        "after_one_correction": corrected,
        "novel_toner_first_shot": novel_first,
        # a new toner's targets corrected once, as the others are (the issue asks the first shot)
        "novel_toner_after_one_correction": novel_corrected,
        "novel_targets": len(novel_rows),
        "novel_oracle_success": novel_oracle,
        "oracle_success": oracle,
        "respray_success": share(rows, "respray"),
        "after_one_perfect_correction": share(rows, "first_or_respray"),
        "first_shot_vs_oracle": ratio(first, oracle),
        "after_one_correction_vs_oracle": ratio(corrected, oracle),
        "novel_toner_first_shot_vs_oracle": ratio(novel_first, novel_oracle),
        "novel_toner_after_one_correction_vs_oracle": ratio(novel_corrected, novel_oracle),
        "first_shot_de00_median": _median(r["first_de00"] for r in rows),
        # first spray-outs within the refinish tolerance's texture limits, whatever judged
        "first_shot_texture_within": share(rows, "first_texture"),
        "oracle_texture_within": share(rows, "oracle_texture"),
        "first_shot_texture_share_p95": _percentile((r["first_texture"] for r in rows), 95),
        "first_shot_metamerism_median": _median(r["first_metamerism"] for r in rows),
        "oracle_metamerism_median": _median(r["oracle_metamerism"] for r in rows),
        # the failed first shots, their spray-outs before and after the correction
        "correction_metamerism_before_median": _median(
            r["first_metamerism"] for r in rows if r["corrected_metamerism"] is not None
        ),
        "correction_metamerism_median": _median(
            r["corrected_metamerism"] for r in rows if r["corrected_metamerism"] is not None
        ),
        "oracle_de00_median": _median(r["oracle_de00"] for r in rows),
        "predicted_de00_median": _median(r["predicted_de00"] for r in rows),
        # targets whose best recipes the physics refined, the ensemble unsure (physics_check)
        "physics_checked_targets": sum(r["physics_checked"] for r in rows),
        "novel_physics_checked_targets": sum(r["physics_checked"] for r in novel_rows),
        "correction_physics_checked_targets": sum(r["correction_physics_checked"] for r in rows),
        "novel_correction_physics_checked_targets": sum(
            r["correction_physics_checked"] for r in novel_rows
        ),
        "latency_p50_s": float(np.percentile(latency, 50)),
        "latency_p95_s": float(np.percentile(latency, 95)),
        "resprays": resprays,
        "lots": lots,
        # the RMS error of the tins' strengths the shop matched with, mean over targets
        "lot_strength_error_rms": _mean_or_none(
            r["lot_error"]["strength"] for r in rows + novel_rows if r["lot_error"]
        ),
        "lot_shade_error_rms_nm": _mean_or_none(
            r["lot_error"]["shade_nm"] for r in rows + novel_rows if r["lot_error"]
        ),
        **{name: mean(rows, key) for name, key in CHANCES.items()},
        "novel_toner_first_shot_chance": mean(novel_rows, "first_chance"),
        "novel_toner_after_one_correction_chance": mean(novel_rows, "corrected_chance"),
        "novel_oracle_chance": mean(novel_rows, "oracle_chance"),
        **({"per_target": rows + novel_rows} if per_target else {}),
    }
