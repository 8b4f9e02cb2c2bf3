"""How thick a basecoat must be to hide what it is sprayed over, and over which primer grey.

A refinish basecoat is built up coat by coat until the primer no longer shows through. A
strong solid or a metallic hides in one coat; a clean red, a yellow or a transparent-pigment
pearl can take four, and a panel sprayed short of hiding reads the primer's colour with its
own, which the colorist takes for a wrong recipe. Paint makers therefore give each colour a
grey-shade primer, the one of their greys (white to black) over which it hides soonest.

**Hiding.** The film build at which the paint over black and over white differ by
:data:`HIDING_DE00`: a colorimetric hiding criterion, read as DIN 55987 reads hiding from the
colour difference between a film over a contrast chart's black and over its white; here in
ΔE00, at every geometry the instrument reads, since a metallic's flop hides otherwise than
its face. The chart's black and white are :data:`CONTRAST_CHART`'s; the contrast
ratio, the film's Y over black over its Y over white, is reported at the library's nominal
build at :data:`~flakelab.core.geometry.FACE_GEOMETRY`, the instrument's 45°:0°.

**The primer.** For each primer (by default :data:`GREY_SHADES`, neutral greys evenly spaced
in L*, white to black, as the refinish grey-shade systems are; or a shop's own, as measured),
the film build at which the paint over it comes within :data:`HIDING_DE00` of the colour it
tends to as it is built up (over that primer at :data:`BUILD_GRID`'s thickest, where every
primer reads alike for a paint that hides the chart there). The best primer is, of those
over which it comes in the fewest coats, the one nearest its own colour at 45°:0° in ΔE*ab
(the grey-shade systems' rule, nearest in lightness, for neutral greys, whose a* and b* are
0: over a primer of the paint's own colour, what a thin spot shows of it shows least). That
can take longer than hiding the chart: a yellow brighter than the chart's white nears its
full colour from below over the black and the white alike, which then agree before either is
reached. A paint that does not hide the chart within the grid (a transparent pigment's
masstone, a pearl alone) tends to no colour of its own, and over no primer is it said to.

**A ground as read.** A contrast chart, a grey and a shop's primer are given as an instrument
reads them bare at 45°:0°; what the physics needs is the ground's reflectance under the
basecoat, R_g (:func:`under_basecoat`). A matte ground's surface returns part of the light
from inside it, as the clearcoat's does, so the two differ: a primer that reads Y 5 % bare
reflects 11.5 % under the binder. The library's own primer is given as R_g already.

Everything is the physics' (:func:`~flakelab.physics.application.sprayed_reflectance` with the
library's basecoat, its primer replaced): the learned model knows only the primer the shops'
cases were sprayed over. A grey's reflectance is taken as flat at its luminance factor Y,
which a neutral grey's is to a per cent or so; a measured primer's is its own.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import colour
import numpy as np
from numpy.typing import ArrayLike, NDArray

from flakelab.core.colorimetry import reflectance_to_Lab, reflectance_to_XYZ
from flakelab.core.defaults import HIDING_DE00
from flakelab.core.difference import delta_E, delta_E_CIE2000
from flakelab.core.geometry import FACE_GEOMETRY, Geometry
from flakelab.core.spectra import WAVELENGTHS
from flakelab.library.toners import Library
from flakelab.physics.application import sprayed_layer
from flakelab.physics.fast import flake_geometry, reflectance_factor
from flakelab.physics.layer import Layer, internal_diffuse_reflectance, layer_from_fractions

__all__ = [
    "HIDING_DE00",
    "CONTRAST_CHART",
    "GREY_SHADES",
    "BUILD_GRID",
    "COATS_AT_NOMINAL",
    "GROUNDS",
    "Hiding",
    "hiding",
    "grey_primer",
    "grey_shades",
    "ground_reflectance",
    "reflectance_over",
    "under_basecoat",
    "read_bare",
]

CONTRAST_CHART = {"black": 0.01, "white": 0.80}
"""Luminance factors Y of a contrast chart's black and white, read bare at 45°:0° [-]: a deep
black and a white of 80 %, about those of the charts a contrast ratio is read on
(ISO 6504-3)."""
GREY_SHADES = {f"G{i + 1}": float(L) for i, L in enumerate(np.linspace(93.0, 27.0, 7))}
"""Grey-shade primers, white to black, by their L* read bare at 45°:0° (D65/10): seven steps
evenly in lightness from a white primer's 93 to a dark grey's 27. The demo library's primer
reads L* 16 bare (:func:`read_bare`), darker than any."""
BUILD_GRID = 10.0 ** (np.arange(-80, 37) / 40)
"""Film builds the physics is evaluated at, relative to the library's basecoat [-]: from a
hundredth of the nominal to 8.4 times it, 40 a decade (6 % apart, the nominal among them),
between which the build that hides is interpolated."""
NOMINAL = int(np.flatnonzero(BUILD_GRID == 1.0)[0])
"""Where the nominal build lies on :data:`BUILD_GRID`."""
COATS_AT_NOMINAL = 2
"""Coats a refinish basecoat is sprayed in to its nominal build: a coat is half of it."""
GROUNDS = ("primer", *CONTRAST_CHART, *GREY_SHADES)
"""What a panel may be sprayed over (:func:`ground_reflectance`): the library's primer, a
contrast chart's black or white, or a grey-shade primer."""


@dataclass(frozen=True)
class Hiding:
    """What hides ``fractions[F, T]``'s paints (:func:`hiding`).

    ``film_um[B]`` the builds evaluated [µm]; ``contrast_de00[F, B]`` the worst-geometry ΔE00
    between each paint over the chart's black and white at each; ``hiding_um[F]`` the build
    at which that falls to ``threshold`` (inf: not within the grid); ``contrast_ratio[F]``
    Y over black / Y over white at ``nominal_um`` (NaN where not read at
    :data:`~flakelab.core.geometry.FACE_GEOMETRY`); ``primers`` the primers' names,
    ``primer_lab[P, 3]`` their CIELAB as read bare at 45°:0°, ``primer_curve[F, P, B]`` the
    worst-geometry ΔE00 of each paint at each build over each primer from the colour it
    tends to, ``primer_hiding_um[F, P]`` the build at which that falls to ``threshold``
    (inf throughout for a paint that does not hide the chart within the grid: module notes);
    ``lab[F, 3]`` each paint's CIELAB built up, at 45°:0° (the mean over ``geometries``
    where it is not among them; NaN where it does not hide); ``coat_um`` one coat's build.
    CIELAB is D65/10's."""

    film_um: NDArray[np.float64]
    contrast_de00: NDArray[np.float64]
    hiding_um: NDArray[np.float64]
    contrast_ratio: NDArray[np.float64]
    primers: tuple[str, ...]
    primer_lab: NDArray[np.float64]
    primer_curve: NDArray[np.float64]
    primer_hiding_um: NDArray[np.float64]
    lab: NDArray[np.float64]
    nominal_um: float
    coat_um: float
    threshold: float

    @property
    def lightness(self) -> NDArray[np.float64]:
        """Each paint's L* built up ``[F]`` (NaN where it does not hide)."""
        return self.lab[:, 0]

    @property
    def primer_de00(self) -> NDArray[np.float64]:
        """Each paint's worst-geometry ΔE00 at the nominal build over each primer from its
        colour built up ``[F, P]``."""
        return self.primer_curve[..., NOMINAL]

    @property
    def primer_distance(self) -> NDArray[np.float64]:
        """ΔE*ab between each paint built up and each primer as read, at 45°:0° ``[F, P]``
        (NaN where the paint does not hide)."""
        return delta_E(self.lab[:, None], self.primer_lab[None], method="CIE 1976")

    def coats(self, film_um: ArrayLike) -> NDArray[np.float64]:
        """Coats that build ``film_um`` [µm] (inf for inf)."""
        return np.ceil(np.asarray(film_um, dtype=float) / self.coat_um - 1e-9)

    @property
    def best_primer(self) -> list[str | None]:
        """The primer each paint is best sprayed over (module notes; None where it hides over
        none)."""
        best: list[str | None] = []
        for hides, apart in zip(self.primer_hiding_um, self.primer_distance, strict=True):
            coats = self.coats(hides)
            fewest = np.isfinite(coats) & (coats == coats.min())
            nearest = np.where(fewest, apart, np.inf)
            best.append(self.primers[int(np.argmin(nearest))] if fewest.any() else None)
        return best


def grey_primer(lightness: float) -> NDArray[np.float64]:
    """A neutral primer's reflectance ``[W]`` as read bare, flat at the luminance factor of
    ``lightness`` (CIE 1976 L*)."""
    Y = float(colour.colorimetry.luminance_CIE1976(lightness)) / 100
    return np.full(WAVELENGTHS.size, Y)


def grey_shades() -> dict[str, NDArray[np.float64]]:
    """:data:`GREY_SHADES` as read bare ``{name: [W]}``, the primers :func:`hiding` tries
    where no others are given."""
    return {name: grey_primer(L) for name, L in GREY_SHADES.items()}


def _face_terms(n: float) -> tuple[float, float]:
    """The clearcoat's transmittances in and out over n² at 45°:0°, and its reflectance for
    diffuse light from inside: what the fast model's diffuse channel reads a ground
    through."""
    return float(flake_geometry((FACE_GEOMETRY,), n)["interface"][0]), (
        internal_diffuse_reflectance(n)
    )


def under_basecoat(bare: ArrayLike, n: float) -> NDArray[np.float64]:
    """A matte ground's reflectance under a basecoat of refractive index ``n``, R_g ``[..., W]``,
    from its reflectance factor read bare at 45°:0° (module notes): the inverse of what the
    fast model reads of it through a film of no build, t·R_g / (1 − r_i·R_g), its own
    surface taken as the clearcoat's. At most 1 (a reading brighter than a perfect white's
    there is a fluorescent's, or an error)."""
    t, r_i = _face_terms(n)
    R = np.asarray(bare, dtype=float)
    return np.clip(R / (t + r_i * R), 0.0, 1.0)


def read_bare(R_g: ArrayLike, n: float) -> NDArray[np.float64]:
    """A ground's reflectance factor read bare at 45°:0° from its reflectance under the
    basecoat ``R_g`` (the inverse of :func:`under_basecoat`)."""
    t, r_i = _face_terms(n)
    R = np.asarray(R_g, dtype=float)
    return t * R / (1 - r_i * R)


def ground_reflectance(library: Library, ground: str) -> NDArray[np.float64]:
    """The reflectance under the basecoat ``[W]`` of what a panel is sprayed over, one of
    :data:`GROUNDS`."""
    if ground == "primer":
        return library.binder.primer_reflectance
    n = library.binder.refractive_index
    if ground in CONTRAST_CHART:
        return under_basecoat(np.full(WAVELENGTHS.size, CONTRAST_CHART[ground]), n)
    if ground in GREY_SHADES:
        return under_basecoat(grey_primer(GREY_SHADES[ground]), n)
    raise ValueError(f"expected a ground among {', '.join(GROUNDS)}, got {ground!r}")


def reflectance_over(
    layer: Layer, library: Library, grounds: Sequence[str], geometries: tuple[Geometry, ...]
) -> NDArray[np.float64]:
    """Reflectance factors ``[F, G, W]`` of each formulation of ``layer`` sprayed over its one
    of ``grounds[F]`` (:data:`GROUNDS`), at ``geometries``."""
    grounds = np.asarray(grounds)
    R = np.empty((layer.size, len(geometries), WAVELENGTHS.size))
    for ground in np.unique(grounds):  # the formulations over each, at once
        rows = np.flatnonzero(grounds == ground)
        over = replace(layer[rows], primer=ground_reflectance(library, str(ground)))
        R[rows] = reflectance_factor(over, geometries)
    return R


def hiding(
    library: Library,
    fractions: ArrayLike,
    geometries: tuple[Geometry, ...],
    threshold: float = HIDING_DE00,
    primers: Mapping[str, ArrayLike] | None = None,
) -> Hiding:
    """How thick each paint of ``fractions[F, T]`` (library order) must be to hide the
    contrast chart and each of ``primers`` (name → reflectance ``[W]`` read bare at 45°:0°;
    default :func:`grey_shades`), judged at ``geometries`` (module notes)."""
    x = np.atleast_2d(np.asarray(fractions, dtype=float))
    primers = grey_shades() if primers is None else dict(primers)
    if not primers:
        raise ValueError("expected at least one primer, got none")
    F, B, nominal = len(x), BUILD_GRID.size, library.binder.thickness_um
    layer = sprayed_layer(layer_from_fractions(library, np.repeat(x, B, axis=0)), library,
                          np.tile(BUILD_GRID, F), np.ones(F * B))  # fmt: skip
    n = library.binder.refractive_index

    def over(R_g: NDArray) -> NDArray:  # [F, B, G, W] over a ground of R_g under the basecoat
        R = reflectance_factor(replace(layer, primer=R_g), geometries)
        return R.reshape(F, B, len(geometries), WAVELENGTHS.size)

    chart = {name: over(ground_reflectance(library, name)) for name in CONTRAST_CHART}
    Lab = {name: reflectance_to_Lab(R) for name, R in chart.items()}  # [F, B, G, 3]
    contrast = _worst_de00(Lab["black"], Lab["white"])  # [F, B]
    hides = _where_it_falls_to(contrast, threshold)
    over_primers = [reflectance_to_Lab(over(under_basecoat(bare, n))) for bare in primers.values()]
    built_up = np.stack([_worst_de00(lab, lab[:, -1:]) for lab in over_primers], axis=1)
    built_up[~np.isfinite(hides)] = np.inf  # tends to no colour of its own: [F, P, B]
    names = [g.name for g in geometries]
    face = names.index(FACE_GEOMETRY) if FACE_GEOMETRY in names else slice(None)
    full = Lab["white"][:, -1, face].reshape(F, -1, 3).mean(axis=1)  # built up
    Y = {c: reflectance_to_XYZ(R[:, NOMINAL, face])[..., 1] for c, R in chart.items()}
    ratio = Y["black"] / Y["white"] if FACE_GEOMETRY in names else np.full(F, np.nan)
    return Hiding(
        film_um=BUILD_GRID * nominal,
        contrast_de00=contrast,
        hiding_um=hides * nominal,
        contrast_ratio=ratio,
        primers=tuple(primers),
        primer_lab=reflectance_to_Lab(np.array(list(primers.values()), dtype=float)),
        primer_curve=built_up,
        primer_hiding_um=_where_it_falls_to(built_up, threshold) * nominal,
        lab=np.where(np.isfinite(hides)[:, None], full, np.nan),
        nominal_um=nominal,
        coat_um=nominal / COATS_AT_NOMINAL,
        threshold=threshold,
    )


def _worst_de00(a: NDArray, b: NDArray) -> NDArray:
    """ΔE00 between ``a`` and ``b`` ``[..., G, 3]``, the worst geometry's ``[...]``."""
    a, b = np.broadcast_arrays(a, b)
    return delta_E_CIE2000(a, b).max(axis=-1)


def _where_it_falls_to(de: NDArray, threshold: float) -> NDArray:
    """The relative build ``[...]`` past which ``de[..., B]`` stays at or under ``threshold``,
    interpolated in log build between the grid's neighbours (inf where it never does, the
    grid's least where it always does)."""
    stays = np.flip(np.logical_and.accumulate(np.flip(de <= threshold, -1), -1), -1)
    first = np.argmax(stays, axis=-1)[..., None]  # the first build of the run to the end
    before = np.maximum(first - 1, 0)
    d0 = np.take_along_axis(de, before, -1)[..., 0]
    d1 = np.take_along_axis(de, first, -1)[..., 0]
    log_build = np.log(BUILD_GRID)
    lo, hi = log_build[before[..., 0]], log_build[first[..., 0]]
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(first[..., 0] > 0, (d0 - threshold) / (d0 - d1), 0.0)
    return np.where(stays[..., -1], np.exp(lo + np.nan_to_num(share) * (hi - lo)), np.inf)
