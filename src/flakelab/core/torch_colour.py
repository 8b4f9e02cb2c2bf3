"""Differentiable colour for the optimiser, and the exact scores the colorist sees.

The optimiser needs gradients, which colour-science (numpy) does not give; so reflectance →
XYZ uses the same ASTM E308 weight matrix as :mod:`flakelab.core.colorimetry` and XYZ → CIELAB
its defining formula (CIE 15), in torch. The loss is CIE94's weighting of ΔL*, ΔC*, ΔH*, a
smooth stand-in for CIEDE2000; every number reported is CIEDE2000 from colour-science.
"""

from __future__ import annotations

import numpy as np
import torch

from flakelab.core.colorimetry import D65_10, Conditions, tristimulus_weights, white_point
from flakelab.core.difference import BLACK_TRISTIMULUS, METAMERISM_ILLUMINANTS

__all__ = ["TorchColour", "TorchMetamerism"]

_EPSILON = 216 / 24389
_KAPPA = 24389 / 27


_F_TO_LAB = ((0.0, 500.0, 0.0), (116.0, -500.0, 200.0), (0.0, 0.0, -200.0))
"""L* = 116 f(Y) − 16, a* = 500 (f(X) − f(Y)), b* = 200 (f(Y) − f(Z)) as one matrix on
(f(X), f(Y), f(Z)): a product instead of a dozen element-wise steps, which matters to the
optimiser's backward pass (CIE 15:2018 eq. 8.1)."""


def _weights_over_white(conditions: Conditions) -> np.ndarray:
    """The ASTM E308 weights ``[31, 3]`` with the white point divided in."""
    return np.array(tristimulus_weights(conditions=conditions)) / np.asarray(
        white_point(conditions=conditions), float
    )


class TorchColour:
    """CIELAB of reflectance tensors ``[..., 31]`` under fixed conditions."""

    def __init__(
        self,
        conditions: Conditions = D65_10,
        dtype: torch.dtype = torch.float64,
        device: torch.device | str = "cpu",
    ) -> None:
        # the white point divided in once: t = R · (W / white)
        self.weights = torch.as_tensor(_weights_over_white(conditions), dtype=dtype, device=device)
        self.f_to_lab = torch.as_tensor(_F_TO_LAB, dtype=dtype, device=device)
        self.lab_offset = torch.as_tensor((-16.0, 0.0, 0.0), dtype=dtype, device=device)

    def lab(self, R: torch.Tensor) -> torch.Tensor:
        return self.lab_of_ratios(R.to(self.weights.dtype) @ self.weights)

    def lab_of_ratios(self, t: torch.Tensor) -> torch.Tensor:
        """CIELAB ``[..., 3]`` of tristimulus values over the white's, ``t = XYZ / XYZ_n``."""
        f = torch.where(
            t > _EPSILON, torch.clamp(t, min=_EPSILON) ** (1 / 3), (_KAPPA * t + 16) / 116
        )
        return torch.addmm(self.lab_offset, f.reshape(-1, 3), self.f_to_lab).reshape(f.shape)

    @staticmethod
    def delta_e94(lab_ref: torch.Tensor, lab: torch.Tensor) -> torch.Tensor:
        """CIE94 (graphic arts) colour difference, smooth everywhere (a small floor under the
        square root keeps the gradient finite at a perfect match)."""
        return torch.sqrt(TorchColour.delta_e94_squared(lab_ref, lab))

    @staticmethod
    def lch_differences(
        lab_ref: torch.Tensor, lab: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """ΔL*, ΔC*ab, ΔH*ab² (clamped at 0) and the reference's C*ab, over ``[..., 3]``."""
        d = lab - lab_ref
        C1 = torch.sqrt((lab_ref[..., 1:] ** 2).sum(-1) + 1e-9)
        C2 = torch.sqrt((lab[..., 1:] ** 2).sum(-1) + 1e-9)
        dC = C2 - C1
        dH2 = torch.clamp((d[..., 1:] ** 2).sum(-1) - dC**2, min=0.0)
        return d[..., 0], dC, dH2, C1

    @staticmethod
    def delta_e94_squared(
        lab_ref: torch.Tensor,
        lab: torch.Tensor,
        kL: float = 1.0,
        kC: float = 1.0,
        kH: float = 1.0,
    ) -> torch.Tensor:
        """ΔE94² (plus the floor) with parametric factors ``kL``, ``kC``, ``kH`` (CIE 116-1995):
        what a mean-squared loss needs, without a root to undo."""
        dL, dC, dH2, C1 = TorchColour.lch_differences(lab_ref, lab)
        SC, SH = 1 + 0.045 * C1, 1 + 0.015 * C1
        return dL**2 / kL**2 + (dC / (kC * SC)) ** 2 + dH2 / (kH * SH) ** 2 + 1e-6


class TorchMetamerism(TorchColour):
    """The metamerism index of reflectance tensors against a ``standard`` ``[G, 31]`` under the
    illuminants ``tests`` (None: :data:`~flakelab.core.difference.METAMERISM_ILLUMINANTS`),
    smooth, for the optimiser: ISO 18314-4's multiplicative correction in XYZ, as
    :func:`~flakelab.core.difference.metamerism_index`, with CIE94 for CIEDE2000."""

    def __init__(
        self,
        standard: np.ndarray,
        tests: tuple[str, ...] | None = None,
        reference: Conditions = D65_10,
        dtype: torch.dtype = torch.float64,
    ) -> None:
        super().__init__(reference, dtype)
        tests = tests or METAMERISM_ILLUMINANTS
        lights = [reference] + [Conditions(t, reference.observer) for t in tests]
        # one product for every light: t = R · [W_ref | W_1 | … | W_K], each over its white
        self.all_weights = torch.as_tensor(
            np.concatenate([_weights_over_white(c) for c in lights], axis=1), dtype=dtype
        )  # [31, 3 (K + 1)]
        t = self._ratios(torch.as_tensor(standard, dtype=dtype))
        self.standard_reference = t[..., :1, :]  # [G, 1, 3]
        self.standard_test_lab = self.lab_of_ratios(t[..., 1:, :])  # [G, K, 3]
        # CIE94's weights depend on the standard's chroma only, so they are fixed once:
        # ΔE94² = ΔL² + (Δa² + Δb²) / SH² + ΔC² (1 / SC² − 1 / SH²), with ΔH² = Δa² + Δb² − ΔC²
        self.standard_chroma = torch.sqrt((self.standard_test_lab[..., 1:] ** 2).sum(-1) + 1e-9)
        SC, SH = 1 + 0.045 * self.standard_chroma, 1 + 0.015 * self.standard_chroma
        self.lab_weights = torch.stack([torch.ones_like(SH), SH**-2, SH**-2], dim=-1)
        self.chroma_weight = SC**-2 - SH**-2

    def _ratios(self, R: torch.Tensor) -> torch.Tensor:
        """``t`` of ``R[..., G, 31]`` under the reference, then each test light: ``[..., G,
        K + 1, 3]``."""
        t = R.to(self.all_weights.dtype) @ self.all_weights
        return t.reshape(*t.shape[:-1], -1, 3)

    def indices(self, R: torch.Tensor) -> torch.Tensor:
        """Smooth metamerism index ``[..., G, K]`` of ``R[..., G, 31]`` under each test
        illuminant."""
        return self.lab_and_indices(R)[1]

    def lab_and_indices(self, R: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """CIELAB ``[..., G, 3]`` of ``R[..., G, 31]`` under the reference and its smooth
        metamerism index ``[..., G, K]`` under each test illuminant, from one product and one
        CIELAB: the optimiser needs both at every step, and the reference's share of the work
        is the same."""
        t = self._ratios(R)
        reference = t[..., :1, :]
        # a sample reading black has no multiplicative correction (its 0/0 made the
        # correction of a black spray-out NaN); as difference.metamerism_indices floors it
        floor = BLACK_TRISTIMULUS / 100
        corrected = t[..., 1:, :] * (self.standard_reference / reference.clamp_min(floor))
        lab = self.lab_of_ratios(torch.cat([reference, corrected], dim=-2))
        return lab[..., 0, :], self._delta_e94(lab[..., 1:, :])

    def _delta_e94(self, lab: torch.Tensor) -> torch.Tensor:
        """:meth:`delta_e94` from the standard's CIELAB under the test illuminants, with its
        weights fixed: a third of the operations, each of which the optimiser pays for twice
        (forward and backward) at every step."""
        d = lab - self.standard_test_lab
        dC = torch.sqrt((lab[..., 1:] ** 2).sum(-1) + 1e-9) - self.standard_chroma
        return torch.sqrt((d * d * self.lab_weights).sum(-1) + dC * dC * self.chroma_weight + 1e-6)
