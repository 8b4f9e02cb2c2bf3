"""Fit the appearance-based processes to anchor panels, and check the closed loop.

Kirchner et al. fitted their constants to BYK-mac images of *anchor panels*: paints whose
texture steps from fine to coarse while their colour stays put. Our anchor panels are the
physical flake images of :mod:`flakelab.texture.images` over a ladder of flake types — a
coarseness ladder (flake radius 3–28 µm, diffuse light) and a glint ladder (flake
alignment and size, 45° lamp). Each anchor's texture value is measured on its image with
:mod:`flakelab.texture.metrics`: graininess G for coarseness c, sparkle grade SG for glint g.

Fitting (paper 001: the squared differences of the histograms' median, mean and 10th–90th
percentiles, minimised): we add the 95th, 99th and 99.9th percentiles, where glints live,
and compare logarithms (the histograms span four decades). Each anchor's controls are
fitted first; the count is not searched but follows from the anchor's measured value through
the expected metric of the patch process (Campbell's theorem for graininess, a sparse-patch
sum for sparkle), so the generator returns the value it is asked for. Then the functional
forms (A, B, e per control) go through the per-anchor controls, the count's form chosen so
the expected value equals the prescribed one across the range.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from importlib.resources import files
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import curve_fit, least_squares, minimize

from flakelab.io.records import write_atomically
from flakelab.texture.generator import (
    CONTROLS,
    PROCESSES,
    UNITS,
    TextureProcess,
    control_values,
    count_for_graininess,
    count_for_sparkle_grade,
    expected_graininess,
    expected_mean,
    expected_sparkle,
    patch_image,
)
from flakelab.texture.images import FlakePopulation, flake_image
from flakelab.texture.metrics import (
    GRAIN_SCALE_UM,
    SPARKLE_LEVEL,
    graininess,
    sparkle,
    sparkle_grade,
)

__all__ = [
    "PERCENTILES",
    "AnchorPanel",
    "anchor_panels",
    "measure_texture",
    "histogram_statistics",
    "fit_process",
    "refit_grey",
    "load_processes",
    "save_processes",
    "shipped_processes",
    "roundtrip",
]

PERCENTILES = (10, 20, 30, 40, 50, 60, 70, 80, 90, 95, 99, 99.9)
"""Histogram percentiles compared (with the mean) between generated and anchor images."""
ANCHOR_LIGHT = {"coarseness": "diffuse", "glint": 45.0}
_MAX_COUNT = 50.0
_REFUSED = 1e3
_LOG_FLOOR = 0.03  # grey levels below 3 % of a white diffuser all look black
_VALUE_WEIGHT = 20.0
_SHIPPED = "texture-processes.json"
_SMOOTHING_PX = GRAIN_SCALE_UM / 15.0  # the metric's smoothing at the camera's 15 µm pixels
_EXPONENTS = {"coarseness": (-4.0, 4.0), "glint": (0.2, 4.0)}
"""Bounds of e: outside them a power law turns into a step; glint's e near 0 into a log."""
ANCHOR_PX = 512
"""Side of the anchor panels the shipped processes were fitted to [pixels]."""


@dataclass(frozen=True)
class AnchorPanel:
    """One rung of a ladder: its flake population, physical image and measured value."""

    population: FlakePopulation
    image: NDArray[np.float64]
    value: float


def _ladder(process: str) -> list[FlakePopulation]:
    """Coarseness: flake radius 3–28 µm at constant flake rate (so near-constant colour).
    Glint: 10 µm flakes from aligned (4° spread) to loose (12°), at constant flake rate."""
    if process == "coarseness":
        rungs = [(a, 10.0) for a in (3.0, 4.0, 5.5, 7.5, 10.0, 13.0, 17.0, 22.0, 28.0)]
    elif process == "glint":
        rungs = [(10.0, s) for s in (4.0, 4.5, 5.0, 5.5, 6.0, 7.0, 8.5, 10.0, 12.0)]
    else:
        raise ValueError(f"process: expected one of {PROCESSES}, got {process!r}")
    return [
        FlakePopulation(np.array([a]), np.array([0.1]), np.array([s]), np.array([0.88]))
        for a, s in rungs
    ]


def measure_texture(process: str, image: NDArray) -> float:
    """Coarseness c = graininess G of a diffuse image; glint g = sparkle grade SG."""
    if process == "coarseness":
        return graininess(image)
    return sparkle_grade(*sparkle(image))


def anchor_panels(process: str, size_px: int = 256, seed: int = 0) -> list[AnchorPanel]:
    """The anchor ladder of ``process``, ordered by increasing measured value."""
    panels = []
    for population in _ladder(process):
        image = flake_image(population, ANCHOR_LIGHT[process], size_px=size_px, seed=seed)
        panels.append(AnchorPanel(population, image, measure_texture(process, image)))
    return sorted(panels, key=lambda p: p.value)


def histogram_statistics(image: NDArray) -> NDArray[np.float64]:
    """log10 of (mean, percentiles) of the grey levels, floored at 3 % of white."""
    stats = np.concatenate([[image.mean()], np.percentile(image, PERCENTILES)])
    return np.log10(np.maximum(stats, _LOG_FLOOR))


def _mismatch(process: str, controls: dict, anchor: AnchorPanel, shape, seed: int) -> float:
    """Histogram and value mismatch of the process's image with the anchor's; a count the
    prescribed value cannot be reached with (infinite, or above 50 patches per pixel) is
    refused with a large loss before any image is drawn."""
    if not np.isfinite(controls["count"]) or controls["count"] > _MAX_COUNT:
        return _REFUSED
    image = patch_image(**controls, shape=shape, rng=np.random.default_rng(seed))
    value = measure_texture(process, image)
    stats = histogram_statistics(image) - histogram_statistics(anchor.image)
    missed = np.log(max(value, 1e-3) / anchor.value)
    return float(np.mean(stats**2) + _VALUE_WEIGHT * missed**2)


def _initial_controls(process: str, anchor: AnchorPanel) -> NDArray:
    """A physical first guess of the free controls: (size, sparkler) for coarseness, (size,
    grey, sparkler) for glint."""
    radius = float(anchor.population.radius_um[0])
    if process == "coarseness":
        return np.array([max(2 * radius / 15.0, 0.5), 20.0])
    return np.array([1.5, 200.0, 30.0])


def _complete(process: str, free: NDArray, value, mean: float) -> dict[str, float]:
    """All four controls from the free ones: the count (and for coarseness the grey level)
    that give the prescribed ``value`` (and ``mean`` grey) in expectation."""
    if process == "coarseness":
        size, sparkler = free
        count = float(count_for_graininess(value, size, sparkler, _SMOOTHING_PX))
        grey = float(mean / expected_mean(size, 1.0, count, sparkler))
    else:
        size, grey, sparkler = free
        count = count_for_sparkle_grade(value, size, grey, sparkler, SPARKLE_LEVEL)
    return {"size": size, "grey": grey, "count": count, "sparkler": sparkler}


def _fit_anchor(process: str, anchor: AnchorPanel, shape, seed: int) -> NDArray:
    """Controls (size, grey, count, sparkler) best matching one anchor's histogram. The count
    is not searched: it follows from the anchor's measured texture value through the
    process's expected metric (Campbell's theorem for graininess, the sparse-patch sum for
    sparkle), so the closed loop holds by construction; coarseness's grey level likewise
    follows from the anchor's mean grey."""
    mean = float(anchor.image.mean())

    def controls(log_free):
        free = np.exp(log_free)
        free[-1] += 1.0  # the sparkler is a range ≥ 1
        return _complete(process, free, anchor.value, mean)

    def loss(log_free):
        return _mismatch(process, controls(log_free), anchor, shape, seed)

    start = np.log(_initial_controls(process, anchor))
    result = minimize(loss, start, method="Nelder-Mead", options={"maxiter": 400})
    best = controls(result.x)
    return np.array([best[c] for c in CONTROLS])


def _power_law(v, A, B, e):
    return A + B * v**e


def _positive_power_law(v, A, B, e):
    return np.log(np.maximum(_power_law(v, A, B, e), 1e-12))


def _fit_form(process: str, values, raw):
    """(A, B, e) of one control through the per-anchor fitted values (eq. 2 or 4). A power
    law is fitted to the logarithms: positive at every anchor, and so (monotone) across the
    ladder, where a fit in linear units, pulled by one large value, could cross zero inside
    the range."""
    if process == "coarseness":
        target = np.log(raw)
        form = _positive_power_law
    else:  # invert 1 + 100/(1 + exp(z)) and fit z = A + B·g^e
        y = np.clip(raw, 1.02, 100.5)
        target = np.log(100.0 / (y - 1.0) - 1.0)
        form = _power_law
    low, high = _EXPONENTS[process]
    level = float(np.exp(target.mean())) if process == "coarseness" else target.mean()
    best, best_cost = np.array([level, 0.0, 1.0]), np.inf
    for e0 in (-1.0, 0.5, 1.0, 2.0):
        if not low <= e0 <= high:
            continue
        bounds = ([-np.inf, -np.inf, low], [np.inf, np.inf, high])
        start = (level, 0.0, e0)
        try:
            constants, _ = curve_fit(form, values, target, start, bounds=bounds, maxfev=20000)
        except RuntimeError:
            continue
        cost = np.sum((form(values, *constants) - target) ** 2)
        if cost < best_cost:
            best, best_cost = constants, cost
    return best


def fit_process(
    process: str,
    *,
    size_px: int = 256,
    anchor_px: int = ANCHOR_PX,
    seed: int = 0,
    iterations: int = 400,
    progress: Callable[[str], None] | None = None,
) -> tuple[TextureProcess, dict]:
    """Fit ``process`` to its anchor ladder; returns the process and a report."""
    note = progress or (lambda _: None)
    anchors = anchor_panels(process, size_px=anchor_px, seed=seed)
    shape = (size_px, size_px)
    per_anchor = []
    for i, anchor in enumerate(anchors):
        note(f"{process}: anchor {i + 1}/{len(anchors)} (value {anchor.value:.2f})")
        per_anchor.append(_fit_anchor(process, anchor, shape, seed + 1))
    per_anchor = np.array(per_anchor)  # [anchor, control]
    values = np.array([a.value for a in anchors])
    units = np.array([UNITS[process][c] for c in CONTROLS])
    constants = np.array(
        [_fit_form(process, values, per_anchor[:, j] / units[j]) for j in range(4)]
    )
    note(f"{process}: fitting the forms of size, grey level and sparkler over the ladder")
    constants = _fit_free_forms(process, constants, anchors, shape, seed + 1, iterations)
    constants = _fit_closed_loop(process, constants, values, per_anchor)
    if process == "coarseness":
        constants = _fit_grey_to_means(constants, anchors)
    fitted = TextureProcess(process, constants, (float(values[0]), float(values[-1])))
    mismatch = [_mismatch(process, fitted.controls(a.value), a, shape, seed + 1) for a in anchors]
    report = {
        "process": process,
        "anchor_values": values.round(4).tolist(),
        "anchor_controls": per_anchor.round(5).tolist(),
        "histogram_mismatch": np.round(mismatch, 4).tolist(),
    }
    return fitted, report


def _fit_free_forms(process, constants, anchors, shape, seed, iterations) -> NDArray:
    """Refine the forms of the searched controls together over the whole ladder (the
    paper's joint fit), each anchor's count (and coarseness grey) following from its value,
    so that noise in single anchors' fits does not bend the forms."""
    free_rows = [0, 3] if process == "coarseness" else [0, 1, 3]

    ends = np.array([anchors[0].value, anchors[-1].value])

    def ladder_loss(flat):
        trial = constants.copy()
        trial[free_rows] = flat.reshape(len(free_rows), 3)
        trial[:, 2] = np.clip(trial[:, 2], *_EXPONENTS[process])
        if process == "coarseness" and np.any(
            _power_law(ends, *trial[free_rows].T[..., None]) <= 0
        ):
            return _REFUSED  # a form that leaves its domain inside the ladder (monotone: its ends)
        total = 0.0
        for anchor in anchors:
            controls = control_values(process, trial, anchor.value)
            free = np.array([float(controls[CONTROLS[r]]) for r in free_rows])
            full = _complete(process, free, anchor.value, float(anchor.image.mean()))
            loss = _mismatch(process, full, anchor, shape, seed)
            if loss >= _REFUSED:
                return _REFUSED
            total += loss
        return total / len(anchors)

    start = constants[free_rows].ravel()
    result = minimize(
        ladder_loss, start, method="Nelder-Mead", options={"maxiter": iterations, "adaptive": True}
    )
    best = constants.copy()
    if result.fun < ladder_loss(start):
        best[free_rows] = result.x.reshape(len(free_rows), 3)
    best[:, 2] = np.clip(best[:, 2], *_EXPONENTS[process])
    return best


def expected_value(process: str, controls: dict) -> float:
    """The texture value a process's controls give in expectation (the metric's value)."""
    if process == "coarseness":
        size, count, sparkler = (controls[c] for c in ("size", "count", "sparkler"))
        return float(expected_graininess(size, count, sparkler, _SMOOTHING_PX))
    floats = {k: float(v) for k, v in controls.items()}
    return sparkle_grade(*expected_sparkle(**floats, level=SPARKLE_LEVEL))


def _fit_closed_loop(
    process: str, constants: NDArray, values: NDArray, per_anchor: NDArray
) -> NDArray:
    """Refit the count's (A, B, e) — for glint the grey level's too — so that the expected
    texture value equals the prescribed one across the ladder's range (the closed loop, in
    expectation); the grey level is held near its per-anchor fits by a weak penalty, so the
    histograms stay matched. Graininess does not depend on the grey level (Campbell)."""
    rows = [2] if process == "coarseness" else [1, 2]
    prescribed = np.geomspace(values[0], values[-1], 25)
    low, high = _EXPONENTS[process]

    def residuals(flat):
        full = constants.copy()
        full[rows] = flat.reshape(len(rows), 3)
        controls = control_values(process, full, prescribed)
        got = [
            expected_value(process, {k: v[i] for k, v in controls.items()})
            for i in range(prescribed.size)
        ]
        missed = np.log(np.maximum(got, 1e-9) / prescribed)
        if len(rows) == 1:
            return missed
        grey = control_values(process, full, values)["grey"]
        return np.concatenate([missed, 0.2 * np.log(grey / per_anchor[:, 1])])

    bounds = (
        np.tile([-np.inf, -np.inf, low], len(rows)),
        np.tile([np.inf, np.inf, high], len(rows)),
    )
    start = np.clip(constants[rows].ravel(), *bounds)
    best = constants.copy()
    best[rows] = least_squares(residuals, start, bounds=bounds).x.reshape(len(rows), 3)
    return best


def _fit_grey_to_means(constants: NDArray, anchors: list[AnchorPanel]) -> NDArray:
    """Coarseness: refit the grey level's (A, B, e) so that the process's mean grey (Campbell)
    is each anchor's, in log, with the final forms of size, count and sparkler. The grey
    levels its first form went through followed from the anchors' means with the controls
    before the joint and closed-loop refits; after them that form no longer gave the
    anchors' brightness (at the bottom of the ladder it fell below zero, and the rendered
    grain vanished). Graininess does not depend on it, so the closed loop holds."""
    values = np.array([a.value for a in anchors])
    means = np.array([float(a.image.mean()) for a in anchors])

    def residuals(grey_form):
        trial = constants.copy()
        trial[1] = grey_form
        c = control_values("coarseness", trial, values)
        return np.log(expected_mean(c["size"], c["grey"], c["count"], c["sparkler"]) / means)

    low, high = _EXPONENTS["coarseness"]
    fits = [
        least_squares(
            residuals, (0.0, 1.0, e0), bounds=([-np.inf, -np.inf, low], [np.inf, np.inf, high])
        )
        for e0 in (-1.0, 0.5, 1.0, 2.0)
    ]
    best = constants.copy()
    best[1] = min(fits, key=lambda fit: fit.cost).x
    return best


def refit_grey(
    process: TextureProcess, *, anchor_px: int = ANCHOR_PX, seed: int = 0
) -> TextureProcess:
    """A fitted coarseness process with its grey level refitted to the anchors' brightness
    (:func:`_fit_grey_to_means`), its other controls kept."""
    if process.process != "coarseness":
        raise ValueError(f"{process.process}: only the coarseness grey level follows the anchors")
    anchors = anchor_panels("coarseness", size_px=anchor_px, seed=seed)
    constants = _fit_grey_to_means(process.constants, anchors)
    return TextureProcess(process.process, constants, process.value_range)


def roundtrip(
    process: TextureProcess, points: int = 9, size_px: int = 1024, seed: int = 100
) -> dict:
    """Closed loop: generate at prescribed values across the usable range, measure them."""
    low, high = process.value_range
    prescribed = np.geomspace(low, high, points)
    measured = np.array(
        [
            measure_texture(process.process, process.image(v, (size_px, size_px), seed + i))
            for i, v in enumerate(prescribed)
        ]
    )
    relative = np.abs(measured / prescribed - 1)
    return {
        "prescribed": prescribed.round(4).tolist(),
        "measured": measured.round(4).tolist(),
        "rel_error": relative.round(4).tolist(),
        "rel_error_max": float(relative.max()),
    }


def save_processes(processes: dict[str, TextureProcess], path: Path) -> None:
    document = {
        name: {
            "constants": p.constants.tolist(),
            "value_range": list(p.value_range),
            "controls": list(CONTROLS),
        }
        for name, p in processes.items()
    }
    text = json.dumps(document, indent=2) + "\n"
    write_atomically(path, lambda temporary: temporary.write_text(text))


def load_processes(path: Path) -> dict[str, TextureProcess]:
    """Fitted processes from a JSON file written by :func:`save_processes`."""
    try:
        document = json.loads(Path(path).read_text())
        return {
            name: TextureProcess(
                name,
                np.array(document[name]["constants"], float),
                tuple(document[name]["value_range"]),
            )
            for name in PROCESSES
        }
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise ValueError(f"{path}: not a texture-process file ({error})") from error


@cache
def shipped_processes() -> dict[str, TextureProcess]:
    """The processes fitted by ``scripts/fit_texture.py`` and shipped with the package."""
    return load_processes(Path(str(files("flakelab.data") / _SHIPPED)))
