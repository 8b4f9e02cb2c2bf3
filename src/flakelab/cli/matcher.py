"""CLI: what the match, correct and weigh commands share — their options, the matcher's
forward model, the shop's habits, the toners a model leaves out."""

from __future__ import annotations

from datetime import datetime
from pathlib import Path
from typing import Annotated

import typer

from flakelab.cli.common import WEIGHT_MAX, errors
from flakelab.cli.sources import (
    cases_hint_in,
    current_forward,
    existing_engine,
    learned_forward,
    shop_spelled,
    since_option,
)
from flakelab.core.times import shown_time
from flakelab.core.wording import database_label
from flakelab.errors import FlakelabError

MetamerismOption = Annotated[
    float,
    typer.Option(
        min=0.0,
        max=WEIGHT_MAX,
        help="Weight of the metamerism index against the target (ΔE00 after ISO 18314-4's "
        "correction, under the test lights) in the objective: steers recipes to the car's own "
        "pigments (0: colour under D65/10 alone).",
    ),
]


WithoutOption = Annotated[
    list[str] | None,
    typer.Option(
        "--without",
        metavar="TONER",
        help="A toner the recipe may not use: out of stock, or not in the shop's mixing bank "
        "(repeat for each).",
    ),
]


RecipeOutOption = Annotated[
    Path | None,
    typer.Option(
        "--recipe-out",
        help="Write the recipe as a file {toner: grams}, as 'correct --recipe' and "
        "'cases record --recipe' read it.",
    ),
]


QuantityOption = Annotated[
    str,
    typer.Option(
        help="Can size to weigh, e.g. 250g, 0.5kg, 1lb (to the scale's nearest step), or by "
        "volume, e.g. 0.5l, 500ml, 1qt (weighed from the toners' densities in the library)."
    ),
]


def _checked_resolution(grams: float) -> float:
    """``--resolution`` read before any work, so that a scale that weighs nothing is named by
    its option (it was refused after the search, as "resolution: …")."""
    from flakelab.match.recipe import check_resolution

    try:
        check_resolution(grams)
    except FlakelabError as error:
        raise typer.BadParameter(str(error).removeprefix("resolution: ")) from None
    return grams


ResolutionOption = Annotated[
    float, typer.Option(help="Scale resolution in grams.", callback=_checked_resolution)
]


ModelOption = Annotated[
    Path | None,
    typer.Option(
        "--model",
        "-m",
        help="Model file, or a registered version NAME:VERSION (default: current for the "
        "instrument).",
    ),
]


PhysicsOption = Annotated[
    bool,
    typer.Option(
        "--physics",
        help="Predict with the library's physics model alone (colour and texture), not a "
        "learned model: no cases needed and every toner known, but a match takes ten to twenty "
        "times as long.",
    ),
]


HabitsOption = Annotated[
    Path | None,
    typer.Option(
        "--habits",
        help="The shop's habits file ('flakelab cases habits --out'): recipes are aimed off "
        "for its film build, flake alignment and instrument.",
    ),
]


HabitsShopOption = Annotated[
    str | None,
    typer.Option(
        "--shop",
        callback=shop_spelled,
        help="Match for this shop: with its own model where one was adapted to its cases "
        "('flakelab model adapt --shop NAME'), aimed off for its habits where they are "
        "stored ('flakelab cases habits --shop NAME --save'), and weighed for its tins where "
        "they are stored ('flakelab lots save FILE --shop NAME'). Default (not for 'match "
        "evaluate'): the workplace's shop, FLAKELAB_SHOP, which may have none of them.",
    ),
]


def matcher_setup(
    library: Path | None,
    instrument: str,
    model: Path | None,
    database: str | None,
    physics: bool = False,
    shop: str | None = None,
):
    """The library, the matcher's forward model (learned: the current one for ``shop``, or
    with ``physics`` the library's physics alone) and the library's effect-toner mask."""
    from flakelab.match.models import effect_mask

    if physics:
        from flakelab.core.geometry import instrument_geometries
        from flakelab.io import read_library
        from flakelab.match.forward import PhysicsForward

        if model is not None:
            raise FlakelabError("--physics and --model: expected one of them, not both")
        lib = read_library(library)
        forward = PhysicsForward(lib, instrument_geometries(instrument))
    else:
        lib, forward = learned_forward(library, instrument, model, database, shop)
    return lib, forward, effect_mask(lib, forward.toners)


def habits_for(
    path: Path | None,
    shop: str | None,
    database: str | None,
    forward,
    *,
    named: bool = True,
    with_tins: bool = False,
):
    """The shop's habits from the file ``path`` or stored in the database for ``shop`` (None:
    none), with a warning when they were measured against another model than ``forward``, or
    over a change of the shop's habits; None, with a note, where ``forward``'s model was
    adapted to them (:meth:`~flakelab.match.habits.ShopHabits.learned_by`). A shop with a model
    of its own (``forward``, adapted to its cases) or tins stored need not have habits
    stored; nor need the workplace's shop where ``--shop`` ``named`` none
    (:func:`~flakelab.cli.sources.workplace_shop`), and a habits file then stands in for its
    stored habits. Habits read at the standard tins (:attr:`~flakelab.match.habits.
    ShopHabits.cases_with_tins`) but used ``with_tins`` False, or read as poured from the
    standard but used ``with_tins``, are used with a note."""
    if path is None and shop is None:
        return None
    if path is not None and shop is not None and named:
        raise FlakelabError("--habits and --shop: expected one of them, not both")
    from flakelab.cases.database import open_database
    from flakelab.cases.shop_lots import stored_lots
    from flakelab.match.habits import adaptation_of, read_habits, stored_habits

    if path is not None:
        found = read_habits(path)
    else:
        # the workplace's shop reads, never makes, the user's database: a fresh one has none
        engine = open_database(database, must_exist=True) if named else existing_engine(database)
        if engine is None:
            return None
        try:
            found = stored_habits(engine, shop, forward.model_id)
        except FlakelabError:
            own_model = (adaptation_of(forward) or {}).get("shop") == shop
            if not named or own_model or stored_lots(engine, shop) is not None:
                return None  # the shop's own model learned them; a workplace may have none yet
            raise FlakelabError(
                f"{database_label(engine)}: shop {shop!r}{cases_hint_in(engine, shop)} has no "
                "habits, tins or model of its own stored: read its habits with flakelab cases "
                f"habits CASES --shop {shop!r} --save, "
                f"its tins with flakelab lots calibrate PANEL --recipe R --shop {shop!r}, or "
                f"adapt a model to its cases with flakelab model adapt CASES --shop {shop!r}"
            ) from None
    if found.learned_by(forward):
        errors.print(
            f"note: {path or shop}: habits read against {found.model}, and the model in use, "
            f"{forward.model_id}, was adapted to the shop's cases: it has learned them, so "
            "they are not added again (read them against this model for what it has not "
            "learned)",
            highlight=False,
        )
        return None
    if found.cases_with_tins and not with_tins:
        errors.print(
            f"note: {path or shop}: habits read at the standard tins ({found.cases_with_tins} "
            "of their cases record their tins), used here for recipes taken as poured from "
            "the standard: they hold the model's own offset from the standard, which the "
            "shop's tins (--lots, or those stored for the shop) would match",
            highlight=False,
        )
    if found.cases and not found.cases_with_tins and with_tins:
        errors.print(
            f"note: {path or shop}: habits read as poured from the standard tins (none of "
            f"their {found.cases} cases record their tins), used here for the shop's tins: "
            "they hold what those cases' tins shared and lack the model's own offset from "
            "the standard; read them from cases that record their tins",
            highlight=False,
        )
    if found.model != forward.model_id:
        errors.print(
            f"[yellow]warning:[/] {path or shop}: habits measured against "
            f"{found.model or 'an unnamed model'}, not {forward.model_id}: read them again "
            "against this model",
            highlight=False,
        )
    if found.changed_since:
        since = datetime.fromisoformat(found.changed_since)
        errors.print(
            f"[yellow]warning:[/] {path or shop}: habits read over a change of the shop's "
            f"habits, from about {shown_time(since)}: read them again from the recent "
            f"cases (flakelab cases habits {since_option(since)})",
            highlight=False,
        )
    return found


def spectra_for_model(path, reading, forward):
    """A reading's spectra at the model's geometries (:func:`~flakelab.match.search.
    target_spectra`); a reading that lacks some is named with its file."""
    from flakelab.match.search import MatchError, target_spectra

    try:
        return target_spectra(reading, forward)
    except MatchError as error:
        raise FlakelabError(f"{path}: sample {error}") from None


def left_out_model(
    measurement, forward, library, database: str | None, physics: bool, shop: str | None = None
):
    """A model that predicts geometries of ``measurement`` that ``forward`` left out: the
    current model for ``shop`` (with ``physics``, the library's physics) of the geometry set
    that holds the most of them, the largest such set where several hold as many. None when
    there is none. A BYK-mac i reading's 45as-15, which the five-angle model leaves out, is
    the MA-T12 model's too: it required a target read at all twelve before, and said
    nothing of how a candidate looks there."""
    from flakelab.core.geometry import INSTRUMENT_GEOMETRIES, instrument_geometries
    from flakelab.match.search import unused_geometries
    from flakelab.models.network import ModelError
    from flakelab.models.registry import SHIPPED

    unused = set(unused_geometries(measurement, forward))

    def predicted(name: str) -> tuple[int, int]:  # the left-out geometries it predicts
        return len(unused & set(INSTRUMENT_GEOMETRIES[name])), len(INSTRUMENT_GEOMETRIES[name])

    fullest = max(INSTRUMENT_GEOMETRIES if physics else SHIPPED, key=predicted)
    if not predicted(fullest)[0]:
        return None
    if physics:
        from flakelab.match.forward import PhysicsForward

        return PhysicsForward(library, instrument_geometries(fullest))
    try:
        return current_forward(library, fullest, None, database, shop)
    except ModelError:  # the user's library is not the one that model knows: no cross-check
        return None


def with_left_out(target, names: list, reference_lab, samples: dict, others, there: list):
    """A chart's geometries, reference and samples (label → CIELAB ``[G, 3]``), followed by
    the target's ``others`` geometries, where each sample has its CIELAB in ``there`` (in the
    samples' order) and the reference is the target as read."""
    import numpy as np

    from flakelab.core.colorimetry import reflectance_to_Lab

    if not others:
        return names, reference_lab, samples
    target_there = reflectance_to_Lab(target.storage_spectra(list(others)))
    extended = {
        label: np.concatenate([lab, more])
        for (label, lab), more in zip(samples.items(), there, strict=True)
    }
    return names + list(others), np.concatenate([reference_lab, target_there]), extended


def metamerism_values(worst: dict[str, float]) -> str:
    return "  ".join(f"{light} {value:.2f}" for light, value in worst.items())


def metamerism_text(worst: dict[str, float], metamer: bool, label: str = "") -> str:
    """The worst geometry's metamerism index under each test illuminant, on one line; a
    ``metamer`` (as the report judged it, :func:`~flakelab.core.difference.is_metamer`)
    called one."""
    return (
        "metamerism index against the target (ISO 18314-4, ΔE00, worst geometry): "
        f"{label}{metamerism_values(worst)}{' (a metamer)' if metamer else ''}"
    )
