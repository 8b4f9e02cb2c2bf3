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

__all__ = ["TorchColour"]

_EPSILON = 216 / 24389
_KAPPA = 24389 / 27


class TorchColour:
    """CIELAB of reflectance tensors ``[..., 31]`` under fixed conditions."""

    def __init__(self, conditions: Conditions = D65_10, dtype: torch.dtype = torch.float64) -> None:
        weights = np.array(tristimulus_weights(conditions=conditions))
        self.weights = torch.as_tensor(weights, dtype=dtype)
        self.white = torch.as_tensor(white_point(conditions=conditions), dtype=dtype)

    def lab(self, R: torch.Tensor) -> torch.Tensor:
        t = (R.to(self.weights.dtype) @ self.weights) / self.white
        f = torch.where(
            t > _EPSILON, torch.clamp(t, min=_EPSILON) ** (1 / 3), (_KAPPA * t + 16) / 116
        )
        L = 116 * f[..., 1] - 16
        a = 500 * (f[..., 0] - f[..., 1])
        b = 200 * (f[..., 1] - f[..., 2])
        return torch.stack([L, a, b], dim=-1)

    @staticmethod
    def delta_e94(lab_ref: torch.Tensor, lab: torch.Tensor) -> torch.Tensor:
        """CIE94 (graphic arts) colour difference, smooth everywhere (a small floor under the
        square root keeps the gradient finite at a perfect match)."""
        dL = lab[..., 0] - lab_ref[..., 0]
        C1 = torch.sqrt(lab_ref[..., 1] ** 2 + lab_ref[..., 2] ** 2 + 1e-9)
        C2 = torch.sqrt(lab[..., 1] ** 2 + lab[..., 2] ** 2 + 1e-9)
        dC = C2 - C1
        da, db = lab[..., 1] - lab_ref[..., 1], lab[..., 2] - lab_ref[..., 2]
        dH2 = torch.clamp(da**2 + db**2 - dC**2, min=0.0)
        SC, SH = 1 + 0.045 * C1, 1 + 0.015 * C1
        return torch.sqrt(dL**2 + (dC / SC) ** 2 + dH2 / SH**2 + 1e-6)
