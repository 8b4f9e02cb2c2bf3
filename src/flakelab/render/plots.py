"""Plots of multi-angle measurements: spectra per geometry, L* and C* versus aspecular angle;
the multi-angle difference chart against a tolerance; the scaling experiment; a shop's habits
against its spray-outs; a shop's tins version by version."""

from __future__ import annotations

import logging
import textwrap
import warnings
from collections.abc import Mapping, Sequence
from os import PathLike
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.ticker import FixedLocator, FormatStrFormatter, NullFormatter  # noqa: E402

from flakelab.core.colorimetry import (  # noqa: E402
    D65_10,
    Conditions,
    Lab_to_LCh,
    Lab_to_sRGB,
    reflectance_to_Lab,
)
from flakelab.core.geometry import FLOP_AXES, Geometry  # noqa: E402
from flakelab.core.measurement import Measurement  # noqa: E402
from flakelab.core.tolerance import Tolerance  # noqa: E402
from flakelab.core.wording import counted  # noqa: E402
from flakelab.errors import Note  # noqa: E402
from flakelab.io.records import write_atomically  # noqa: E402

__all__ = [
    "figure_format",
    "plot_measurements",
    "plot_differences",
    "plot_scaling",
    "plot_habits",
    "plot_variants",
    "plot_tins_history",
    "plot_pigment_read",
    "plot_flake_read",
    "plot_hiding",
    "plot_model_errors",
    "plot_harness",
    "plot_realism",
    "plot_losses",
    "plot_rendering",
    "plot_side_by_side",
    "plot_camera_pictures",
    "flop_series",
    "FLOP_AXES",
]


def figure_format(path: str | PathLike) -> str:
    """The format a figure file's suffix names (PNG without one); checked before any work,
    so that a mistyped name does not cost a whole run."""
    from matplotlib.backend_bases import FigureCanvasBase

    fmt = Path(path).suffix.lstrip(".").lower() or "png"
    if fmt not in FigureCanvasBase.get_supported_filetypes():
        raise ValueError(f"{path}: expected a figure file ending .png, .pdf, .svg or .jpg")
    return fmt


def _save(figure, path: str | PathLike, dpi: int) -> None:
    """Lay ``figure`` out and write it atomically, in the format its suffix names, then
    free it."""
    try:
        fmt = figure_format(path)
        figure.tight_layout()
        write_atomically(path, lambda temporary: _savefig(figure, temporary, dpi, fmt, path))
    finally:
        plt.close(figure)


def _savefig(figure, path: Path, dpi: int, fmt: str, named: str | PathLike) -> None:
    """``figure.savefig``, where a write the disk refused is raised as that ``OSError``:
    matplotlib's PDF writer, closing its stream after it, fails again in zlib ("Error -2 while
    flushing"), and that error, not the disk's, reached the user as an internal error. The
    transparency PostScript cannot hold is told as a :class:`~flakelab.errors.Note`, where
    matplotlib's own line named neither the file (``named``) nor what to write instead."""
    dropped = _DroppedTransparency()
    postscript = logging.getLogger("matplotlib.backends.backend_ps")
    postscript.addFilter(dropped)
    try:
        figure.savefig(path, dpi=dpi, format=fmt)
    except Exception as error:
        refused = error.__context__
        if isinstance(error, OSError) or not isinstance(refused, OSError):
            raise
        raise refused from None
    finally:
        postscript.removeFilter(dropped)
    if dropped.seen:
        warnings.warn(f"{named}: PostScript holds no transparency, so the grid and the "
                      "shaded areas are drawn opaque (PDF, SVG and PNG keep it)", Note,
                      stacklevel=3)  # fmt: skip


class _DroppedTransparency(logging.Filter):
    """Matplotlib's PostScript writer logging that it drew transparent artists opaque."""

    seen = False

    def filter(self, record: logging.LogRecord) -> bool:
        if "does not support transparency" in record.getMessage():
            self.seen = True
            return False
        return True


def flop_series(
    measurement: Measurement, conditions: Conditions = D65_10, against: str = "aspecular"
) -> dict[float, tuple[np.ndarray, np.ndarray]]:
    """Per lamp (illumination angle): the in-plane geometries it lit, as ``x`` (the aspecular
    angle, or ``"flake-tilt"``: θ_flake) ascending and their L*, C*ab ``[K, 2]``."""
    from flakelab.core.geometry import flake_angles, lit_by

    if against not in FLOP_AXES:
        raise ValueError(f"against: expected one of {', '.join(FLOP_AXES)}, got {against!r}")
    lch = Lab_to_LCh(measurement.lab(conditions))
    series = {}
    for lamp in sorted({g.illumination for g in measurement.geometries if g.in_plane}):
        rows = lit_by(measurement.geometries, lamp)
        lit = [measurement.geometries[i] for i in rows]
        x = (flake_angles(lit)[0] if against == "flake-tilt"
             else np.array([g.aspecular for g in lit]))  # fmt: skip
        order = np.argsort(x, kind="stable")
        series[lamp] = (x[order], lch[np.asarray(rows)[order], :2])
    return series


def plot_measurements(
    measurements: list[Measurement],
    path: str | PathLike,
    *,
    conditions: Conditions = D65_10,
    against: str = "aspecular",
    dpi: int = 120,
) -> None:
    """Save a figure: reflectance spectra per geometry (one row per sample; line colour by
    aspecular angle, dashed for illumination below 30°) and L*, C*ab versus aspecular angle
    (or flake tilt: :func:`flop_series`) per illumination angle."""
    n = len(measurements)
    figure, axes = plt.subplots(n, 2, figsize=(11, 3.6 * n), squeeze=False)
    for row, m in enumerate(measurements):
        spectra, trend = axes[row]
        aspecular = np.array([g.aspecular for g in m.geometries])
        span = np.ptp(aspecular) or 1.0
        for i, g in enumerate(m.geometries):
            spectra.plot(
                m.wavelengths,
                m.reflectance[i],
                color=plt.cm.viridis((g.aspecular - aspecular.min()) / span),
                ls="-" if g.illumination >= 30 else "--",
                lw=1.5,
                label=g.name,
            )
        # spectra recovered from L*a*b* are one metamer of many: drawn so, not as measured
        recovered = " (recovered from L*a*b*: one metamer)" if m.spectra_recovered else ""
        spectra.set(
            xlabel="wavelength [nm]", ylabel="reflectance factor", title=m.sample + recovered
        )
        spectra.legend(fontsize=7, ncol=2, frameon=False)
        spectra.grid(alpha=0.3)

        lightness_axis, chroma_axis = trend, trend.twinx()
        series = flop_series(m, conditions, against)
        for illumination, (x, lc) in series.items():
            lightness_axis.plot(x, lc[:, 0], "o-", label=f"L*  {illumination:g}° light")
            chroma_axis.plot(x, lc[:, 1], "s--", alpha=0.7, label=f"C*  {illumination:g}° light")
        lightness_axis.set(xlabel=FLOP_AXES[against], ylabel="L*", title=f"flop ({conditions})")
        chroma_axis.set_ylabel("C*ab")
        handles = lightness_axis.get_legend_handles_labels()
        extra = chroma_axis.get_legend_handles_labels()
        lightness_axis.legend(
            handles[0] + extra[0], handles[1] + extra[1], fontsize=7, frameon=False
        )
        lightness_axis.grid(alpha=0.3)
        if against == "aspecular":
            lightness_axis.set_xticks(np.unique(aspecular))
            lightness_axis.tick_params(axis="x", labelrotation=60, labelsize=8)
    _save(figure, path, dpi)


DIFFERENCE_COMPONENTS = ("ΔL*", "ΔC*", "ΔH*")


def plot_differences(
    geometries: Sequence[str],
    reference_lab: np.ndarray,
    samples: Mapping[str, np.ndarray],
    tolerance: Tolerance,
    path: str | PathLike,
    *,
    title: str = "",
    apart: int | None = None,
    apart_label: str = "",
    texture: Mapping[str, Mapping[str, float]] | None = None,
    dpi: int = 120,
) -> None:
    """The multi-angle difference chart: ΔL*, ΔC*, ΔH* of each sample's CIELAB ``[G, 3]``
    from the reference's at every geometry, inside the tolerance's limits where it bounds
    them, and how much of each geometry's limit the difference uses (≤ 100 % passes; failing
    geometries ringed), all as ``tolerance`` judges them. Geometries from index ``apart`` on
    are drawn dashed with open markers beyond a dotted line, labelled ``apart_label``
    (predicted by another model, say). Lines join geometries of one illumination angle.
    ``texture`` (sample label → reading → share of its limit, as
    :meth:`~flakelab.core.tolerance.Tolerance.texture_share` gives it) adds the bounded
    texture readings to the share panel, right of the geometries."""
    names = list(geometries)
    x = np.arange(len(names))
    apart = len(names) if apart is None else apart
    groups = _geometry_groups(names, apart)
    bounds = tolerance.bounds(names)
    judged = {label: tolerance.judge(names, reference_lab, lab) for label, lab in samples.items()}
    figure, axes = plt.subplots(2, 2, figsize=(12, 7.5))
    component_axes = (axes[0, 0], axes[0, 1], axes[1, 0])
    for axis in component_axes[1:]:
        axis.sharex(component_axes[0])
    for k, (axis, label) in enumerate(zip(component_axes, DIFFERENCE_COMPONENTS, strict=True)):
        limit = bounds[:, k + 1]
        bounded = np.isfinite(limit)
        if bounded.any():
            shown = np.where(bounded, limit, np.nan)
            axis.fill_between(x, -shown, shown, step="mid", color="0.88", label="limit")
        axis.axhline(0.0, color="0.3", lw=0.8)
        values = np.concatenate([dLCH[:, k] for _, dLCH, _ in judged.values()])
        scale = np.max(limit[bounded]) if bounded.any() else np.min(bounds[:, 0])
        span = 1.1 * max(np.max(np.abs(values), initial=0.0), scale if np.isfinite(scale) else 0)
        axis.set_ylim(-span or -1.0, span or 1.0)  # the limits' scale, not the differences'
        note = "" if bounded.any() else "  (no limit of its own)"
        axis.set(ylabel=label, title=label + note)
    used = axes[1, 1]
    used.axhline(100.0, color="tab:red", lw=1.0, ls="--", label="limit")
    used.set(ylabel="share of the limit used [%]", title=f"tolerance {tolerance.name}")
    for index, (label, (de00, dLCH, passed)) in enumerate(judged.items()):
        share = 100.0 * tolerance.share_of_limit(names, de00=de00, dLCH=dLCH)
        colour = f"C{index}"
        for k, axis in enumerate(component_axes):
            _plot_series(axis, x, dLCH[:, k], groups, colour, label)
        _plot_series(used, x, share, groups, colour, label)
        used.scatter(
            x[~passed], share[~passed], s=140, facecolors="none", edgecolors="tab:red", zorder=3
        )
    for axis in axes.flat:
        if apart < len(names):
            axis.axvline(apart - 0.5, color="0.4", ls=":", lw=1.0)
        axis.grid(alpha=0.3)
        axis.set_xticks(x, names, rotation=60, fontsize=8)
    if texture and any(texture.values()):
        _plot_texture_shares(used, len(names), texture, list(samples))
    if apart < len(names):
        used.annotate(textwrap.fill(apart_label, 28), (apart - 0.4, 1.0),
                      xycoords=("data", "axes fraction"), xytext=(0, -6),
                      textcoords="offset points", va="top", fontsize=7)  # fmt: skip
    used.set_ylim(bottom=0.0, top=max(125.0, used.get_ylim()[1]))
    axes[0, 0].legend(fontsize=7, frameon=False)
    used.legend(fontsize=7, frameon=False)
    figure.suptitle(_fitted(title, figure))
    _save(figure, path, dpi)


def _plot_texture_shares(axis, start: int, texture, labels: list[str]) -> None:
    """Each sample's texture shares (per cent of each bounded reading's limit) at positions
    ``start`` + 1, …, beyond a dotted line, failing ones ringed, the samples' colours kept
    and each set a little aside so that equal shares do not hide one another."""
    readings = list(dict.fromkeys(k for shares in texture.values() for k in shares))
    x = start + 1 + np.arange(len(readings))
    for index, label in enumerate(labels):
        shares = texture.get(label, {})
        at = [i for i, k in enumerate(readings) if k in shares]
        share = 100.0 * np.array([shares[readings[i]] for i in at])
        aside = x[at] + 0.15 * (index - (len(labels) - 1) / 2)
        axis.plot(aside, share, "s", color=f"C{index}")
        failing = share > 100.0
        axis.scatter(aside[failing], share[failing], s=140, facecolors="none",
                     edgecolors="tab:red", zorder=3)  # fmt: skip
    axis.axvline(start, color="0.4", ls=":", lw=1.0)
    ticks = [*axis.get_xticks(), *x]
    names = [t.get_text() for t in axis.get_xticklabels()] + [f"texture {k}" for k in readings]
    axis.set_xticks(ticks, names, rotation=60, fontsize=8)


def _geometry_groups(names: list[str], apart: int) -> list[tuple[np.ndarray, bool]]:
    """Runs of neighbouring geometries that one line joins (same illumination angle, same
    side of ``apart``), each with whether it lies beyond ``apart``."""
    keys = [(Geometry.parse(n).illumination, i >= apart) for i, n in enumerate(names)]
    starts = [i for i in range(len(keys)) if i == 0 or keys[i] != keys[i - 1]]
    ends = [*starts[1:], len(keys)]
    return [(np.arange(a, b), keys[a][1]) for a, b in zip(starts, ends, strict=True)]


def _plot_series(axis, x, y, groups, colour: str, label: str) -> None:
    """One sample's values along the geometries, a line per group (dashed with open markers
    beyond the chart's ``apart``), labelled once."""
    for n, (rows, apart) in enumerate(groups):
        axis.plot(x[rows], y[rows], "o--" if apart else "o-", color=colour,
                  mfc="none" if apart else colour, label=None if n else label)  # fmt: skip


def plot_scaling(series, path: str | PathLike, *, dpi: int = 120) -> None:
    """The hybrid paper's Figs. 5–7 for a :class:`~flakelab.physics.scaling.ScalingSeries`:
    normalised g̃ of every sample against the dye's normalised extinction (Monte Carlo);
    g at a near-specular and a far geometry for Monte Carlo, fast model and single-collision
    scaling; the span of g against dye concentration with straight-line fits."""
    from flakelab.physics.scaling import TABLE1_DYE, dye_extinction

    wl = np.arange(400, 701, 10)
    figure, (shape, curves, span) = plt.subplots(1, 3, figsize=(16, 4.6))
    g_mc = series.g(series.monte_carlo)
    near, far = series.geometries.index("45as15"), series.geometries.index("45as75")
    for i, c in enumerate(TABLE1_DYE):
        colour_ = plt.cm.Blues(0.35 + 0.65 * i / (len(TABLE1_DYE) - 1))
        shape.plot(wl, g_mc[i, near] / g_mc[i, near].max(), color=colour_, label=f"{c:.2%}")
    eps = dye_extinction()
    shape.plot(wl, eps / eps.max(), "k--", label="extinction")
    shape.set(xlabel="wavelength [nm]", ylabel="g̃ = g / max g", title="45as15, Monte Carlo")
    shape.legend(fontsize=7, title="dye PVC", title_fontsize=7)
    methods = (
        ("Monte Carlo", g_mc, "-"),
        ("fast model", series.g(series.fast), "--"),
        ("single collision", series.g(series.single, series.single_base), ":"),
    )
    for label, g, style in methods:
        for index, colour_ in ((near, "tab:blue"), (far, "tab:red")):
            curves.plot(
                wl, g[-1, index], style, color=colour_, label=f"{label}, {series.geometries[index]}"
            )
    curves.set(
        xlabel="wavelength [nm]", ylabel="g = f0/f − 1", title=f"dye PVC {TABLE1_DYE[-1]:.2%}"
    )
    curves.legend(fontsize=7)
    for label, g, style in methods:
        spans = g.max(-1) - g.min(-1)
        for index, colour_ in ((near, "tab:blue"), (far, "tab:red")):
            span.plot(
                TABLE1_DYE * 100,
                spans[:, index],
                "o" + style,
                color=colour_,
                ms=3,
                label=f"{label}, {series.geometries[index]}",
            )
    span.set(
        xlabel="dye PVC [%]",
        ylabel="span of g (max − min over λ)",
        title="degree of non-uniformity",
    )
    span.legend(fontsize=7)
    figure.suptitle(f"Scaling experiment, orientation spread {series.spread_deg:g}°")
    _save(figure, path, dpi)


def _plot_change_scan(axis, scan: dict) -> None:
    """Each habit's z (later habits against earlier) at every split of the cases in time."""
    for k, name in enumerate(scan["names"]):
        axis.plot(scan["when"], scan["z"][:, k], "-", lw=1.2, label=name)
    for sign in (-1, 1):
        axis.axhline(sign * scan["bar"], color="0.5", ls="--", lw=0.8)
    if scan["changed"]:
        axis.axvline(scan["split_when"], color="k", lw=0.8, label="change found")
    else:  # the split of the largest difference, under the bar: no change
        axis.axvline(scan["split_when"], color="0.5", lw=0.8, ls=":", label="largest, no change")
    axis.set(
        xlabel="split: the first case of the later habits",
        ylabel="later − earlier [s.e.]",
        title="Did the habits change? Each split of the cases in time order",
    )
    axis.legend(fontsize=8, ncol=4)


def plot_habits(
    fit: dict,
    path: str | PathLike,
    *,
    title: str = "",
    scan: dict | None = None,
    dpi: int = 120,
) -> None:
    """What a shop's habits explain (:func:`~flakelab.match.habits.habits_fit`): the mean
    ΔL*, Δa*, Δb* of its spray-outs from the model (points) and the habits' mean offset (line)
    against aspecular angle, and the mean ΔE00 per geometry from the model alone and with
    the habits. With ``scan`` a second row shows the change scan
    (:func:`~flakelab.match.habits.change_scan`): each habit's later-minus-earlier z
    (``z[K, H]``, habits ``names``) at the time of every split (``when[K]``), the bar ``±bar``
    and the split found (``split_when``; ``changed``: whether it passes the bar)."""
    names = fit["geometries"]
    aspecular = np.array([Geometry.parse(n).aspecular for n in names])
    order = np.argsort(aspecular)
    figure = plt.figure(figsize=(16, 3.8 if scan is None else 7.4))
    grid = figure.add_gridspec(1 if scan is None else 2, 4)
    axes = [figure.add_subplot(grid[0, i]) for i in range(4)]
    for axis in axes[1:3]:  # one scale: a small Δa* is not drawn as large as ΔL*
        axis.sharey(axes[0])
    for k, (axis, label) in enumerate(zip(axes[:3], ("ΔL*", "Δa*", "Δb*"), strict=True)):
        axis.axhline(0, color="0.7", lw=0.8)
        axis.plot(aspecular[order], fit["offset_measured"][order, k], "o", label="spray-outs")
        axis.plot(aspecular[order], fit["offset_habits"][order, k], "-", label="habits")
        axis.set(xlabel="aspecular angle [°]", ylabel=f"mean {label} from the model")
    axes[0].legend(fontsize=8)
    bars = axes[3]
    position = np.arange(len(names))
    bars.bar(position - 0.2, fit["de00_model"][order], 0.4, label="model alone")
    bars.bar(position + 0.2, fit["de00_habits"][order], 0.4, label="with the habits")
    bars.set_xticks(position, [names[i] for i in order], rotation=45, fontsize=8)
    bars.set(ylabel="mean ΔE00 of the spray-outs")
    bars.legend(fontsize=8)
    if scan is not None:
        _plot_change_scan(figure.add_subplot(grid[1, :]), scan)
    figure.suptitle(title or f"Shop habits against {fit['cases']} spray-outs")
    _save(figure, path, dpi)


LEGEND_VARIANTS = 10
"""Variants a figure of a code's variants names in its legend (the ten colours it cycles)."""


def plot_variants(variants: Sequence, path: str | PathLike, *, title: str = "",
                  car: np.ndarray | None = None, dpi: int = 120) -> None:  # fmt: skip
    """A colour code's variants (:class:`~flakelab.cases.variants.ColourVariant`, most cars
    first): every car's ΔL*, Δa*, Δb* from the main variant's centre car against aspecular
    angle (a code's variants differ by a unit or two, which L* itself, 10 to 100 over the
    angles, would hide), each variant in its own colour, its centre car bold; the ``car`` in
    the booth (reflectance ``[G, 31]`` at their geometries) black and dashed."""
    geometries = variants[0].centre.geometries
    aspecular = np.array([g.aspecular for g in geometries])
    order = np.argsort(aspecular)
    x = aspecular[order]
    main = reflectance_to_Lab(variants[0].centre.target)[order]
    figure, axes = plt.subplots(1, 3, figsize=(15, 4.4), sharey=True)
    for k, variant in enumerate(variants):
        colour = plt.cm.tab10(k % 10)
        cars = reflectance_to_Lab(np.stack([c.target for c in variant.cases]))[:, order] - main
        centre = reflectance_to_Lab(variant.centre.target)[order] - main
        shown = k < LEGEND_VARIANTS  # more would bury the lines; the rest drawn unnamed
        label = f"#{k + 1} ({counted(len(variant.cases), 'car')})" if shown else None
        for j, axis in enumerate(axes):
            axis.plot(x, cars[..., j].T, color=colour, alpha=0.2, lw=0.8)
            axis.plot(x, centre[:, j], "o-", color=colour, lw=2, label=label)
    if car is not None:
        booth = reflectance_to_Lab(car)[order] - main
        for j, axis in enumerate(axes):
            axis.plot(x, booth[:, j], "s--", color="k", lw=1.5, label="the car")
    for axis, name in zip(axes, ("ΔL*", "Δa*", "Δb*"), strict=True):
        axis.axhline(0, color="0.6", lw=0.8)
        axis.set(xlabel="aspecular angle [°]", ylabel=f"{name} from #1's centre car")
        axis.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    figure.suptitle(title or f"{counted(len(variants), 'variant')} of a colour code")
    _save(figure, path, dpi)


def plot_tins_history(
    tins: Mapping[str, Sequence[Mapping]], path: str | PathLike, *, title: str = "", dpi: int = 120
) -> None:
    """A shop's tins version by version (``flakelab lots history --plot``): each toner's
    strength against the standard and, where read, its shade [nm], with a bar of ± one
    standard deviation, against the version of the shop's tins. ``tins``: each toner's tins
    (:func:`~flakelab.cases.shop_lots.tins_through`); a tin is one line, a new tin of the
    toner starts another (an open marker) in the toner's colour."""
    figure, (strength, shade) = plt.subplots(1, 2, figsize=(13, 4.6), sharex=True)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    versions = sorted({v for runs in tins.values() for tin in runs for v in tin["version"]})
    for k, (name, runs) in enumerate(sorted(tins.items())):
        colour = colours[k % len(colours)]
        for i, tin in enumerate(runs):
            marker = dict(marker="o", mfc=colour if i == 0 else "white", color=colour, capsize=2)
            label = name if i == 0 else None
            strength.errorbar(tin["version"], tin["strength"], tin["strength_sd"], label=label,
                              **marker)  # fmt: skip
            read = [j for j, value in enumerate(tin["shade_nm"]) if value is not None]
            if read:
                shade.errorbar([tin["version"][j] for j in read],
                               [tin["shade_nm"][j] for j in read],
                               [tin["shade_sd_nm"][j] for j in read], **marker)  # fmt: skip
    strength.axhline(1.0, color="0.6", lw=0.8)
    shade.axhline(0.0, color="0.6", lw=0.8)
    strength.set(xlabel="version", ylabel="strength against the standard (± 1 s.d.)")
    shade.set(xlabel="version", ylabel="shade [nm] (± 1 s.d.; where read)")
    strength.set_xticks(versions)
    strength.legend(fontsize=8, ncol=2)
    title = title or "A shop's tins, version by version"
    figure.suptitle(f"{title} (open marker: a new tin)")
    _save(figure, path, dpi)


def plot_pigment_read(
    wavelengths: np.ndarray,
    fitted: Mapping[str, np.ndarray],
    start: Mapping[str, np.ndarray],
    sd: Mapping[str, np.ndarray],
    geometries: Sequence[str],
    panels: Mapping[str, np.ndarray],
    path: str | PathLike,
    *,
    title: str = "",
    dpi: int = 120,
) -> None:
    """A pigment read from calibration panels (``flakelab library characterise --plot``):
    its absorption and scattering [1/µm] fitted, with a band of ± one standard deviation
    (``sd``: of their logs), beside the Kubelka–Munk start (dashed), on a log axis; and each
    panel's ΔE00 between its reading and the fit at each of ``geometries`` (``panels``:
    name → ``[G]``, NaN where not read)."""
    figure, (spectra, misfit) = plt.subplots(1, 2, figsize=(13, 4.6))
    for k, (key, label) in enumerate((("absorption", "absorption κ"),
                                      ("scattering", "scattering σ"))):  # fmt: skip
        colour = f"C{k}"
        values = np.asarray(fitted[key], float)
        if not np.any(values > 0):
            spectra.plot([], [], color=colour, label=f"{label}: none (transparent)")
            continue
        spectra.plot(wavelengths, values, color=colour, lw=2, label=f"{label}, fitted")
        band = np.nan_to_num(np.asarray(sd[key], float))
        spectra.fill_between(wavelengths, values * np.exp(-band), values * np.exp(band),
                             color=colour, alpha=0.2, lw=0)  # fmt: skip
        spectra.plot(wavelengths, start[key], color=colour, ls="--", lw=1,
                     label=f"{label}, Kubelka–Munk at 45as45")  # fmt: skip
    spectra.set_yscale("log")
    spectra.set(xlabel="wavelength [nm]", ylabel="per unit mass fraction [1/µm] (± 1 s.d.)")
    spectra.legend(fontsize=8)
    _misfit_bars(misfit, geometries, panels)
    figure.suptitle(_fitted(title or "A pigment read from calibration panels", figure))
    _save(figure, path, dpi)


def plot_flake_read(
    geometries: Sequence[str],
    names: Sequence[str],
    Lab: Mapping[str, np.ndarray],
    panels: Mapping[str, np.ndarray],
    path: str | PathLike,
    *,
    travel: bool = False,
    title: str = "",
    dpi: int = 120,
) -> None:
    """An aluminium flake or a pearl read from calibration panels (``flakelab library
    characterise --plot``): each panel's CIELAB (D65/10) at each of ``geometries``,
    ``Lab["read"]`` (markers, NaN where not read) and ``Lab["fitted"]`` (lines) ``[N, G, 3]``,
    panels ``names``, as its L* flop (a flake) or, with ``travel``, its colour travel in the
    a*b* plane (a pearl); and each panel's ΔE00 between its reading and the fit
    (``panels``)."""
    figure, (left, misfit) = plt.subplots(1, 2, figsize=(13, 4.6))
    lamps = _geometry_groups(list(geometries), len(geometries))  # a line for each lamp
    (_colour_travel if travel else _lightness_flop)(left, geometries, names, Lab, lamps)
    left.legend(fontsize=8)
    _misfit_bars(misfit, geometries, panels)
    made = "A pearl" if travel else "An aluminium flake"
    figure.suptitle(_fitted(title or f"{made} read from calibration panels", figure))
    _save(figure, path, dpi)


def _lightness_flop(axis, geometries: Sequence[str], names, Lab, lamps) -> None:
    """Each panel's L* at each geometry, read (markers) and fitted (a line for each lamp)."""
    at = np.arange(len(geometries))
    for n, name in enumerate(names):
        for i, (rows, _) in enumerate(lamps):
            axis.plot(at[rows], Lab["fitted"][n][rows, 0], color=f"C{n}", lw=1.5,
                      label=None if i else f"{name}, fitted")  # fmt: skip
        axis.plot(at, Lab["read"][n][:, 0], "o", color=f"C{n}", mfc="none", label=f"{name}, read")
    axis.set_xticks(at, list(geometries), rotation=60, fontsize=8)
    axis.set(ylabel="L* (D65/10)")


def _colour_travel(axis, geometries: Sequence[str], names, Lab, lamps) -> None:
    """Each panel's a*, b* across the geometries, read (markers; a square at each lamp's
    nearest the specular) and fitted (a line for each lamp)."""
    aspecular = np.array([Geometry.parse(g).aspecular for g in geometries])
    for n, name in enumerate(names):
        read, fitted = Lab["read"][n], Lab["fitted"][n]
        for i, (rows, _) in enumerate(lamps):
            axis.plot(fitted[rows, 1], fitted[rows, 2], color=f"C{n}", lw=1.5,
                      label=None if i else f"{name}, fitted")  # fmt: skip
            near = rows[np.argmin(np.abs(aspecular[rows] - 1e-3))]  # 15° before −15°
            axis.plot(read[near, 1], read[near, 2], "s", color=f"C{n}", mfc="none")
        axis.plot(read[:, 1], read[:, 2], "o", color=f"C{n}", mfc="none", label=f"{name}, read")
    axis.axhline(0, color="0.7", lw=0.8)
    axis.axvline(0, color="0.7", lw=0.8)
    axis.set(xlabel="a* (D65/10)", ylabel="b* (D65/10)")
    axis.set_aspect("equal", adjustable="datalim")  # a hue's turn drawn as it is
    axis.set_title("colour travel; a square: nearest the specular, under each lamp", fontsize=9)


def plot_hiding(found, names: Sequence[str], path: str | PathLike, *, dpi: int = 120) -> None:
    """``flakelab hiding --plot``: for each recipe (``names``, of a
    :class:`~flakelab.physics.hiding.Hiding`), the worst-geometry ΔE00 between the film over
    a contrast chart's black and white against its build (black line), and over each primer
    from its colour built up (lines of the primer's own colour, darkened to show on white),
    with the threshold and the nominal build marked."""
    columns = min(len(names), 3)
    rows = -(-len(names) // columns)
    figure, axes = plt.subplots(rows, columns, figsize=(5.2 * columns, 3.9 * rows), squeeze=False)
    floor = 1e-3  # a log axis: a film past hiding reads 0
    rgb = Lab_to_sRGB(found.primer_lab)
    rgb *= np.minimum(1.0, 0.85 / np.maximum(rgb.max(axis=-1, keepdims=True), 1e-6))
    for axis, name, f in zip(axes.flat, names, range(len(names)), strict=False):
        for i, primer in enumerate(found.primers):
            axis.plot(found.film_um, np.maximum(found.primer_curve[f, i], floor), color=rgb[i],
                      lw=1, label=f"over {primer}")  # fmt: skip
        axis.plot(found.film_um, np.maximum(found.contrast_de00[f], floor), color="k", lw=2.2,
                  label="black vs white")  # fmt: skip
        axis.axhline(found.threshold, color="C3", ls="--", lw=1)
        axis.axvline(found.nominal_um, color="C0", ls=":", lw=1)
        axis.set(xscale="log", yscale="log", xlabel="film build [µm]",
                 ylabel="worst-geometry ΔE00")  # fmt: skip
        hides = found.hiding_um[f]
        said = f"hides at {hides:.1f} µm" if np.isfinite(hides) else "does not hide"
        axis.set_title(f"{name}: {said}", fontsize=9)
    axes.flat[0].legend(fontsize=7, ncol=2)
    for axis in list(axes.flat)[len(names) :]:
        axis.set_visible(False)
    figure.suptitle(_fitted("Hiding: the primer's trace against film build (dashed: the "
                            "threshold; dotted: the nominal build)", figure))  # fmt: skip
    _save(figure, path, dpi)


def _misfit_bars(axis, geometries: Sequence[str], panels: Mapping[str, np.ndarray]) -> None:
    """Each panel's ΔE00 between its reading and the fit, a bar per panel at each geometry."""
    at = np.arange(len(geometries))
    width = 0.8 / max(len(panels), 1)
    for n, (name, de00) in enumerate(panels.items()):
        axis.bar(at + (n - (len(panels) - 1) / 2) * width, np.nan_to_num(de00), width,
                 label=name)  # fmt: skip
    axis.set_xticks(at, list(geometries), rotation=60, fontsize=8)
    axis.set(ylabel="ΔE00, reading vs fit (D65/10)")
    axis.legend(fontsize=8)


def plot_model_errors(
    errors,
    path: str | PathLike,
    *,
    families: Sequence[str] | None = None,
    mismatch: float | None = None,
    title: str = "",
    dpi: int = 120,
) -> None:
    """A model against measured spray-outs (``flakelab model evaluate --plot``;
    ``errors``: :class:`~flakelab.models.training.PredictionErrors`): the ΔE00 of the cases at
    each geometry as boxes (5–95 % whiskers, a diamond at the mean), one per paint family
    (``families[N]``) side by side; the predicted minus the measured L* against the measured
    at every geometry (a bias shows as a drift off zero); and each case's worst ΔE00 over its
    geometries, with the bar above which a spray-out is likely another panel's
    (``mismatch``)."""
    names = list(errors.geometries)
    de = np.asarray(errors.de00)
    groups = np.asarray(families if families is not None else ["all cases"] * len(de))
    kinds = sorted(set(groups.tolist()))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    figure, (boxes, lightness, worst) = plt.subplots(
        1, 3, figsize=(17, 4.8), gridspec_kw={"width_ratios": [1.6, 1, 1]}
    )
    width = 0.8 / len(kinds)
    for k, kind in enumerate(kinds):
        rows = groups == kind
        at = np.arange(len(names)) - 0.4 + width * (k + 0.5)
        drawn = boxes.boxplot(
            [de[rows, g] for g in range(len(names))], positions=at, widths=width * 0.9,
            whis=(5, 95), showfliers=False, patch_artist=True, showmeans=True,
            meanprops=dict(marker="D", markerfacecolor="white", markeredgecolor="black", ms=4),
            medianprops=dict(color="black"),
        )  # fmt: skip
        for box in drawn["boxes"]:
            box.set(facecolor=colours[k % len(colours)], alpha=0.6)
        boxes.plot([], [], "s", color=colours[k % len(colours)], label=f"{kind} ({rows.sum()})")
    boxes.set_xticks(np.arange(len(names)), names, rotation=45 if len(names) > 6 else 0)
    boxes.set(ylabel="ΔE00, predicted against measured", ylim=(0, None))
    boxes.legend(fontsize=8, title="cases", title_fontsize=8)
    measured = errors.measured_lab[..., 0]
    # the MA-T12's twelve geometries outnumber the colour cycle's ten
    shades = colours if len(names) <= len(colours) else plt.cm.tab20(np.arange(len(names)))
    for g, name in enumerate(names):
        lightness.plot(measured[:, g], errors.predicted_lab[:, g, 0] - measured[:, g], ".", ms=3,
                       alpha=0.5, color=shades[g], label=name)  # fmt: skip
    lightness.axhline(0, color="0.5", lw=0.8)
    lightness.set(xlabel="L* measured", ylabel="ΔL*, predicted − measured")
    lightness.legend(fontsize=7, markerscale=3, ncol=2 if len(names) > 6 else 1)
    per_case = de.max(axis=1)
    worst.hist(per_case, bins=40, color="0.55")
    if mismatch is not None:
        above = int(np.sum(per_case > mismatch))
        worst.axvline(mismatch, color="tab:red", ls="--", lw=1)
        worst.text(mismatch, worst.get_ylim()[1] * 0.95, f"likely another panel's: {above} ",
                   color="tab:red", fontsize=8, va="top", ha="right")  # fmt: skip
    worst.set(xlabel="worst ΔE00 of a case over its geometries", ylabel="cases")
    summary = (
        f"ΔE00 mean {de.mean():.3f}, p95 {np.percentile(de, 95):.2f}, max {de.max():.2f} over "
        f"{counted(len(de), 'case')} × {counted(len(names), 'geometry', 'geometries')}"
    )
    figure.suptitle(f"{title}: {summary}" if title else summary)
    _save(figure, path, dpi)


HARNESS_CURVES = {
    "first": "first shot",
    "first_unsprayed": "first recipe, its colour without the spray's noise",
    "corrected": "after one correction",
    "oracle": "the hidden formula sprayed",
    "respray": "the car's own paint sprayed again",
}
"""The harness's sprays (:func:`~flakelab.match.evaluate.evaluate_matching`'s per-target
keys) that :func:`plot_harness` draws, and their names."""


def plot_harness(
    rows: Sequence[Mapping],
    novel_rows: Sequence[Mapping],
    path: str | PathLike,
    *,
    tolerance: str,
    title: str = "",
    dpi: int = 120,
) -> None:
    """The match harness's targets (``flakelab match evaluate --plot``; ``rows``, then
    ``novel_rows`` with a new toner: its per-target trials): the share of targets whose
    worst share of the ``tolerance`` lies at or below each value, for each spray of
    :data:`HARNESS_CURVES` (at 1 it reads the success rate; how far the failures miss reads
    off to the right), and each first shot's worst ΔE00 sprayed against its model's
    prediction, by paint family (the new toner's targets' where they were judged alone)."""
    figure, (shares, predicted) = plt.subplots(1, 2, figsize=(14, 5.2))
    curves = [(rows, key, name) for key, name in HARNESS_CURVES.items()]
    if not rows:  # the new toner's targets judged alone: against their own hidden formulas
        curves = [(novel_rows, key, f"{HARNESS_CURVES[key]}, new toner")
                  for key in ("corrected", "oracle")]  # fmt: skip
    curves += [(novel_rows, "first", "new toner, first shot")] if novel_rows else []
    for trials, key, name in curves:
        values = np.sort([t[key] for t in trials])
        rate = float(np.mean(values <= 1.0))
        reached = np.arange(values.size + 1) / values.size  # from none below the least
        shares.step(np.r_[values[0], values], reached, where="post", label=f"{name}: {rate:.2f}",
                    ls="--" if trials is novel_rows else "-")  # fmt: skip
    shares.axvline(1.0, color="0.4", lw=0.8)
    shares.set_xscale("log")
    shares.xaxis.set_major_locator(FixedLocator([0.05, 0.1, 0.2, 0.5, 1, 2, 5, 10, 20]))
    shares.xaxis.set_major_formatter(FormatStrFormatter("%g"))
    shares.xaxis.set_minor_formatter(NullFormatter())
    shares.set(xlabel=f"worst share of the tolerance {tolerance} (≤ 1 passes)",
               ylabel="share of targets at or below", ylim=(0, 1.02))  # fmt: skip
    shares.legend(fontsize=8, loc="upper left", title="passing", title_fontsize=8)
    scattered = rows or novel_rows
    for family in sorted({t["family"] for t in scattered}):
        own = [t for t in scattered if t["family"] == family]
        predicted.plot([t["predicted_de00"] for t in own], [t["first_de00"] for t in own], ".",
                       alpha=0.7, label=f"{family} ({len(own)})")  # fmt: skip
    top = max(max(t["first_de00"] for t in scattered), max(t["predicted_de00"] for t in scattered))
    predicted.plot([0, top], [0, top], color="0.6", lw=0.8)
    predicted.set(xlabel="predicted worst ΔE00 of the recipe (the model's)",
                  ylabel="sprayed worst ΔE00 (the world's)")  # fmt: skip
    predicted.legend(fontsize=8)
    figure.suptitle(
        title
        or f"Match harness: {counted(len(rows), 'target')} + {len(novel_rows)} with a new toner"
    )
    _save(figure, path, dpi)


def plot_realism(
    draws,
    ranges: Mapping[str, tuple[float, float]],
    path: str | PathLike,
    *,
    title: str = "",
    dpi: int = 120,
) -> None:
    """How hard the generated world is (``flakelab cases realism --plot``; ``draws``:
    :class:`~flakelab.cases.generator.RealismDraws`): each statistic's draws, its median (its
    standard deviation for the batches' strength) as a line, and the range a real shop shows
    (``ranges``, :data:`~flakelab.cases.generator.REALISTIC_RANGES`) shaded."""
    figure, axes = plt.subplots(1, 4, figsize=(18, 4.2))
    families = np.asarray(draws.families)
    panels = (
        ("remeasure_de00_median", {"all": draws.remeasure},
         "ΔE00, one panel read twice (45as45)"),
        ("respray_de00_median", {f: draws.respray[families == f] for f in np.unique(families)},
         "worst ΔE00, one recipe sprayed twice"),
        ("batch_strength_sd", {"all": np.ravel(draws.strength) - 1},
         "toner strength between batches − 1"),
        ("weathered_target_de00_median", {"all": draws.weathered},
         "worst ΔE00, weathered against fresh"),
    )  # fmt: skip
    for axis, (key, groups, label) in zip(axes, panels, strict=True):
        lo, hi = ranges[key]
        top = max(float(np.percentile(v, 99)) for v in groups.values())
        bins = np.linspace(-top, top, 41) if key == "batch_strength_sd" else np.linspace(0, top, 41)
        for name, values in groups.items():
            axis.hist(values, bins=bins, histtype="step", lw=1.4, label=f"{name} ({values.size})")
        if key == "batch_strength_sd":  # the range is a spread: ± one standard deviation
            value = float(np.std(draws.strength))
            for sign in (-1, 1):
                axis.axvspan(sign * lo, sign * hi, color="tab:green", alpha=0.15)
                axis.axvline(sign * value, color="black", lw=1)
            shown = f"s.d. {value:.3f}"
        else:
            value = float(np.median(groups["metallic"] if "metallic" in groups else groups["all"]))
            axis.axvspan(lo, hi, color="tab:green", alpha=0.15)
            axis.axvline(value, color="black", lw=1)
            shown = "median" + (" (metallics)" if "metallic" in groups else "") + f" {value:.3f}"
        axis.set(xlabel=label, ylabel="tins" if key == "batch_strength_sd" else "formulations")
        axis.set_title(f"{shown}; real: {lo:g}–{hi:g}", fontsize=10)
        if len(groups) > 1:
            axis.legend(fontsize=8)
    shaded = "shaded: where a real shop's median lies (for the strength, its s.d.)"
    figure.suptitle(f"{title or 'Generated world'}; {shaded}")
    _save(figure, path, dpi)


def _epoch_steps(log: Sequence[Mapping]) -> list[int]:
    """Each log entry's place on one time axis: stages trained one after another follow each
    other; members trained side by side (their entries interleaved, epoch by epoch) share
    their epochs."""
    steps, step, now = [], -1, set()
    previous = None
    for entry in log:
        side_by_side = (
            previous is not None
            and entry["epoch"] == previous["epoch"]
            and entry["stage"] not in now
        )
        if not side_by_side:
            step, now = step + 1, set()
        now.add(entry["stage"])
        steps.append(step)
        previous = entry
    return steps


def plot_losses(
    log: Sequence[Mapping], path: str | PathLike, *, title: str = "", dpi: int = 120
) -> None:
    """A training's losses (``flakelab train --plot``, ``model adapt --plot``; ``log``: its
    entries, :func:`~flakelab.models.training.train_protocol`): each stage's loss per epoch on
    one time axis, a stage's fine-tuning dashed in its colour, and where a stage judged held-out
    cases their mean ΔE00 (right axis)."""
    steps = np.array(_epoch_steps(log))
    stages = list(dict.fromkeys(entry["stage"] for entry in log))
    bases = list(dict.fromkeys(stage.removesuffix(" fine-tune") for stage in stages))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    figure, axis = plt.subplots(figsize=(12, 5.6))
    judged = None
    for stage in stages:
        rows = [i for i, entry in enumerate(log) if entry["stage"] == stage]
        base = stage.removesuffix(" fine-tune")
        colour = colours[bases.index(base) % len(colours)]
        fine = stage != base
        axis.plot(steps[rows], [log[i]["loss"] for i in rows], color=colour,
                  ls="--" if fine else "-", lw=1.2, label=stage)  # fmt: skip
        scored = [i for i in rows if log[i].get("validation_de00") is not None]
        if scored:
            judged = judged or axis.twinx()
            judged.plot(steps[scored], [log[i]["validation_de00"] for i in scored], ":",
                        color=colour, lw=1.5, label=f"{stage}: held-out ΔE00")  # fmt: skip
    axis.set_yscale("log")
    axis.yaxis.set_major_formatter(FormatStrFormatter("%g"))
    low, high = axis.get_ylim()
    # within a decade the minor ticks are the only ones to read; across several, clutter
    axis.yaxis.set_minor_formatter(FormatStrFormatter("%g") if high < 10 * low else NullFormatter())
    axis.tick_params(axis="y", which="minor", labelsize=7)
    axis.set(xlabel="epoch (stages one after another; members side by side)", ylabel="loss")
    handles, labels = axis.get_legend_handles_labels()
    if judged is not None:
        judged.set_ylabel("held-out cases' mean ΔE00 (dotted)")
        more = judged.get_legend_handles_labels()
        handles, labels = handles + more[0], labels + more[1]
    axis.legend(handles, labels, fontsize=7, ncol=4, loc="upper center",
                bbox_to_anchor=(0.5, -0.14))  # fmt: skip
    figure.suptitle(title or f"Training losses, {len(stages)} stages")
    _save(figure, path, dpi)


_TITLE_CHARACTERS_PER_INCH = 9
"""About as many characters of a figure's title as fit an inch, at matplotlib's default."""


def plot_rendering(
    stacks: Sequence,
    labels: list[str],
    path: str | PathLike,
    *,
    title: str = "",
    dpi: int = 120,
) -> None:
    """Stacks of curved panels (:class:`~flakelab.render.appearance.LampStack`), one above the
    other with the lamp named (and where its colours were interpolated from): one band per
    label from the top, the aspecular angle along the bottom."""
    from flakelab.core.colorimetry import encode_sRGB

    figure, axes = plt.subplots(
        len(stacks), 1, figsize=(11, (0.9 + 1.6 * len(labels)) * len(stacks)), squeeze=False
    )
    for axis, stack in zip(axes[:, 0], stacks, strict=True):
        rows = stack.image.shape[0]
        band = rows / len(labels)
        axis.imshow(encode_sRGB(stack.image), extent=(*stack.span, rows, 0), aspect="auto")
        axis.set_yticks(band * (np.arange(len(labels)) + 0.5), labels)
        axis.set_xticks(np.arange(stack.span[0], stack.span[1] + 1, 15))
        sources = " and ".join(f"{a:g}°" for a in stack.interpolated_from)
        axis.set_xlabel(
            f"aspecular angle [°], lamp at {stack.lamp:g}°"
            + (f" (not read: interpolated over flake tilt from the {sources} lamp's geometries)"
               if sources else "")
        )  # fmt: skip
        for k in range(1, len(labels)):
            axis.axhline(k * band, color="white", lw=0.6)
    axes[0, 0].set_title(_fitted(title, figure))
    _save(figure, path, dpi)


def _fitted(title: str, figure) -> str:
    """``title`` broken into lines as wide as ``figure`` (a verdict that names every one of
    an MA-T12's twelve geometries ran off the side), at spaces only: a geometry (45as-15) or
    a model (demo-five-angle) split at its hyphen reads as two."""
    width = int(_TITLE_CHARACTERS_PER_INCH * figure.get_figwidth())
    return textwrap.fill(title, width, break_on_hyphens=False)


def plot_camera_pictures(
    samples: Sequence[tuple[Measurement, Mapping[str, np.ndarray]]],
    path: str | PathLike,
    *,
    conditions: Conditions = D65_10,
    columns: int = 4,
    dpi: int = 100,
) -> None:
    """An instrument camera's pictures of each measured spot (row label → 8-bit sRGB image,
    :func:`~flakelab.io.mat12_xlsx.read_mat12_images`), each titled by its geometry with a
    swatch below it of the colour the sample's spectrum gives there: the camera is not a
    colorimeter (its pictures of the shared exports lie 10-28 L* darker than the spectra), so
    the picture shows where the spot is uneven or how it sparkles, the swatch what was
    measured. One sample fills a grid ``columns`` wide; several, a row each, their pictures
    of one geometry in one column (a reference above its sample)."""
    labels = list(dict.fromkeys(label for _, pictures in samples for label in pictures))
    one = len(samples) == 1
    rows, width = (-(-len(labels) // columns), columns) if one else (len(samples), len(labels))
    figure, axes = plt.subplots(rows, width, figsize=(3.2 * width, 2.75 * rows), squeeze=False)
    for axis in axes.flat:
        axis.set_axis_off()
    for k, (measurement, pictures) in enumerate(samples):
        lab = dict(zip(measurement.geometry_names, measurement.lab(conditions), strict=True))
        for i, label in enumerate(labels):
            if label in pictures:
                axis = axes.flat[i] if one else axes[k, i]
                _picture_tile(axis, pictures[label], label, lab.get(label))
        if not one:
            axes[k, 0].text(-0.08, 0.5, measurement.sample, rotation=90, va="center", ha="right",
                            transform=axes[k, 0].transAxes, fontsize=9)  # fmt: skip
    names = " above ".join(measurement.sample for measurement, _ in samples)
    figure.suptitle(
        _fitted(f"{names}: the instrument camera's pictures; below each, the colour the "
                f"spectrum gives at that geometry ({conditions})", figure), fontsize=10
    )  # fmt: skip
    _save(figure, path, dpi)


def _picture_tile(axis, picture: np.ndarray, label: str, lab: np.ndarray | None) -> None:
    """One camera picture, titled by its geometry, above a swatch of ``lab`` (none where
    the sample has no reading there: the diffuse-light picture)."""
    from flakelab.core.colorimetry import Lab_to_sRGB

    height, width = picture.shape[:2]
    axis.set_axis_on()
    axis.imshow(picture, extent=(0, width, height, 0))
    axis.set_ylim(_SWATCH * height, 0)
    axis.set_xticks([])
    axis.set_yticks([])
    if lab is None:
        axis.set_title(f"{label}\n{_picture_caption(label)}", fontsize=9)
        return
    axis.add_patch(
        plt.Rectangle((0, height), width, (_SWATCH - 1) * height, color=Lab_to_sRGB(lab))
    )
    values = " ".join(f"{k}* {v:.1f}" for k, v in zip("Lab", lab, strict=True))
    axis.set_title(f"{label}\n{values}", fontsize=9)


_SWATCH = 1.2
"""A picture's height and its swatch's below it, in the picture's heights."""


def _picture_caption(label: str) -> str:
    """What a picture without a reading of its own shows: the diffuse-light picture (``15d``)
    is the one an instrument judges graininess on."""
    from flakelab.io.mat12_xlsx import is_diffuse_picture

    return "diffuse light (graininess)" if is_diffuse_picture(label) else "no spectral reading"


def plot_side_by_side(
    readings: list[Measurement],
    labels: list[str],
    path: str | PathLike,
    *,
    title: str = "",
    conditions: Conditions = D65_10,
    lamps: Sequence[float] | None = None,
) -> None:
    """Readings (measured or predicted) drawn as curved panels, one band each from the top,
    in one texture draw (:func:`~flakelab.render.appearance.render_stack`), under each of
    ``lamps`` (default: each every reading was read under, an MA-T12's 45° and 15°), one
    stack each (:func:`~flakelab.render.appearance.render_under_lamps`)."""
    from flakelab.render.appearance import render_under_lamps

    stacks = render_under_lamps(readings, conditions, lamps)
    plot_rendering(stacks, labels, path, title=title)
