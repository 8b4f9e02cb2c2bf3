"""One refinish case: a target, the recipe mixed for it, the spray-out and how it ended."""

from __future__ import annotations

import itertools
import unicodedata
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime

import numpy as np
from numpy.typing import NDArray

from flakelab.core.colorimetry import D65_10, reflectance_to_Lab
from flakelab.core.defaults import DEFAULT_CONDITIONS
from flakelab.core.difference import delta_E
from flakelab.core.geometry import Geometry, parse_geometries
from flakelab.core.measurement import (
    REFLECTANCE_RANGE,
    TEXTURE_RANGE,
    TEXTURE_READINGS,
    colour_stated_elsewhere,
    outside,
)
from flakelab.core.spectra import WAVELENGTHS
from flakelab.core.times import zoned_here
from flakelab.core.units import is_number
from flakelab.core.wording import did_you_mean, tidy_name
from flakelab.errors import FlakelabError
from flakelab.library.lots import TonerLot

__all__ = [
    "Case",
    "CaseError",
    "OUTCOMES",
    "TEXT_LENGTHS",
    "cases_at",
    "check_readings_kept",
    "colour_code_hint",
    "colour_code_words",
    "has_colour_code",
    "recovered_note",
    "select_cases",
    "tin_fields",
    "worst_differences",
]

OUTCOMES = ("accepted", "corrected", "rejected")
"""How a case ended: the spray-out passed, needed a correction, or was given up."""
RECIPE_SUM_TOLERANCE = 1e-12
"""A recipe whose amounts sum to one within this is kept as given, not divided by its sum
again: dividing changes the last digits of some, and a case file read and written back
differed from its original (found on the world with white pearls, stop 107)."""

TEXT_LENGTHS = {
    "case_id": 64,
    "shop": 120,
    "instrument": 60,
    "conditions": 30,
    "colour_code": 40,
}
"""The longest text each field may hold: the database's column widths (PostgreSQL refuses a
longer value; SQLite would keep it), checked with every case so that no store fails on one."""


def recovered_note(target: bool, sprayout: bool, *, learning: bool = True) -> str | None:
    """What a report says of a case whose ``target`` or ``sprayout`` (or both) was known by
    its L*a*b* in D65/10 alone, with whether a model learns from it (``learning``); None where
    both were measured."""
    if not (target or sprayout):
        return None
    which = (
        "the target and the spray-out are known by their"
        if target and sprayout
        else f"the {'target' if target else 'spray-out'} is known by its"
    )
    learnt = (
        "; the models learn the spray-out's colour alone, not its recovered spectra"
        if sprayout
        else "; the models learn from the spray-out's measured spectra"
    )
    return (
        f"{which} L*a*b* in D65/10 alone (spectra recovered from it: one metamer of many)"
        + learnt * learning
    )


class CaseError(FlakelabError):
    """A case that is wrong: names the case, the field and the problem."""


def check_readings_kept(target, sprayout) -> None:
    """Refuse a reading (:class:`~flakelab.core.measurement.Measurement`) a case cannot keep as
    it is: one known by its L*a*b* alone under other conditions than D65/10. A case's readings
    are read for their colour in D65/10 (its outcome, the nearest cases, the variants of a
    colour, a shop's habits, the mix-up check), which a spectrum recovered from that colour
    gives exactly; such a reading is kept, flagged (:attr:`Case.target_recovered`,
    :attr:`Case.sprayout_recovered`), and a model learns a spray-out known so by that colour
    alone (:class:`~flakelab.models.training.CaseArrays`' ``colour_alone``)."""
    for role, reading in (("target", target), ("spray-out", sprayout)):
        if stated := colour_stated_elsewhere(reading):
            raise CaseError(
                f"{role}: {reading.sample!r} gives L*a*b* under {stated} alone: a case keeps "
                f"its readings' colour in {D65_10}, by which its outcome is judged and the "
                f"shop's habits read, and its file gives none; export its spectra, or its "
                f"colour in {D65_10}"
            )


_CODE_BREAKS = str.maketrans({c: " " for c in "/,;+&"})


def colour_code_words(code: str) -> tuple[str, ...]:
    """The words of a car maker's colour code as stored and looked for: upper case, each
    word its letters and digits alone, so that the plate's 'NH-731P' and the 'nh731p' a
    colorist types are one code. Spaces, '/', ',', ';', '+' and '&' part words
    ('VW/Audi LY9B': VW, AUDI, LY9B)."""
    words = unicodedata.normalize("NFC", code).translate(_CODE_BREAKS).upper().split()
    return tuple(w for w in ("".join(c for c in word if c.isalnum()) for word in words) if w)


def colour_code_hint(asked: str, codes: Iterable[str]) -> str:
    """ " (did you mean 'NH731P'?)": the one of the shop's ``codes`` that a code that found
    no case most likely means: the code whose words hold the ones asked but for a number's
    leading zeros ('gen 2' for 'GEN 002'), else the code of which a run of words is the one
    asked but for spaces ('NH 731P' is two words, no case's code; 'LY 9B' is in 'VW AUDI
    LY9B'), else the closest spelling; "" where none is near, or where the code asked is
    among them (its cases were left out for another reason: their shop, or their
    geometries)."""
    codes = sorted(set(codes) - {""})
    if any(has_colour_code(code, asked) for code in codes):
        return ""
    unpadded = set(_unpadded(colour_code_words(asked)))
    for code in codes:  # 'gen 2' for 'GEN 002', 'Toyota 40' for 'TOYOTA 040'
        if unpadded <= set(_unpadded(colour_code_words(code))):
            return f" (did you mean {code!r}?)"
    runs = {}
    for code in codes:
        words = colour_code_words(code)
        for start, end in itertools.combinations(range(len(words) + 1), 2):
            runs.setdefault("".join(words[start:end]), code)
    wanted = "".join(colour_code_words(asked))
    if wanted in runs:
        return f" (did you mean {runs[wanted]!r}?)"
    return did_you_mean(asked, codes, lambda c: "".join(colour_code_words(c)))


def _unpadded(words: tuple[str, ...]) -> tuple[str, ...]:
    """Code words with a number's leading zeros left out ('002' → '2')."""
    return tuple(w.lstrip("0") or "0" if w.isdigit() else w for w in words)


def has_colour_code(code: str, asked: str) -> bool:
    """Whether a case's ``code`` is the ``asked`` one: every word asked among its words, so
    that '1G3' finds 'Toyota 1G3' and 'Lexus 1G3', 'Toyota 1G3' the first alone, and 'Toyota'
    every Toyota colour."""
    return set(colour_code_words(asked)) <= set(colour_code_words(code))


def _recipe_amounts(where: str, recipe) -> dict[str, float]:
    """A recipe's amounts as floats, checked: a mapping toner → a number ≥ 0, summing above 0."""
    if not isinstance(recipe, Mapping):
        raise CaseError(
            f"{where}: recipe: expected a mapping toner → amount, got {type(recipe).__name__}"
        )
    if not recipe:
        raise CaseError(f"{where}: recipe: expected at least one toner")
    wrong = next((k for k, v in recipe.items() if not is_number(v)), None)
    if wrong is not None:
        raise CaseError(f"{where}: recipe: {wrong}: expected a number, got {recipe[wrong]!r}")
    amounts = {str(k): float(v) for k, v in recipe.items()}
    if any(not np.isfinite(v) or v < 0 for v in amounts.values()) or sum(amounts.values()) <= 0:
        raise CaseError(f"{where}: recipe: expected non-negative amounts with a positive sum")
    return amounts


TIN_FIELDS = ("lot", "strength", "shade_nm")
"""What a case keeps of each tin it was poured from: the lot number and the shop's reading of
its strength and shade (:class:`~flakelab.library.lots.TonerLot`)."""


def tin_fields(tin: TonerLot) -> dict:
    """A case's tin as stored and written: :data:`TIN_FIELDS`."""
    return {name: getattr(tin, name) for name in TIN_FIELDS}


def _tins(where: str, tins, recipe: Mapping[str, float]) -> dict[str, TonerLot]:
    """A case's tins, checked: toner → a tin (or its :data:`TIN_FIELDS`) of a toner of the
    recipe."""
    if not isinstance(tins, Mapping):
        raise CaseError(f"{where}: tins: expected a mapping toner → tin, got {type(tins).__name__}")
    checked = {}
    for toner, tin in tins.items():
        if toner not in recipe:
            raise CaseError(f"{where}: tins: {toner}: not a toner of the recipe")
        if isinstance(tin, TonerLot):
            checked[toner] = tin
            continue
        if not isinstance(tin, Mapping) or set(tin) - set(TIN_FIELDS):
            raise CaseError(
                f"{where}: tins: {toner}: expected an object of {', '.join(TIN_FIELDS)}, "
                f"got {tin!r}"
            )
        numbers = ("strength", "shade_nm")
        wrong = next((k for k in numbers if k in tin and not is_number(tin[k])), None)
        if wrong or not isinstance(tin.get("lot", ""), str):
            field_name = wrong or "lot"
            raise CaseError(
                f"{where}: tins: {toner}: {field_name}: expected a "
                f"{'number' if wrong else 'text'}, got {tin[field_name]!r}"
            )
        try:
            checked[toner] = TonerLot(toner, **tin)
        except ValueError as error:
            raise CaseError(f"{where}: tins: {toner}: {error}") from None
    return checked


def _texture_readings(where: str, name: str, readings) -> dict[str, float]:
    """A case's texture readings ``name`` (``target_texture``, ``sprayout_texture``), checked:
    known readings, numbers, each in :data:`TEXTURE_RANGE`."""
    if not isinstance(readings, Mapping):
        raise CaseError(f"{where}: {name}: expected readings by name, got {readings!r}")
    unknown = sorted(set(readings) - set(TEXTURE_READINGS))
    if unknown:
        raise CaseError(f"{where}: {name}: unknown readings {unknown}")
    for k, v in readings.items():
        if not is_number(v):
            raise CaseError(f"{where}: {name}: {k}: expected a number, got {v!r}")
    readings = {k: float(v) for k, v in readings.items()}
    low, high = TEXTURE_RANGE
    bad = np.flatnonzero(outside(list(readings.values()), TEXTURE_RANGE))
    if bad.size:  # every reading in one check: a database holds tens of thousands of cases
        k = list(readings)[bad[0]]
        raise CaseError(
            f"{where}: {name}: {k}: expected a texture reading in [{low:g}, {high:g}], got "
            f"{readings[k]:g}"
        )
    return readings


@dataclass(frozen=True, eq=False)
class Case:
    """Spectra on the storage grid, ``[G, 31]`` reflectance factors; ``recipe`` maps toner
    names to mass fractions (summing to 1); textures map :data:`TEXTURE_READINGS` names;
    ``created_at`` without a time zone is taken as local time
    (:func:`~flakelab.core.times.zoned_here`), and kept in UTC. ``tins`` maps a toner of the
    recipe to the tin it was poured from, as the shop had read it (none recorded: every toner
    at the standard, as far as anyone knows). ``colour_code`` is the car maker's code for the
    car's colour, as on its plate (with the maker where codes clash: 'Toyota 1G3'), kept as
    its :func:`colour_code_words`; empty where none was recorded. ``target_recovered``
    (``sprayout_recovered``): the car (the spray-out) was known by its L*a*b* in D65/10 alone,
    and ``target`` (``sprayout``) was recovered from it: its colour there is the reading's, its
    spectral shape one metamer of many."""

    case_id: str
    geometries: tuple[Geometry, ...]
    recipe: Mapping[str, float]
    target: NDArray[np.float64]
    sprayout: NDArray[np.float64]
    target_texture: Mapping[str, float] = field(default_factory=dict)
    sprayout_texture: Mapping[str, float] = field(default_factory=dict)
    instrument: str = "unknown"
    shop: str = "unknown"
    conditions: str = DEFAULT_CONDITIONS
    outcome: str = "accepted"
    synthetic: bool = False
    created_at: datetime = field(default_factory=lambda: datetime.now(UTC))
    tins: Mapping[str, TonerLot] = field(default_factory=dict)
    colour_code: str = ""
    target_recovered: bool = False
    sprayout_recovered: bool = False

    def __post_init__(self) -> None:
        where = f"case {self.case_id!r}"
        try:
            geometries = parse_geometries([getattr(g, "name", g) for g in self.geometries])
        except (ValueError, TypeError) as error:
            raise CaseError(f"{where}: geometries: {error}") from None
        object.__setattr__(self, "geometries", geometries)
        for name in ("target", "sprayout"):
            values = np.asarray(getattr(self, name), dtype=float)
            if values.shape != (len(geometries), WAVELENGTHS.size):
                raise CaseError(
                    f"{where}: {name}: expected {len(geometries)} × {WAVELENGTHS.size} reflectance "
                    f"values, got shape {values.shape}"
                )
            bad = np.flatnonzero(outside(values, REFLECTANCE_RANGE))
            if bad.size:
                low, high = REFLECTANCE_RANGE
                raise CaseError(
                    f"{where}: {name}: expected reflectance factors in [{low:g}, {high:g}], got "
                    f"{values.ravel()[bad[0]]:g}"
                )
            object.__setattr__(self, name, values)
        amounts = _recipe_amounts(where, self.recipe)
        total = sum(amounts.values())
        if abs(total - 1.0) > RECIPE_SUM_TOLERANCE:
            amounts = {k: v / total for k, v in amounts.items()}
        object.__setattr__(self, "recipe", amounts)
        object.__setattr__(self, "tins", _tins(where, self.tins, self.recipe))
        object.__setattr__(self, "created_at", zoned_here(self.created_at).astimezone(UTC))
        if isinstance(self.shop, str):
            object.__setattr__(self, "shop", tidy_name(self.shop))
        if isinstance(self.colour_code, str):
            object.__setattr__(self, "colour_code", " ".join(colour_code_words(self.colour_code)))
        for name, longest in TEXT_LENGTHS.items():
            text = getattr(self, name)
            if not isinstance(text, str) or len(text) > longest:
                raise CaseError(
                    f"{where}: {name}: expected a text of at most {longest} characters, "
                    f"got {text!r}"
                )
        if not self.case_id.strip():
            raise CaseError(f"{where}: case_id: expected an id, got an empty text")
        if self.outcome not in OUTCOMES:
            raise CaseError(
                f"{where}: outcome: expected one of {', '.join(OUTCOMES)}, got {self.outcome!r}"
            )
        for name in ("target_texture", "sprayout_texture"):
            object.__setattr__(self, name, _texture_readings(where, name, getattr(self, name)))

    @property
    def geometry_names(self) -> tuple[str, ...]:
        return tuple(g.name for g in self.geometries)

    def known_by_colour(self, role: str) -> bool:
        """Whether its ``role`` reading (``target``, ``sprayout``) was known by its L*a*b* in
        D65/10 alone (:attr:`target_recovered`, :attr:`sprayout_recovered`)."""
        return getattr(self, f"{role}_recovered")

    def as_read(self, role: str) -> dict:
        """How its ``role`` reading (``target``, ``sprayout``) was read, as a
        :class:`~flakelab.core.measurement.Measurement`'s fields: its L*a*b* in D65/10 alone
        where its spectra were recovered from it, so that a file gives it so; none where
        measured."""
        if not self.known_by_colour(role):
            return {}
        return {"stored_lab": reflectance_to_Lab(getattr(self, role)), "spectra_recovered": True}

    def reads(self, geometries: Sequence[str]) -> bool:
        """Whether the case was read at every one of ``geometries``."""
        return set(geometries) <= set(self.geometry_names)

    def at_geometries(self, geometries: Sequence[str]) -> Case:
        """The case read at ``geometries`` alone, in their order: an MA-T12 case is a
        five-angle case too. Its instrument and id stay those it was recorded with."""
        names = self.geometry_names
        if tuple(geometries) == names:
            return self
        missing = [g for g in geometries if g not in names]
        if missing:
            raise CaseError(f"case {self.case_id!r}: geometries: not read at {', '.join(missing)}")
        rows = [names.index(g) for g in geometries]
        return replace(
            self,
            geometries=tuple(geometries),
            target=self.target[rows],
            sprayout=self.sprayout[rows],
        )


def cases_at(cases: Iterable[Case], geometries: Sequence[str]) -> list[Case]:
    """The cases read at every one of ``geometries``, each restricted to them: what a model of
    that geometry set learns from, whatever instrument read the case."""
    geometries = tuple(geometries)
    return [c.at_geometries(geometries) for c in cases if c.reads(geometries)]


def select_cases(
    cases: Iterable[Case],
    *,
    shop: str | None = None,
    since: datetime | None = None,
    geometries: Sequence[str] | None = None,
    colour_code: str | None = None,
) -> list[Case]:
    """The cases of ``shop`` made at or after ``since`` (without a zone: local time), read at
    ``geometries`` (:func:`cases_at`), for ``colour_code`` (:func:`has_colour_code`); None:
    any shop, any time, as read, any colour."""
    since = since and zoned_here(since)
    chosen = [
        c
        for c in cases
        if (shop is None or c.shop == shop)
        and (since is None or c.created_at >= since)
        and (colour_code is None or has_colour_code(c.colour_code, colour_code))
    ]
    return chosen if geometries is None else cases_at(chosen, geometries)


def worst_differences(cases: list[Case]) -> tuple[np.ndarray, list[str]]:
    """Each case's largest ΔE00 between target and spray-out, and the geometry where it lies
    (all cases' geometries in one colour computation)."""
    counts = np.array([len(c.geometries) for c in cases])
    targets = np.concatenate([c.target for c in cases])
    sprayouts = np.concatenate([c.sprayout for c in cases])
    de = delta_E(reflectance_to_Lab(targets), reflectance_to_Lab(sprayouts))
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    worst = np.maximum.reduceat(de, starts)
    where = [
        c.geometry_names[int(np.argmax(de[start : start + len(c.geometries)]))]
        for c, start in zip(cases, starts, strict=True)
    ]
    return worst, where
