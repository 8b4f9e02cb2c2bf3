"""The colour objective that the search and the correction minimise, set by the tolerance.

A recipe is judged by the colorist's tolerance: per geometry, ΔE00 with its kL, kC, kH
against that geometry's limit, or |ΔL*|, |ΔC*|, |ΔH*| against theirs
(:meth:`~flakelab.core.tolerance.Tolerance.share_of_limit`). The optimiser needs the same
judgement, smooth: per geometry, ΔE94 with the tolerance's kL, kC, kH (CIEDE2000's own
weighting, without its discontinuities) as a share of the geometry's ΔE00 limit; where
components are bounded, the root sum of squares of each component's share of its limit
(:data:`COMPONENT_NORM`); the larger of the two where both are. Over
geometries: the mean plus half the worst, times the tightest geometry's ΔE00 limit
(:meth:`~flakelab.core.tolerance.Tolerance.share_unit`). The search's regularisers and
thresholds (sparsity, texture, how much a toner must matter) are in those units: without
that factor a tolerance of ΔE00 ≤ 2.5 shrank the colour term 2.5 times against them, and a
bronze metallic that the search brings to 1.23 under ΔE00 ≤ 1.0 was left at 1.53 (stop 55;
``tests/test_match.py -k swap_stage_finds``).

With ΔE00 ≤ 1.0 at every geometry (the preset ``de00-1.0``, the harness's criterion) this is
the plain multi-angle ΔE94 that the search used before tolerances steered it, to the last
bit. A tolerance wider near specular lets the optimiser spend its error there, and one with
kL = 2 lets lightness go.

The search also weighs each recipe's mean metamerism index against the target
(``MatchSettings.metamerism`` per ΔE; ISO 18314-4 under A, F11 and LED-B3, smooth as CIE94:
:meth:`MatchObjective.metamerism_loss`) beside its daylight colour, so that it prefers the
car's own pigments to a metamer of others, which would match in daylight and not under the
shop's tubes. In the harness (200 + 50 targets, seed 4242, the shipped ensemble) weights
0 / 0.3 / 1 / 3 passed first time 0.595 / 0.575 / 0.605 / 0.605, after one correction
0.855 / 0.835 / 0.86 / 0.875 and with a new toner 0.42 / 0.46 / 0.54 / 0.48, and left the
first spray-out's worst metamerism index at a median of 0.49 / 0.40 / 0.34 / 0.29, against
0.16 for the hidden formula itself sprayed (1 again after the smooth index was regrouped,
float32's last digits moving some recipes: 0.59, 0.855, 0.52, 0.35). Weight 1 makes a match
about a fifth slower (``benchmarks/metamerism_cost.py``: medians 0.84 s against 0.69 s on 15
targets; a step of the objective 0.83 ms against 0.53 ms for 20 recipes).

The optimiser takes that term afresh every ``MatchSettings.metamerism_every`` steps (4) and
follows its tangent between (:class:`MetamerismTangent`); rows are ranked, and candidates
judged, by the exact index. Same harness, one run each (2026-11-26,
``benchmarks/match_variants.py … "metamerism_every=1"``): five-angle, every step / every
4th passed 0.60 / 0.58 first time, 0.87 / 0.865 after one correction, 0.54 / 0.60 with a new
toner, first spray-out's index median 0.34 / 0.36, latency p50 0.79 / 0.72 s, p95 1.79 /
1.81 s; MA-T12 (every 8th too) 0.51 / 0.505 / 0.485, 0.82 / 0.83 / 0.815, 0.52 / 0.48 / 0.56,
p50 1.04 / 0.95 / 0.91 s, p95 2.74 / 2.72 / 2.76 s. The pass rates are within their noise
(about 0.035 on 200 targets, 0.07 on 50). The slow tail was the search through new toners'
physics, which this tangent does not touch; :class:`~flakelab.match.forward.HeldJacobian`
does (MA-T12 p95 2.14 s against 3.19 s, the same day, one run).
"""

from __future__ import annotations

import numpy as np
import torch

from flakelab.core.tolerance import Tolerance, tolerance_preset
from flakelab.core.torch_colour import TorchColour, TorchMetamerism

__all__ = ["MatchObjective", "MetamerismTangent", "OBJECTIVE_DEFAULT"]

OBJECTIVE_DEFAULT = "de00-1.0"
"""The tolerance that the search, the correction and the harness
(:func:`~flakelab.match.evaluate.evaluate_matching`) aim at and judge by when given none:
issue 5's ΔE00 ≤ 1.0 at every geometry."""

COMPONENT_NORM = 2
"""The p of the p-norm over the components' shares of their limits. The verdict takes the
largest share; p = 2 instead seeks the centre of the box of limits, where a spray's own
scatter is least likely to leave it. Sprayed in the harness's shop world
(``benchmarks/tolerance_aim.py``, 60 targets × 6 sprays, the ``components`` preset), p = 2
passed −0.036 ± 0.029 (seed 4242) and +0.056 ± 0.044 (seed 4343) against aiming at ΔE00,
p = 8, nearly the largest, −0.058 ± 0.034 and +0.017 ± 0.037: noise, both. Where no recipe
can reach the target p = 8 lowers the worst share further (a white and phthalo blue for a
target dulled by burnt sienna: 10.2 against 12.0 with p = 2 and 15.8 aimed at ΔE00), but
no spray passes there either way."""


class MatchObjective(TorchColour):
    """CIELAB of reflectance tensors and, over ``geometries``, how far recipes are from
    passing ``tolerance`` (default :data:`OBJECTIVE_DEFAULT`); with the target's ``spectra``
    ``[G, 31]`` and a ``metamerism`` weight, how metameric recipes are to it under the test
    ``lights`` (default :data:`~flakelab.core.difference.METAMERISM_ILLUMINANTS`)."""

    def __init__(
        self,
        geometries: list[str] | tuple,
        tolerance: Tolerance | None = None,
        dtype: torch.dtype = torch.float64,
        spectra=None,
        metamerism: float = 0.0,
        lights: tuple[str, ...] | None = None,
    ) -> None:
        super().__init__(dtype=dtype)
        self.metamerism_weight = metamerism
        self.metamerism = (
            TorchMetamerism(spectra, lights, dtype=dtype)
            if spectra is not None and metamerism
            else None
        )
        tolerance = tolerance or tolerance_preset(OBJECTIVE_DEFAULT)
        self.tolerance = tolerance
        self.k = (tolerance.kL, tolerance.kC, tolerance.kH)
        self.unit = tolerance.share_unit(geometries)
        # 1 / limit, 0 where a quantity is unchecked
        scale = 1.0 / tolerance.bounds(geometries)
        self.de00_scale = torch.as_tensor(scale[:, 0], dtype=dtype)
        components = scale[:, 1:]
        self.component_scale = (
            torch.as_tensor(components, dtype=dtype) if np.any(components) else None
        )

    def shares_of_limit(self, target_lab: torch.Tensor, lab: torch.Tensor) -> torch.Tensor:
        """Smooth share of the limit ``[..., G]`` of recipes ``lab[..., G, 3]`` against
        ``target_lab[G, 3]``: ≤ 1 about where the tolerance passes."""
        share = torch.sqrt(self.delta_e94_squared(target_lab, lab, *self.k)) * self.de00_scale
        if self.component_scale is None:
            return share
        dL, dC, dH2, _ = self.lch_differences(target_lab, lab)
        s, p = self.component_scale, COMPONENT_NORM
        components = (
            (dL * s[:, 0]) ** p + (dC * s[:, 1]) ** p + (dH2 * s[:, 2] ** 2) ** (p / 2) + 1e-6
        ) ** (1 / p)
        return torch.maximum(share, components)

    def loss(self, target_lab: torch.Tensor, lab: torch.Tensor) -> torch.Tensor:
        """The objective over geometries ``[N]`` of recipes ``lab[N, G, 3]`` against
        ``target_lab[G, 3]``: the mean share of the limit plus half the worst, in the
        tightest geometry's ΔE00 (:meth:`~flakelab.core.tolerance.Tolerance.share_unit`)."""
        share = self.shares_of_limit(target_lab[None], lab)
        return (share.mean(dim=1) + 0.5 * share.max(dim=1).values) * self.unit

    def recipe_loss(self, target_lab: torch.Tensor, R: torch.Tensor) -> torch.Tensor:
        """The objective ``[N]`` of recipes with reflectances ``R[N, G, 31]``: :meth:`loss`
        of their colour against ``target_lab[G, 3]``, plus :meth:`metamerism_loss` where
        the objective weighs it (both from one product with the weights)."""
        if self.metamerism is None:
            return self.loss(target_lab, self.lab(R))
        lab, metamerism = self.lab_and_metamerism_loss(R)
        return self.loss(target_lab, lab) + metamerism

    def lab_and_metamerism_loss(self, R: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """CIELAB ``[N, G, 3]`` of reflectances ``R[N, G, 31]`` and their
        :meth:`metamerism_loss` ``[N]``, from one product with the weights."""
        lab, indices = self.metamerism.lab_and_indices(R)
        return lab, self._weighed_mean(indices)

    def metamerism_loss(self, R: torch.Tensor) -> torch.Tensor:
        """The weighed mean metamerism index ``[N]`` (ΔE, over test illuminants and
        geometries) of recipes ``R[N, G, 31]`` against the target's spectra."""
        return self._weighed_mean(self.metamerism.indices(R))

    def _weighed_mean(self, indices: torch.Tensor) -> torch.Tensor:
        return self.metamerism_weight * indices.mean(dim=(-2, -1))

    def colour_loss(self, target_lab: torch.Tensor, R: torch.Tensor) -> torch.Tensor:
        """:meth:`loss` of the daylight colour alone of reflectances ``R[N, G, 31]``."""
        return self.loss(target_lab, self.lab(R))


class MetamerismTangent:
    """The objective's metamerism term for an optimiser, taken afresh every ``every`` calls
    and followed along its tangent between: ``m(R₀) + ∇m(R₀)·(R − R₀)``.

    The exact term costs an optimiser step as much again as the daylight colour (three more
    lights in CIELAB, and their ΔE94, forward and backward), and at twelve geometries it made
    a match two fifths slower; its gradient turns slowly along a search, and Adam needs only
    its direction. The search ranks its rows, after each phase, by the exact term."""

    def __init__(self, objective: MatchObjective, every: int) -> None:
        self.objective, self.every, self.calls = objective, every, 0
        self.offset = self.slope = None

    def __call__(self, R: torch.Tensor) -> torch.Tensor:
        """The term ``[N]`` at reflectances ``R[N, G, 31]``."""
        if self.calls % self.every == 0:
            self._retake(R.detach())
        self.calls += 1
        return self.offset + (self.slope * R).sum(dim=(-2, -1))

    def _retake(self, R: torch.Tensor) -> None:
        with torch.enable_grad():
            R = R.requires_grad_(True)
            value = self.objective.metamerism_loss(R)
            (self.slope,) = torch.autograd.grad(value.sum(), R)
        # m(R₀) − ∇m(R₀)·R₀, so that a step costs one product and one sum
        self.offset = value.detach() - (self.slope * R.detach()).sum(dim=(-2, -1))
