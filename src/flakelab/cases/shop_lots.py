"""A shop's toner tins in the database, where every workplace of the shop finds them.

A toner-lot file (:mod:`flakelab.io.lots_file`) serves one workplace; a shop whose colorists
share a database keeps its tins there beside its cases and habits. ``flakelab lots calibrate
--shop NAME`` reads the shop's latest tins, updates them from the panels and stores the next
version; ``match``, ``correct`` and ``cases record`` for the shop (``--shop``, or the
workplace's) take the latest. Every version is kept. A version is numbered one above the one
it was read from, once per shop, so two workplaces that read panels against the same version
at once cannot both store theirs: the second is refused and told to read its panels again,
and neither reading is lost unseen.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, datetime

from sqlalchemy import Engine, select
from sqlalchemy.exc import IntegrityError, SQLAlchemyError
from sqlalchemy.orm import Session

from flakelab.cases.case import TEXT_LENGTHS
from flakelab.cases.database import DatabaseError, reading_rows, refusal
from flakelab.cases.schema import ShopLotsRow
from flakelab.core.times import shown_time
from flakelab.core.wording import database_label
from flakelab.errors import FlakelabError
from flakelab.io.lots_file import lots_document, lots_from_document
from flakelab.library.lots import TonerLots

__all__ = [
    "StoredLots",
    "stored_lots",
    "store_lots",
    "lots_history",
    "list_stored_lots",
    "tins_through",
]


@dataclass(frozen=True)
class StoredLots:
    """A shop's tins as stored: the lots, their version (1, 2, … per shop) and when."""

    shop: str
    lots: TonerLots
    version: int
    saved_at: datetime

    def describe(self) -> str:
        when = shown_time(self.saved_at)
        return f"the tins stored for shop {self.shop!r} (version {self.version} of {when})"


def _checked_shop(shop: str) -> str:
    if not isinstance(shop, str) or not shop.strip() or len(shop) > TEXT_LENGTHS["shop"]:
        raise FlakelabError(
            f"shop: expected a name of 1 to {TEXT_LENGTHS['shop']} characters, got {shop!r}"
        )
    return shop


def stored_lots(
    engine: Engine, shop: str, toners=None, version: int | None = None
) -> StoredLots | None:
    """The latest tins stored for ``shop``, or its ``version`` (None: none stored), each of
    one of ``toners`` when given (a library's names: another is refused, the nearest
    named)."""
    query = select(ShopLotsRow).where(ShopLotsRow.shop == _checked_shop(shop))
    if version is not None:
        query = query.where(ShopLotsRow.version == version)
    with reading_rows(engine, ShopLotsRow, "tins of shop", "shop") as session:
        row = session.scalars(query.order_by(ShopLotsRow.version.desc()).limit(1)).first()
    return None if row is None else _stored(engine, row, toners)


def lots_history(engine: Engine, shop: str) -> list[StoredLots]:
    """Every version of the tins stored for ``shop``, the first first."""
    query = select(ShopLotsRow).where(ShopLotsRow.shop == _checked_shop(shop))
    with reading_rows(engine, ShopLotsRow, "tins of shop", "shop") as session:
        rows = session.scalars(query.order_by(ShopLotsRow.version)).all()
    return [_stored(engine, row) for row in rows]


def tins_through(versions: list[StoredLots]) -> dict[str, list[dict]]:
    """Each toner's tins through the ``versions`` of a shop's tins (:func:`lots_history`):
    a tin lasts while consecutive versions hold the same lot of the toner, and another
    begins with a new lot or where the toner comes back after a version without it. Each
    tin: its ``lot`` and, at every version that holds it, the ``version``, ``strength``,
    ``strength_sd``, ``shade_nm`` and ``shade_sd_nm`` (None where its shade was never read:
    :attr:`~flakelab.library.lots.TonerLot.shade_read`)."""
    fields = ("version", "strength", "strength_sd", "shade_nm", "shade_sd_nm")
    tins: dict[str, list[dict]] = {}
    held: dict[str, int] = {}  # each toner's version last seen
    for stored in versions:
        for name, t in sorted(stored.lots.lots.items()):
            series = tins.setdefault(name, [])
            last = series[-1] if series else None
            if last is None or last["lot"] != t.lot or held[name] != stored.version - 1:
                series.append({"lot": t.lot, **{k: [] for k in fields}})
            shade = (t.shade_nm, t.shade_sd_nm) if t.shade_read else (None, None)
            values = (stored.version, t.strength, t.strength_sd, *shade)
            for key, value in zip(fields, values, strict=True):
                series[-1][key].append(value)
            held[name] = stored.version
    return tins


def _stored(engine: Engine, row: ShopLotsRow, toners=None) -> StoredLots:
    where = f"{database_label(engine)}: the tins of shop {row.shop!r}, version {row.version}"
    lots = lots_from_document(row.document, where, toners)
    return StoredLots(row.shop, lots, row.version, row.created_at)


def store_lots(engine: Engine, shop: str, lots: TonerLots, read_from: int | None) -> StoredLots:
    """Store ``lots`` as the shop's next version after ``read_from`` (the version they were
    read from; None: none was stored). Where another was stored after it meanwhile, nothing
    is stored and the error says so."""
    stored = StoredLots(_checked_shop(shop), lots, (read_from or 0) + 1, datetime.now(UTC))
    row = ShopLotsRow(
        shop=shop, version=stored.version, document=lots_document(lots), created_at=stored.saved_at
    )
    try:
        with Session(engine) as session, session.begin():
            session.add(row)
    except IntegrityError:
        latest = stored_lots(engine, shop)
        raise DatabaseError(
            f"{database_label(engine)}: the tins of shop {shop!r} were stored as version "
            f"{latest.version if latest else '?'} by another reading since version "
            f"{read_from or 'none'} was read: nothing was stored; read the panels again "
            "against the latest"
        ) from None
    except SQLAlchemyError as error:
        raise DatabaseError(
            f"{database_label(engine)}: cannot store the tins of shop {shop!r}: "
            f"{refusal(error, engine)}; nothing was stored"
        ) from None
    return stored


def list_stored_lots(engine: Engine) -> list[dict]:
    """Every shop with tins stored: its latest version, how many tins and when."""
    with reading_rows(engine, ShopLotsRow, "tins of shop", "shop") as session:
        rows = session.scalars(select(ShopLotsRow).order_by(ShopLotsRow.version)).all()
        latest = {r.shop: r for r in rows}
    stored = (_stored(engine, r) for r in sorted(latest.values(), key=lambda r: r.shop))
    return [
        {
            "shop": s.shop,
            "version": s.version,
            "tins": len(s.lots.lots),
            "saved_at": s.saved_at.isoformat(),
        }
        for s in stored
    ]
