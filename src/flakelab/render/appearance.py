"""Appearance-based rendering: colour + texture images of a measured paint (paper 001).

Pipeline (DESIGN.md §4):

1. **Appearance of a measurement** — L*a*b* at the in-plane geometries one lamp lit (45°
   unless told; an MA-T12 also lit at 15°), indexed by aspecular angle; under a lamp the
   instrument did not use, its 45° readings interpolated over flake tilt
   (:mod:`flakelab.render.angular`); the diffuse-light colour as the mean reflectance over
   those geometries (a hemispherical average of the directional readings); glint impression
   g per lamp angle (sparkle grade √(Sa·Si)/2 at 15°, 45°, 75°: the texture camera looks
   along the normal, at 15as15, 45as45, 75as75) and diffuse coarseness c (graininess G).
2. **Texture images** from the fitted appearance-based processes, tone-mapped to display
   grey T = G/(G + 1) (a white diffuser at half scale, glints near full scale), as the
   instrument camera's 8-bit images are.
3. **Composition** — eqs 5–6: colour + (T − mean T) per channel in linear light, clipped to
   [0, 1]; the paper's renormalisation is done so each column's mean light is the uniform
   colour's (the light clipped away is given back to the unclipped pixels), so adding
   texture does not change colour. Eq. 7 mixes the diffuse and directional images with the
   diffuse fraction d; gloss adds white near the specular direction.
4. **Curved panel** — columns sweep the aspecular angle 0–110° (to 80° under an MA-T12's 15°
   lamp); colour (in CIELAB) is interpolated between the geometries with cardinal splines,
   glint over the flake tilt each column's geometry needs, between the camera's three.
5. **Distance** — the eye resolves about 1′ of arc, so relative to the reference distance
   the coarseness pattern is blurred by the growth of the eye's spot (contrast falls), while
   each glint keeps its size and is dimmed by the share of the spot it fills (its light is
   spread over the spot but the eye still sees a point): two different methods, as the
   paper found necessary. Texture is drawn at the camera's scale, one pixel = 15 µm.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import CubicHermiteSpline
from scipy.ndimage import fourier_gaussian, gaussian_filter, gaussian_filter1d

from flakelab.core.colorimetry import (
    D65_10,
    Conditions,
    Lab_to_linear_sRGB,
    encode_sRGB,
    reflectance_to_Lab,
)
from flakelab.core.geometry import flake_angles_at, geometry_angles, lit_by
from flakelab.core.measurement import Measurement
from flakelab.core.units import parse_amount
from flakelab.io.records import write_atomically
from flakelab.texture.calibration import shipped_processes
from flakelab.texture.generator import FWHM_PER_SIGMA, TextureProcess, patch_image
from flakelab.texture.metrics import sparkle_grade

__all__ = [
    "DIFFUSE_FRACTION",
    "REFERENCE_DISTANCE_M",
    "Appearance",
    "appearance_of",
    "appearance_under",
    "lamps_of",
    "curved_range",
    "cardinal_spline",
    "same_aspecular_reading",
    "render_panel",
    "render_curved",
    "render_stack",
    "render_under_lamps",
    "LampStack",
    "parse_lamps",
    "image_format",
    "IMAGE_FORMATS",
    "render_grid",
    "compose",
    "parse_distance",
    "save_image",
]

DIFFUSE_FRACTION = 0.7
"""Default diffuse share of the light: a body shop (paper 001: 70 % diffuse, 30 % direct)."""
REFERENCE_DISTANCE_M = 0.5
"""Distance at which texture is drawn as the camera saw it."""
FARTHEST_DISTANCE_M = 1000.0
"""Distance beyond which a panel is drawn as from it: the eye's blur there (σ 8,200 camera
pixels) already smooths the widest image drawn (8,192), and a farther distance's square
overflowed (``--distance 1e308m``)."""
EYE_RESOLUTION_ARCMIN = 1.0
CAMERA_PIXEL_UM = 15.0
GLOSS_WIDTH_DEG = 3.0
"""Angular half-width of the clearcoat's highlight around the specular direction."""
SPARKLE_ANGLES = (15.0, 45.0, 75.0)
"""The texture camera's lamps: it looks along the normal, so each reads at ``NasN``."""
CURVED_RANGE_DEG = (0.0, 110.0)
"""The aspecular angles a curved panel sweeps, those of the lamp's measured geometries
within it (paper 001 Fig. 4: 0–110° under the 45° lamp)."""
LAMP_DEG = 45.0
"""The lamp a paint is drawn under unless told: the one every multi-angle instrument has."""
INTERPOLATED_STEP_DEG = 5.0
"""Aspecular step of the colours interpolated under a lamp the instrument did not use."""
DETECTOR_LIMIT_DEG = 80.0
"""The furthest from the normal an interpolated reading's detector lies (instruments read
within 65°, 45as110; near the horizon the clearcoat reflects most light away)."""
PANEL_ASPECULAR_DEG = 45.0
"""Where a flat panel (and the grid of texture tiles) is seen unless told: mid-flop."""
_TENSION = 0.0  # cardinal spline tension: 0 is Catmull–Rom


@dataclass(frozen=True)
class Appearance:
    """What the renderer needs: colour along aspecular angle under one lamp (``lamp``° from
    the normal), diffuse colour, texture."""

    aspecular: NDArray[np.float64]  # [K] degrees, increasing
    Lab: NDArray[np.float64]  # [K, 3]
    diffuse_Lab: NDArray[np.float64]  # [3]
    glint: NDArray[np.float64]  # [3] at SPARKLE_ANGLES; 0 when unmeasured
    coarseness: float  # 0 when unmeasured
    name: str = ""
    lamp: float = LAMP_DEG
    interpolated_from: float | None = None  # the lamp whose readings were interpolated


def lamps_of(measurement: Measurement) -> tuple[float, ...]:
    """The lamps ``measurement`` can be drawn under: those that light two or more of its
    in-plane geometries, 45° first (an MA-T12 reading: 45°, then 15°)."""
    lit = [g.illumination for g in measurement.geometries if g.in_plane]
    lamps = {lamp for lamp in lit if lit.count(lamp) >= 2}
    return tuple(sorted(lamps, key=lambda lamp: (lamp != LAMP_DEG, lamp)))


def appearance_of(
    measurement: Measurement, conditions: Conditions = D65_10, lamp: float = LAMP_DEG
) -> Appearance:
    """Colour and texture of ``measurement`` for rendering under a lamp ``lamp``° from the
    normal; needs two or more in-plane geometries it lit (45as15, 45as45 … at 45°, the
    family every multi-angle instrument has; 15as-15, 15as15 … on an MA-T12)."""
    rows = lit_by(measurement.geometries, lamp)
    if len(rows) < 2:
        lamps = lamps_of(measurement)
        has = f"it can be drawn under {', '.join(f'{a:g}°' for a in lamps)}" if lamps else (
            f"got {', '.join(map(str, measurement.geometries))}")  # fmt: skip
        raise ValueError(
            f"{measurement.sample}: rendering under a lamp at {lamp:g}° needs two or more "
            f"in-plane geometries it lit ({lamp:g}as15, {lamp:g}as45 …); {has}"
        )
    aspecular = np.array([measurement.geometries[i].aspecular for i in rows])
    order = np.argsort(aspecular)
    reflectance = measurement.reflectance[rows][order]
    Lab = reflectance_to_Lab(reflectance, measurement.wavelengths, conditions)
    diffuse = reflectance_to_Lab(reflectance.mean(0), measurement.wavelengths, conditions)
    texture = measurement.texture
    glint = np.array(
        [
            sparkle_grade(texture.get(f"Sa{a:.0f}", 0.0), texture.get(f"Si{a:.0f}", 0.0))
            for a in SPARKLE_ANGLES
        ]
    )
    return Appearance(aspecular[order], Lab, diffuse, glint, float(texture.get("G", 0.0)),
                      measurement.sample, float(lamp))  # fmt: skip


def appearance_under(
    measurement: Measurement,
    lamp: float,
    conditions: Conditions = D65_10,
    source: float | None = None,
) -> Appearance:
    """:func:`appearance_of` under a lamp ``lamp``° from the normal that the instrument did
    not use: its readings under ``source`` (default: the first of :func:`lamps_of`, 45° on
    every multi-angle instrument) interpolated over flake tilt (:mod:`flakelab.render.angular`)
    every :data:`INTERPOLATED_STEP_DEG` of aspecular angle from -15° to 110°, the detector
    within :data:`DETECTOR_LIMIT_DEG` of the normal. Texture and diffuse colour are the
    reading's own: neither depends on the lamp's angle."""
    from flakelab.render.angular import tilt_interpolation

    lamps = lamps_of(measurement)
    if source is None and not lamps:
        raise ValueError(
            f"{measurement.sample}: drawing under a lamp at {lamp:g}° interpolates the readings "
            f"under one lamp the instrument used, two or more of them in plane (45as15, 45as45 "
            f"…); got {', '.join(map(str, measurement.geometries))}"
        )
    source = lamps[0] if source is None else source
    measured = appearance_of(measurement, conditions, source)
    bottom = max(-15.0, lamp - DETECTOR_LIMIT_DEG)
    top = min(CURVED_RANGE_DEG[1], lamp + DETECTOR_LIMIT_DEG)
    aspecular = np.unique(np.append(np.arange(bottom, top, INTERPOLATED_STEP_DEG), top))
    reflectance = tilt_interpolation(measurement, source).reflectance(lamp, aspecular)
    Lab = reflectance_to_Lab(reflectance, measurement.wavelengths, conditions)
    return replace(measured, aspecular=aspecular, Lab=Lab, lamp=float(lamp),
                   interpolated_from=float(source))  # fmt: skip


def curved_range(appearances: Sequence[Appearance]) -> tuple[float, float]:
    """The aspecular angles curved panels of ``appearances`` sweep, side by side: 0° to the
    last angle every one measured within :data:`CURVED_RANGE_DEG` (under a 15° lamp an
    MA-T12 reads up to 80°, and a detector beyond 105° would lie below the horizon)."""
    top = min(float(a.aspecular[-1]) for a in appearances)
    return CURVED_RANGE_DEG[0], min(max(top, CURVED_RANGE_DEG[0] + 1.0), CURVED_RANGE_DEG[1])


def glint_along(appearance: Appearance, aspecular: NDArray) -> NDArray:
    """The glint impression at aspecular angles under the appearance's lamp, from its readings
    under the texture camera's lamps, interpolated over the flake tilt each geometry sees
    (θ_flake, DESIGN.md §7): a flake glints where its tilt mirrors the lamp into the eye, so
    the tilt, not the aspecular angle, says how many flakes glint (under a 45° lamp 75° from
    specular needs 24° of tilt, the camera's 75° lamp 20°)."""
    knots = flake_angles_at(SPARKLE_ANGLES, SPARKLE_ANGLES)[0]
    tilt = flake_angles_at(appearance.lamp, aspecular)[0]
    return cardinal_spline(knots, appearance.glint, tilt)


def cardinal_spline(x: NDArray, y: NDArray, at: NDArray, tension: float = _TENSION) -> NDArray:
    """Cardinal spline through (x, y) (y ``[K, ...]``), evaluated at ``at``; held constant
    beyond the end points. Tangents (1 − tension)·(y[k+1] − y[k−1])/(x[k+1] − x[k−1])."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    if x.size == 1:
        return np.broadcast_to(y[0], np.shape(at) + y.shape[1:]).copy()
    slope = np.gradient(y, x, axis=0, edge_order=1)  # central differences inside
    inner = (y[2:] - y[:-2]) / (x[2:] - x[:-2]).reshape((-1,) + (1,) * (y.ndim - 1))
    slope[1:-1] = inner
    spline = CubicHermiteSpline(x, y, (1 - tension) * slope, axis=0)
    return spline(np.clip(at, x[0], x[-1]))


def same_aspecular_reading(geometries, readings: NDArray, aspecular: NDArray) -> NDArray:
    """The naive reading under a lamp not read: the one ``readings`` (``[K, ...]``, at the
    in-plane ``geometries`` of one lamp) give at the same aspecular angle, whatever the lamp
    (a cardinal spline through them, held beyond them). The baseline that interpolation over
    flake tilt (:mod:`flakelab.render.angular`) is measured against."""
    knots = geometry_angles(geometries)[1]
    return cardinal_spline(knots, readings, np.asarray(aspecular, float))


def _tone(grey: NDArray) -> NDArray:
    """Display grey of a texture image in white-diffuser units (a white at half scale)."""
    return grey / (grey + 1.0)


def compose(colour: NDArray, texture: NDArray, iterations: int = 4) -> NDArray:
    """Eqs 5–6: linear ``colour`` ``[cols, 3]`` (or ``[3]``) + (T − mean T), clipped to
    [0, 1], renormalised so the colour's mean light is kept where it can be. Means are
    taken over rows and smoothed across neighbouring columns: a curved panel's colour and
    texture change along its columns, and a raw column mean would stripe the image."""
    rows, cols = texture.shape
    colour = np.broadcast_to(np.asarray(colour, float), (cols, 3))
    target = np.clip(colour, 0.0, 1.0)
    deviation = texture - _column_mean(texture)[None]
    image = np.clip(target[None] + deviation[..., None], 0.0, 1.0)
    # the colour's mean smoothed as the image's is: against the raw colour, a steep change
    # along the columns (a dark face) reads as a deficit even where nothing was clipped
    kept = _smoothed_along_columns(target)
    for _ in range(iterations):
        deficit = kept - _column_mean(image)  # [cols, 3]
        free = np.where(deficit[None] > 0, image < 1, image > 0)
        share = np.maximum(free.sum(axis=0), 1)
        image = np.clip(image + free * (deficit * rows / share)[None], 0.0, 1.0)
    return image


def _column_mean(image: NDArray) -> NDArray:
    """Mean over rows, smoothed over about 1/64 of the columns."""
    return _smoothed_along_columns(image.mean(axis=0))


def _smoothed_along_columns(values: NDArray) -> NDArray:
    """``values`` ``[cols, ...]`` smoothed over about 1/64 of the columns."""
    width = values.shape[0] / 64
    return gaussian_filter1d(values, width, axis=0, mode="nearest") if width >= 1 else values


def _eye_blur_px(distance_m: float) -> float:
    """Extra blur σ [camera pixels] of the eye's spot at ``distance_m`` beyond the reference."""
    spot = np.radians(EYE_RESOLUTION_ARCMIN / 60.0) / FWHM_PER_SIGMA
    extra = max(min(distance_m, FARTHEST_DISTANCE_M) ** 2 - REFERENCE_DISTANCE_M**2, 0.0)
    return float(np.sqrt(extra) * spot * 1e6 / CAMERA_PIXEL_UM)


def _as_map(value: NDArray | float) -> NDArray:
    """A value per column (1-D), per pixel (2-D) or one for all, as a 2-D broadcastable map."""
    value = np.asarray(value, dtype=float)
    return value[None, :] if value.ndim == 1 else np.atleast_2d(value)


def _texture_value(process: TextureProcess, value: NDArray) -> tuple[NDArray, NDArray]:
    """Values clamped into the fitted range, and a strength that fades texture out below it
    (a solid colour has none)."""
    low, high = process.value_range
    return np.clip(value, low, high), np.clip(value / low, 0.0, 1.0)


def texture_images(
    glint: NDArray | float,
    coarseness: NDArray | float,
    shape: tuple[int, int],
    *,
    distance_m: float = REFERENCE_DISTANCE_M,
    seed: int = 0,
    processes: dict[str, TextureProcess] | None = None,
) -> tuple[NDArray, NDArray]:
    """Display-grey texture images (directional, diffuse) for ``glint`` and ``coarseness``
    values that broadcast to ``shape`` (per column for a curved panel)."""
    processes = processes or shipped_processes()
    rng = np.random.default_rng(seed)
    blur = _eye_blur_px(distance_m)
    g, g_strength = _texture_value(processes["glint"], _as_map(glint))
    controls = processes["glint"].controls(g)
    sigma = controls["size"] / FWHM_PER_SIGMA
    controls["grey"] = controls["grey"] * sigma**2 / (sigma**2 + blur**2)
    directional = _tone(patch_image(**controls, shape=shape, rng=rng)) * g_strength
    c, c_strength = _texture_value(processes["coarseness"], _as_map(coarseness))
    grey = patch_image(**processes["coarseness"].controls(c), shape=shape, rng=rng)
    if blur > 0:
        grey = _periodic_blur(grey, blur)
    return directional, _tone(grey) * c_strength


def _periodic_blur(image: NDArray, sigma: float) -> NDArray:
    """Gaussian blur of a tileable image; a kernel wider than the image (a panel seen from far
    off: σ grows with the distance) is applied in Fourier space, at the cost of any other."""
    if 4 * sigma < min(image.shape):
        return gaussian_filter(image, sigma, mode="wrap")
    return np.fft.irfft2(
        fourier_gaussian(np.fft.rfft2(image), sigma, n=image.shape[1]), image.shape
    )


def _gloss(aspecular: NDArray, level: float) -> NDArray:
    return level * np.exp(-0.5 * (np.asarray(aspecular, float) / GLOSS_WIDTH_DEG) ** 2)


def _render(
    appearance: Appearance,
    aspecular: NDArray,
    shape: tuple[int, int],
    *,
    diffuse_fraction: float,
    distance_m: float,
    gloss: float,
    texture: bool,
    seed: int,
) -> NDArray:
    """Linear-light image ``[rows, cols, 3]`` with column ``j`` at ``aspecular[j]``."""
    if distance_m <= 0:
        raise ValueError(f"distance: expected a positive distance, got {distance_m} m")
    directional_colour = Lab_to_linear_sRGB(
        cardinal_spline(appearance.aspecular, appearance.Lab, aspecular)
    )
    diffuse_colour = Lab_to_linear_sRGB(appearance.diffuse_Lab)
    if texture:
        glint = glint_along(appearance, aspecular)
        T_dir, T_diff = texture_images(
            np.maximum(glint, 0.0), appearance.coarseness, shape, distance_m=distance_m, seed=seed
        )
    else:
        T_dir = T_diff = np.zeros(shape)
    image = _mix(directional_colour, diffuse_colour, T_dir, T_diff, diffuse_fraction)
    highlight = _gloss(aspecular, gloss) * (1 - diffuse_fraction)
    return np.clip(image + highlight[None, :, None], 0.0, 1.0)


def _mix(
    directional_colour: NDArray,
    diffuse_colour: NDArray,
    directional_texture: NDArray,
    diffuse_texture: NDArray,
    diffuse_fraction: float,
) -> NDArray:
    """Eqs 5–7: each light's colour with its texture, mixed with the diffuse fraction d."""
    if not 0.0 <= diffuse_fraction <= 1.0:
        raise ValueError(f"light: expected a diffuse fraction in [0, 1], got {diffuse_fraction}")
    directional = compose(directional_colour, directional_texture)
    diffuse = compose(diffuse_colour, diffuse_texture)
    return np.clip(diffuse * diffuse_fraction + directional * (1 - diffuse_fraction), 0.0, 1.0)


def render_panel(
    appearance: Appearance,
    aspecular: float = PANEL_ASPECULAR_DEG,
    size_px: int = 512,
    *,
    diffuse_fraction: float = DIFFUSE_FRACTION,
    distance_m: float = REFERENCE_DISTANCE_M,
    gloss: float = 0.0,
    texture: bool = True,
    seed: int = 0,
) -> NDArray:
    """Flat panel seen at one aspecular angle, within the measured ones: linear-light
    ``[size, size, 3]``."""
    low, high = appearance.aspecular[0], appearance.aspecular[-1]
    if not low <= aspecular <= high:
        raise ValueError(
            f"aspecular: expected an angle within the {_range_kind(appearance)} "
            f"{low:g}–{high:g}° of {appearance.name!r} under the {appearance.lamp:g}° lamp, "
            f"got {aspecular:g}°"
        )
    columns = np.full(size_px, float(aspecular))
    options = dict(diffuse_fraction=diffuse_fraction, distance_m=distance_m, gloss=gloss)
    return _render(appearance, columns, (size_px, size_px), texture=texture, seed=seed, **options)


def _range_kind(appearance: Appearance) -> str:
    if appearance.interpolated_from is None:
        return "measured"
    return f"interpolated (from the {appearance.interpolated_from:g}° lamp's readings)"


def render_curved(
    appearance: Appearance,
    size_px: tuple[int, int] = (512, 1024),
    *,
    diffuse_fraction: float = DIFFUSE_FRACTION,
    distance_m: float = REFERENCE_DISTANCE_M,
    gloss: float = 0.8,
    texture: bool = True,
    seed: int = 0,
    aspecular_range: tuple[float, float] | None = None,
) -> NDArray:
    """Curved panel: columns sweep aspecular 0–110° (paper 001 Fig. 4; under another lamp to
    the last angle it measured: :func:`curved_range`), ``[rows, cols, 3]``."""
    columns = np.linspace(*(aspecular_range or curved_range([appearance])), size_px[1])
    options = dict(diffuse_fraction=diffuse_fraction, distance_m=distance_m, gloss=gloss)
    return _render(appearance, columns, size_px, texture=texture, seed=seed, **options)


def render_stack(
    appearances: Sequence[Appearance], band_px: int = 160, width_px: int = 1024, **options
) -> NDArray:
    """Curved panels of several paints, one band each from top to bottom, touching as panels
    laid side by side in a light booth: ``[bands × band_px, width, 3]``, each over the same
    angles (:func:`curved_range`). Every band takes the same ``options`` of
    :func:`render_curved`, its texture ``seed`` too, so what differs from band to band is the
    paint, not the noise."""
    span = curved_range(appearances)
    bands = [render_curved(a, (band_px, width_px), aspecular_range=span, **options)
             for a in appearances]  # fmt: skip
    return np.concatenate(bands, axis=0)


@dataclass(frozen=True)
class LampStack:
    """Curved panels of several readings under one lamp (:func:`render_under_lamps`):
    ``image`` ``[bands × rows, cols, 3]`` over the aspecular angles ``span``; where
    ``interpolated_from`` names lamps, the readings were not taken under ``lamp`` and are
    their readings under those interpolated over flake tilt."""

    image: NDArray
    span: tuple[float, float]
    lamp: float
    interpolated_from: tuple[float, ...] = ()


def render_under_lamps(
    readings: Sequence[Measurement],
    conditions: Conditions = D65_10,
    lamps: Sequence[float] | None = None,
    **options,
) -> list[LampStack]:
    """Readings as stacks of curved panels (:func:`render_stack`), one stack under each of
    ``lamps`` (default: each lamp every reading was read under, an MA-T12's 45° and 15°;
    :func:`lamps_of`). A lamp not every reading was read under draws each from its own
    first lamp's readings, interpolated over flake tilt (:func:`appearance_under`). None
    shared: the 45° lamp's refusal names the reading that lacks its geometries."""
    read = [lamp for lamp in lamps_of(readings[0]) if all(lamp in lamps_of(m) for m in readings)]
    stacks = []
    for lamp in lamps or read or [LAMP_DEG]:
        if lamp in read or not lamps:
            appearances = [appearance_of(m, conditions, lamp) for m in readings]
        else:
            appearances = [appearance_under(m, lamp, conditions) for m in readings]
        image = render_stack(appearances, **options)
        sources = sorted({a.interpolated_from for a in appearances} - {None}, reverse=True)
        stacks.append(LampStack(image, curved_range(appearances), float(lamp), tuple(sources)))
    return stacks


def parse_lamps(text: str) -> tuple[float, ...]:
    """``45,15`` → the lamps' angles from the normal [°], each from 0 to 89, none twice."""
    try:
        lamps = tuple(float(part) for part in text.split(","))
    except ValueError:
        lamps = ()
    if not lamps or not all(0.0 <= a <= 89.0 for a in lamps) or len(set(lamps)) < len(lamps):
        raise ValueError(
            f"--render-lamps: expected lamp angles from the normal, 0 to 89°, comma-separated "
            f"and each once (45,15), got {text!r}"
        )
    return lamps


def render_grid(
    appearance: Appearance,
    steps: int = 8,
    tile_px: int = 128,
    *,
    aspecular: float = PANEL_ASPECULAR_DEG,
    diffuse_fraction: float = 0.5,
    seed: int = 0,
    processes: dict[str, TextureProcess] | None = None,
) -> NDArray:
    """Paper 001 Fig. 3: colour fixed; glint rises in ``steps`` across, coarseness up.
    Each tile is composed on its own, with one mean over its pixels, so every tile keeps the
    colour (a mean down whole columns would mix the rows' different textures)."""
    processes = processes or shipped_processes()
    glint = np.geomspace(*processes["glint"].value_range, steps)
    coarse = np.geomspace(*processes["coarseness"].value_range, steps)[::-1]  # top: coarsest
    colour = Lab_to_linear_sRGB(cardinal_spline(appearance.aspecular, appearance.Lab, aspecular))
    diffuse_colour = Lab_to_linear_sRGB(appearance.diffuse_Lab)
    side = steps * tile_px
    T_dir, T_diff = texture_images(
        np.repeat(glint, tile_px)[None, :],
        np.repeat(coarse, tile_px)[:, None],
        (side, side),
        seed=seed,
        processes=processes,
    )
    image = np.empty((side, side, 3))
    for i in range(steps):
        for j in range(steps):
            tile = np.s_[i * tile_px : (i + 1) * tile_px, j * tile_px : (j + 1) * tile_px]
            # a tile's texture is uniform: one mean over all its pixels (as one column)
            mixed = _mix(colour, diffuse_colour, T_dir[tile].reshape(-1, 1),
                         T_diff[tile].reshape(-1, 1), diffuse_fraction)  # fmt: skip
            image[tile] = mixed.reshape(tile_px, tile_px, 3)
    return image


def parse_distance(text: str) -> float:
    """``0.5m``, ``50cm``, ``500mm`` (or a bare number of metres) → metres."""
    return parse_amount(text, {"mm": 1e-3, "cm": 1e-2, "m": 1.0}, "--distance", "0.5m or 50cm")


IMAGE_FORMATS = {"png": "png", "jpg": "jpeg", "jpeg": "jpeg", "tif": "tiff", "tiff": "tiff"}
"""An image file's suffix → the format Pillow writes it in: Pillow knows "tiff" and "jpeg",
not "tif" (a ``.tif`` render was refused "error: TIF" before stop 86)."""


def image_format(path) -> str:
    """The image format that ``path``'s suffix names (png, jpeg, tiff), else a ValueError."""
    suffix = str(path).rsplit(".", 1)[-1].lower() if "." in str(path) else ""
    if suffix not in IMAGE_FORMATS:
        raise ValueError(f"{path}: expected an image file ending .png, .jpg or .tif")
    return IMAGE_FORMATS[suffix]


def save_image(image: NDArray, path) -> None:
    """Write a linear-light ``[rows, cols, 3]`` image as 8-bit sRGB (PNG, JPEG, TIFF by the
    file's suffix), atomically."""
    from matplotlib.image import imsave

    fmt = image_format(path)
    pixels = np.round(encode_sRGB(image) * 255).astype(np.uint8)
    write_atomically(path, lambda temporary: imsave(temporary, pixels, format=fmt))
