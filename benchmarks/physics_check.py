"""Matcher: where the model's ensemble is unsure, does the library's physics do better?

``flakelab match`` refines its best candidates through the library's physics where the
networks of the model's ensemble disagree on the best one by more than
:func:`~flakelab.match.physics_check.check_over` (0.5 ΔE00, 1.0 for an MA-T12 model;
``MatchSettings.physics_check``, ``--physics-check``). This runs the evaluation harness
(``flakelab match evaluate``) twice on the same targets, without the check (the baseline)
and with it, each first recipe sprayed ``--resprays`` times more, and compares the first
shot's chance on the targets the physics checked (paired: the same targets and spray
streams) and over all, with the hidden formulas' chance there, and the latency.

In the harness the library's physics is the world's own nominal physics: a library as well
calibrated as a library can be. With ``--miscalibrated`` two more runs, unchecked and
checked, go through a library whose pigments are off by one lot each, as a library
characterised from one tin of each toner is (strength × N(1,
:data:`~flakelab.library.lots.LOT_STRENGTH_SD`), shade N(0,
:data:`~flakelab.library.lots.LOT_SHADE_SD_NM`) nm; drawn once from ``--seed``: one shop's
library), while the learned model stays the one that learned the world's cases. The hybrid's
scaling for a new toner goes through that library in both. ``--only-miscalibrated`` runs
those two alone, in half the time, for more seeds of the realistic library.

With ``--thresholds 0.3,0.5,0.8`` it weighs the spread over which the matcher checks
(:func:`~flakelab.match.physics_check.check_over`): the checked runs check
over the lowest, and each threshold's first shots take a target's checked row where the
model's spread on its best recipe exceeds that threshold, else its unchecked one. That is
what a run at the threshold gives, to the spray: each target is matched and sprayed on its
own streams, and the spread is the learned search's, before any check. The corrections are
not composed so (a correction is checked on its own spread), and the runs' own figures, the
paired ones above among them, are then those at the lowest threshold. Each threshold's
figures break down by paint family too (the hidden formula's): the targets checked and the
target-chances gained, which add up to the threshold's.

With ``--lots calibrated`` (or ``referenced``, ``known``: ``flakelab match evaluate
--lots``) every run's shop predicts for its own tins, read from its calibration panels, and
the physics check's physics then does too (:func:`~flakelab.match.physics_check.physics_for`).
Through the library off by a lot only the check's physics and the hybrid's scaling are off:
the tins are read, and the learned model's shade moved, by the exact library's physics
(ratios of its predictions, in which a lot's error mostly cancels); with ``--tins-read-off``
by the library off by a lot too (:func:`library_off_by`), as a shop's own library reads them.

    python benchmarks/physics_check.py [--targets 200] [--novel-targets 50] [--seed 4242]
        [--resprays 20] [--model FILE] [--miscalibrated] [--thresholds T,T,...]
        [--lots none|calibrated|referenced|known] [--only-miscalibrated] [--tins-read-off]
        [--json]
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import json
from collections.abc import Iterator
from dataclasses import replace

import numpy as np

from _matcher import (
    add_harness_arguments,
    column,
    families,
    mean_and_se,
    parse_with_chances,
    shipped_ensemble,
    thresholds_from,
    timed_harness,
)
from flakelab.core.spectra import shift_spectra
from flakelab.core.wording import counted
from flakelab.library.lots import LOT_SHADE_SD_NM, LOT_STRENGTH_SD, TIN_KNOWLEDGE, TINS_READ
from flakelab.match import evaluate, physics_check, search
from flakelab.match.lots import WithLots
from flakelab.match.settings import PHYSICS_CHECK, MatchSettings


def spreads(rows: list[dict]) -> np.ndarray:
    """The ensemble's spread on each target's best recipe before any check (ΔE00; 0 for one
    network, which is never checked)."""
    return np.array([r["predicted_spread"] or 0.0 for r in rows])


def paired(learned: list[dict], checked: list[dict]) -> dict:
    """The first shot's chance of the harness's rows ``learned`` (no check) and ``checked``
    (the same targets, with it), on the targets the physics checked and over all; the hidden
    formulas' chance on those targets; and their latency, p50 and p95 over all targets."""
    mask = np.array([r["physics_checked"] for r in checked])
    before, after = column(learned, "first_chance"), column(checked, "first_chance")
    gain = after[mask] - before[mask]
    family = families(checked)
    latency = {
        name: [float(np.percentile(column(rows, "latency_s"), q)) for q in (50, 95)]
        for name, rows in (("learned", learned), ("checked", checked))
    }
    added = (column(checked, "latency_s") - column(learned, "latency_s"))[mask]
    return {
        "checked_targets": int(mask.sum()),
        "checked_by_family": {str(f): int((mask & (family == f)).sum()) for f in np.unique(family)},
        "checked_first_chance_learned": float(before[mask].mean()) if mask.any() else None,
        "checked_first_chance_physics": float(after[mask].mean()) if mask.any() else None,
        "checked_gain_se": mean_and_se(gain)[1],
        "checked_oracle_chance": float(column(checked, "oracle_chance")[mask].mean())
        if mask.any()
        else None,
        "first_chance_learned": float(before.mean()),
        "first_chance_checked": float(after.mean()),
        "latency_p50_p95_s": latency,
        # what the check added to the checked targets' match, median and worst (paired)
        "checked_added_s": [float(np.median(added)), float(added.max())] if mask.any() else None,
    }


def by_threshold(learned: list[dict], checked: list[dict], thresholds: list[float]) -> list[dict]:
    """The first shot's chance over all targets had the matcher checked over each of
    ``thresholds`` (ΔE00): each target's row of ``checked`` (a run checking over the lowest)
    where its unchecked best recipe's spread exceeds the threshold, else its row of
    ``learned``; the checked targets' paired gain, and what the check added to their match."""
    spread = spreads(learned)
    before, after = column(learned, "first_chance"), column(checked, "first_chance")
    added = column(checked, "latency_s") - column(learned, "latency_s")
    family = families(checked)
    figures = []
    for threshold in thresholds:
        mask = spread > threshold
        gain, gain_se = mean_and_se(after[mask] - before[mask])
        figures.append({
            "threshold": threshold,
            "checked_targets": int(mask.sum()),
            "first_chance": float(np.where(mask, after, before).mean()),
            "checked_gain": gain,
            "checked_gain_se": gain_se,
            "checked_added_s_median": float(np.median(added[mask])) if mask.any() else None,
            "by_family": {
                str(f): _gain_where(mask & (family == f), before, after) for f in np.unique(family)
            },
        })  # fmt: skip
    return figures


def _gain_where(mask: np.ndarray, before: np.ndarray, after: np.ndarray) -> dict:
    """The targets ``mask`` picks, and the check's paired gain in first-shot chance on them
    (target-chances: the sum, so that families add up to the threshold's whole)."""
    gain = after[mask] - before[mask]
    se = mean_and_se(gain)[1]
    return {
        "checked_targets": int(mask.sum()),
        "gained": float(gain.sum()),
        "gained_se": None if se is None else float(se * mask.sum()),
    }


def composed_mismatches(learned: list[dict], checked: list[dict], lowest: float) -> int:
    """Targets the run checking over ``lowest`` checked where the learned run's spread says it
    would not, or the other way round: 0 where :func:`by_threshold`'s composition holds."""
    would = spreads(learned) > lowest
    return int((would != np.array([r["physics_checked"] for r in checked])).sum())


@contextlib.contextmanager
def checking_over(threshold: float | None) -> Iterator[None]:
    """The physics check acting over the spread ``threshold`` (None: the matcher's own,
    :func:`~flakelab.match.physics_check.check_over`)."""
    default = physics_check.check_over
    if threshold is not None:
        physics_check.check_over = lambda geometries: threshold
    try:
        yield
    finally:
        physics_check.check_over = default


def lot_errors(library, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A library's calibration error, one lot's deviation per pigment (effect toners exact):
    relative strength and shade [nm] in the library's toner order, drawn from ``seed``."""
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(7,)))
    pigments = ~np.asarray(library.effect)
    strength = np.where(pigments, rng.normal(1.0, LOT_STRENGTH_SD, pigments.size), 1.0)
    shade = np.where(pigments, rng.normal(0.0, LOT_SHADE_SD_NM, pigments.size), 0.0)
    return strength, shade


def rms_error(library, strength: np.ndarray, shade: np.ndarray) -> dict[str, float]:
    """The RMS of :func:`lot_errors` over the library's pigments: strength and shade [nm]."""
    pigments = ~np.asarray(library.effect)
    return {
        "strength_rms": float(np.sqrt(np.mean((strength[pigments] - 1) ** 2))),
        "shade_rms_nm": float(np.sqrt(np.mean(shade[pigments] ** 2))),
    }


def library_off_by(library, strength: np.ndarray, shade: np.ndarray):
    """``library`` as characterised from one lot of each pigment: its absorption and
    scattering times ``strength``, its absorption moved by ``shade`` [nm] (as the world's
    batches move theirs)."""
    toners = tuple(
        replace(t, absorption=s * shift_spectra(t.absorption, d), scattering=s * t.scattering)
        if t.kind == "pigment"
        else t
        for t, s, d in zip(library.toners, strength, shade, strict=True)
    )
    return replace(library, toners=toners)


@contextlib.contextmanager
def physics_off_by(
    forward,
    library,
    strength: np.ndarray,
    shade: np.ndarray,
    check: bool = True,
    tins: bool = False,
) -> Iterator[None]:
    """The library's physics off by ``strength`` and ``shade`` per toner wherever the matcher
    uses it: the hybrid's scaling for a new toner (``forward.physics``) and, with ``check``,
    the physics check's (:func:`~flakelab.match.physics_check.physics_for`, in the search
    and the correction); with ``tins``, where the shop reads its tins and moves their shades
    (:func:`~flakelab.match.evaluate.shop_forward`, by :func:`library_off_by`)."""
    exact, hybrid = physics_check.physics_for, getattr(forward, "physics", None)
    shop_forward = evaluate.shop_forward
    if tins:
        off_library = library_off_by(library, strength, shade)
        evaluate.shop_forward = functools.partial(shop_forward, library=off_library)

    def off(forward, library):
        physics = exact(forward, library)
        return None if physics is None else WithLots(physics, strength, shade, library)

    if check:
        physics_check.physics_for = search.physics_for = off
    if hybrid is not None:
        forward.physics = WithLots(hybrid, strength, shade, library)
    try:
        yield
    finally:
        physics_check.physics_for = search.physics_for = exact
        evaluate.shop_forward = shop_forward
        if hybrid is not None:
            forward.physics = hybrid


def by_part(
    rows: dict[str, list[dict]], baseline: str, run: str, known: int, suffix: str = ""
) -> dict[str, dict | None]:
    """:func:`paired` of the runs named ``baseline`` and ``run``: on the first ``known``
    targets (known toners) and on the rest (a new toner); None for a part with no targets
    (``--targets 0`` judges a new toner's alone)."""
    novel = len(rows[run]) > known
    return {
        f"known{suffix}": paired(rows[baseline][:known], rows[run][:known]) if known else None,
        f"novel{suffix}": paired(rows[baseline][known:], rows[run][known:]) if novel else None,
    }


PAIRS = (("", "learned", "checked"), ("_miscalibrated", "learned_off", "miscalibrated"))
"""The runs compared, unchecked and checked: through the exact library and through the one
off by a lot (the figures' keys' suffix, the baseline's name, the checked run's)."""


def pairs_run(rows: dict[str, list[dict]]) -> list[tuple[str, str, str]]:
    """The :data:`PAIRS` whose checked run ``rows`` holds (``--only-miscalibrated`` runs one)."""
    return [p for p in PAIRS if p[2] in rows]


def thresholds_by_part(
    rows: dict[str, list[dict]], known: int, thresholds: list[float]
) -> dict[str, dict]:
    """:func:`by_threshold` on the known toners' targets and on a new toner's, through each
    library ``rows`` has runs through (:data:`PAIRS`), with each pair's
    :func:`composed_mismatches`."""
    figures = {}
    for suffix, baseline, run in pairs_run(rows):
        for part, where in (("known", slice(None, known)), ("novel", slice(known, None))):
            learned, checked = rows[baseline][where], rows[run][where]
            if learned:
                figures[f"thresholds_{part}{suffix}"] = {
                    "mismatches": composed_mismatches(learned, checked, thresholds[0]),
                    "by_threshold": by_threshold(learned, checked, thresholds),
                }
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_harness_arguments(parser, targets=200, novel_targets=50)
    parser.add_argument(
        "--miscalibrated",
        action="store_true",
        help="two more runs through a library off by one lot per pigment, unchecked and checked",
    )
    parser.add_argument(
        "--only-miscalibrated",
        action="store_true",
        help="the two runs through the library off by a lot alone (implies --miscalibrated)",
    )
    parser.add_argument(
        "--thresholds",
        type=thresholds_from,
        help="spreads (ΔE00) to compare as the check's threshold, e.g. 0.3,0.5,0.8: the "
        "checked runs check over the lowest, and each threshold's first shots are composed "
        "from the two runs (default: the matcher's own alone, 0.5 or the MA-T12's 1.0)",
    )
    parser.add_argument(
        "--lots",
        choices=TIN_KNOWLEDGE,
        default="none",
        help="what every run's shop knows of its tins, as 'flakelab match evaluate --lots' "
        "(default: none, every tin taken at the standard)",
    )
    parser.add_argument(
        "--tins-read-off",
        action="store_true",
        help="with --lots calibrated or referenced, the shop reads its tins and moves their "
        "shades through the library off by a lot too (the runs through it; default: through "
        "the exact library's physics)",
    )
    parser.set_defaults(resprays=20)
    args = parse_with_chances(parser)
    if args.tins_read_off and not (
        args.lots in TINS_READ and (args.miscalibrated or args.only_miscalibrated)
    ):
        parser.error(
            "--tins-read-off: needs --lots calibrated or referenced and a run through the "
            "library off by a lot (--miscalibrated or --only-miscalibrated)"
        )
    world, forward, effect = shipped_ensemble(parser, args)
    plans = []
    if not args.only_miscalibrated:
        plans.append(("learned", 0, contextlib.nullcontext()))
        plans.append(("checked", PHYSICS_CHECK, contextlib.nullcontext()))
    library_error = None
    if args.miscalibrated or args.only_miscalibrated:  # the library off by a lot
        strength, shade = lot_errors(world.library, args.seed)
        library_error = rms_error(world.library, strength, shade)
        off = (forward, world.library, strength, shade)
        tins = args.tins_read_off
        plans.append(("learned_off", 0, physics_off_by(*off, check=False, tins=tins)))
        plans.append(("miscalibrated", PHYSICS_CHECK, physics_off_by(*off, tins=tins)))
    runs, seconds = {}, {}
    lowest = args.thresholds[0] if args.thresholds else None
    for name, check, context in plans:
        with context, checking_over(lowest):
            runs[name], seconds[name] = timed_harness(
                world, forward, effect, args, forward.novel, f"harness ({name})",
                settings=MatchSettings(physics_check=check), per_target=True, lots=args.lots,
            )  # fmt: skip
    rows = {name: report["per_target"] for name, report in runs.items()}
    figures = {}
    for suffix, baseline, run in pairs_run(rows):
        figures |= by_part(rows, baseline, run, args.targets, suffix)
    if args.thresholds:
        figures |= thresholds_by_part(rows, args.targets, args.thresholds)
    summary = {
        "targets": args.targets,
        "novel_targets": args.novel_targets,
        "seed": args.seed,
        "resprays": args.resprays,
        "lots": args.lots,
        "tins_read_off": args.tins_read_off,
        "physics_check": PHYSICS_CHECK,
        "library_error": library_error,
        **{
            f"{name}_{key}": runs[name][key]
            for name in runs
            for key in ("first_shot_success", "after_one_correction", "novel_toner_first_shot")
        },
        **figures,
        "wall_s": seconds,
    }
    if args.json:
        print(json.dumps(summary, indent=2))
        return
    for part, f in figures.items():
        if part.startswith("thresholds_"):
            _print_thresholds(part, f)
            continue
        if f is None:
            continue
        print(f"{_part_label(part)}: over all, first-shot chance {f['first_chance_learned']:.3f} → "
              f"{f['first_chance_checked']:.3f}; the physics checked "
              f"{counted(f['checked_targets'], 'target')} {f['checked_by_family']}")  # fmt: skip
        if f["checked_targets"]:
            se = f"± {f['checked_gain_se']:.3f} paired" if f["checked_gain_se"] else "one target"
            print(f"  their first-shot chance {f['checked_first_chance_learned']:.3f} as the "
                  f"model matched them, {f['checked_first_chance_physics']:.3f} checked ({se}); "
                  f"their hidden formulas {f['checked_oracle_chance']:.3f}")  # fmt: skip
        for name, (p50, p95) in f["latency_p50_p95_s"].items():
            print(f"  latency {name}: p50 {p50:.2f} s, p95 {p95:.2f} s")
        if f["checked_added_s"]:
            median, worst = f["checked_added_s"]
            print(f"  the check added {median:.2f} s to a checked match (worst {worst:.2f})")
    for name in runs:
        r = runs[name]
        print(f"{name}: first shot {_rate(r['first_shot_success'])}, after one correction "
              f"{_rate(r['after_one_correction'])}, new toner {_rate(r['novel_toner_first_shot'])}"
              f" ({seconds[name]:.0f} s)")  # fmt: skip


def _part_label(part: str) -> str:
    """A part of the figures (``known``, ``novel_miscalibrated``, ``thresholds_known``…) in
    words."""
    toners, _, off = part.removeprefix("thresholds_").partition("_")
    return f"{toners} toners" + (", the library off by a lot" if off else "")


def _print_thresholds(part: str, figures: dict) -> None:
    print(f"{_part_label(part)}, checked over:")
    for f in figures["by_threshold"]:
        gain = "" if f["checked_gain"] is None else f", their chance {f['checked_gain']:+.3f}"
        se = "" if f["checked_gain_se"] is None else f" ± {f['checked_gain_se']:.3f}"
        print(f"  {f['threshold']:g} ΔE00: {counted(f['checked_targets'], 'target')} checked"
              f"{gain}{se}, first-shot chance over all {f['first_chance']:.3f}")  # fmt: skip
        gained = (
            f"{name} {g['checked_targets']} ({g['gained']:+.1f}"
            + ("" if g["gained_se"] is None else f" ± {g['gained_se']:.1f}")
            + ")"
            for name, g in f["by_family"].items()
        )
        print(f"    by family, checked (target-chances gained): {', '.join(gained)}")
    if figures["mismatches"]:
        print(f"  the composition does not hold on {counted(figures['mismatches'], 'target')}")


def _rate(value: float | None) -> str:
    return "-" if value is None else f"{value:.3f}"


if __name__ == "__main__":
    main()
