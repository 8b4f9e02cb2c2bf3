"""CLI: what the case and model commands share: their options, and where they read
cases and models from (a case file or database, the current or a named model)."""

from __future__ import annotations

import os
import shlex
from datetime import datetime
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer

from flakelab.cli.common import COUNT_MAX
from flakelab.core.geometry import INSTRUMENT_GEOMETRIES, instrument_name
from flakelab.core.times import shown_time, zoned, zoned_here
from flakelab.core.wording import database_label, hidden_passwords, shop_meant, tidy_name
from flakelab.errors import FlakelabError

WORKPLACE_SHOP = "FLAKELAB_SHOP"
"""The environment variable naming a workplace's shop: the shop ``cases record`` records, and
the one ``match`` and ``correct`` match for (its own model and habits) where ``--shop`` names
none."""
WORKPLACE_PRIMERS = "FLAKELAB_PRIMERS"
"""The environment variable naming a measurement file of the workplace's primers, which
``match`` and ``hiding`` choose among where ``--primers`` names none."""


def workplace_shop(shop: str | None) -> tuple[str | None, bool]:
    """The shop ``--shop`` names, else the workplace's (:data:`WORKPLACE_SHOP`), else None;
    and whether ``--shop`` named it."""
    if shop is not None:
        return tidy_name(shop), True
    return tidy_name(os.environ.get(WORKPLACE_SHOP) or "") or None, False


def shop_spelled(shop: str | None) -> str | None:
    """``--shop`` as shops are stored (:func:`~flakelab.core.wording.tidy_name`), refused
    where that leaves no name or a longer one than a case keeps: ``FLAKELAB_SHOP="  "``
    recorded cases of shop "", and the refusal named no option. Click calls it for every
    command that has the option, given or not."""
    if shop is None:
        return None
    from flakelab.cases.case import TEXT_LENGTHS

    tidy, longest = tidy_name(shop), TEXT_LENGTHS["shop"]
    if not tidy or len(tidy) > longest:
        raise typer.BadParameter(
            f"expected a shop's name of 1 to {longest} characters, got {shop!r}"
        )
    return tidy


def colour_code_spelled(code: str | None) -> str | None:
    """``--colour-code`` as cases store it (:func:`~flakelab.cases.case.colour_code_words`),
    refused where it holds no letter or digit, or more than a case keeps."""
    if code is None:  # Click calls it for every command that has the option
        return None
    from flakelab.cases.case import TEXT_LENGTHS, colour_code_words

    stored, longest = " ".join(colour_code_words(code)), TEXT_LENGTHS["colour_code"]
    if not stored or len(stored) > longest:
        raise typer.BadParameter(
            f"expected a car maker's colour code of letters and digits, at most {longest} "
            f"characters (e.g. 'Toyota 1G3'), got {code!r}"
        )
    return stored


ColourCodeOption = Annotated[
    str | None,
    typer.Option(
        callback=colour_code_spelled,
        help="Only the cases of this colour code, as on the car's plate: '1G3' finds "
        "'Toyota 1G3' and 'Lexus 1G3', 'Toyota 1G3' the first alone; case and '-' aside.",
    ),
]


DatabaseOption = Annotated[
    str | None,
    typer.Option(
        "--database",
        "-d",
        help="Database URL or SQLite file (default: FLAKELAB_DATABASE_URL or the "
        "user data folder).",
    ),
]


CaseSourceOption = Annotated[
    str | None,
    typer.Option(
        "--database",
        "-d",
        help="Database URL or SQLite file, or a case file (CSV/CxF) (default: "
        "FLAKELAB_DATABASE_URL or the user data folder).",
    ),
]


def database_option(database: str | None) -> str:
    """`` -d DATABASE`` for a command a report suggests next, where the user named one (its
    password hidden: a hint is read over a shoulder too), else ""."""
    return f" -d {shlex.quote(hidden_passwords(database))}" if database else ""


def instrument_spelled(name: str | None) -> str | None:
    """``--instrument`` in the spelling cases and models record it (``MA-T12``, ``ma_t12`` →
    ``ma-t12``): some commands took the instrument's own spelling, and ``match -i MA-T12`` was
    refused "no shipped model for 'MA-T12' (shipped: five-angle, ma-t12)". A name of no
    instrument is left for the command to refuse, naming those there are."""
    try:
        return name and instrument_name(name)
    except ValueError:
        return name


InstrumentOption = Annotated[
    str,
    typer.Option(
        "--instrument",
        "-i",
        callback=instrument_spelled,
        help="Geometry set: five-angle, ma-t12, byk-mac-i.",
    ),
]


KeptGeometriesOption = Annotated[
    str | None,
    typer.Option(
        "--instrument",
        "-i",
        callback=instrument_spelled,
        help="Keep only this geometry set: five-angle, ma-t12, byk-mac-i.",
        show_default="every geometry the car's reading and the spray-out's share",
    ),
]


LibraryOption = Annotated[
    Path | None, typer.Option("--library", "-l", help="Toner library file (default: demo).")
]


CasesArgument = Annotated[str, typer.Argument(help="Case file (CSV/CxF) or database URL/file.")]


ShopOption = Annotated[
    str | None,
    typer.Option(callback=shop_spelled, help="Only this shop's cases (default: every case given)."),
]


ShopModelOption = Annotated[
    str | None,
    typer.Option(
        "--shop",
        callback=shop_spelled,
        help="Only this shop's cases, against its own model where one was adapted to it "
        "(default: every case given, against the instrument's current model).",
    ),
]


TIME_FORMATS = ["%Y-%m-%d", "%Y-%m-%dT%H:%M", "%Y-%m-%d %H:%M", "%Y-%m-%dT%H:%M:%S",
                "%Y-%m-%d %H:%M:%S", "%Y-%m-%dT%H:%M:%S%z"]  # fmt: skip
"""How a date and time may be typed at the command line: local time, to the minute as the
reports show it (``2026-02-10 08:17``, copied from a table, and as a case file's times are
read) or to the second, or with its zone as the JSON reports write it
(``2026-02-10T08:17:00+00:00``). To the minute was refused before."""


def typed_time(when: datetime | None) -> datetime | None:
    """A date and time typed at the command line, in this machine's local time
    (:func:`~flakelab.core.times.zoned_here`)."""
    return when and zoned_here(when)


def time_option(help: str, **settings) -> Any:
    """An option that takes a date, and a time if given (:data:`TIME_FORMATS`), in local
    time; its help names the form, where click listed the six formats, 106 columns wide."""
    return typer.Option(
        formats=TIME_FORMATS, callback=typed_time, metavar="YYYY-MM-DD[ HH:MM]", help=help,
        **settings,
    )  # fmt: skip


SinceOption = Annotated[
    datetime | None,
    time_option(
        "Only cases made on or after this date (local time), e.g. since the shop's new gun."
    ),
]


UnseenOption = Annotated[
    bool,
    typer.Option(
        "--unseen",
        help="Only the cases the model never learned from (its error on those it learned "
        "flatters it); without it they are counted and warned of.",
    ),
]


StartOption = Annotated[
    datetime | None,
    time_option(
        "Date and time (local time) of the first generated case.",
        show_default="2026-01-01 00:00 UTC",
    ),
]


ModelFileOption = Annotated[
    str | None,
    typer.Option(
        "--model",
        "-m",
        help="Model file, or a registered version NAME:VERSION (default: current).",
    ),
]


NoTinsOption = Annotated[
    bool,
    typer.Option(
        "--no-tins",
        help="Take every case as poured from the standard tins, even where it records the "
        "tins it was poured from (as a shop that reads none).",
    ),
]


def source_arrays(source, cases: list, library, *, effect: bool = False):
    """The training arrays of ``cases`` read from ``source``; a case the library cannot
    encode (a toner it lacks) is named with the file or database it came from."""
    from flakelab.models.network import ModelError
    from flakelab.models.training import case_arrays

    try:
        return case_arrays(cases, library.names, library.effect if effect else None)
    except ModelError as error:
        raise FlakelabError(f"{source}: {error}") from None


def recorded_tins_used(data, library, no_tins: bool):
    """Cases as a model learns from them, and a shop's habits are read from them: at the
    standard tins (where they record tins: :func:`~flakelab.match.lots.at_standard_tins`),
    or, with ``no_tins``, as if they recorded none; with which of them record tins that
    were used ``[N]``."""
    from flakelab.match.lots import at_standard_tins

    used = data.without_tins() if no_tins else data
    return at_standard_tins(used, library), used.tins_recorded


def load_cases(
    source: str,
    shop: str | None = None,
    since: datetime | None = None,
    colour_code: str | None = None,
) -> list:
    """The cases of ``shop`` made at or after ``since`` for ``colour_code`` (None: any shop,
    any time, any colour) in a CSV/CxF file, or in a database (URL or .db/.sqlite file),
    which chooses them itself."""
    from flakelab.cases.case import select_cases
    from flakelab.cases.database import iter_cases
    from flakelab.cases.exchange import is_case_file, read_cases

    path = Path(source)
    if is_case_file(path):
        return select_cases(read_cases(path), shop=shop, since=since, colour_code=colour_code)
    engine = case_database(source)
    return list(iter_cases(engine, shop=shop, since=since, colour_code=colour_code))


def case_database(source: str):
    """The database of cases ``source`` names (a URL, or a .db/.sqlite file that must be
    there: a name of neither is no case file or database)."""
    from flakelab.cases.database import open_database
    from flakelab.cases.exchange import PIPED_CASES
    from flakelab.io import STANDARD_STREAM

    if source == STANDARD_STREAM:
        raise FlakelabError(PIPED_CASES)
    if "://" not in source and not Path(source).exists():
        raise FlakelabError(f"{source}: no such case file or database")
    return open_database(source, must_exist=True)


def cases_hint_in(source, shop: str | None, colour_code: str | None = None) -> str:
    """ " (did you mean 'Dupont & Fils'?)" where ``shop`` names no shop of ``source`` (a case
    file or a database, or its engine) and one of its shops is near: the same but for case,
    spaces and punctuation ('dupont-fils'), else the closest spelling; else " (did you mean
    'NH731P'?)" where ``colour_code`` found none of ``shop``'s cases and one of their codes is
    near. A shop misspelt was "no cases from shop 'dupont-fils'", as if it had none."""
    from flakelab.cases.case import colour_code_hint
    from flakelab.cases.database import colour_codes, open_database, shop_names
    from flakelab.cases.exchange import is_case_file

    if not shop and not colour_code:
        return ""
    if isinstance(source, str | Path) and is_case_file(source):
        cases = load_cases(str(source))
        shops = {case.shop for case in cases}
        codes = [case.colour_code for case in cases if case.shop == shop or not shop]
    else:
        engine = source if hasattr(source, "url") else open_database(source, must_exist=True)
        shops = set(shop_names(engine))
        codes = colour_codes(engine, shop=shop) if colour_code else []
    if shop and shop not in shops:
        return shop_meant(shop, shops)
    return colour_code_hint(colour_code, codes) if colour_code else ""


def recipe_fractions(library, grams: dict[str, float], path) -> np.ndarray:
    """Mass fractions in ``library`` order of a recipe file's ``grams``; a toner the library
    lacks is named with the file."""
    from flakelab.library import LibraryError

    try:
        return library.fractions(grams)
    except LibraryError as error:
        raise FlakelabError(f"{path}: {error}") from None


def shop_cases(source: str, shop: str | None, geometries, since: datetime | None = None) -> list:
    """The cases of ``shop`` (None: every shop) in ``source`` read at ``geometries`` (among
    others: each is restricted to them), made at or after ``since`` (None: any time; without a
    zone: UTC)."""
    from flakelab.cases.case import cases_at

    chosen = cases_at(load_cases(source, shop, since), geometries)
    if not chosen:
        raise FlakelabError(
            f"{source}: no cases {which_cases(shop, since)}{cases_hint_in(source, shop)} read "
            f"at the model's geometries {tuple(geometries)}"
        )
    return chosen


def instrument_key(name: str) -> str:
    """``--instrument``'s key of :data:`INSTRUMENT_GEOMETRIES`, or an error naming the option."""
    try:
        return instrument_name(name)
    except ValueError as error:
        raise FlakelabError(f"--instrument: {error}") from None


def which_cases(shop: str | None, since: datetime | None, colour_code: str | None = None) -> str:
    """The cases ``shop``, ``since`` and ``colour_code`` choose, in words for a message."""
    whose = f"from shop {shop!r}" if shop else "from any shop"
    code = f" of colour code {colour_code!r}" if colour_code else ""
    return whose + code + (f" since {shown_time(since)}" if since else "")


def unseen_cases(model, chosen: list, source: str, which: str) -> tuple[list, int]:
    """The cases of ``chosen`` that ``model`` never learned from, and how many it did; all
    learned is refused (``which``: the cases, in words)."""
    learned = model.learned_from([c.case_id for c in chosen])
    if learned.all():
        raise FlakelabError(
            f"{source}: the model learned from all {learned.size} cases {which}: none is unseen"
        )
    return [c for c, seen in zip(chosen, learned, strict=True) if not seen], int(learned.sum())


def since_option(when: datetime) -> str:
    """The ``--since`` that reads the cases made at ``when`` and after."""
    return f"--since {zoned(when).astimezone():%Y-%m-%dT%H:%M:%S}"


def chosen_model(
    model: str | Path | None, instrument: str, database: str | None, shop: str | None = None
):
    """The model ``--model`` names (:func:`named_model`), else the current one for ``shop``
    on the instrument (promoted for the shop or the instrument in the database, else the
    shipped: :func:`~flakelab.models.registry.current_model`)."""
    from flakelab.models.registry import current_model

    if model is None:
        return current_model(existing_engine(database), instrument, shop)
    return named_model(str(model), database, "--model")[0]


def named_model(spec: str, database: str | None, label: str = "MODEL"):
    """The model ``spec`` names, a file, a registered version ``NAME:VERSION`` or an
    instrument's current model, and where it was found."""
    from flakelab.cases.database import open_database
    from flakelab.models.registry import (
        current_model_and_source,
        list_models,
        load_model_file,
        registered_model,
    )

    path = Path(spec)
    if path.exists() or path.suffix == ".pt":
        return load_model_file(path), str(path)
    registered = name_and_version(spec)
    if registered:
        engine = open_database(database, must_exist=True)
        name, version = registered
        model = registered_model(engine, name, version)
        (row,) = list_models(engine, name, version)
        return model, (
            f"{database_label(engine)}: {name} v{version}, {row['status']}, held-out ΔE00 "
            f"{row['held_out_de00']:.3f} when registered "
            f"({shown_time(row['created_at'], day=True)})"
        )
    if spec in INSTRUMENT_GEOMETRIES:
        return current_model_and_source(existing_engine(database), spec)
    raise FlakelabError(
        f"{label}: expected a model file, NAME:VERSION of 'flakelab model list' or an "
        f"instrument ({', '.join(INSTRUMENT_GEOMETRIES)}), got {spec!r}"
    )


def name_and_version(spec: str) -> tuple[str, int] | None:
    """``NAME:VERSION`` of a registered model (``flakelab model list``), else None. VERSION
    is in ASCII digits ('five-angle:²' was refused "invalid literal for int()") and at most
    :data:`~flakelab.cli.common.COUNT_MAX` (past SQLite's integers, an internal error)."""
    name, colon, version = spec.rpartition(":")
    if not (colon and name and version.isascii() and version.isdigit()):
        return None
    if int(version) > COUNT_MAX:
        raise FlakelabError(f"{spec}: VERSION: expected at most {COUNT_MAX:,}")
    return name, int(version)


def learned_forward(
    library: Path | None, instrument: str, model, database: str | None, shop: str | None = None
):
    """The toner library and the matcher's forward of the model file ``model``, else of the
    current model for ``shop`` on the instrument (:func:`chosen_model`)."""
    from flakelab.io import read_library

    lib = read_library(library)
    return lib, current_forward(lib, instrument, model, database, shop)


def current_forward(lib, instrument: str, model, database: str | None, shop: str | None = None):
    """The matcher's forward for the library ``lib``: of the model file ``model``, else of
    the current model for ``shop`` on the instrument."""
    from flakelab.match.models import forward_for

    return forward_for(chosen_model(model, instrument, database, shop), lib)


def existing_engine(database: str | None):
    """The database named or configured, else the user data folder's own where it exists
    (where 'flakelab train' registers and promotes by default); none on a fresh machine,
    whose shipped model needs none."""
    from flakelab.cases.database import open_database, user_database_file

    if database or os.environ.get("FLAKELAB_DATABASE_URL"):
        return open_database(database, must_exist=True)
    return open_database() if user_database_file().is_file() else None
