"""Regenerate flakelab's demo toner library (synthetic; labelled so in the file).

Absorption spectra are sums of Gaussian bands placed at the published absorption features of
each automotive pigment family (band centres from the usual reflectance spectra of these
pigments: phthalocyanine blue's double band near 610/700 nm, quinacridone's 520–560 nm band,
the iron oxides' rising edge below 550–600 nm, bismuth vanadate's edge near 500 nm …);
strengths and scattering are chosen to give typical masstone and tint strengths in a 15 µm
basecoat. They are not measured data.

    python scripts/make_demo_library.py
"""

from __future__ import annotations

import numpy as np

from flakelab.core.spectra import WAVELENGTHS
from flakelab.io.library_file import demo_library_path, write_library
from flakelab.library.toners import AluminiumFlake, Binder, Library, Pearl, Pigment

WL = WAVELENGTHS


def bands(*spec: tuple[float, float, float], base: float = 0.0) -> np.ndarray:
    """Σ strength·exp(−((λ − centre)/width)²) + base, per unit mass fraction [1/µm]."""
    return base + sum(s * np.exp(-(((WL - c) / w) ** 2)) for c, w, s in spec)


def edge(position: float, width: float, strength: float) -> np.ndarray:
    """Absorption that is strong below ``position`` [nm] (an absorption edge)."""
    return strength / (1 + np.exp((WL - position) / width))


def rayleigh_like(strength: float, exponent: float = 1.5) -> np.ndarray:
    return strength * (550 / WL) ** exponent


NONE = np.zeros_like(WL)

PIGMENTS = [
    (
        "Phthalo blue GS",
        "phthalocyanine",
        bands((615, 45, 9.0), (695, 40, 8.0), (330, 60, 3.0)),
        NONE,
    ),
    (
        "Phthalo blue RS",
        "phthalocyanine",
        bands((600, 50, 8.5), (680, 40, 7.0), (345, 60, 2.5)),
        NONE,
    ),
    (
        "Phthalo green",
        "phthalocyanine",
        bands((640, 60, 9.0), (420, 45, 5.0), (710, 40, 6.0)),
        NONE,
    ),
    (
        "Phthalo green yellowish",
        "phthalocyanine",
        bands((650, 60, 8.0), (430, 40, 6.0), (400, 30, 4.0)),
        NONE,
    ),
    (
        "Quinacridone red",
        "quinacridone",
        bands((530, 45, 8.0), (565, 30, 5.0), (430, 50, 2.0)),
        NONE,
    ),
    (
        "Quinacridone magenta",
        "quinacridone",
        bands((545, 50, 8.0), (585, 30, 4.0), (450, 60, 1.0)),
        NONE,
    ),
    ("Quinacridone violet", "quinacridone", bands((555, 55, 8.5), (600, 35, 5.0)), NONE),
    ("Perylene maroon", "perylene", bands((560, 70, 7.0), (480, 60, 6.0), (620, 30, 3.0)), NONE),
    ("Perylene red", "perylene", bands((520, 55, 8.0), (460, 50, 5.0), (570, 25, 4.0)), NONE),
    (
        "DPP red",
        "diketopyrrolopyrrole",
        bands((510, 50, 9.0), (450, 50, 6.0)) + edge(560, 8, 2.0),
        rayleigh_like(0.15),
    ),
    (
        "DPP orange",
        "diketopyrrolopyrrole",
        bands((480, 50, 9.0)) + edge(530, 8, 2.5),
        rayleigh_like(0.12),
    ),
    (
        "Iron oxide red",
        "iron oxide",
        edge(585, 18, 6.0) + bands((520, 60, 1.5), base=0.15),
        rayleigh_like(1.6, 1.0),
    ),
    (
        "Iron oxide yellow",
        "iron oxide",
        edge(520, 20, 5.0) + bands((440, 40, 1.5), base=0.08),
        rayleigh_like(1.8, 1.0),
    ),
    (
        "Transparent iron oxide red",
        "iron oxide",
        edge(575, 22, 5.5) + bands((500, 50, 1.0), base=0.1),
        NONE,
    ),
    ("Transparent iron oxide yellow", "iron oxide", edge(505, 22, 4.5), NONE),
    ("Bismuth vanadate yellow", "bismuth vanadate", edge(495, 10, 7.0), rayleigh_like(2.2, 1.2)),
    ("Isoindoline yellow", "isoindoline", edge(480, 10, 7.5) + bands((400, 30, 2.0)), NONE),
    (
        "Indanthrone blue",
        "indanthrone",
        bands((590, 60, 7.0), (660, 50, 6.0), (420, 40, 1.5)),
        NONE,
    ),
    ("Carbon black", "carbon", bands(base=12.0) + rayleigh_like(1.0, 1.0), rayleigh_like(0.2)),
    (
        "Titanium dioxide white",
        "titanium dioxide",
        # rutile's band edge: K/S 0.11 at 400 nm as in Okumura's measured titanium white
        # (../shared/data/pigment-km); an edge at 410 nm read a cream, a* −5 and b* +8
        edge(400, 5, 3.0) + bands(base=0.005),
        rayleigh_like(9.0, 1.2),
    ),
]

FLAKES = [
    ("Al fine bright", 5.0, 0.15, 9.0, 0.95, "fine silver-dollar, high brightness"),
    ("Al fine", 6.0, 0.2, 12.0, 0.85, "fine cornflake, soft sparkle"),
    ("Al fine dark", 6.5, 0.25, 15.0, 0.75, "fine, dark flop"),
    ("Al medium bright", 9.0, 0.25, 9.0, 0.95, "medium silver-dollar"),
    ("Al medium", 10.0, 0.3, 11.0, 0.85, "medium cornflake"),
    ("Al medium coarse", 12.5, 0.35, 12.0, 0.85, "medium-coarse"),
    ("Al coarse bright", 16.0, 0.4, 8.0, 0.95, "coarse silver-dollar, strong sparkle"),
    ("Al coarse", 18.0, 0.45, 10.0, 0.85, "coarse cornflake"),
    ("Al extra coarse", 22.0, 0.5, 9.0, 0.9, "extra coarse, glitter"),
    ("Al VMP", 7.0, 0.05, 5.0, 1.0, "vacuum-metallised, liquid-metal look"),
]

PEARLS = [
    ("Pearl silver white", 60.0, "mica", 400.0, 9.0, 10.0, "TiO2 on mica, silver-white"),
    ("Pearl interference red", 100.0, "mica", 400.0, 9.0, 10.0, "TiO2 on mica, red-magenta"),
    ("Pearl interference blue", 120.0, "mica", 400.0, 9.0, 10.0, "TiO2 on mica, blue"),
    ("Pearl interference green", 140.0, "mica", 400.0, 9.0, 10.0, "TiO2 on mica, green"),
    ("Xirallic crystal silver", 60.0, "alumina", 300.0, 10.0, 6.0, "TiO2 on alumina, sparkling"),
]


DENSITY_G_ML = {
    "aluminium": 0.98,
    "pearl": 1.02,
    "organic": 0.98,
    "iron oxide": 1.20,
    "transparent iron oxide": 1.02,
    "bismuth vanadate": 1.25,
    "carbon": 0.97,
    "titanium dioxide": 1.45,
}
"""Densities as sold [g/mL], typical of solventborne basecoat mixing toners (the pigment
dispersed in resin and solvent): most are near 1, the heavy inorganic pigments denser. They
weigh a can ordered by volume. Typical values, not measured."""


def pigment_density(name: str, family: str) -> float:
    if family == "iron oxide" and name.startswith("Transparent"):
        return DENSITY_G_ML["transparent iron oxide"]
    return DENSITY_G_ML.get(family, DENSITY_G_ML["organic"])


def main() -> None:
    toners = [
        *(
            AluminiumFlake(
                n,
                r,
                t,
                sd,
                q,
                volume_fraction=0.04 if t < 0.1 else 0.13,
                description=d,
                density_g_ml=DENSITY_G_ML["aluminium"],
            )
            for n, r, t, sd, q, d in FLAKES
        ),
        *(
            Pigment(
                n,
                fam,
                np.round(k, 6),
                np.round(s, 6),
                g=0.3 if np.any(s) else 0.0,
                description="synthetic, shaped after the family's published absorption bands",
                density_g_ml=pigment_density(n, fam),
            )
            for n, fam, k, s in PIGMENTS
        ),  # fmt: skip
        *(
            Pearl(n, c, sub, sn, r, sd, description=d, density_g_ml=DENSITY_G_ML["pearl"])
            for n, c, sub, sn, r, sd, d in PEARLS
        ),
    ]
    library = Library(
        name="flakelab demo",
        toners=tuple(toners),
        binder=Binder(
            refractive_index=1.5, thickness_um=15.0, primer_reflectance=np.full(WL.size, 0.05)
        ),
        synthetic=True,
        description="Synthetic demo refinish system: 10 aluminium flakes, 20 pigments, 5 pearls. "
        "Spectra are shaped from published features, and densities typical of mixing toners, "
        "not measured (scripts/make_demo_library.py).",
    )
    write_library(library, demo_library_path())
    print(f"wrote {len(toners)} toners to {demo_library_path()}")


if __name__ == "__main__":
    main()
