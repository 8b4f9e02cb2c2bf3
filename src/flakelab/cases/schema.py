"""Database tables (SQLAlchemy 2): cases, the model registry, the shops' habits and tins.

Spectra are stored as little-endian float32 arrays (``[G, 31]``); recipes, texture readings
and the tins a recipe was poured from as JSON. Geometry names travel with every case, so
cases from different instruments share one table. The schema evolves through Alembic
migrations in ``migrations/``.
"""

from __future__ import annotations

from datetime import datetime

from sqlalchemy import (
    JSON,
    Boolean,
    DateTime,
    Float,
    Integer,
    LargeBinary,
    UniqueConstraint,
    false,
    types,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

from flakelab.cases.case import TEXT_LENGTHS

MODEL_STATUSES = ("candidate", "promoted", "retired")
"""A registered version's status: stored and not current, the current one of its name, or
current once (:mod:`flakelab.models.registry`)."""

MODEL_NAME_LENGTH = 200
"""A registered model's name: an instrument's, or 'INSTRUMENT @ SHOP' for a shop's own model
(60 + 3 + 120 characters of :data:`~flakelab.cases.case.TEXT_LENGTHS`; migration 0003)."""

__all__ = ["Base", "CaseRow", "ModelRow", "HabitsRow", "ShopLotsRow"]


class _Kept(types.TypeDecorator):
    """A column type whose reading refuses a value of another kind. SQLite keeps whatever a
    statement gives any column (another tool's or a hand's: a shop name as bytes, a version
    as text), and such a value would fail far from its row; refused as it is read, it is
    named with its row and field (:func:`flakelab.cases.database.reading_rows`)."""

    kinds: tuple[type, ...] = ()
    expected = ""

    def process_result_value(self, value, dialect):
        if value is not None and (not isinstance(value, self.kinds) or isinstance(value, bool)):
            raise ValueError(f"expected {self.expected}, got {type(value).__name__}")
        return value


class KeptString(_Kept):
    """Text, as ``sqlalchemy.String``."""

    impl = types.String
    cache_ok = True  # each type says so itself (SQLAlchemy reads the class's own)
    kinds, expected = (str,), "text"


class KeptChoice(KeptString):
    """One of ``choices``, as ``sqlalchemy.String``: a value outside them is refused as it is
    read, as one of another kind is."""

    cache_ok = True

    def __init__(self, length: int, choices: tuple[str, ...]):
        super().__init__(length)
        self.choices = choices

    def process_result_value(self, value, dialect):
        value = super().process_result_value(value, dialect)
        if value is not None and value not in self.choices:
            raise ValueError(f"expected one of {', '.join(self.choices)}, got {value!r}")
        return value


class KeptInteger(_Kept):
    """A whole number, as ``sqlalchemy.Integer``."""

    impl = Integer
    cache_ok = True
    kinds, expected = (int,), "a whole number"


class KeptFloat(_Kept):
    """A number, as ``sqlalchemy.Float``."""

    impl = Float
    cache_ok = True
    kinds, expected = (int, float), "a number"


def render_for_migration(kind: str, obj, _context) -> str | bool:
    """Alembic's ``render_item``: a checked column type written into a new migration as the
    SQLAlchemy type it stores as (``sa.String(length=120)``), so that migrations do not
    import this module, whose types may change after them; False for anything else, which
    Alembic renders itself."""
    if kind == "type" and isinstance(obj, _Kept):
        return f"sa.{obj.impl!r}"
    return False


class Base(DeclarativeBase):
    pass


class CaseRow(Base):
    __tablename__ = "cases"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    case_id: Mapped[str] = mapped_column(
        KeptString(TEXT_LENGTHS["case_id"]), unique=True, index=True
    )
    shop: Mapped[str] = mapped_column(KeptString(TEXT_LENGTHS["shop"]), index=True)
    instrument: Mapped[str] = mapped_column(KeptString(TEXT_LENGTHS["instrument"]), index=True)
    conditions: Mapped[str] = mapped_column(KeptString(TEXT_LENGTHS["conditions"]))
    outcome: Mapped[str] = mapped_column(KeptString(20))
    synthetic: Mapped[bool] = mapped_column(Boolean)
    geometries: Mapped[list] = mapped_column(JSON)
    recipe: Mapped[dict] = mapped_column(JSON)
    target: Mapped[bytes] = mapped_column(LargeBinary)
    sprayout: Mapped[bytes] = mapped_column(LargeBinary)
    target_texture: Mapped[dict] = mapped_column(JSON)
    sprayout_texture: Mapped[dict] = mapped_column(JSON)
    # toner → the tin's lot, strength and shade as the shop read it (migration 0004)
    tins: Mapped[dict | None] = mapped_column(JSON, nullable=True)
    # the car maker's code for the colour, its words upper case; '' where none (migration 0007)
    colour_code: Mapped[str] = mapped_column(
        KeptString(TEXT_LENGTHS["colour_code"]), server_default=""
    )
    # the target's (the spray-out's) spectra recovered from its L*a*b* in D65/10 (migration 0009)
    target_recovered: Mapped[bool] = mapped_column(Boolean, server_default=false())
    sprayout_recovered: Mapped[bool] = mapped_column(Boolean, server_default=false())
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), index=True)
    updated_at: Mapped[datetime] = mapped_column(DateTime(timezone=True))


class ModelRow(Base):
    __tablename__ = "models"
    # one row per version of a name: registrations that run at once cannot share a number
    __table_args__ = (UniqueConstraint("name", "version", name="uq_models_name_version"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    # a shop's own model is 'INSTRUMENT @ SHOP' (models.registry.shop_model_name)
    name: Mapped[str] = mapped_column(KeptString(MODEL_NAME_LENGTH), index=True)
    version: Mapped[int] = mapped_column(KeptInteger)
    instrument: Mapped[str] = mapped_column(KeptString(60))
    status: Mapped[str] = mapped_column(KeptChoice(20, MODEL_STATUSES))
    toners: Mapped[list] = mapped_column(JSON)
    data_hash: Mapped[str] = mapped_column(KeptString(64))
    metrics: Mapped[dict] = mapped_column(JSON)
    held_out_de00: Mapped[float] = mapped_column(KeptFloat)
    artefact: Mapped[bytes] = mapped_column(LargeBinary)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True))
    # when its training read its cases; None where not known (migration 0008)
    cases_read_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)


class HabitsRow(Base):
    """A shop's habits read from its spray-outs against one model (``flakelab cases habits
    --save``); every reading is kept, the latest is used."""

    __tablename__ = "shop_habits"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    shop: Mapped[str] = mapped_column(KeptString(120), index=True)
    model: Mapped[str] = mapped_column(KeptString(80))
    instrument: Mapped[str] = mapped_column(KeptString(60))
    report: Mapped[dict] = mapped_column(JSON)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True))


class ShopLotsRow(Base):
    """A shop's toner tins as read so far (a toner-lot document, ``flakelab lots calibrate
    --shop``); every version is kept, the latest is used. A version is one more than the one
    it was read from, once per shop: two workplaces storing readings of the same version
    clash instead of one losing the other's (migration 0005)."""

    __tablename__ = "shop_lots"
    __table_args__ = (UniqueConstraint("shop", "version", name="uq_shop_lots_shop_version"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    shop: Mapped[str] = mapped_column(KeptString(TEXT_LENGTHS["shop"]), index=True)
    version: Mapped[int] = mapped_column(KeptInteger)
    document: Mapped[dict] = mapped_column(JSON)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True))
