"""What the matcher benchmarks share: the shipped five-angle model, or any model file judged in
its own instrument's world, on the demo library."""

from __future__ import annotations

import argparse
import dataclasses
import math
import time

import numpy as np

from flakelab.cases.generator import SHOP_WITH_HABITS, World, WorldSettings
from flakelab.cli.common import progress_bar
from flakelab.io import read_library, read_tolerance
from flakelab.library import PAINT_FAMILIES
from flakelab.match.evaluate import HARNESS_WORLDS, evaluate_matching, harness_world
from flakelab.match.models import effect_mask, forward_for
from flakelab.models.registry import load_model_file, shipped_model

MODEL_HELP = (
    "model file, judged in the world of its own instrument (default: the shipped five-angle one)"
)


def add_harness_arguments(
    parser: argparse.ArgumentParser, targets: int, novel_targets: int
) -> None:
    """The harness's options (``flakelab match evaluate``) with these default target counts,
    the model file and ``--json``."""
    parser.add_argument("--targets", type=int, default=targets)
    parser.add_argument("--novel-targets", type=int, default=novel_targets)
    parser.add_argument("--seed", type=int, default=4242)
    parser.add_argument("--world", choices=list(HARNESS_WORLDS), default="shop")
    parser.add_argument(
        "--kinds",
        type=parse_kinds,
        help="the hidden targets' paint families, e.g. pearl=1 (default: the generator's mix)",
    )
    add_white_pearls_argument(parser, "the hidden pearls (e.g. 1 with --kinds pearl=1)")
    parser.add_argument("--model", help=MODEL_HELP)
    parser.add_argument(
        "--tolerance", help="preset or TOML/JSON file the sprays are judged by (default de00-1.0)"
    )
    parser.add_argument(
        "--resprays",
        type=int,
        default=0,
        help="each first recipe and hidden formula sprayed this many times more: the chances",
    )
    parser.add_argument("--json", action="store_true")


def column(rows: list[dict], key: str) -> np.ndarray:
    """The harness's per-target figure ``key`` of ``rows``, as floats."""
    return np.array([r[key] for r in rows], dtype=float)


def families(rows: list[dict]) -> np.ndarray:
    """The paint family of each of the harness's ``rows`` (its hidden formula's)."""
    return np.array([r["family"] for r in rows])


def mean_and_se(values: np.ndarray) -> tuple[float | None, float | None]:
    """The mean of ``values`` and its standard error; None for each where there are too few
    (no values; one, for the error)."""
    if not values.size:
        return None, None
    se = float(values.std(ddof=1) / np.sqrt(values.size)) if values.size > 1 else None
    return float(values.mean()), se


def thresholds_from(text: str) -> list[float]:
    """``"0.3,0.5,0.8"`` → sorted positive spreads [ΔE00]."""
    try:
        values = sorted({float(part) for part in text.split(",") if part.strip()})
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected numbers, e.g. 0.3,0.5,0.8") from None
    if not values or values[0] <= 0 or not np.isfinite(values[-1]):
        raise argparse.ArgumentTypeError(f"{text!r}: expected positive spreads, e.g. 0.3,0.5,0.8")
    return values


def parse_with_chances(parser: argparse.ArgumentParser) -> argparse.Namespace:
    """``parser``'s options, ``--resprays`` refused under 1: the chances need them."""
    args = parser.parse_args()
    if args.resprays < 1:
        parser.error(
            f"--resprays: expected at least 1 (the chances need them), got {args.resprays}"
        )
    return args


def run_harness(
    world,
    forward,
    effect,
    args,
    novel,
    settings=None,
    progress=None,
    target_texture=True,
    habits=None,
    per_target=False,
    lots="none",
) -> dict:
    """The harness's report for ``forward`` on the targets the options ``args`` name, those
    with a new toner drawn from ``novel``; without ``target_texture`` the matcher reads the
    targets without their texture readings; with a shop's ``habits`` it aims off for them;
    with ``per_target`` the report keeps every target's trial; ``lots`` says what the shop
    knows of its tins (``flakelab match evaluate --lots``)."""
    return evaluate_matching(
        world,
        forward,
        effect,
        tolerance=harness_tolerance(args),
        targets=args.targets,
        seed=args.seed,
        novel=novel,
        novel_targets=args.novel_targets,
        settings=settings,
        target_texture=target_texture,
        resprays=getattr(args, "resprays", 0),
        progress=progress,
        habits=habits,
        per_target=per_target,
        lots=lots,
    )


def harness_tolerance(args):
    """The tolerance the options ``args`` name (``--tolerance``), or None: the harness's own."""
    tolerance = getattr(args, "tolerance", None)
    return read_tolerance(tolerance) if tolerance else None


def timed_harness(
    world,
    forward,
    effect,
    args,
    novel,
    label: str,
    settings=None,
    target_texture=True,
    habits=None,
    per_target=False,
    lots="none",
) -> tuple[dict, float]:
    """:func:`run_harness`'s report under a progress bar labelled ``label`` (none with
    ``--json``), and the run's wall time in seconds."""
    total = args.targets + (args.novel_targets if novel else 0)
    start = time.perf_counter()
    with progress_bar(args.json) as bar:
        task = bar.add_task(label, total=total)
        report = run_harness(
            world,
            forward,
            effect,
            args,
            novel,
            settings,
            progress=lambda: bar.advance(task),
            target_texture=target_texture,
            habits=habits,
            per_target=per_target,
            lots=lots,
        )
    return report, time.perf_counter() - start


def shipped_matcher(
    world: str = "shop",
    model: str | None = None,
    kinds: dict[str, float] | None = None,
    shop_habits: dict[str, float] | None = None,
    white_pearls: float | None = None,
):
    """The demo library's harness world (``flakelab match evaluate --world``) for the
    instrument of the shipped five-angle model (or of the model file ``model``), its hidden
    targets drawn from the paint families ``kinds`` (default: the generator's mix), a share
    ``white_pearls`` of its pearls white pearls (default: the world's) and its shop given the
    habits ``shop_habits`` (:func:`parse_world_habits`), the model's forward and its
    effect-toner mask."""
    library = read_library(None)
    learned = load_model_file(model) if model else shipped_model("five-angle")
    forward = forward_for(learned, library)
    harness = harness_world(library, learned.instrument, world)
    changes = {**({"kinds": kinds} if kinds else {}), **(shop_habits or {})}
    if white_pearls is not None:
        changes["white_pearl_share"] = white_pearls
    if changes:
        settings = dataclasses.replace(harness.settings, **changes)
        harness = World(library, learned.instrument, settings)
    return harness, forward, effect_mask(library, forward.toners)


def shipped_ensemble(parser: argparse.ArgumentParser, args: argparse.Namespace):
    """:func:`shipped_matcher` for the harness's options ``args``, a model of one network
    refused: it has no ensemble to disagree."""
    world, forward, effect = shipped_matcher(
        args.world, args.model, args.kinds, white_pearls=args.white_pearls
    )
    if getattr(forward, "members", 1) < 2:
        parser.error("--model: a single network has no ensemble to disagree")
    return world, forward, effect


def generated_recipes(world, forward, n: int, rng) -> list[dict[str, float]]:
    """``n`` of the world's OEM-like formulations as recipes {toner: share}."""
    names = list(forward.toners)
    x = world.formulations(n, rng)
    return [{names[i]: float(row[i]) for i in np.flatnonzero(row > 0)} for row in x]


WORLD_HABITS_HELP = (
    "the world's shop: film build, flake spread, instrument gain, e.g. 1.015,0.99,0.0015"
)


def parse_world_habits(text: str) -> dict[str, float]:
    """``"1.015,0.99,0.0015"`` → the world's shop settings: film build and flake spread as
    factors on the factory's, the instrument's gain as a fraction."""
    try:
        film, spread, gain = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected FILM,SPREAD,GAIN, got {text!r}") from None
    if not (film > 0 and spread > 0 and math.isfinite(film * spread * gain)):
        raise argparse.ArgumentTypeError(f"expected positive film and spread, got {text!r}")
    return dict(zip(SHOP_WITH_HABITS, (film, spread, gain), strict=True))


def world_habits(world) -> dict[str, float]:
    """The world's shop settings, as :func:`parse_world_habits` gives them."""
    return {key: getattr(world.settings, key) for key in SHOP_WITH_HABITS}


def parse_kinds(text: str) -> dict[str, float]:
    """``"metallic=0.6,pearl=0.25,solid=0.15"`` → shares of the paint families."""
    kinds = {}
    for part in filter(None, (p.strip() for p in text.split(","))):
        name, _, share = part.partition("=")
        try:
            kinds[name.strip()] = float(share)
        except ValueError:
            raise SystemExit(f"--kinds: {part!r} is not family=share") from None
    unknown = sorted(set(kinds) - set(PAINT_FAMILIES))
    shares = list(kinds.values())
    if (
        unknown
        or not kinds
        or not all(map(math.isfinite, shares))
        or min(shares) < 0
        or sum(shares) <= 0
    ):
        raise SystemExit(f"--kinds: expected shares of {', '.join(PAINT_FAMILIES)}, got {text!r}")
    return kinds


def add_white_pearls_argument(parser: argparse.ArgumentParser, pearls: str, default=None) -> None:
    """``--white-pearls SHARE``: the share of ``pearls`` that are white pearls, beside the
    library's white (``WorldSettings.white_pearl_share``; ``default`` None: the world's)."""
    parser.add_argument(
        "--white-pearls",
        type=white_pearl_share,
        default=default,
        help=f"share of {pearls} that are white pearls, beside the library's white "
        "(default: the world's, WorldSettings.white_pearl_share)",
    )


def white_pearl_share(text: str) -> float:
    """``"0.5"`` → 0.5, a share of the pearls as :class:`WorldSettings` takes it (which
    refuses one outside 0 to 1)."""
    try:
        return WorldSettings(white_pearl_share=float(text)).white_pearl_share
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def seeds_from(text: str) -> list[int]:
    """``"77"``, ``"77,78"`` or ``"81-86"`` (and mixtures) → seeds."""
    seeds = []
    for part in filter(None, (p.strip() for p in text.split(","))):
        first, _, last = part.partition("-")
        try:
            seeds.extend(range(int(first), int(last or first) + 1))
        except ValueError:
            raise SystemExit(f"--seed: {part!r} is not a seed or a range of seeds") from None
    return seeds
