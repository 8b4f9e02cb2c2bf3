"""Judging candidate recipes with the numbers the colorist sees (DESIGN.md §6, the search's
last stage): CIEDE2000 per geometry, texture differences, the tolerance, a small penalty per
toner, the metamerism index; and the candidates and the result the search returns.

Recipes outside the learned model's support rank after every one inside it
(:mod:`flakelab.match.support`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray

from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import (
    delta_E,
    is_metamer,
    metamerism_indices,
    worst_per_light,
)
from flakelab.core.geometry import parse_geometries
from flakelab.core.measurement import TEXTURE_READINGS, Measurement
from flakelab.core.spectra import WAVELENGTHS
from flakelab.core.tolerance import (
    failing_geometries,
    failures,
    over_limit,
)
from flakelab.core.units import check_mass_fractions
from flakelab.match.forward import model_name_for
from flakelab.match.support import outside_support

__all__ = [
    "Assessment",
    "Candidate",
    "MatchResult",
    "assess",
    "evaluate_recipes",
    "geometry_rows",
    "judge",
    "model_spread",
    "recipe_vector",
]


def geometry_rows(geometries, lab: NDArray, dLCH: NDArray, de00: NDArray) -> dict[str, dict]:
    """A report's numbers per geometry: predicted L*a*b* ``lab[G, 3]``, its ΔL*, ΔC*, ΔH*
    ``dLCH[G, 3]`` and ΔE00 ``de00[G]`` from the target, rounded."""
    return {
        g: {
            "L": round(float(lab[i, 0]), 3),
            "a": round(float(lab[i, 1]), 3),
            "b": round(float(lab[i, 2]), 3),
            "dL": round(float(dLCH[i, 0]), 3),
            "dC": round(float(dLCH[i, 1]), 3),
            "dH": round(float(dLCH[i, 2]), 3),
            "dE00": round(float(de00[i]), 3),
        }
        for i, g in enumerate(geometries)
    }


@dataclass
class Candidate:
    """One recipe with its predicted appearance and its differences to the target."""

    fractions: dict[str, float]
    geometries: tuple[str, ...]
    reflectance: NDArray
    lab: NDArray
    target_lab: NDArray
    de00: NDArray
    dLCH: NDArray
    texture: dict[str, float]
    texture_delta: dict[str, float]
    passes: bool  # at every geometry and every texture reading the tolerance bounds
    failing: list[str]
    model: str
    novel: list[str]
    score: float
    limit_share: NDArray  # each geometry's share of the tolerance's limit (≤ 1 passes)
    in_support: bool = True
    spread: NDArray | None = None  # an ensemble's disagreement, ΔE00 per geometry
    # the metamerism index against the target per test illuminant and geometry (ISO 18314-4)
    metamerism: dict[str, NDArray] = field(default_factory=dict)
    # each texture reading the tolerance bounds: |Δ| as a share of its limit (≤ 1 passes)
    texture_share: dict[str, float] = field(default_factory=dict)
    # with the shop's habits: whether this recipe was aimed off for them (None: no habits)
    aimed_off: bool | None = None

    @property
    def failing_texture(self) -> list[str]:
        return over_limit(self.texture_share)

    def failures(self) -> list[str]:
        return failures(self.failing, self.failing_texture)

    def as_measurement(self, sample: str) -> Measurement:
        """The candidate's predicted reading, as the instrument would give it (to render, plot
        or save), with the model that predicted it in its metadata."""
        return Measurement(
            sample=sample,
            geometries=parse_geometries(self.geometries),
            wavelengths=WAVELENGTHS,
            reflectance=np.asarray(self.reflectance, float),
            texture=self.texture,
            metadata={"predicted by": self.model},
        )

    def to_dict(self) -> dict[str, Any]:
        rows = geometry_rows(self.geometries, self.lab, self.dLCH, self.de00)
        if self.spread is not None:
            for row, spread in zip(rows.values(), self.spread, strict=True):
                row["model_spread"] = round(float(spread), 3)
        return {
            "recipe": {k: round(v, 6) for k, v in self.fractions.items()},
            "model": self.model,
            "novel_toners": self.novel,
            "in_model_support": self.in_support,
            "passes": self.passes,
            "failing_geometries": self.failing,
            "failing_texture": self.failing_texture,
            "de00_max": float(self.de00.max()),
            "de00_mean": float(self.de00.mean()),
            "limit_share_max": round(
                max([self.limit_share.max(), *self.texture_share.values()]), 3
            ),
            "score": round(self.score, 4),
            "geometries": rows,
            "texture_delta": {k: round(v, 3) for k, v in self.texture_delta.items()},
            "texture_limit_share": {k: round(v, 3) for k, v in self.texture_share.items()},
            "metamerism_index": {k: v.round(3).tolist() for k, v in self.metamerism.items()},
            "metamerism_index_max": worst_per_light(self.metamerism),
            "metamer": is_metamer(self.metamerism),
            "aimed_off": self.aimed_off,
        }


@dataclass
class MatchResult:
    target: str
    geometries: tuple[str, ...]
    candidates: list[Candidate]
    tolerance: str
    seconds: float
    subsets_tried: int
    notes: list[str] = field(default_factory=list)
    texture_limits: dict[str, float] = field(default_factory=dict)  # the tolerance's, if any
    model_id: str = ""  # which model exactly (name and fingerprint): an adapted one keeps its name

    def to_dict(self) -> dict[str, Any]:
        return {
            "target": self.target,
            "model_id": self.model_id,
            "geometries": list(self.geometries),
            "tolerance": self.tolerance,
            "texture_limits": self.texture_limits,
            "seconds": round(self.seconds, 3),
            "subsets_tried": self.subsets_tried,
            "notes": self.notes,
            "candidates": [c.to_dict() for c in self.candidates],
        }


def recipe_vector(forward, fractions: dict[str, float]) -> NDArray:
    """A recipe's fractions ``{toner: share}`` as a vector over the model's toners."""
    return np.array([fractions.get(n, 0.0) for n in forward.toners])


def evaluate_recipes(forward, x: NDArray) -> tuple[NDArray, NDArray | None]:
    """``forward``'s reflectance ``[N, G, 31]`` and texture readings of recipes ``x[N, T]``,
    mass fractions (refused otherwise), in float64."""
    check_mass_fractions(x)
    with torch.no_grad():
        R, texture = forward(torch.as_tensor(x, dtype=forward.dtype))
    return R.double().numpy(), None if texture is None else texture.double().numpy()


def model_spread(forward, x: NDArray, lab: NDArray) -> NDArray | None:
    """How far an ensemble's members disagree on recipes ``x[N, T]`` predicted at ``lab``
    ``[N, G, 3]``: the root mean square over members of each member's ΔE00 from ``lab``,
    ``[N, G]``; None for a single network, which cannot say."""
    if getattr(forward, "members", 1) < 2:
        return None
    members = reflectance_to_Lab(forward.member_reflectance(x))
    return np.sqrt(np.mean(delta_E(lab[None], members) ** 2, axis=0))


def recipe_spread(forward, x: NDArray) -> NDArray | None:
    """:func:`model_spread` of one recipe ``x[T]`` about ``forward``'s own prediction: ΔE00
    per geometry ``[G]`` (of recipes ``x[N, T]``, in one pass: ``[N, G]``); None for a
    single network."""
    if getattr(forward, "members", 1) < 2:
        return None
    rows = np.atleast_2d(x)
    R = evaluate_recipes(forward, rows)[0]
    spread = model_spread(forward, rows, reflectance_to_Lab(R))
    return spread if np.ndim(x) == 2 else spread[0]


@dataclass(frozen=True)
class Assessment:
    """Recipes ``x[N, T]`` as the judge sees them: predictions, differences from the target
    per geometry, shares of the tolerance's limits, and the score that ranks them."""

    R: NDArray
    texture: NDArray | None
    target_lab: NDArray
    lab: NDArray
    de00: NDArray
    dLCH: NDArray
    passed: NDArray
    share: NDArray
    texture_share: NDArray
    limits: dict[str, float]
    has_texture: bool
    metamerism: dict[str, NDArray]
    score: NDArray

    def rows(self, rows: NDArray) -> Assessment:
        """The assessment of the recipes ``x[rows]`` alone."""
        return replace(
            self,
            texture=None if self.texture is None else self.texture[rows],
            **{k: getattr(self, k)[rows] for k in _ROW_FIELDS},
            metamerism={light: index[rows] for light, index in self.metamerism.items()},
        )


_ROW_FIELDS = ("R", "lab", "de00", "dLCH", "passed", "share", "texture_share", "score")
"""The fields of :class:`Assessment` that hold one row per recipe in every case."""


def assess(
    forward, x, spectra, texture, tolerance, settings, offset=None, predicted=None
) -> Assessment:
    """Predict and score recipes ``x[N, T]``; ``offset[N, G, 3]`` is added to the predicted
    L*a*b* (the shop's habits); ``predicted``, where given, is their
    :func:`evaluate_recipes` already."""
    R, tex = predicted or evaluate_recipes(forward, x)
    target_lab = reflectance_to_Lab(spectra)
    lab = reflectance_to_Lab(R) + (0.0 if offset is None else offset)
    de00, dlch, passed = tolerance.judge(forward.geometries, target_lab[None], lab)
    share = tolerance.share_of_limit(forward.geometries, de00=de00, dLCH=dlch)
    has_texture = tex is not None and texture and all(k in texture for k in TEXTURE_READINGS)
    # [N, judged readings]: a texture limit ranks as one more geometry's would
    limits = tolerance.texture_limits() if has_texture else {}
    texture_share = np.zeros((len(x), len(limits)))
    if has_texture:
        target_tex = np.array([texture[k] for k in TEXTURE_READINGS])
        judged = [TEXTURE_READINGS.index(k) for k in limits]
        texture_share = np.abs(tex - target_tex)[:, judged] / np.array(list(limits.values()))
    # in the objective's units (``share_unit``), against which the penalties are set
    worst = np.max(np.concatenate([share, texture_share], axis=1), axis=1)
    score = (worst + share.mean(1)) * tolerance.share_unit(forward.geometries)
    score = score + settings.toner_penalty * (x > 0).sum(1)
    # [N, G] per test illuminant
    metamerism = metamerism_indices(spectra, R, tests=settings.lights)
    if settings.metamerism:
        score = score + settings.metamerism * np.mean(list(metamerism.values()), axis=(0, 2))
    if has_texture:
        score = score + settings.texture_weight * np.abs(tex[:, -2:] - target_tex[-2:]).sum(1)
    return Assessment(
        R, tex, target_lab, lab, de00, dlch, passed, share, texture_share, limits,
        bool(has_texture), metamerism, score,
    )  # fmt: skip


def judge(
    forward, x, effect, spectra, texture, tolerance, settings, aimed=None, assessed=None
) -> list[Candidate]:
    """The best distinct candidates of ``x[N, T]``, by score; recipes outside the model's
    support rank after every one inside it. ``assessed`` is their :func:`assess`, where
    it is made already (with the shop's habits: ``aimed[N]`` marks the recipes aimed off
    for them)."""
    a = assessed or assess(forward, x, spectra, texture, tolerance, settings)
    outside = outside_support(x, effect, settings)
    chosen, seen = [], set()
    for row in np.lexsort((a.score, outside)):
        key = tuple(np.flatnonzero(x[row] > 0))
        if key in seen:
            continue
        seen.add(key)
        chosen.append(row)
        if len(chosen) == settings.candidates:
            break
    rows = np.array(chosen, int)
    spread = model_spread(forward, x[rows], reflectance_to_Lab(a.R[rows]))
    out = []
    for i, row in enumerate(chosen):
        failing = failing_geometries(forward.geometries, a.passed[row])
        fractions = {
            forward.toners[j]: float(x[row, j]) for j in np.argsort(-x[row]) if x[row, j] > 0
        }
        out.append(
            Candidate(
                fractions=fractions,
                geometries=tuple(forward.geometries),
                reflectance=a.R[row],
                lab=a.lab[row],
                target_lab=a.target_lab,
                de00=a.de00[row],
                dLCH=a.dLCH[row],
                texture={}
                if a.texture is None
                else dict(zip(TEXTURE_READINGS, a.texture[row].tolist(), strict=True)),
                texture_delta={}
                if not a.has_texture
                else {
                    k: float(a.texture[row, i] - texture[k]) for i, k in enumerate(TEXTURE_READINGS)
                },
                passes=not failing and bool(np.all(a.texture_share[row] <= 1)),
                failing=failing,
                model=model_name_for(forward, fractions),
                novel=[n for n in fractions if n in forward.novel],
                score=float(a.score[row]),
                in_support=not outside[row],
                spread=None if spread is None else spread[i],
                limit_share=a.share[row],
                metamerism={light: index[row] for light, index in a.metamerism.items()},
                texture_share=dict(zip(a.limits, a.texture_share[row].tolist(), strict=True)),
                aimed_off=None if aimed is None else bool(aimed[row]),
            )
        )
    return out
