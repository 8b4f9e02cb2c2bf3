"""Multi-angle description and comparison of measurements: the numbers a colorist reads."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flakelab.core.colorimetry import D65_10, Conditions, Lab_to_LCh, reflectance_to_Lab
from flakelab.core.defaults import DEFAULT_TOLERANCE
from flakelab.core.difference import (
    METAMERISM_ILLUMINANTS,
    delta_E,
    delta_E_CIE2000,
    metamerism_indices,
    worst_per_light,
)
from flakelab.core.geometry import flake_angles
from flakelab.core.measurement import Measurement, recovered_note
from flakelab.core.tolerance import Tolerance, failing_geometries, over_limit, tolerance_preset

__all__ = [
    "Comparison",
    "RankedReference",
    "compare",
    "describe",
    "rank_references",
    "spread_of_readings",
    "READINGS_SPREAD_SHARE",
]

READINGS_SPREAD_SHARE = 0.5
"""A reading further than this share of the tolerance from the mean of its fellows is worth a
word: a recipe matching the mean leaves that spot at least this far off."""


def describe(measurement: Measurement, conditions: Conditions = D65_10) -> dict[str, Any]:
    """Per-geometry L*, a*, b*, C*, h, flake angles and stored-Lab agreement, as plain data."""
    lab = measurement.lab(conditions)
    lch = Lab_to_LCh(lab)
    theta_flake, theta_inc = flake_angles(measurement.geometries)
    stored_de = None
    stored = measurement.stored_lab is not None and not measurement.spectra_recovered
    if stored and measurement.stored_lab_conditions == conditions:  # recovered: 0 by design
        stored_de = delta_E_CIE2000(lab, measurement.stored_lab)
    geometries = []
    for i, g in enumerate(measurement.geometries):
        row = {
            "name": g.name,
            "L": float(lab[i, 0]),
            "a": float(lab[i, 1]),
            "b": float(lab[i, 2]),
            "C": float(lch[i, 1]),
            "h": float(lch[i, 2]),
            "theta_flake": float(theta_flake[i]),
            "theta_inc": float(theta_inc[i]),
        }
        if stored_de is not None:
            row["de00_vs_stored"] = float(stored_de[i])
        geometries.append(row)
    return {
        "sample": measurement.sample,
        "instrument": measurement.instrument,
        "measured_at": None
        if measurement.measured_at is None
        else measurement.measured_at.isoformat(),
        "conditions": str(conditions),
        "geometries": geometries,
        "flop_index": measurement.flop_index(conditions),
        "texture": dict(measurement.texture),
        "spectra_recovered": recovered_note(measurement),
    }


@dataclass(frozen=True)
class Comparison:
    """Sample against reference at their common geometries."""

    reference: Measurement
    sample: Measurement
    geometries: tuple[str, ...]
    lab_reference: NDArray[np.float64]
    lab_sample: NDArray[np.float64]
    dLCH: NDArray[np.float64]
    de00: NDArray[np.float64]
    de_other: dict[str, NDArray[np.float64]]
    passed: NDArray[np.bool_]
    limit_share: NDArray[np.float64]  # per geometry, the share of its limit (≤ 1 passes)
    tolerance: Tolerance
    conditions: Conditions
    metamerism: dict[str, NDArray[np.float64]]  # per test illuminant and geometry
    # each texture reading the tolerance bounds and both hold: |Δ| as a share of its limit
    texture_share: dict[str, float]
    # what the reports say of each measurement whose spectra were recovered from L*a*b*
    recovered: tuple[str, ...] = ()

    @property
    def failing_texture(self) -> list[str]:
        return over_limit(self.texture_share)

    @property
    def not_compared(self) -> dict[str, list[str]]:
        """Each measurement's geometries the other lacks: a verdict covers only the rest."""
        return {
            "reference": [g for g in self.reference.geometry_names if g not in self.geometries],
            "sample": [g for g in self.sample.geometry_names if g not in self.geometries],
        }

    @property
    def de00_max(self) -> float:
        return float(self.de00.max())

    @property
    def de00_mean(self) -> float:
        return float(self.de00.mean())

    @property
    def all_pass(self) -> bool:
        """Every geometry and every texture reading the tolerance bounds passes."""
        return bool(self.passed.all()) and not self.failing_texture

    def to_dict(self) -> dict[str, Any]:
        rows = [
            {
                "name": name,
                "L_reference": float(self.lab_reference[i, 0]),
                "L_sample": float(self.lab_sample[i, 0]),
                "dL": float(self.dLCH[i, 0]),
                "dC": float(self.dLCH[i, 1]),
                "dH": float(self.dLCH[i, 2]),
                "de00": float(self.de00[i]),
                **{f"de_{k}": float(v[i]) for k, v in self.de_other.items()},
                "limit_share": float(self.limit_share[i]),
                "metamerism_index": {k: float(v[i]) for k, v in self.metamerism.items()},
                "pass": bool(self.passed[i]),
            }
            for i, name in enumerate(self.geometries)
        ]
        flop_ref, flop_smp = (
            self.reference.flop_index(self.conditions),
            self.sample.flop_index(self.conditions),
        )
        texture = {
            k: self.sample.texture[k] - self.reference.texture[k]
            for k in self.reference.texture
            if k in self.sample.texture
        }
        shares = dict(zip(self.geometries, self.limit_share.tolist(), strict=True))
        shares |= self.texture_share
        limit_share_at = max(shares, key=shares.__getitem__)  # a geometry, or a texture reading
        return {
            "reference": self.reference.sample,
            "sample": self.sample.sample,
            "conditions": str(self.conditions),
            "tolerance": self.tolerance.name,
            "geometries": rows,
            "not_compared": self.not_compared,
            "de00_max": self.de00_max,
            "de00_max_at": self.geometries[int(np.argmax(self.de00))],
            "de00_mean": self.de00_mean,
            "limit_share_max": shares[limit_share_at],
            "limit_share_at": limit_share_at,
            "metamerism_index_max": worst_per_light(self.metamerism),
            "pass": self.all_pass,
            "failing_geometries": failing_geometries(self.geometries, self.passed),
            "flop_index_reference": flop_ref,
            "flop_index_sample": flop_smp,
            "texture_difference": texture,
            "texture_limit_share": self.texture_share,
            "failing_texture": self.failing_texture,
            "spectra_recovered": list(self.recovered),
        }


def compare(
    reference: Measurement,
    sample: Measurement,
    tolerance: Tolerance | str = DEFAULT_TOLERANCE,
    *,
    conditions: Conditions = D65_10,
    also: tuple[str, ...] = ("CIE 1976", "CMC", "DIN99", "CAM16-UCS"),
    lights: tuple[str, ...] = METAMERISM_ILLUMINANTS,
) -> Comparison:
    """Compare ``sample`` with ``reference`` at every geometry both hold; the metamerism index
    from ``conditions`` to each of the test ``lights``, where both measured their spectra (one
    recovered from L*a*b* is a metamer of many: an index against it means nothing).

    Raises
    ------
    ValueError
        When the two measurements share no geometry.
    """
    tolerance = tolerance_preset(tolerance) if isinstance(tolerance, str) else tolerance
    common = [g for g in reference.geometry_names if g in set(sample.geometry_names)]
    if not common:
        raise ValueError(
            f"{reference.sample} and {sample.sample} share no geometry "
            f"({', '.join(reference.geometry_names)} vs {', '.join(sample.geometry_names)})"
        )
    ref, smp = reference.select(common), sample.select(common)
    lab_ref, lab_smp = ref.lab(conditions), smp.lab(conditions)
    de00, dLCH, passed = tolerance.judge(common, lab_ref, lab_smp)
    recovered = tuple(note for m in (reference, sample) if (note := recovered_note(m)))
    metamerism = {} if recovered else metamerism_indices(
        ref.storage_spectra(common), smp.storage_spectra(common), conditions, lights
    )  # fmt: skip
    return Comparison(
        reference=reference,
        sample=sample,
        geometries=tuple(common),
        lab_reference=lab_ref,
        lab_sample=lab_smp,
        dLCH=dLCH,
        de00=de00,
        de_other={m: delta_E(lab_ref, lab_smp, method=m) for m in also},
        passed=passed,
        limit_share=tolerance.share_of_limit(common, de00=de00, dLCH=dLCH),
        tolerance=tolerance,
        conditions=conditions,
        metamerism=metamerism,
        texture_share=tolerance.texture_share(reference.texture, sample.texture),
        recovered=recovered,
    )


@dataclass(frozen=True)
class RankedReference:
    """A ``reference`` (a standard, a variant chip) and how far a sample lies from it, as
    :func:`compare` judges them: ΔE00 and the share of the tolerance's limit per geometry
    both hold (``geometries``), the share of each texture reading the tolerance bounds, and
    whether every one passes."""

    reference: Measurement
    geometries: tuple[str, ...]
    de00: NDArray[np.float64]
    limit_share: NDArray[np.float64]
    texture_share: dict[str, float]
    passes: bool

    @property
    def shares(self) -> dict[str, float]:
        """The share of the limit at each geometry, then each texture reading."""
        return dict(zip(self.geometries, self.limit_share.tolist(), strict=True)) | dict(
            self.texture_share
        )

    @property
    def share(self) -> float:
        """The worst share of the limit: what ranks the references."""
        return max(self.shares.values())

    def to_dict(self) -> dict[str, Any]:
        worst = int(np.argmax(self.de00))
        shares = self.shares
        return {
            "reference": self.reference.sample,
            "de00_max": float(self.de00[worst]),
            "geometry": self.geometries[worst],
            "limit_share_max": self.share,
            "limit_share_at": max(shares, key=shares.__getitem__),
            "pass": self.passes,
            "geometries": list(self.geometries),
        }


def rank_references(
    references: Sequence[Measurement],
    sample: Measurement,
    tolerance: Tolerance | str = DEFAULT_TOLERANCE,
    *,
    conditions: Conditions = D65_10,
) -> list[RankedReference]:
    """The ``references`` that share a geometry with ``sample``, nearest first: by the worst
    share of ``tolerance``'s limit over the geometries each shares with it and the texture
    readings the tolerance bounds, as :func:`compare` judges one pair (the reference the
    standard). References read at the same geometries on one wavelength grid (a chip deck's)
    are judged together."""
    tolerance = tolerance_preset(tolerance) if isinstance(tolerance, str) else tolerance
    held = set(sample.geometry_names)
    groups: dict[tuple, list[int]] = {}
    for i, ref in enumerate(references):
        common = tuple(g for g in ref.geometry_names if g in held)
        if common:
            groups.setdefault((common, tuple(ref.wavelengths)), []).append(i)
    ranked = []
    for (common, wavelengths), members in groups.items():
        spectra = np.stack([references[i].select(common).reflectance for i in members])
        lab_ref = reflectance_to_Lab(spectra, np.array(wavelengths), conditions)
        de00, dLCH, passed = tolerance.judge(common, lab_ref, sample.select(common).lab(conditions))
        shares = tolerance.share_of_limit(common, de00=de00, dLCH=dLCH)
        for k, i in enumerate(members):
            texture = tolerance.texture_share(references[i].texture, sample.texture)
            ok = bool(passed[k].all()) and not over_limit(texture)
            ranked.append(RankedReference(references[i], common, de00[k], shares[k], texture, ok))
    return sorted(ranked, key=lambda r: r.share)


def spread_of_readings(
    readings: list[Measurement],
    mean: Measurement,
    tolerance: Tolerance,
    conditions: Conditions = D65_10,
) -> dict[str, Any]:
    """How far each of several readings of one surface lies from their ``mean``: the largest
    ΔE00 over the readings at each geometry, and the largest share of ``tolerance``'s limit,
    with the reading that reaches it. Readings of one spot differ by the instrument's
    repeatability (ΔE00 0.02–0.10); spots of one car differ more where its paint is uneven."""
    geometries = list(mean.geometry_names)
    lab_mean = mean.lab(conditions)
    de00, shares = [], []
    for reading in readings:
        lab = reading.select(geometries).lab(conditions)
        d, dLCH, _ = tolerance.judge(geometries, lab_mean, lab)
        de00.append(d)
        shares.append(tolerance.share_of_limit(geometries, de00=d, dLCH=dLCH).max())
    furthest = int(np.argmax(shares))
    return {
        "readings": [r.sample for r in readings],
        "geometries": geometries,
        "de00_from_mean_max": np.max(de00, axis=0).round(3).tolist(),
        "limit_share_max": float(shares[furthest]),
        "furthest": readings[furthest].sample,
    }
