"""Synthetic refinish cases from the physics model — labelled synthetic in every case.

The generated world (DESIGN.md §5): an OEM paint (the hidden formulation) is sprayed at the
factory with its own toner batches and application, weathers on the car, and is measured by
the shop's instrument (the *target*). The colorist's recipe is that formulation as a good
but imperfect match finds it; it is mixed from the shop's batches, sprayed with the shop's
application and measured (the *spray-out*). Every random draw comes from one seeded
generator, so ``(n, seed)`` gives the same cases on every machine.

Formulations (:meth:`World.formulations`, the family mix ``kinds``): a metallic is one or two
aluminiums, a pearl one or two pearls (``white_pearl_share`` of them with the library's white
beside them, white pearls; half the rest over a little aluminium), each with up to four
pigments at log-uniform amounts; a solid is a pigment that hides the primer — the
library's white for ``solid_white_share`` of them, else an opaque iron oxide, BiVO4 or a
black — with up to three tints.

Sources of variation (all in :class:`WorldSettings`):
* toner batches: strength × N(1, 3 %) per toner, hue drift of the pigment absorption by a
  shift of N(0, 1.5 nm);
* application: film build × N(1, 4 %), flake alignment (spread) × logN(0, 2 %);
* weathering of targets: organic pigments fade 1–6 %, clearcoat haze adds 0.1–0.4 % flat
  reflectance;
* instrument: smooth multiplicative noise 0.1 % per band, a gain error 0.12 % per geometry
  per reading, additive 2·10⁻⁴; texture readings of one spot of the camera's field, glints
  counted (Poisson) and grain sampled (:func:`~flakelab.texture.readings.counted_readings`),
  drawn from a stream of their own so that no colour depends on them;
* the colorist's recipe: the formulation's toners with amounts off by logN(0, 5 %);
* the shop's tins last (``tin_sprayouts``, 1 by default): with K > 1 each tin of a toner
  serves K spray-outs that use it before the next is opened (each toner's first tin part
  used), so the cases of a stretch share their tins' strengths and each pigment's own shade,
  and a tin read once carries its reading's error into every case poured from it; drawn
  from a stream of the seed's own (:class:`LastingTins`), whatever the chunks;
* the tins a shop records (``tins``, :data:`~flakelab.library.lots.TIN_KNOWLEDGE`, none by
  default): every tin of a spray-out read, as ``flakelab lots`` reads one from a panel
  against the model (``calibrated``), to ``tin_strength_read_sd``
  and ``tin_shade_read_sd_nm`` (what that reading came to, ``benchmarks/toner_lots.py``), or
  against the paint maker's panel (``referenced``, ``tin_*_referenced_sd``), or known
  exactly; drawn from a stream of their own, so the cases are the same either way;
* the shop's own habits (``shop_*``, none by default): its sprayer's mean film build and
  flake spread against the factory's, and its instrument's gain against the instrument the
  shipped model learned from. These are what the protocol's adaptation phase is for
  (``flakelab model adapt``): every case of one shop carries them, no case of another does;
* the car makers' colour codes (``colour_codes``, none by default): with K > 0 every car is
  painted in one of K OEM colours (:class:`ColourCatalogue`), met as often as a popular
  colour is met, and its case records the colour's code; cars of one code still differ by
  their factory batches, spray line and weathering. Without, every car is a colour of its
  own and records no code.

They were set so that ``World.realism`` lands in the ranges a shop sees (issue 4).
"""

from __future__ import annotations

import uuid
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime, timedelta

import numpy as np
from numpy.typing import NDArray

from flakelab.cases.case import Case
from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.defaults import DEFAULT_CONDITIONS
from flakelab.core.difference import delta_E
from flakelab.core.geometry import (
    DEFAULT_INSTRUMENT,
    FACE_GEOMETRY,
    Geometry,
    instrument_geometries,
)
from flakelab.core.measurement import TEXTURE_FAMILIES, TEXTURE_READINGS
from flakelab.core.spectra import shift_spectra
from flakelab.library.lots import MAX_SHADE_NM, TIN_KNOWLEDGE, TINS_READ, TonerLot
from flakelab.library.toners import Library
from flakelab.physics.application import FILM_BUILD_SD, SPREAD_SD, sprayed_layer
from flakelab.physics.fast import reflectance_factor
from flakelab.physics.layer import Layer, layer_from_fractions
from flakelab.texture.readings import (
    GLINT_SD,
    GLINT_SHARE,
    GRAIN_SD,
    counted_readings,
    texture_readings,
)

__all__ = [
    "WorldSettings",
    "World",
    "Variation",
    "CHUNK",
    "LastingTins",
    "ColourCatalogue",
    "SHOP_WITH_HABITS",
    "NEAR_BLACK_L",
    "near_black",
    "REALISTIC_RANGES",
    "RealismDraws",
]

CHUNK = 250
"""Cases drawn from one random stream (the unit of reproducibility)."""

REALISTIC_RANGES = {
    "remeasure_de00_median": (0.02, 0.10),
    "respray_de00_median": (0.3, 0.8),
    "batch_strength_sd": (0.02, 0.04),
    "weathered_target_de00_median": (0.5, 2.0),
}
"""What a real shop shows (issue 4): one panel read twice (instrument repeatability, at
45as45); one recipe sprayed twice and read (the worst geometry; metallics); toner strength
between batches (standard deviation); a weathered car against its fresh formula."""

TIN_STREAM = 7105
"""The key of the stream a shop's lasting tins are drawn from (:class:`LastingTins`), beside
the seed: apart from every chunk's."""

TIN_BLOCK = 64
"""Tins of one toner drawn from one stream: tin k's draws are the same whatever the chunk."""

CODE_STREAM = 7106
"""The key of the streams a world's colour codes are drawn from (:class:`ColourCatalogue`),
beside the seed: apart from every chunk's and the tins'."""

CODE_POPULARITY = 1.0
"""How often a shop meets a car maker's colour: the r-th most met code's share goes as
1 / r to this power (Zipf): a few whites, silvers and blacks make many of the cars."""

ORGANIC_FAMILIES = (
    "phthalocyanine",
    "quinacridone",
    "perylene",
    "diketopyrrolopyrrole",
    "isoindoline",
    "indanthrone",
)
"""Pigment families that fade in sunlight (inorganics — iron oxides, TiO2, carbon — hold)."""


@dataclass(frozen=True)
class WorldSettings:
    """The size of every variation in the generated world (see the module notes)."""

    batch_strength_sd: float = 0.03
    batch_hue_shift_nm: float = 1.5
    film_build_sd: float = FILM_BUILD_SD
    spread_sd: float = SPREAD_SD
    fade_range: tuple[float, float] = (0.01, 0.06)
    haze_range: tuple[float, float] = (0.001, 0.004)
    noise_band: float = 0.001
    noise_gain: float = 0.0012
    noise_offset: float = 2e-4
    glint_share: float = GLINT_SHARE
    glint_sd: float = GLINT_SD
    grain_sd: float = GRAIN_SD
    recipe_error_sd: float = 0.05
    weathered_share: float = 0.5
    accept_de00: float = 1.0
    correct_de00: float = 2.5
    shop_film_build: float = 1.0
    shop_spread: float = 1.0
    shop_gain: float = 0.0
    tins: str = "none"  # TIN_KNOWLEDGE
    # a tin read from one panel against the model: RMS error over the harness's shops
    # (docs/matching.md, *The shop's tins*, stop 74); against the paint maker's panel, the same
    tin_strength_read_sd: float = 0.0111
    tin_shade_read_sd_nm: float = 0.75
    tin_strength_referenced_sd: float = 0.0059
    tin_shade_referenced_sd_nm: float = 0.29
    tin_sprayouts: int = 1
    colour_codes: int = 0  # the car makers' colours a shop meets (0: every car its own)
    solid_white_share: float = 0.5
    white_pearl_share: float = 0.3
    kinds: dict[str, float] = field(
        default_factory=lambda: {"metallic": 0.7, "pearl": 0.15, "solid": 0.15}
    )

    def __post_init__(self) -> None:
        for name in ("weathered_share", "solid_white_share", "white_pearl_share"):
            share = getattr(self, name)
            if not 0 <= share <= 1:
                raise ValueError(f"WorldSettings.{name}: {share!r} is not a share from 0 to 1")


SHOP_WITH_HABITS = {"shop_film_build": 1.05, "shop_spread": 0.96, "shop_gain": 0.005}
"""An example shop's habits (:class:`WorldSettings` changes): its sprayer lays 5 % more film
than the factory, with flakes 4 % flatter, and its instrument reads 0.5 % high. The shipped
model errs ΔE00 1.07 on its cases against 0.69 in the world it learned
(``benchmarks/adaptation.py``)."""


@dataclass(frozen=True)
class RealismDraws:
    """The draws behind :meth:`World.realism`, each formulation's: ΔE00 of one panel read
    twice at 45as45 ``[n]``; the worst ΔE00 of one recipe sprayed twice from the same cans
    ``[n]``; the batches' toner strengths ``[n, T]``; the worst ΔE00 of a weathered car against
    its fresh formula ``[n]``; the cases' noise floor (:meth:`World.exact_model_de00`, ``[n,
    G]``); each one's paint family; the effect paints' texture readings read twice, |Δ|
    ``[effect, 8]``; which read black at every geometry (:func:`near_black`)."""

    remeasure: NDArray
    respray: NDArray
    strength: NDArray
    weathered: NDArray
    floor: NDArray
    families: NDArray
    texture_remeasure: NDArray
    near_black: NDArray
    seed: int

    def summary(self) -> dict:
        """The medians and spreads :meth:`World.realism` reports."""
        families, respray, floor = self.families, self.respray, self.floor
        kinds = np.unique(families).tolist()
        return {
            "remeasure_de00_median": float(np.median(self.remeasure)),
            # effect paints' texture read twice: |Δ|, the largest over the lights for Sa, Si
            "remeasure_texture_median": {
                name: float(np.median(self.texture_remeasure[:, columns].max(1)))
                for name, columns in TEXTURE_FAMILIES.items()
            },
            # the range is for metallics: aluminium without pearl (paint_families)
            "respray_de00_median": float(np.median(respray[families == "metallic"])),
            "respray_de00_median_all": float(np.median(respray)),
            "respray_de00_median_by_family": {
                f: float(np.median(respray[families == f])) for f in kinds
            },
            "batch_strength_sd": float(np.std(self.strength)),
            "weathered_target_de00_median": float(np.median(self.weathered)),
            # paints black at every geometry (solids of organics that absorb the whole
            # spectrum between them, no hiding pigment): darker than any real paint reads
            "near_black_share": float(np.mean(self.near_black)),
            "exact_model_de00_mean": float(floor.mean()),
            "exact_model_de00_p95": float(np.percentile(floor, 95)),
            "exact_model_de00_mean_by_family": {
                f: float(floor[families == f].mean()) for f in kinds
            },
            "formulations": int(respray.size),
            "seed": self.seed,
        }


@dataclass(frozen=True)
class Variation:
    """Per-formulation draws: toner strength ``[F, T]``, hue shift ``[F]`` [nm] of every
    pigment alike (or ``[F, T]``, each pigment's own: lasting tins), film build ``[F]``
    (relative), spread scale ``[F]``."""

    strength: NDArray
    hue_shift: NDArray
    film: NDArray
    spread: NDArray

    def tins_at_nominal(self, n: int) -> Variation:
        """``n`` sprays from the first spray's tins at the nominal application (film build and
        flake spread 1): what those tins make of a paint, the spray aside."""
        return Variation(np.repeat(self.strength[:1], n, 0), np.repeat(self.hue_shift[:1], n, 0),
                         np.ones(n), np.ones(n))  # fmt: skip


class World:
    """Formulations, their appearance and its measurement for one library and instrument."""

    def __init__(
        self,
        library: Library,
        instrument: str = DEFAULT_INSTRUMENT,
        settings: WorldSettings | None = None,
        exclude: tuple[str, ...] = (),
    ) -> None:
        self.library = library
        self.instrument = instrument
        self.geometries: tuple[Geometry, ...] = instrument_geometries(instrument)
        self.settings = settings or WorldSettings()
        names = library.names
        for name in exclude:
            library[name]  # unknown names are an error
        self.exclude = tuple(exclude)

        def pool(kind: str) -> list[int]:
            return [names.index(t.name) for t in library.of_kind(kind) if t.name not in exclude]

        self._aluminium, self._pearls, self._pigments = map(pool, ("aluminium", "pearl", "pigment"))
        self._white, self._other_bases = library.solid_bases(self._pigments)
        self._organic = np.array(
            [t.kind == "pigment" and t.family in ORGANIC_FAMILIES for t in library.toners]
        )

    def without(self, toners: tuple[str, ...]) -> World:
        """This world with ``toners`` left out of its formulations: the same library,
        instrument and settings (hidden targets drawn only on the toners a model knows)."""
        return World(self.library, self.instrument, self.settings, exclude=tuple(toners))

    # -- formulations ---------------------------------------------------------------------
    def formulations(self, n: int, rng: np.random.Generator) -> NDArray:
        """OEM-like mass fractions ``[n, T]``: an effect base and up to four pigments."""
        kinds = list(self.settings.kinds)
        p = np.array(list(self.settings.kinds.values()))
        choice = rng.choice(len(kinds), size=n, p=p / p.sum())
        x = np.zeros((n, len(self.library.toners)))
        for row, kind in enumerate(choice):
            x[row] = self._one_formulation(kinds[kind], rng)
        return x

    def _one_formulation(self, kind: str, rng: np.random.Generator) -> NDArray:
        x = np.zeros(len(self.library.toners))
        if kind == "metallic":
            for i in _pick(rng, self._aluminium, rng.integers(1, 3)):
                x[i] = rng.uniform(0.3, 1.0)
        elif kind == "pearl":
            for i in _pick(rng, self._pearls, rng.integers(1, 3)):
                x[i] = rng.uniform(0.3, 1.0)
            share = self.settings.white_pearl_share  # no draw at 0: the world as before
            if self._white is not None and share > 0 and rng.random() < share:
                x[self._white] = rng.uniform(0.3, 1.0)  # a white pearl: pearl over white
            elif rng.random() < 0.5 and self._aluminium:
                x[rng.choice(self._aluminium)] = rng.uniform(0.05, 0.3)
        elif kind == "solid" and self._white is not None:
            x[self._solid_base(rng)] = rng.uniform(0.3, 1.0)
        effect = x.sum()
        if kind != "solid":
            low, high, most = 0, 5, 0.15
        elif effect > 0:  # tints over the hiding base
            low, high, most = 0, 4, 0.5
        else:  # a library with no pigment that hides
            low, high, most = 1, 5, 1.0
        tints = [i for i in self._pigments if x[i] == 0]
        for i in _pick(rng, tints, rng.integers(low, high)):
            # tinting strengths span two decades: log-uniform amounts
            x[i] = np.exp(rng.uniform(np.log(0.003), np.log(most)))
        if kind != "solid" and x.sum() - effect > 0.5 * x.sum():
            x[tints] *= 0.5
        return x / x.sum()

    def _solid_base(self, rng: np.random.Generator) -> int:
        """A solid's hiding pigment: the library's white for ``solid_white_share`` of solids
        (whites, greys and pastels are most of a shop's solids), else another that hides."""
        if not self._other_bases or rng.random() < self.settings.solid_white_share:
            return self._white
        return int(rng.choice(self._other_bases))

    # -- appearance -----------------------------------------------------------------------
    def variation(self, n: int, rng: np.random.Generator, at_shop: bool = True) -> Variation:
        """Batches and application of ``n`` sprays, at the shop or (``at_shop=False``) at
        the factory, which has none of the shop's habits."""
        s = self.settings
        T = len(self.library.toners)
        strength = rng.normal(1.0, s.batch_strength_sd, (n, T))
        hue_shift = rng.normal(0.0, s.batch_hue_shift_nm, n)
        return Variation(strength, hue_shift, *self.application(n, rng, at_shop))

    def one_set_of_tins(self, n: int, rng: np.random.Generator, at_shop: bool = False):
        """``n`` sprays from one set of tins (one batch of each toner), each with its own
        application: calibration panels sprayed in one session."""
        tins = self.variation(1, rng, at_shop)
        film, spread = self.application(n, rng, at_shop)
        return replace(tins.tins_at_nominal(n), film=film, spread=spread)

    def nominal(self, n: int, at_shop: bool = False) -> Variation:
        """No batch or application variation: the formulation as the library describes it,
        sprayed at the factory's (or ``at_shop``, the shop's) mean application."""
        T = len(self.library.toners)
        film, spread = self._mean_application(at_shop)
        return Variation(np.ones((n, T)), np.zeros(n), np.full(n, film), np.full(n, spread))

    def layer(self, fractions: NDArray, variation: Variation) -> Layer:
        """The basecoat of ``fractions`` mixed from ``variation``'s batches and sprayed."""
        mixed = fractions * variation.strength
        if variation.hue_shift.ndim == 2:  # each pigment's tin its own shade
            layer = layer_from_fractions(self.library, mixed, shade_nm=variation.hue_shift)
        else:
            layer = layer_from_fractions(self.library, mixed)
            layer = replace(layer, absorption=shift_spectra(layer.absorption, variation.hue_shift))
        return sprayed_layer(layer, self.library, variation.film, variation.spread)

    def appearance(self, fractions: NDArray, variation: Variation) -> tuple[NDArray, NDArray]:
        """Reflectance factors ``[F, G, 31]`` (π·BRDF) and expected texture readings
        ``[F, 8]`` (:meth:`measure_texture` reads them)."""
        layer = self.layer(fractions, variation)
        R = reflectance_factor(layer, self.geometries)
        return R, texture_readings(layer, self.library.flake_radii_um)

    def weather(self, fractions: NDArray, rng: np.random.Generator) -> tuple[NDArray, NDArray]:
        """Faded fractions ``[F, T]`` and the clearcoat haze ``[F]`` of weathered targets."""
        lo, hi = self.settings.fade_range
        fade = rng.uniform(lo, hi, (fractions.shape[0], 1))
        faded = fractions * np.where(self._organic[None, :], 1 - fade, 1.0)
        return faded, rng.uniform(*self.settings.haze_range, fractions.shape[0])

    def measure(self, R: NDArray, rng: np.random.Generator) -> NDArray:
        """One reading of reflectance ``[F, G, W]`` by the shop's instrument: smooth band
        noise, a gain error per geometry, the instrument's own gain and an offset."""
        s = self.settings
        F, G, W = R.shape
        smooth = _smooth_noise(rng, (F, G, W)) * s.noise_band
        gain = rng.normal(0, s.noise_gain, (F, G, 1))
        return R * (1 + smooth + gain + s.shop_gain) + rng.normal(0, s.noise_offset, (F, G, 1))

    def measure_texture(self, texture: NDArray, rng: np.random.Generator) -> NDArray:
        """One texture reading ``[F, 8]`` of coatings whose expected readings are
        ``texture``: the glints and grain of one spot in the camera's field
        (:func:`~flakelab.texture.readings.counted_readings`)."""
        s = self.settings
        return counted_readings(
            texture, rng, glint_share=s.glint_share, glint_sd=s.glint_sd, grain_sd=s.grain_sd
        )

    # -- cases ----------------------------------------------------------------------------
    def cases(
        self,
        n: int,
        seed: int,
        *,
        batch: int = 500,
        shop: str = "synthetic shop",
        start: datetime | None = None,
    ) -> Iterator[list[Case]]:
        """``n`` cases in lists of ``batch``, reproducible from ``seed``: case i is the same
        whatever ``n`` or ``batch`` (each block of :data:`CHUNK` draws from its own stream)."""
        start = start or datetime(2026, 1, 1, tzinfo=UTC)
        pending: list[Case] = []
        tins = LastingTins(self, seed) if self.settings.tin_sprayouts != 1 else None
        catalogue = ColourCatalogue(self, seed) if self.settings.colour_codes else None
        for first in range(0, n, CHUNK):
            rng = np.random.default_rng([seed, first // CHUNK])
            codes = catalogue and catalogue.codes_met(first // CHUNK, CHUNK)
            pending += self._batch(rng, shop, start, first, tins, codes)[: n - first]
            while len(pending) >= batch:
                yield pending[:batch]
                pending = pending[batch:]
        if pending:
            yield pending

    def _batch(
        self,
        rng,
        shop,
        start,
        offset,
        tins: LastingTins | None = None,
        codes: tuple[NDArray, tuple[str, ...], NDArray] | None = None,
    ) -> list[Case]:
        """One block of :data:`CHUNK` cases, drawn whole whatever part of it is kept: a block
        cut short would draw each array at another size, and so other cases. ``tins``: the
        shop's lasting tins, which its spray-outs are poured from (None: a batch of each
        toner for every spray-out). ``codes``: each car's colour (formulations ``[CHUNK,
        T]``) and code (:meth:`ColourCatalogue.codes_met`; None: each car a colour of its
        own)."""
        s, size = self.settings, CHUNK
        hidden = self.formulations(size, rng)  # drawn either way: every other draw the same
        if codes is not None:
            hidden = codes[0]
        oem = self.variation(size, rng, at_shop=False)
        weathered = rng.random(size) < s.weathered_share
        aged, haze = self.weather(hidden, rng)
        aged = np.where(weathered[:, None], aged, hidden)
        target_R, target_tex = self.appearance(aged, oem)
        target_R = target_R + np.where(weathered, haze, 0.0)[:, None, None]
        target = self.measure(target_R, rng)
        recipe = self.colorist_recipe(hidden, rng)
        shop_batches = self.variation(size, rng)
        reading = None
        if tins is not None:  # the spray's application as drawn, from the shop's lasting tins
            strength, shade, reading = tins.poured(recipe)
            shop_batches = replace(shop_batches, strength=strength, hue_shift=shade)
        spray_R, spray_tex = self.appearance(recipe, shop_batches)
        sprayout = self.measure(spray_R, rng)
        # texture noise from a stream of its own, so every case's colour stays as it was
        texture_rng = rng.spawn(1)[0]
        target_tex = self.measure_texture(target_tex, texture_rng)
        spray_tex = self.measure_texture(spray_tex, texture_rng)
        recorded = self.recorded_tins(recipe, shop_batches, rng.spawn(1)[0], reading)
        worst = self.worst_de00(target, sprayout)
        outcome = np.where(
            worst <= s.accept_de00,
            "accepted",
            np.where(worst <= s.correct_de00, "corrected", "rejected"),
        )
        names = self.library.names
        cases = []
        for i in range(size):
            ids = np.flatnonzero(recipe[i] > 0)
            cases.append(
                Case(
                    case_id=str(uuid.UUID(int=int(rng.integers(0, 2**63)) << 64 | offset + i)),
                    geometries=self.geometries,
                    recipe={names[j]: float(recipe[i, j]) for j in ids},
                    target=target[i],
                    sprayout=sprayout[i],
                    target_texture=dict(zip(TEXTURE_READINGS, target_tex[i], strict=True)),
                    sprayout_texture=dict(zip(TEXTURE_READINGS, spray_tex[i], strict=True)),
                    instrument=self.instrument,
                    shop=shop,
                    conditions=DEFAULT_CONDITIONS,
                    outcome=str(outcome[i]),
                    synthetic=True,
                    created_at=start + timedelta(minutes=37 * (offset + i)),
                    tins=recorded[i],
                    colour_code="" if codes is None else codes[1][codes[2][i]],
                )
            )
        return cases

    def recorded_tins(
        self,
        recipe: NDArray,
        batches: Variation,
        rng: np.random.Generator,
        reading: tuple[NDArray, NDArray] | None = None,
    ) -> list[dict[str, TonerLot]]:
        """What each case records of the tins its ``recipe[F, T]`` was poured from
        (``settings.tins``): nothing, the shop's reading of each tin (log strength and shade
        off the batch by ``tin_*_read_sd``, or ``tin_*_referenced_sd`` read against the
        paint maker's panel), or the batch itself. An effect toner has no
        shade; a pigment's is the batch's drift. ``reading``: each tin's reading errors in
        standard deviations ``[F, T]`` (strength, shade), where a tin read once serves several
        cases (:class:`LastingTins`); else drawn for each case from ``rng``."""
        s, (F, T) = self.settings, recipe.shape
        if s.tins not in TIN_KNOWLEDGE:
            raise ValueError(f"tins: expected one of {', '.join(TIN_KNOWLEDGE)}, got {s.tins!r}")
        if s.tins == "none":
            return [{} for _ in range(F)]
        strength = batches.strength
        drift = batches.hue_shift if batches.hue_shift.ndim == 2 else batches.hue_shift[:, None]
        shade = np.where(self.library.effect[None, :], 0.0, drift)
        if s.tins in TINS_READ:
            if reading is None:
                reading = (rng.normal(0, 1, (F, T)), rng.normal(0, 1, (F, T)))
            strength_sd, shade_sd = (
                (s.tin_strength_read_sd, s.tin_shade_read_sd_nm)
                if s.tins == "calibrated"
                else (s.tin_strength_referenced_sd, s.tin_shade_referenced_sd_nm)
            )
            strength = strength * np.exp(strength_sd * reading[0])
            shade = shade + np.where(self.library.effect[None, :], 0.0, shade_sd * reading[1])
        strength = strength.clip(0.5, 2.0)  # a tin's readable range (TonerLot)
        shade = shade.clip(-MAX_SHADE_NM, MAX_SHADE_NM)
        names = self.library.names
        return [
            {
                names[j]: TonerLot(
                    names[j],
                    strength=round(float(strength[i, j]), 5),
                    shade_nm=round(float(shade[i, j]), 3),
                )
                for j in np.flatnonzero(recipe[i] > 0)
            }
            for i in range(F)
        ]

    def colorist_recipe(self, hidden: NDArray, rng: np.random.Generator) -> NDArray:
        """The match a colorist mixes: every toner of the formulation, amounts off by
        logN(0, ``recipe_error_sd``)."""
        noisy = hidden * np.exp(rng.normal(0, self.settings.recipe_error_sd, hidden.shape))
        return noisy / noisy.sum(axis=1, keepdims=True)

    @staticmethod
    def worst_de00(a: NDArray, b: NDArray) -> NDArray:
        """Largest ΔE00 over geometries between reflectances ``[F, G, W]``."""
        return delta_E(reflectance_to_Lab(a), reflectance_to_Lab(b)).max(axis=1)

    # -- realism --------------------------------------------------------------------------
    def realism(self, n: int = 400, seed: int = 0) -> dict[str, float]:
        """How hard the generated world is, in the quantities a shop knows (issue 4), beside
        :data:`REALISTIC_RANGES`: :meth:`realism_draws` summarised."""
        return self.realism_draws(n, seed).summary()

    def realism_draws(self, n: int = 400, seed: int = 0) -> RealismDraws:
        """What :meth:`realism` summarises, each of ``n`` formulations drawn with ``seed``."""
        rng = np.random.default_rng(seed)
        x = self.formulations(n, rng)
        R, texture = self.appearance(x, self.variation(n, rng))
        index = [g.name for g in self.geometries].index(FACE_GEOMETRY)
        first_reading, second_reading = self.measure(R, rng), self.measure(R, rng)
        remeasure = delta_E(reflectance_to_Lab(first_reading), reflectance_to_Lab(second_reading))[
            :, index
        ]
        batch = self.variation(n, rng)

        def same_batch() -> Variation:  # the same cans, sprayed again
            return Variation(batch.strength, batch.hue_shift, *self.application(n, rng))

        first, _ = self.appearance(x, same_batch())
        second, _ = self.appearance(x, same_batch())
        respray = self.worst_de00(self.measure(first, rng), self.measure(second, rng))
        aged, haze = self.weather(x, rng)
        weathered_R, _ = self.appearance(aged, self.nominal(n))
        fresh_R, _ = self.appearance(x, self.nominal(n))
        weathered = self.worst_de00(fresh_R, weathered_R + haze[:, None, None])
        floor = self.exact_model_de00(x, rng)
        families = np.asarray(self.library.paint_families(x))
        texture_rng = rng.spawn(1)[0]  # drawn apart: the colour figures stay as they were
        texture_remeasure = np.abs(
            self.measure_texture(texture, texture_rng) - self.measure_texture(texture, texture_rng)
        )[families != "solid"]
        return RealismDraws(
            remeasure, respray, batch.strength, weathered, floor, families, texture_remeasure,
            near_black(reflectance_to_Lab(fresh_R)), seed,
        )  # fmt: skip

    def exact_model_de00(self, fractions: NDArray, rng: np.random.Generator) -> NDArray:
        """ΔE00 ``[F, G]`` between spray-outs of ``fractions`` (shop batches, application,
        instrument) and their nominal appearance: what a forward model that knew this world's
        physics exactly would score in ``flakelab model evaluate`` — the cases' noise floor."""
        n = fractions.shape[0]
        R, _ = self.appearance(fractions, self.variation(n, rng))
        nominal, _ = self.appearance(fractions, self.nominal(n))
        return delta_E(reflectance_to_Lab(self.measure(R, rng)), reflectance_to_Lab(nominal))

    def application(
        self, n: int, rng: np.random.Generator, at_shop: bool = True
    ) -> tuple[NDArray, NDArray]:
        """One spraying: relative film build and flake-spread scale ``[n]`` each, about the
        shop's habits (``at_shop``) or the factory's."""
        s = self.settings
        film, spread = self._mean_application(at_shop)
        return (
            rng.normal(film, s.film_build_sd, n).clip(0.7, 1.3),
            np.exp(rng.normal(np.log(spread), s.spread_sd, n)),
        )

    def _mean_application(self, at_shop: bool) -> tuple[float, float]:
        """Mean film build and flake spread at the shop (its habits) or at the factory."""
        s = self.settings
        return (s.shop_film_build, s.shop_spread) if at_shop else (1.0, 1.0)


NEAR_BLACK_L = 1.0
"""A paint whose nominal L* is below this at every geometry is near-black
(:meth:`World.realism`'s ``near_black_share``; ``benchmarks/near_black.py``)."""


def near_black(lab: NDArray, lightness: float = NEAR_BLACK_L) -> NDArray[np.bool_]:
    """Which paints of CIELAB ``lab[F, G, 3]`` read below ``lightness`` at every geometry."""
    return (lab[..., 0] < lightness).all(axis=-1)


def _pick(rng: np.random.Generator, pool: list[int], count: int) -> NDArray:
    """Up to ``count`` distinct toners from ``pool`` (fewer when the library has fewer)."""
    return rng.choice(pool, size=min(int(count), len(pool)), replace=False) if pool else []


def _smooth_noise(rng: np.random.Generator, shape: tuple[int, int, int]) -> NDArray:
    """Unit-variance noise correlated over ~3 bands (an instrument's spectral noise)."""
    raw = rng.normal(size=(*shape[:-1], shape[-1] + 4))
    kernel = np.array([1, 2, 3, 2, 1], dtype=float)
    kernel /= np.sqrt(np.sum(kernel**2))
    return sum(kernel[i] * raw[..., i : i + shape[-1]] for i in range(5))


class ColourCatalogue:
    """The car makers' colours a shop meets (``WorldSettings.colour_codes`` = K > 0): K OEM
    formulations drawn once from the stream ``(seed, CODE_STREAM)``, coded ``GEN 001`` …
    (synthetic codes, as the cases are), the r-th met in proportion to 1 / r^
    :data:`CODE_POPULARITY`. Which code each car of a chunk has is drawn from the stream
    ``(seed, CODE_STREAM, chunk)``: case i's code is the same whatever the batches."""

    def __init__(self, world: World, seed: int) -> None:
        count = world.settings.colour_codes
        if not isinstance(count, int) or isinstance(count, bool) or count < 0:
            raise ValueError(f"colour_codes: expected a whole number from 0, got {count!r}")
        self.seed = seed
        self.formulations = world.formulations(count, np.random.default_rng([seed, CODE_STREAM]))
        digits = max(3, len(str(count)))
        self.codes = tuple(f"GEN {k:0{digits}d}" for k in range(1, count + 1))
        popularity = np.arange(1, count + 1) ** -CODE_POPULARITY
        self.share = popularity / popularity.sum()

    def codes_met(self, chunk: int, size: int) -> tuple[NDArray, tuple[str, ...], NDArray]:
        """The formulations ``[size, T]`` of the cars of ``chunk``, the codes, and each car's
        index among them ``[size]``."""
        rng = np.random.default_rng([self.seed, CODE_STREAM, chunk])
        met = rng.choice(len(self.codes), size=size, p=self.share)
        return self.formulations[met], self.codes, met


class LastingTins:
    """A shop's tins as they last (``WorldSettings.tin_sprayouts`` = K > 1): each tin of a
    toner serves K spray-outs that use it, then the next is opened. The toners' first tins
    were opened at different times (each part used, by a uniform share of K), so the shop's
    tins do not all change at once. Tin k of toner t has its own strength, shade (a
    pigment's absorption moved, each pigment's own) and the errors of the shop's one reading
    of it, drawn from the stream ``(seed, TIN_STREAM, t, k // TIN_BLOCK)``: the same whatever
    the chunks. Spray-outs are poured in order (:meth:`poured`), as a shop uses its tins."""

    def __init__(self, world: World, seed: int) -> None:
        self.settings, self.seed = world.settings, seed
        lasting = self.settings.tin_sprayouts
        if not isinstance(lasting, int) or isinstance(lasting, bool) or lasting < 1:
            raise ValueError(f"tin_sprayouts: expected a whole number from 1, got {lasting!r}")
        T = len(world.library.toners)
        self.used = np.random.default_rng([seed, TIN_STREAM]).integers(0, lasting, T)

    def poured(self, recipe: NDArray) -> tuple[NDArray, NDArray, tuple[NDArray, NDArray]]:
        """The tins the spray-outs of ``recipe[F, T]`` are poured from, in order: strength
        ``[F, T]``, shade ``[F, T]`` [nm] and the shop's reading errors in standard deviations
        (strength, shade; each ``[F, T]``). A toner a recipe does not use serves it nothing."""
        used = recipe > 0
        before = self.used[None, :] + np.cumsum(used, axis=0) - used
        self.used = self.used + used.sum(axis=0)
        z = self._draws(before // self.settings.tin_sprayouts)
        s = self.settings
        strength = 1.0 + s.batch_strength_sd * z[..., 0]
        return strength, s.batch_hue_shift_nm * z[..., 1], (z[..., 2], z[..., 3])

    def _draws(self, tin: NDArray) -> NDArray:
        """Four standard normal draws ``[F, T, 4]`` of each case's tin ``tin[F, T]``."""
        z = np.empty((*tin.shape, 4))
        for t in range(tin.shape[1]):  # a few streams of TIN_BLOCK tins per toner per chunk
            for block in np.unique(tin[:, t] // TIN_BLOCK):
                rows = tin[:, t] // TIN_BLOCK == block
                drawn = np.random.default_rng([self.seed, TIN_STREAM, t, int(block)])
                z[rows, t] = drawn.standard_normal((TIN_BLOCK, 4))[tin[rows, t] % TIN_BLOCK]
        return z
