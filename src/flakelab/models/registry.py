"""Model registry: versioned artefacts in the case database, and the shipped defaults.

A version holds the weights and normalisation (one ``flakelab-model`` blob), the toner list,
instrument, training-data hash and metrics. A new version is promoted only when its held-out
ΔE00 beats the promoted one's on the *same* held-out cases (both are evaluated again there).
Without a promoted version, the shipped model for the instrument is the current one.

A model adapted to one shop's cases (``flakelab model adapt --shop``, ``train --adapt``) is
registered under the shop's own name (:func:`shop_model_name`) and is current for that shop
alone: it has learned the shop's film build, flake alignment and instrument, which another
shop sharing the database does not have. On 500 fresh cases of the habits shop the shipped
model errs by ΔE00 1.04 and the model adapted to 2,000 others of it by 0.65; on 500 cases of
a shop without those habits, by 0.62 and 1.03 (docs/cases-and-model.md, "A model per
shop"). A shop without a model of its own uses the instrument's.
"""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING

from sqlalchemy import Engine, func, select
from sqlalchemy.orm import Session

from flakelab.cases.database import (
    DatabaseError,
    lock_database,
    reading_rows,
    write_transaction,
)
from flakelab.cases.schema import ModelRow
from flakelab.core.geometry import DEFAULT_INSTRUMENT, instrument_name
from flakelab.core.times import zoned
from flakelab.core.wording import database_label
from flakelab.errors import ModelError
from flakelab.models.files import model_file

# torch, the generator and the physics are imported where a model is loaded or trained, so that
# listing what the database holds ('cases shops') imports none of them
if TYPE_CHECKING:
    from flakelab.models.network import ForwardModel
    from flakelab.models.training import CaseArrays

__all__ = [
    "shop_model_name",
    "shop_of",
    "shop_models",
    "serving_version",
    "serving_model",
    "shipped_model_path",
    "shipped_model",
    "register",
    "promoted_model",
    "list_models",
    "load_model_file",
    "current_model",
    "current_model_and_source",
    "registered_model",
    "held_already",
    "newest_training",
    "model_card",
    "promote",
    "retire",
]

SHIPPED = {DEFAULT_INSTRUMENT: "demo-five-angle.pt", "ma-t12": "demo-ma-t12.pt"}
"""Shipped models per instrument (trained on generated cases for the demo library)."""


_FOR_SHOP = " @ "
"""Between the instrument and the shop in a shop's own model's registered name."""


def shop_model_name(instrument: str, shop: str | None = None) -> str:
    """The registered name of the model current for ``shop`` on ``instrument`` (None: the
    instrument's, for every shop without one of its own)."""
    return instrument if shop is None else f"{instrument}{_FOR_SHOP}{shop}"


def shop_of(name: str) -> str | None:
    """The shop whose own model the registered ``name`` is (:func:`shop_model_name`), else
    None."""
    _, at, shop = name.partition(_FOR_SHOP)
    return shop if at else None


def shop_models(engine: Engine) -> dict[str, list[str]]:
    """Each shop's own promoted models (:func:`shop_model_name`), as 'NAME vVERSION'."""
    found: dict[str, list[str]] = {}
    for row in list_models(engine):
        shop = shop_of(row["name"])
        if shop is not None and row["status"] == "promoted":
            found.setdefault(shop, []).append(f"{row['name']} v{row['version']}")
    return found


def serving_version(
    engine: Engine, instrument: str, shop: str | None = None
) -> tuple[str, int] | None:
    """The registered name and version of the promoted model current for ``shop`` on the
    instrument (the shop's own, else the instrument's); None where the shipped one is."""
    with _reading(engine) as session:
        return _serving(session, instrument, shop)


def _serving(session: Session, instrument: str, shop: str | None) -> tuple[str, int] | None:
    names = [shop_model_name(instrument, shop)] if shop is not None else []
    for name in [*names, instrument]:
        row = _promoted_row(session, name)
        if row is not None:
            return name, row.version
    return None


def shipped_model_path(instrument: str) -> Path:
    try:  # no instrument at all, not one without a model
        instrument = instrument_name(instrument)
    except ValueError as error:
        raise ModelError(f"--instrument: {error}") from None
    if instrument not in SHIPPED:
        raise ModelError(
            f"instrument: no shipped model for {instrument!r} "
            f"(shipped: {', '.join(SHIPPED)}); train one with flakelab train"
        )
    return Path(__file__).resolve().parent.parent / "data" / "models" / SHIPPED[instrument]


def load_model_file(path: str | Path) -> ForwardModel:
    from flakelab.models.network import ForwardModel

    path = model_file(path)
    return ForwardModel.from_bytes(path.read_bytes(), str(path))


def shipped_model(instrument: str = DEFAULT_INSTRUMENT) -> ForwardModel:
    return load_model_file(shipped_model_path(instrument))


def list_models(engine: Engine, name: str | None = None, version: int | None = None) -> list[dict]:
    """Every registered version (of ``name``; only ``version``), without reading the
    artefacts (the database gives their sizes): a registry of many versions lists as fast as
    one of few."""
    columns = (
        ModelRow.name,
        ModelRow.version,
        ModelRow.instrument,
        ModelRow.status,
        ModelRow.held_out_de00,
        ModelRow.toners,
        ModelRow.data_hash,
        ModelRow.created_at,
        ModelRow.cases_read_at,
        func.length(ModelRow.artefact).label("size"),
    )
    query = select(*columns).order_by(ModelRow.name, ModelRow.version)
    if name is not None:
        query = query.where(ModelRow.name == name)
    if version is not None:
        query = query.where(ModelRow.version == version)
    with _reading(engine) as session:
        rows = session.execute(query).all()
    for r in rows:
        if not isinstance(r.toners, list):
            raise DatabaseError(
                f"{database_label(engine)}: model {r.name!r} v{r.version}: toners: expected a list "
                f"of toner names, got {r.toners!r}"
            )
    return [
        {
            "name": r.name,
            "version": r.version,
            "instrument": r.instrument,
            "status": r.status,
            "held_out_de00": r.held_out_de00,
            "toners": len(r.toners),
            "data_hash": r.data_hash[:12],
            "created_at": zoned(r.created_at).isoformat(),  # SQLite keeps no zone: UTC
            "cases_read_at": r.cases_read_at and zoned(r.cases_read_at).isoformat(),
            "size_kb": round(r.size / 1024, 1),
        }
        for r in rows
    ]


def promoted_model(engine: Engine, name: str) -> ForwardModel | None:
    with _reading(engine) as session:
        row = _promoted_row(session, name)
        return None if row is None else _stored_model(engine, name, row.version, row.artefact)


def registered_model(engine: Engine, name: str, version: int) -> ForwardModel:
    """Version ``version`` of the registered model ``name``, whatever its status."""
    with _reading(engine) as session:
        row = _version_row(session, engine, name, version)
        return _stored_model(engine, name, version, row.artefact)


def _stored_model(engine: Engine, name: str, version: int, artefact: bytes) -> ForwardModel:
    """A registered version's model read from its stored artefact; one another tool or a
    hand damaged is named with the database, the name and the version."""
    from flakelab.models.network import ForwardModel

    return ForwardModel.from_bytes(artefact, f"{database_label(engine)}: {name} v{version}")


def newest_training(engine: Engine, name: str) -> tuple[int, datetime, bool] | None:
    """The newest version registered as ``name``, whatever its status (a candidate that did
    not beat the current model learned the same cases), when its training read its cases, and
    whether the registry knows that time (a version registered before migration 0008, or from
    a file trained elsewhere, gives the time it was registered); None where none is."""
    columns = (ModelRow.version, ModelRow.cases_read_at, ModelRow.created_at)
    query = select(*columns).where(ModelRow.name == name).order_by(ModelRow.version.desc())
    with _reading(engine) as session:
        row = session.execute(query.limit(1)).first()
    if row is None:
        return None
    read = row.cases_read_at is not None
    return row.version, zoned(row.cases_read_at if read else row.created_at), read


def held_already(engine: Engine, name: str, model: ForwardModel) -> str | None:
    """Where the registry already holds ``model``'s weights and normalisation (its
    :attr:`~flakelab.models.network.ForwardModel.fingerprint`): a registered version of
    ``name`` ('NAME vN') or the shipped model of its instrument; None where it does not. A
    model file registered again is the version it already is."""
    fingerprint = model.fingerprint
    if model.instrument in SHIPPED and shipped_model(model.instrument).fingerprint == fingerprint:
        return f"the shipped {model.instrument} model"
    with _reading(engine) as session:
        rows = session.execute(
            select(ModelRow.version, ModelRow.artefact)
            .where(ModelRow.name == name)
            .order_by(ModelRow.version)
        ).all()
    for version, artefact in rows:
        if _stored_model(engine, name, version, artefact).fingerprint == fingerprint:
            return f"{name} v{version}"
    return None


def promote(engine: Engine, name: str, version: int) -> dict:
    """Make a registered version the current model by hand, the one promoted before retired:
    an operator's override of the automatic promotion, such as a rollback after a new version
    misbehaves in the shop. Returns what changed."""
    with write_transaction(engine, f"promote {name} v{version}", rows=_ROWS) as session:
        _store_lock(session)  # not beside a registration promoting another
        row = _version_row(session, engine, name, version)
        retired = _retire_promoted(session, name, keep=row)
        row.status = "promoted"
        return {"name": name, "version": version, "status": row.status, "retired": retired}


def retire(engine: Engine, name: str, version: int) -> dict:
    """Take a registered version out of use; when it was the promoted one, the next in line
    is current again until another is promoted: for a shop's own model the instrument's, for
    the instrument's the shipped one. Returns what changed and which is current now
    (``current``: the registered 'NAME vVERSION', or ``"shipped"``)."""
    with write_transaction(engine, f"retire {name} v{version}", rows=_ROWS) as session:
        _store_lock(session)
        row = _version_row(session, engine, name, version)
        was = row.status
        row.status = "retired"
        instrument = row.instrument
    shop = shop_of(name)
    now = serving_version(engine, instrument, shop)
    return {
        "name": name,
        "version": version,
        "status": "retired",
        "was": was,
        "shop": shop,
        "current": "shipped" if now is None else f"{now[0]} v{now[1]}",
    }


def _version_row(session: Session, engine: Engine, name: str, version: int) -> ModelRow:
    row = session.scalars(
        select(ModelRow).where(ModelRow.name == name, ModelRow.version == version)
    ).first()
    if row is None:
        versions = session.scalars(
            select(ModelRow.version).where(ModelRow.name == name).order_by(ModelRow.version)
        ).all()
        held = f"versions {', '.join(map(str, versions))}" if versions else "no versions"
        where = database_label(engine)
        raise ModelError(f"{where}: no version {version} of model {name!r} ({held})")
    return row


def _promoted_rows(session: Session, name: str) -> list[ModelRow]:
    return list(
        session.scalars(
            select(ModelRow).where(ModelRow.name == name, ModelRow.status == "promoted")
        )
    )


def _promoted_row(session: Session, name: str) -> ModelRow | None:
    return next(iter(_promoted_rows(session, name)), None)


def _retire_promoted(session: Session, name: str, keep: ModelRow | None = None) -> int | None:
    """Retire the version of ``name`` promoted so far (but ``keep``); returns its number."""
    retired = [row for row in _promoted_rows(session, name) if row is not keep]
    for row in retired:
        row.status = "retired"
    return max((row.version for row in retired), default=None)


def model_card(model: ForwardModel) -> dict:
    """What a model is and what it learned from: its network, instrument and toners (with
    the cases that taught each), the training settings and data, any adaptation."""
    info = model.info
    config = info.get("config", {})
    return {
        "name": info.get("name", model.instrument),
        "instrument": model.instrument,
        "geometries": list(model.geometries),
        "hidden": list(model.hidden),
        "members": model.members,
        "log_offset": model.log_offset,
        "toners": list(model.toners),
        "toner_cases": info.get("toner_cases", {}),
        "novel_toners": list(model.new_toners),
        "trained_cases": info.get("trained_cases"),
        "learned_cases": None if model.learned is None else int(model.learned.size),
        "outliers_dropped": info.get("outliers_dropped"),
        "data_hash": info.get("data_hash", ""),
        "effect_share_floor": info.get("effect_share_floor"),
        "training": {k: v for k, v in config.items() if k != "hidden"},
        "adaptation": model.adaptation,
    }


def current_model(engine: Engine | None, instrument: str, shop: str | None = None) -> ForwardModel:
    """The model promoted for ``shop`` on the instrument, else the one promoted for the
    instrument, else the shipped one."""
    return current_model_and_source(engine, instrument, shop)[0]


def current_model_and_source(
    engine: Engine | None, instrument: str, shop: str | None = None
) -> tuple[ForwardModel, str]:
    """:func:`current_model`, and where it comes from: ``"shipped"``, or the database and
    the promoted version's registered name."""
    serving = None if engine is None else serving_version(engine, instrument, shop)
    source = "shipped" if serving is None else f"{database_label(engine)}: {serving[0]}, promoted"
    return serving_model(engine, instrument, serving), source


def serving_model(
    engine: Engine | None, instrument: str, serving: tuple[str, int] | None
) -> ForwardModel:
    """The model :func:`serving_version` names (None: the instrument's shipped one), for a
    caller that keeps models by the version that serves and loads each once."""
    return shipped_model(instrument) if serving is None else registered_model(engine, *serving)


REGISTER_ATTEMPTS = 20
"""How often :func:`register` judges a model again when another registration promoted a
model of its instrument while it was judging: each waiting registration loses once to each
promotion (eight registering at once on PostgreSQL, nudged copies of one model, ran out of
five tries)."""


def register(
    engine: Engine,
    model: ForwardModel,
    held_out: CaseArrays,
    *,
    name: str | None = None,
    shop: str | None = None,
    metrics: dict | None = None,
    cases_read_at: datetime | None = None,
) -> dict:
    """Store ``model`` as a new version and promote it if it beats the current one (for
    ``shop``, a model adapted to its cases: :func:`shop_model_name`) on ``held_out``, judged
    on the cases whose toners both learned (the network's answer for a toner it never learned
    is no answer: the matcher has physics scale such toners) and neither learned from
    (:func:`~flakelab.models.training.unseen_by`); ``cases_read_at``: when its training read
    its cases (:func:`newest_training`). Returns the version, both scores, the cases judged
    and whether it was promoted.

    Workplaces sharing a database may register at once: models are stored one at a time
    (:func:`_stored`), each version with a number of its own (the database refuses a second
    row of one name and version), and a registration that finds another model current than
    the one it judged against judges again against that one. Six registrations started at
    the same instant on PostgreSQL took three numbers twice and promoted two versions at
    once before (``tests/test_cases.py``)."""
    name = name or shop_model_name(model.instrument, shop)
    artefact = model.to_bytes()
    for _ in range(REGISTER_ATTEMPTS):
        serving = serving_version(engine, model.instrument, shop)
        score, incumbent_score, judged, better = _judged(engine, model, held_out, serving)
        row = ModelRow(
            name=name,
            instrument=model.instrument,
            status="promoted" if better else "candidate",
            toners=list(model.toners),
            data_hash=model.info.get("data_hash", ""),
            metrics=metrics or {},
            held_out_de00=score,
            artefact=artefact,
            created_at=datetime.now(UTC),
            cases_read_at=cases_read_at and cases_read_at.astimezone(UTC),
        )
        version = _stored(engine, row, shop, serving)
        if version is not None:
            return {
                "name": name,
                "version": version,
                "held_out_de00": score,
                "incumbent_de00": incumbent_score,
                "cases_judged": judged,
                "promoted": better,
            }
    raise ModelError(
        f"{database_label(engine)}: {name}: other registrations landed {REGISTER_ATTEMPTS} times "
        "while this one was judged; nothing was stored (register it again)"
    )


def _judged(engine: Engine, model: ForwardModel, held_out: CaseArrays, serving):
    """``model``'s mean ΔE00 and the current one's (``serving``: :func:`serving_version`) on
    the cases of ``held_out`` both can be judged on, their number, and whether ``model`` is
    better. Where no case is comparable it is not; where the instrument has no current model
    (none registered, none shipped) it is the first, and better."""
    from flakelab.models.training import evaluate_model, unseen_by

    try:
        incumbent = serving_model(engine, model.instrument, serving)
    except ModelError:  # no shipped model for this instrument: the first one is promoted
        return evaluate_model(model, held_out)["de00_mean"], None, len(held_out.x), True
    comparable = held_out.without_toners({*model.new_toners, *incumbent.new_toners})
    both = unseen_by(comparable, model, incumbent)
    if not len(both.x):  # nothing shows that it is better
        return evaluate_model(model, held_out)["de00_mean"], None, 0, False
    score = evaluate_model(model, both)["de00_mean"]
    incumbent_score = evaluate_model(incumbent, both)["de00_mean"]
    return score, incumbent_score, len(both.x), score < incumbent_score


REGISTRY_LOCK = 0x666C616B66
"""PostgreSQL's advisory lock under which models are stored, promoted and retired one at a
time."""


_ROWS = (ModelRow, "model", "name")
"""The registry's rows as :func:`~flakelab.cases.database.reading_rows` names a damaged one."""


def _reading(engine: Engine):
    """A session reading the registry, whose damaged rows are named (:func:`reading_rows`)."""
    return reading_rows(engine, *_ROWS)


def _store_lock(session: Session) -> None:
    """Hold the database's lock for storing, promoting or retiring a model until the
    transaction ends, so that a registration reads the last version and the current model as
    they are when it stores, and a promotion by hand does not cross it."""
    lock_database(session.connection(), REGISTRY_LOCK)


def _stored(engine: Engine, row: ModelRow, shop: str | None, serving) -> int | None:
    """Store ``row`` as its name's next version, retiring the promoted one where ``row`` is
    promoted; its number, or None where the current model is no longer ``serving`` (it was
    judged against another)."""
    with write_transaction(
        engine, f"register {row.name}", "nothing was stored", rows=_ROWS
    ) as session:
        _store_lock(session)
        version = (
            session.scalar(select(func.max(ModelRow.version)).where(ModelRow.name == row.name)) or 0
        ) + 1
        if _serving(session, row.instrument, shop) != serving:
            return None
        if row.status == "promoted":
            _retire_promoted(session, row.name)
        row.version = version
        session.add(row)
    return version  # the row itself is expired once committed
