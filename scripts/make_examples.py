"""Regenerate the shipped example measurements (synthetic, labelled so in their metadata).

A blue metallic at the MA-T12 geometries: an aluminium flake lobe over the flake tilt
θ_flake (Gaussian orientation spread) seen through a phthalo-blue-like absorber whose path
length grows as 1/μi' + 1/μo', plus a small diffuse part. The spray-out is the same paint
with 4 % more blue and a 3 % wider flake spread (a wetter application), with instrument
noise. It is a stand-in until the coating-optics model ships; run:

    python scripts/make_examples.py
"""

from __future__ import annotations

from datetime import datetime
from pathlib import Path

import numpy as np

from flakelab.core.geometry import (
    directions,
    flake_angles,
    instrument_geometries,
    refract_into_coating,
)
from flakelab.core.measurement import Measurement
from flakelab.core.spectra import WAVELENGTHS
from flakelab.io import write_measurements

OUT = Path(__file__).resolve().parents[1] / "src" / "flakelab" / "data" / "examples"


def blue_metallic(blue: float, spread_deg: float, rng: np.random.Generator, noise: float):
    geometries = instrument_geometries("ma-t12")
    theta_flake, _ = flake_angles(geometries)
    light, view = directions(geometries)
    mu_sum = 1 / refract_into_coating(light)[:, 2] + 1 / refract_into_coating(view)[:, 2]
    absorption = blue * (
        np.exp(-(((WAVELENGTHS - 600) / 55) ** 2))
        + 0.9 * np.exp(-(((WAVELENGTHS - 690) / 50) ** 2))
        + 0.25 * np.exp(-(((WAVELENGTHS - 530) / 40) ** 2))
    )
    lobe = 2.2 * np.exp(-0.5 * (theta_flake / spread_deg) ** 2) + 0.045
    aluminium = 0.91 - 0.05 * np.exp(-(((WAVELENGTHS - 810) / 100) ** 2))
    R = lobe[:, None] * aluminium * np.exp(-absorption[None, :] * mu_sum[:, None]) + 0.004
    R *= 1 + rng.normal(0, noise, R.shape)
    return geometries, R


def main() -> None:
    rng = np.random.default_rng(20261122)
    OUT.mkdir(parents=True, exist_ok=True)
    for name, blue, spread, texture in (
        (
            "target",
            1.1,
            11.0,
            {
                "Sa15": 14.2,
                "Si15": 11.8,
                "Sa45": 9.6,
                "Si45": 7.9,
                "Sa75": 4.1,
                "Si75": 3.2,
                "SG": 8.7,
                "G": 6.4,
            },
        ),
        (
            "sprayout",
            1.14,
            11.3,
            {
                "Sa15": 14.9,
                "Si15": 11.1,
                "Sa45": 10.3,
                "Si45": 7.4,
                "Sa75": 4.6,
                "Si75": 3.0,
                "SG": 8.4,
                "G": 6.9,
            },
        ),
    ):
        geometries, R = blue_metallic(blue, spread, rng, noise=0.002)
        measurement = Measurement(
            sample=f"Blue metallic {name} (synthetic)",
            geometries=geometries,
            wavelengths=WAVELENGTHS,
            reflectance=R,
            texture=texture,
            instrument="X-Rite MA-T12 (synthetic example)",
            measured_at=datetime(2026, 11, 22, 9, 30 if name == "target" else 45),
            metadata={"synthetic": "yes: scripts/make_examples.py", "paint": "blue metallic"},
        )
        write_measurements([measurement], OUT / f"blue-metallic-{name}.cxf")


if __name__ == "__main__":
    main()
