"""Multi-angle tolerances: per-geometry limits on ΔE00 or on |ΔL*|, |ΔC*|, |ΔH*|, and limits
on texture differences (|ΔG|, |ΔSG|, |ΔSi|, |ΔSa|) → pass/fail."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flakelab.core.difference import delta_E_CIE2000, delta_LCH
from flakelab.core.geometry import Geometry
from flakelab.core.measurement import TEXTURE_FAMILIES, TEXTURE_READINGS
from flakelab.core.units import is_number

__all__ = [
    "Limit",
    "TextureLimit",
    "Tolerance",
    "TOLERANCE_PRESETS",
    "failing_geometries",
    "failures",
    "over_limit",
    "tolerance_preset",
]

_LIMIT_FIELDS = ("de00", "dL", "dC", "dH")
_TEXTURE_FIELDS = ("G", "SG", "Si", "Sa")


MIN_LIMIT = 0.01
"""The tightest limit a tolerance file may set (ΔE00, |ΔL*|, |ΔC*|, |ΔH*| or a texture reading):
an instrument's own repeatability is 0.02–0.10 ΔE00, so a tighter one could not be judged;
1e-320 overflowed the share of the limit."""


PARAMETRIC_FACTORS = (0.1, 10.0)
"""The kL, kC, kH a tolerance file may set: 1 under the reference conditions, 2 for the
lightness of textiles; beyond these a factor comes from a slip (1e-320 overflowed ΔE00)."""


def _check_limits(limits: Mapping[str, float | None]) -> None:
    if all(v is None for v in limits.values()):
        raise ValueError(f"expected at least one of {', '.join(limits)}, got none")
    for k, v in limits.items():
        if v is not None and not (np.isfinite(v) and v > 0):
            raise ValueError(f"expected a positive limit for {k}, got {v!r}")


def _limits_from_dict(cls, fields: tuple[str, ...], data: Mapping[str, Any], where: str):
    if not isinstance(data, Mapping):
        raise ValueError(f"{where}: expected a table of limits ({', '.join(fields)}), got {data!r}")
    unknown = [k for k in data if k not in fields]
    if unknown:
        raise ValueError(f"{where}: expected keys among {', '.join(fields)}, got {unknown}")
    wrong = next((k for k, v in data.items() if v is not None and not is_number(v)), None)
    if wrong is not None:
        raise ValueError(f"{where}: {wrong}: expected a number, got {data[wrong]!r}")
    tight = next((k for k, v in data.items() if v is not None and 0 < v < MIN_LIMIT), None)
    if tight is not None:
        raise ValueError(
            f"{where}: expected a limit for {tight} of at least {MIN_LIMIT}, got {data[tight]!r}"
        )
    try:
        return cls(**{k: None if v is None else float(v) for k, v in data.items()})
    except (TypeError, ValueError) as error:
        raise ValueError(f"{where}: {error}") from None


@dataclass(frozen=True)
class Limit:
    """Upper bounds at one geometry; ``None`` leaves a quantity unchecked.

    ``de00`` bounds ΔE00 (with ``kL``, ``kC``, ``kH`` weights); ``dL``, ``dC``, ``dH`` bound
    the magnitudes of the CIELAB components ΔL*, ΔC*ab, ΔH*ab.
    """

    de00: float | None = None
    dL: float | None = None
    dC: float | None = None
    dH: float | None = None

    def __post_init__(self) -> None:
        _check_limits({k: getattr(self, k) for k in _LIMIT_FIELDS})

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], where: str = "limit") -> Limit:
        return _limits_from_dict(cls, _LIMIT_FIELDS, data, where)

    def to_dict(self) -> dict[str, float]:
        return {k: getattr(self, k) for k in _LIMIT_FIELDS if getattr(self, k) is not None}


@dataclass(frozen=True)
class TextureLimit:
    """Upper bounds on texture differences; ``None`` leaves a reading unchecked.

    ``G`` bounds |ΔG| (graininess), ``SG`` |ΔSG| (sparkle grade), ``Si`` and ``Sa`` the
    sparkle intensity's and area's |ΔSi|, |ΔSa| under each of the directional lights.

    Examples
    --------
    >>> TextureLimit(G=1.0, Si=2.0).bounds().tolist()
    [inf, 2.0, inf, 2.0, inf, 2.0, inf, 1.0]
    """

    G: float | None = None
    SG: float | None = None
    Si: float | None = None
    Sa: float | None = None

    def __post_init__(self) -> None:
        _check_limits({k: getattr(self, k) for k in _TEXTURE_FIELDS})

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], where: str = "texture") -> TextureLimit:
        return _limits_from_dict(cls, _TEXTURE_FIELDS, data, where)

    def to_dict(self) -> dict[str, float]:
        return {k: getattr(self, k) for k in _TEXTURE_FIELDS if getattr(self, k) is not None}

    def bounds(self) -> NDArray[np.float64]:
        """The limit on each of :data:`~flakelab.core.measurement.TEXTURE_READINGS` (Sa15 →
        ``Sa``), ∞ where unchecked."""
        bounds = np.full(len(TEXTURE_READINGS), np.inf)
        for family, columns in TEXTURE_FAMILIES.items():
            if (limit := getattr(self, family)) is not None:
                bounds[list(columns)] = limit
        return bounds

    def share(
        self, reference: Mapping[str, float], sample: Mapping[str, float]
    ) -> dict[str, float]:
        """|Δ| of each reading these limits bound and both readings hold, as a share of its
        limit (≤ 1 passes).

        Examples
        --------
        >>> TextureLimit(G=1.0).share({"G": 3.0, "SG": 2.0}, {"G": 4.5, "SG": 9.0})
        {'G': 1.5}
        """
        bounds = dict(zip(TEXTURE_READINGS, self.bounds(), strict=True))
        return {
            k: abs(float(sample[k]) - float(reference[k])) / bounds[k]
            for k in TEXTURE_READINGS
            if k in reference and k in sample and np.isfinite(bounds[k])
        }


@dataclass(frozen=True)
class Tolerance:
    """Named per-geometry limits, with a default for geometries not listed.

    Examples
    --------
    >>> tol = Tolerance("shop", Limit(de00=1.0), {"45as15": Limit(de00=2.0)})
    >>> tol.passes(["45as15", "45as45"], de00=[1.5, 1.5], dLCH=np.zeros((2, 3))).tolist()
    [True, False]
    """

    name: str
    default: Limit
    per_geometry: Mapping[str, Limit] = field(default_factory=dict)
    description: str = ""
    kL: float = 1.0
    kC: float = 1.0
    kH: float = 1.0
    texture: TextureLimit | None = None  # None: colour alone is judged

    def __post_init__(self) -> None:
        normalised = {Geometry.parse(k).name: v for k, v in self.per_geometry.items()}
        object.__setattr__(self, "per_geometry", normalised)

    def limit(self, geometry: str | Geometry) -> Limit:
        name = geometry.name if isinstance(geometry, Geometry) else Geometry.parse(geometry).name
        return self.per_geometry.get(name, self.default)

    def bounds(self, geometries: list[str] | tuple) -> NDArray[np.float64]:
        """The limits ``[geometry, (ΔE00, |ΔL*|, |ΔC*|, |ΔH*|)]``, ∞ where unchecked."""
        return np.array(
            [
                [np.inf if getattr(lim, k) is None else getattr(lim, k) for k in _LIMIT_FIELDS]
                for lim in (self.limit(g) for g in geometries)
            ]
        )

    def passes(
        self, geometries: list[str] | tuple, *, de00: NDArray | list, dLCH: NDArray
    ) -> NDArray[np.bool_]:
        """Pass/fail per geometry given ΔE00 ``[geometry]`` and ``[geometry, (ΔL, ΔC, ΔH)]``."""
        return np.all(_observed(de00, dLCH) <= self.bounds(geometries), axis=-1)

    def share_of_limit(
        self, geometries: list[str] | tuple, *, de00: NDArray | list, dLCH: NDArray
    ) -> NDArray[np.float64]:
        """Each geometry's checked quantity furthest from passing, as a share of its limit
        (≤ 1 passes): what ranks recipes for this tolerance, whatever its limits bound.

        Examples
        --------
        >>> tol = Tolerance("shop", Limit(de00=1.0), {"45as15": Limit(de00=2.0)})
        >>> tol.share_of_limit(["45as15", "45as45"], de00=[1.5, 1.5], dLCH=np.zeros((2, 3)))
        array([ 0.75,  1.5 ])
        """
        return np.max(_observed(de00, dLCH) / self.bounds(geometries), axis=-1)

    def share_unit(self, geometries: list[str] | tuple) -> float:
        """The tightest ΔE00 limit over ``geometries`` (1 where none bounds ΔE00): a share of
        the limit times this is in ΔE00 of the strictest geometry. The search weighs its
        regularisers and thresholds against such shares, so that a wider tolerance spends
        its error where it allows more and does not make the search care less for colour.

        Examples
        --------
        >>> Tolerance("wide", Limit(de00=2.5), {"45as15": Limit(de00=4.0)}).share_unit(
        ...     ["45as15", "45as45"]
        ... )
        2.5
        """
        de00 = self.bounds(geometries)[:, 0]
        return float(de00.min()) if np.isfinite(de00).any() else 1.0

    def texture_limits(self) -> dict[str, float]:
        """The limit on each texture reading this tolerance bounds, by reading (Si15, …)."""
        if self.texture is None:
            return {}
        bounds = zip(TEXTURE_READINGS, self.texture.bounds().tolist(), strict=True)
        return {k: bound for k, bound in bounds if np.isfinite(bound)}

    def texture_share(
        self, reference: Mapping[str, float], sample: Mapping[str, float]
    ) -> dict[str, float]:
        """:meth:`TextureLimit.share` of this tolerance's texture limits; empty without."""
        return {} if self.texture is None else self.texture.share(reference, sample)

    def failing_texture(
        self, reference: Mapping[str, float], sample: Mapping[str, float]
    ) -> list[str]:
        """The texture readings over their limit (:meth:`texture_share` above 1)."""
        return over_limit(self.texture_share(reference, sample))

    def judge(
        self, geometries: list[str] | tuple, Lab_reference: NDArray, Lab_sample: NDArray
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
        """ΔE00 ``[..., geometry]`` with this tolerance's kL, kC, kH, the components
        ``[..., geometry, (ΔL*, ΔC*, ΔH*)]`` and pass/fail per geometry, of CIELAB arrays
        ``[..., geometry, 3]`` (they broadcast: one reference against many samples).

        Examples
        --------
        >>> tol = Tolerance("lightness", Limit(de00=1.0), kL=2.0)
        >>> de00, _, passed = tol.judge(["45as45"], [[50.0, 0, 0]], [[51.5, 0, 0]])
        >>> round(float(de00[0]), 2), bool(passed[0])
        (0.75, True)
        """
        de00 = delta_E_CIE2000(Lab_reference, Lab_sample, kL=self.kL, kC=self.kC, kH=self.kH)
        dLCH = delta_LCH(Lab_reference, Lab_sample)
        return de00, dLCH, self.passes(geometries, de00=de00, dLCH=dLCH)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], source: str = "tolerance") -> Tolerance:
        """Build from ``{name, description, default: {...}, geometries: {name: {...}}, kL…,
        texture: {G, SG, Si, Sa}}``."""
        if not isinstance(data, Mapping):
            raise ValueError(f"{source}: expected a table with a default limit, got {data!r}")
        allowed = {"name", "description", "default", "geometries", "kL", "kC", "kH", "texture"}
        unknown = [k for k in data if k not in allowed]
        if unknown:
            raise ValueError(f"{source}: expected keys among {sorted(allowed)}, got {unknown}")
        if "default" not in data:
            raise ValueError(f"{source}: default: missing (e.g. default = {{ de00 = 1.0 }})")
        geometries = {}
        per_geometry = data.get("geometries", {})
        if not isinstance(per_geometry, Mapping):
            raise ValueError(
                f"{source}: geometries: expected a table of geometries, got {per_geometry!r}"
            )
        for key, value in per_geometry.items():
            try:
                name = Geometry.parse(key).name
            except ValueError as error:
                raise ValueError(f"{source}: geometries.{key}: {error}") from None
            geometries[name] = Limit.from_dict(value, f"{source}: geometries.{key}")
        weights = {}
        low, high = PARAMETRIC_FACTORS
        for k in ("kL", "kC", "kH"):
            value = data.get(k, 1.0)
            if not is_number(value) or not low <= value <= high:
                raise ValueError(
                    f"{source}: {k}: expected a number from {low} to {high}, got {value!r}"
                )
            weights[k] = float(value)
        for k in ("name", "description"):
            if not isinstance(data.get(k, ""), str):
                raise ValueError(f"{source}: {k}: expected a text, got {data[k]!r}")
        texture = data.get("texture")
        if texture is not None:
            texture = TextureLimit.from_dict(texture, f"{source}: texture")
        return cls(
            name=str(data.get("name", source)),
            default=Limit.from_dict(data["default"], f"{source}: default"),
            per_geometry=geometries,
            description=str(data.get("description", "")),
            **weights,
            texture=texture,
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "description": self.description,
            "kL": self.kL,
            "kC": self.kC,
            "kH": self.kH,
            "default": self.default.to_dict(),
            "geometries": {k: v.to_dict() for k, v in self.per_geometry.items()},
            **({} if self.texture is None else {"texture": self.texture.to_dict()}),
        }


def _observed(de00: NDArray | list, dLCH: NDArray) -> NDArray[np.float64]:
    """ΔE00 and |ΔL*|, |ΔC*|, |ΔH*| side by side ``[..., geometry, 4]``, as the limits."""
    de00 = np.asarray(de00, dtype=float)
    return np.concatenate([de00[..., None], np.abs(np.asarray(dLCH, dtype=float))], axis=-1)


_NEAR_SPECULAR = ("15as-15", "15as15", "45as-15", "45as15")

REFINISH_TEXTURE = TextureLimit(G=1.0, SG=0.5)
"""The texture limits of the ``refinish`` tolerance, on flakelab's reading scales
(:mod:`flakelab.texture.readings`; no instrument publishes its own). About 2.5 times the
largest differences between a factory and a shop spray-out of one formulation in the
generated world, each read once (99th percentiles |ΔG| 0.41, |ΔSG| 0.18), and 12–13 times
the shipped model's texture error on generated cases (mean |ΔG| 0.08, |ΔSG| 0.04): a recipe
fails on texture for its flakes, not for noise (``python benchmarks/texture_tolerance.py``).
Sparkle intensity is left to SG: under a light that shows a coating few glints, Si is the
mean of those few, and two readings of one panel differ by 4 to 5 (99th percentile); SG
weighs each light by √(Sa·Si), so it stays steady."""

TOLERANCE_PRESETS: dict[str, Tolerance] = {
    t.name: t
    for t in (
        Tolerance(
            "de00-1.0",
            Limit(de00=1.0),
            description="ΔE00 ≤ 1.0 at every geometry (the matching harness's success criterion).",
        ),
        Tolerance(
            "refinish",
            Limit(de00=1.0),
            {**{g: Limit(de00=1.5) for g in _NEAR_SPECULAR}, "45as25": Limit(de00=1.2)},
            description="flakelab's body-shop default: ΔE00 1.0, widened to 1.5 near specular "
            "and 1.2 at 45as25 where flake sparkle makes readings less repeatable; texture "
            "|ΔG| ≤ 1.0, |ΔSG| ≤ 0.5. Not any OEM's specification.",
            texture=REFINISH_TEXTURE,
        ),
        Tolerance(
            "components",
            Limit(dL=1.0, dC=0.8, dH=0.6),
            {g: Limit(dL=1.5, dC=1.2, dH=0.9) for g in _NEAR_SPECULAR},
            description="|ΔL*| ≤ 1.0, |ΔC*| ≤ 0.8, |ΔH*| ≤ 0.6, × 1.5 near specular.",
        ),
    )
}
"""Named tolerances shipped with flakelab; user tolerances load from TOML or JSON files."""


def tolerance_preset(name: str) -> Tolerance:
    if name not in TOLERANCE_PRESETS:
        raise ValueError(f"expected a tolerance among {', '.join(TOLERANCE_PRESETS)}, got {name!r}")
    return TOLERANCE_PRESETS[name]


def failing_geometries(geometries: Sequence[str], passed: ArrayLike) -> list[str]:
    """The geometries whose entry of ``passed`` (as :meth:`Tolerance.judge` gives it) is false."""
    return [g for g, ok in zip(geometries, np.asarray(passed), strict=True) if not ok]


def failures(geometries: list[str], texture: list[str]) -> list[str]:
    """What fails a tolerance, as reports name it: the geometries, then ``texture G``…"""
    return list(geometries) + [f"texture {reading}" for reading in texture]


def over_limit(shares: Mapping[str, float]) -> list[str]:
    """The names whose share of their limit is above 1: what fails."""
    return [name for name, share in shares.items() if share > 1]
