"""The case database: SQLite by default (WAL, one file), any SQLAlchemy URL by option.

``FLAKELAB_DATABASE_URL`` (or ``--database``) picks the database; without it flakelab uses
``flakelab.db`` in the user data folder (``$XDG_DATA_HOME/flakelab``). Opening a database
brings its schema up to date through the Alembic migrations shipped in ``migrations/``.
Writes happen in one transaction per call: a batch is stored whole or not at all.
"""

from __future__ import annotations

import functools
import os
import shutil
import sqlite3
import time
import warnings
from collections import Counter
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
from sqlalchemy import (
    Connection,
    Engine,
    create_engine,
    delete,
    distinct,
    event,
    func,
    insert,
    literal,
    select,
)
from sqlalchemy.engine import URL, make_url
from sqlalchemy.exc import ArgumentError, IntegrityError, OperationalError, SQLAlchemyError
from sqlalchemy.orm import Session
from sqlalchemy.pool import NullPool, StaticPool

from flakelab.cases.case import Case, CaseError, colour_code_words, tin_fields
from flakelab.cases.schema import CaseRow
from flakelab.core.documents import json_value
from flakelab.core.spectra import WAVELENGTHS
from flakelab.core.times import zoned, zoned_here
from flakelab.core.wording import counted, database_label, hidden_passwords
from flakelab.errors import FlakelabError, Note
from flakelab.io import STANDARD_STREAM

__all__ = [
    "default_url",
    "open_database",
    "migrate",
    "lock_database",
    "write_transaction",
    "reading_rows",
    "refusal",
    "BUSY_TIMEOUT_S",
    "add_cases",
    "add_new_cases",
    "store_new_cases",
    "iter_cases",
    "count_cases",
    "count_stored_since",
    "case_exists",
    "existing_case_ids",
    "user_database_file",
    "latest_cases",
    "stored_sprayouts",
    "cases_by_rows",
    "remove_case",
    "synthetic_cases",
    "remove_synthetic_cases",
    "find_case_id",
    "short_id",
    "SHORT_ID_LENGTH",
    "shop_summary",
    "code_summary",
    "case_summary",
    "colour_codes",
    "DatabaseError",
]

MIGRATIONS = Path(__file__).resolve().parent / "migrations"

SHORT_ID_LENGTH = 13
"""Characters of a case id that tables show: 48 random bits of a generated id
(``39454a98-4d50``), 32 of a recorded one (``shop-0f3a9c21``), which tell apart the cases of
any shop's database; :func:`find_case_id` takes any unique beginning."""


BUSY_TIMEOUT_S = 30
"""How long a statement waits for another process's write to end before it gives up: on a
SQLite file, whose one writer at a time may be an import or a generation writing each batch in
one transaction (its busy timeout); on PostgreSQL, for a lock another connection holds, a row
it changes or the registry's turn (its ``lock_timeout``), so that a command never hangs."""

_LOCK_NOT_AVAILABLE = "55P03"
"""PostgreSQL's SQLSTATE for a statement that gave up waiting for a lock (``lock_timeout``)."""


class DatabaseError(FlakelabError):
    """The database cannot be opened or written; names the URL and the problem."""


def refusal(error: SQLAlchemyError, engine: Engine | None = None) -> str:
    """Why the database refused a statement, in one line: SQLite's "database is locked" (a
    write kept waiting past :data:`BUSY_TIMEOUT_S` behind another process's) says so and what
    to do; anything else is the driver's first line, and where ``engine``'s SQLite file lies
    on a disk that is full, says so (:func:`_full_disk`)."""
    said = str(getattr(error, "orig", error)).splitlines()[0]
    if isinstance(error, OperationalError) and "readonly database" in said:
        return (
            f"{said}: the file, or its folder, cannot be written from here (a read-only disk "
            "or share, or another user's folder)"
        )
    if isinstance(error, OperationalError) and "database is locked" in said:
        return (
            f"another process has been writing to it for over {BUSY_TIMEOUT_S} s (an import or "
            "a generation writes each batch in one transaction); try again when it is done"
        )
    if getattr(getattr(error, "orig", None), "sqlstate", None) == _LOCK_NOT_AVAILABLE:
        return (
            f"another connection has held what this needs for over {BUSY_TIMEOUT_S} s (a write "
            "in progress, or a session left open in a transaction); try again when it is done"
        )
    return f"{error.__class__.__name__}: {said}{_full_disk(engine)}"


ROOM_NEEDED_BYTES = 1 << 20
"""Free space below which a SQLite file's disk is called full when the file is refused: its
shared-memory file alone takes 32 KiB, and a batch of cases a few hundred."""


def _full_disk(engine: Engine | None) -> str:
    """What the disk holding ``engine``'s SQLite file lacks, where it is full: SQLite calls
    that "disk I/O error" when even a read cannot make its ``-shm`` file, which reads as a
    broken disk; "" for another database, or a disk with room."""
    file = _sqlite_file(str(engine.url)) if engine is not None else None
    if not file:
        return ""
    try:
        free = shutil.disk_usage(Path(file).parent).free
    except OSError:  # no such folder: SQLite's own words say enough
        return ""
    if free >= ROOM_NEEDED_BYTES:
        return ""
    return (
        f" (its disk is full, {free // 1024} KiB free: SQLite needs room beside the file to "
        "write it, and even to read it; free some space and try again)"
    )


@contextmanager
def write_transaction(
    engine: Engine, doing: str, undone: str = "nothing was changed", rows: tuple | None = None
):
    """A session whose writes are one transaction, committed when the block ends. A database
    that refuses it (locked by another process's long write, a server gone) is a
    :class:`DatabaseError` naming the URL, what was being done (``doing``: "remove the
    case") and that it was rolled back (``undone``); so is a row it reads that holds a value
    its column cannot read, named as :func:`reading_rows` names it (``rows``: its row class,
    what a row is and its key column). Other errors (a duplicate's ``IntegrityError``, the
    caller's own) pass through as raised."""
    try:
        with Session(engine) as session, session.begin():
            yield session
    except OperationalError as error:
        raise DatabaseError(
            f"{database_label(engine)}: cannot {doing}: {refusal(error, engine)}; {undone}"
        ) from None
    except FlakelabError:
        raise
    except (ValueError, TypeError):
        found = None if rows is None else _damaged_row(engine, *rows)
        if found is None:
            raise
        raise DatabaseError(
            f"{database_label(engine)}: cannot {doing}: {found}; {undone}"
        ) from None


def default_url() -> str:
    """``FLAKELAB_DATABASE_URL`` (a URL or, as ``--database`` takes, a SQLite file) or a
    SQLite file in the user's data folder."""
    if url := os.environ.get("FLAKELAB_DATABASE_URL"):
        return url_for(url)
    file = user_database_file()
    try:
        file.parent.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise DatabaseError(
            f"{file.parent}: cannot make the user data folder of the default database "
            f"({error.strerror}); name one with --database or FLAKELAB_DATABASE_URL"
        ) from None
    return _sqlite_url(file)


def user_database_file() -> Path:
    """The SQLite file in the user's data folder (XDG), the database of the commands that
    name none; it need not exist yet. ``XDG_DATA_HOME`` set empty or to a relative path is
    ignored, as the XDG Base Directory Specification says: flakelab read ``XDG_DATA_HOME=``
    as the current folder, and each folder a command ran in got a database of its own."""
    data_home = os.environ.get("XDG_DATA_HOME", "")
    base = Path(data_home) if os.path.isabs(data_home) else Path.home() / ".local" / "share"
    return base / "flakelab" / "flakelab.db"


def url_for(target: str | os.PathLike) -> str:
    """A URL as given, or a SQLite URL for a file path; ``-``, which a measurement's reader
    takes for standard input, is refused (it was a database file named "-")."""
    text = str(target)
    if text == STANDARD_STREAM:
        raise DatabaseError(
            "-: a database is a file or a server's URL; standard input and output hold none "
            "(a file named - by its whole path)"
        )
    return text if "://" in text else _sqlite_url(Path(text).resolve())


def _sqlite_url(file: Path) -> str:
    """The SQLite URL of ``file``, quoted as a URL is: a name with ``?`` opened the file before
    it (the rest read as the URL's query) and one with ``%20`` a file with a space."""
    return URL.create("sqlite", database=str(file)).render_as_string(hide_password=False)


def _sqlite_pragmas(dbapi_connection, _record, journal: str = "WAL") -> None:
    cursor = dbapi_connection.cursor()
    cursor.execute(f"PRAGMA busy_timeout={BUSY_TIMEOUT_S * 1000}")
    _switch_journal(cursor, journal)
    cursor.execute("PRAGMA foreign_keys=ON")
    cursor.close()


def _switch_journal(cursor, journal: str) -> None:
    """``PRAGMA journal_mode=…``, tried again for up to :data:`BUSY_TIMEOUT_S`: workplaces
    switching a new file at once meet each other's locks, and SQLite says "database is
    locked" at once there, without the busy timeout's wait (one of four processes opening a
    new database at once was refused so, now and then)."""
    deadline = time.monotonic() + BUSY_TIMEOUT_S
    while True:
        try:
            cursor.execute(f"PRAGMA journal_mode={journal}")
            return
        except sqlite3.OperationalError as error:
            if "locked" not in str(error) or time.monotonic() > deadline:
                raise
            time.sleep(0.01)


def _journal_for(file: str) -> str:
    """WAL, but where the SQLite ``file`` lies on a folder shared over a network: WAL's readers
    and writers share memory through its ``-shm`` file, which workplaces cannot share over a
    network ("WAL does not work over a network filesystem", SQLite's WAL documentation), and
    a database there could be read torn or corrupted. It keeps SQLite's rollback journal
    there, with a note: the share must pass SQLite's file locks on, which many do poorly."""
    from flakelab.io.records import network_file_system  # the file formats: not at start-up

    share = network_file_system(file)
    if share is None:
        return "WAL"
    warnings.warn(
        f"{file} lies on a network share ({share}): SQLite keeps its rollback journal there, "
        "since its WAL needs memory the workplaces cannot share over a network; for several "
        "workplaces writing cases at once, a PostgreSQL server (FLAKELAB_DATABASE_URL) is "
        "safer",
        Note,
        stacklevel=3,
    )
    return "DELETE"


def _postgres_settings(dbapi_connection, _record) -> None:
    cursor = dbapi_connection.cursor()
    cursor.execute(f"SET lock_timeout = {BUSY_TIMEOUT_S * 1000}")
    cursor.close()
    dbapi_connection.commit()  # a SET in a transaction rolled back is undone


SQLITE_HEADER = b"SQLite format 3\x00"
"""The first bytes of every SQLite database file (an empty file is one with no tables yet)."""


def _not_sqlite(file: Path) -> str | None:
    """What a file given as a database is where it is no SQLite database: a case file, told
    how to import it, or another file; None where it is one, empty, or not there. SQLite said
    "file is not a database" of any."""
    try:
        with file.open("rb") as handle:
            head = handle.read(len(SQLITE_HEADER))
    except OSError:  # not there, or unreadable: said where it is opened
        return None
    if not head or head == SQLITE_HEADER:
        return None
    from flakelab.cases.exchange import is_case_file  # the file formats: not at start-up

    if is_case_file(file):
        return f"a case file? 'flakelab cases import {file.name}' stores its cases in one"
    return "its first bytes are not those of one"


def open_database(url: str | os.PathLike | None = None, *, must_exist: bool = False) -> Engine:
    """An engine on an up-to-date database (migrations applied). A SQLite file that does not
    exist is created, unless ``must_exist`` and the file was named (here or by
    ``FLAKELAB_DATABASE_URL``): commands that only read refuse it, since a mistyped path would
    leave an empty database behind and report no cases, or the shipped model."""
    named = url is not None or bool(os.environ.get("FLAKELAB_DATABASE_URL"))
    url = url_for(url) if url is not None else default_url()
    file = _sqlite_file(url)
    shown = file or hidden_passwords(url)  # as database_label names it once open
    # the user data folder's own database is made on first use
    if file and Path(file).is_dir():
        raise DatabaseError(f"{shown}: a folder, not a database file")
    # /dev/null, a pipe (io.records.is_no_regular_file, whose package is not loaded here)
    if file and Path(file).exists() and not Path(file).is_file():
        raise DatabaseError(f"{shown}: not a regular file, so not a database file")
    if must_exist and named and file and not Path(file).is_file():
        raise DatabaseError(
            f"{shown}: no such database file; nothing was created (the commands that store "
            "cases or models create one)"
        )
    if file and (what := _not_sqlite(Path(file))):
        raise DatabaseError(f"{shown}: cannot open the database: not a SQLite one; {what}")
    if file and not Path(file).exists():
        from flakelab.io.records import unwritable_folder  # the file formats: not at start-up

        if problem := unwritable_folder(file):  # SQLite: "unable to open database file"
            raise DatabaseError(f"{shown}: {problem}; nothing was created")
    engine = None
    try:
        # a command holds its database for a few transactions: each connection is closed when
        # its transaction ends, none is left open for the collector (psycopg warns of those);
        # an in-memory SQLite database lives in its one connection, which is kept
        pool = StaticPool if file == "" else NullPool
        # the JSON columns parsed as files are (a report's integer past 64 bits, a float)
        engine = create_engine(
            url, poolclass=pool, json_deserializer=json_value, **_read_only_connections(file)
        )
        if engine.dialect.name == "sqlite":
            journal = _journal_for(file) if file else "WAL"
            event.listen(engine, "connect", functools.partial(_sqlite_pragmas, journal=journal))
        elif engine.dialect.name == "postgresql":
            event.listen(engine, "connect", _postgres_settings)
        migrate(engine)
    except SQLAlchemyError as error:
        said = refusal(error, engine)
        raise DatabaseError(f"{shown}: cannot open the database: {said}") from None
    except ImportError as error:  # the URL's driver (psycopg for PostgreSQL) is not installed
        raise DatabaseError(
            f"{shown}: cannot open the database: its driver is not installed ({error}); for "
            "PostgreSQL: pip install 'flakelab[postgres]'"
        ) from None
    return engine


def _read_only_connections(file: str | None) -> dict:
    """How to open a SQLite ``file`` whose folder cannot be written (a read-only disk or
    share, another user's folder): through a read-only URI, since SQLite would make its
    ``-wal`` and ``-shm`` files there even to read and was refused "unable to open database
    file". Immutable (nothing changes it from here, so SQLite need not watch for changes)
    unless a ``-wal`` file beside it holds changes a writer has not yet moved into the file,
    which only a reader sharing the writer's ``-shm`` sees. Writes are refused "attempt to
    write a readonly database". ``{}`` where the folder can be written, or for no file."""
    from flakelab.io.records import unwritable_folder  # the file formats: not at start-up

    if not file or not Path(file).is_file() or unwritable_folder(file) is None:
        return {}
    wal = Path(f"{file}-wal")
    changes_pending = wal.is_file() and wal.stat().st_size > 0
    uri = f"{Path(file).as_uri()}?mode=ro{'' if changes_pending else '&immutable=1'}"
    return {"creator": lambda: sqlite3.connect(uri, uri=True, check_same_thread=False)}


def _sqlite_file(url: str) -> str | None:
    """The file a SQLite URL names: "" for an in-memory database, None for another kind of
    database (or a malformed URL, which ``create_engine`` names)."""
    try:
        parsed = make_url(url)
    except ArgumentError:
        return None
    if parsed.get_backend_name() != "sqlite":
        return None
    return "" if parsed.database in (None, "", ":memory:") else parsed.database


MIGRATION_LOCK = 0x666C616B65
"""PostgreSQL's advisory lock that migrations take in turn ("flake" in ASCII)."""


def lock_database(connection: Connection, key: int) -> None:
    """Hold the lock ``key`` until ``connection``'s transaction ends, so that writers that
    read before they write take their turns: SQLite's write lock (one for the whole file),
    taken now rather than at the first write; on PostgreSQL the advisory lock ``key``."""
    dialect = connection.dialect.name
    if dialect == "sqlite":
        connection.exec_driver_sql("BEGIN IMMEDIATE")
    elif dialect == "postgresql":
        connection.execute(select(func.pg_advisory_xact_lock(key)))


def _other_applications_tables(connection: Connection, shown: int = 5) -> list[str]:
    """The first ``shown`` tables of a database that holds none of flakelab's (a path
    mistyped onto another application's SQLite file, a URL onto its database): built into,
    it would gain flakelab's tables beside its own. Empty for a flakelab or a new database."""
    from sqlalchemy import inspect

    from flakelab.cases.schema import Base

    tables = sorted(inspect(connection).get_table_names())
    if set(tables) & set(Base.metadata.tables):
        return []
    return tables[:shown] + ([f"{len(tables) - shown} more"] if len(tables) > shown else [])


def migrate(engine: Engine, revision: str = "head") -> None:
    """Bring the database's schema to ``revision`` through the shipped migrations, in one
    transaction that holds the database's migration lock: workplaces opening a new database
    at once build its tables one after another, and all but the first find them built (four
    processes left three refused before, "table cases already exists", on SQLite and on
    PostgreSQL)."""
    # imported here: alembic is a third of a second of every command's start, and a command
    # that opens no database (a match on a fresh machine) needs none of it
    from alembic import command
    from alembic.config import Config
    from alembic.runtime.migration import MigrationContext
    from alembic.script import ScriptDirectory

    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS))
    script = ScriptDirectory.from_config(config)
    wanted = script.get_current_head() if revision == "head" else revision
    # an up-to-date database is read, not locked: a command would otherwise wait for a long
    # write (an import of 61,000 cases is one transaction) before it could read
    with engine.connect() as connection:
        current = MigrationContext.configure(connection).get_current_revision()
        if current == wanted:
            return
        others = _other_applications_tables(connection)
    if others:
        raise DatabaseError(
            f"{database_label(engine)}: holds another application's tables "
            f"({', '.join(others)}) and none of flakelab's; nothing was changed: name a "
            "flakelab database, or a new one"
        )
    if current is not None and current not in {s.revision for s in script.walk_revisions()}:
        from flakelab import __version__

        raise DatabaseError(
            f"{database_label(engine)}: its tables were built by a newer flakelab (migration "
            f"{current!r}, which flakelab {__version__} does not have); open it with that "
            "flakelab or a newer one; nothing was changed"
        )
    with engine.begin() as connection:
        lock_database(connection, MIGRATION_LOCK)
        config.attributes["connection"] = connection
        command.upgrade(config, revision)


def _row(case: Case) -> CaseRow:
    return CaseRow(**_row_values(case))


def _row_values(case: Case) -> dict:
    """A case's row, column by column."""
    now = datetime.now(UTC)
    return dict(
        case_id=case.case_id,
        shop=case.shop,
        instrument=case.instrument,
        conditions=case.conditions,
        outcome=case.outcome,
        synthetic=case.synthetic,
        geometries=list(case.geometry_names),
        recipe=dict(case.recipe),
        target=case.target.astype("<f4").tobytes(),
        sprayout=case.sprayout.astype("<f4").tobytes(),
        target_texture=dict(case.target_texture),
        sprayout_texture=dict(case.sprayout_texture),
        tins={toner: tin_fields(tin) for toner, tin in case.tins.items()} or None,
        colour_code=case.colour_code,
        target_recovered=case.target_recovered,
        sprayout_recovered=case.sprayout_recovered,
        # in UTC: SQLite keeps no zone, so an offset would otherwise be dropped, not applied
        created_at=case.created_at.astimezone(UTC),
        updated_at=now,
    )


def _case(row: CaseRow, engine: Engine) -> Case:
    """The case a row of ``engine``'s database holds; a value it holds damaged (written by
    another tool, or edited by hand) is a :class:`CaseError` naming the database, the case
    and the field."""
    try:
        return _case_of(row)
    except (ValueError, TypeError) as error:
        raise _in_case(engine, row.case_id, error) from None


def _in_case(engine: Engine, case_id: str, error: Exception) -> CaseError:
    """``error``, met reading case ``case_id`` of ``engine``'s database, naming both (once: a
    case's own checks name the case already)."""
    where = f"case {case_id!r}: "
    return CaseError(f"{database_label(engine)}: {where}{str(error).removeprefix(where)}")


def _case_of(row: CaseRow) -> Case:
    names = _geometry_names(row.geometries)
    return Case(
        case_id=row.case_id,
        geometries=tuple(names),
        recipe=row.recipe,
        target=_stored_spectra(row.target, "target", len(names)),
        sprayout=_stored_spectra(row.sprayout, "sprayout", len(names)),
        target_texture=row.target_texture,
        sprayout_texture=row.sprayout_texture,
        instrument=row.instrument,
        shop=row.shop,
        conditions=row.conditions,
        outcome=row.outcome,
        synthetic=row.synthetic,
        created_at=zoned(row.created_at),
        tins=row.tins or {},
        colour_code=row.colour_code,
        target_recovered=row.target_recovered,
        sprayout_recovered=row.sprayout_recovered,
    )


def _geometry_names(names) -> list[str]:
    """A case's stored geometry names, checked to be a list of texts."""
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise CaseError(f"geometries: expected a list of geometry names, got {names!r}")
    return names


def _stored_spectra(blob, name: str, geometries: int) -> np.ndarray:
    """A case's spectra ``[G, 31]`` from their stored bytes (little-endian float32)."""
    size = geometries * WAVELENGTHS.size * 4
    if isinstance(blob, memoryview | bytearray):  # as some drivers give a binary column
        blob = bytes(blob)
    if not isinstance(blob, bytes) or len(blob) != size:
        got = f"{len(blob)} bytes" if isinstance(blob, bytes) else f"{type(blob).__name__}"
        raise CaseError(
            f"{name}: expected {geometries} × {WAVELENGTHS.size} float32 values ({size} bytes) "
            f"for its geometries, got {got}"
        )
    return np.frombuffer(blob, "<f4").reshape(geometries, -1).astype(float)


@contextmanager
def reading_rows(engine: Engine, row_class=CaseRow, what: str = "case", key: str = "case_id"):
    """A session that reads rows of ``row_class``'s table. A value its column's type cannot
    read (JSON that is not, a date that is not: SQLite keeps whatever was written) stops the
    read as it is fetched, before the row is known: the rows are read again raw to name the
    ``what`` (by its ``key`` column), the row and the field (:func:`_damaged_row`), in a
    :class:`DatabaseError`. An error no stored value explains is flakelab's own and passes
    through as raised, so that a bug does not pass for a damaged database."""
    try:
        with Session(engine) as session:
            yield session
    except FlakelabError:
        raise
    except (ValueError, TypeError):
        found = _damaged_row(engine, row_class, what, key)
        if found is None:
            raise
        where = database_label(engine)
        raise DatabaseError(f"{where}: {found}; the database is left as it is") from None


def _damaged_row(engine: Engine, row_class, what: str, key: str) -> str | None:
    """The first row holding a value its column's type cannot read, as "WHAT KEY (row N):
    FIELD: PROBLEM", each raw value put through the type's own reading; None where every one
    reads."""
    table = row_class.__table__
    readers = {
        c.name: reader
        for c in table.columns
        if c.name != "id"
        and (reader := c.type.dialect_impl(engine.dialect).result_processor(engine.dialect, None))
        is not None
    }
    names = ("id", key, *readers)
    query = f"SELECT {', '.join(names)} FROM {table.name} ORDER BY id"  # raw: as stored
    with engine.connect() as connection:
        for row_id, label, *values in connection.exec_driver_sql(query):
            for name, value in zip(names[2:], values, strict=True):
                try:
                    readers[name](value)
                except (ValueError, TypeError) as error:
                    return (
                        f"{what} {label!r} (row {row_id}): {name}: cannot be read as "
                        f"{table.c[name].type} ({error}), got {str(value)[:40]!r}"
                    )
    return None


def add_cases(engine: Engine, cases: Iterable[Case]) -> int:
    """Store cases in one transaction; a duplicate case id rolls the whole batch back."""
    rows = [_row_values(c) for c in cases]
    if not rows:
        return 0
    try:  # as one bulk insert: half the time of the ORM's objects, row by row
        with Session(engine) as session, session.begin():
            session.execute(insert(CaseRow), rows)
    except IntegrityError as error:
        clash = _clash(engine, [r["case_id"] for r in rows], error)
        raise CaseError(f"{database_label(engine)}: {clash}; nothing was stored") from None
    except SQLAlchemyError as error:  # e.g. a value the server refuses (DataError)
        raise DatabaseError(
            f"{database_label(engine)}: cannot store the cases: {refusal(error, engine)}; "
            "nothing was stored"
        ) from None
    return len(rows)


def add_new_cases(engine: Engine, cases: list[Case]) -> tuple[int, int]:
    """Store those of ``cases`` not stored yet (one transaction) and return how many were
    stored and how many were there already (:func:`store_new_cases`)."""
    stored = store_new_cases(engine, cases)
    return len(stored), len(cases) - len(stored)


def store_new_cases(engine: Engine, cases: list[Case]) -> list[Case]:
    """Store those of ``cases`` not stored yet (one transaction) and return them. A case
    already stored must be stored as given, field by field (a generation cut short, or a
    shorter one of the same seed, stored it); an id stored with another case is a
    :class:`CaseError` naming the id and the field, and nothing is stored. Where another
    writer stores some of them meanwhile (the same generation run twice at once), they are
    looked at again."""
    left = _ADD_NEW_ATTEMPTS
    while True:
        new = _not_stored(engine, cases)
        try:
            add_cases(engine, new)
            return new
        except CaseError:
            left -= 1
            if not left:
                raise


def _not_stored(engine: Engine, cases: list[Case]) -> list[Case]:
    """Those of ``cases`` not stored; a :class:`CaseError` where one is stored otherwise."""
    stored = _stored_rows(engine, [c.case_id for c in cases])
    for case in cases:
        if case.case_id in stored:
            field = _differing_field(stored[case.case_id], _row(case))
            if field is not None:
                raise CaseError(
                    f"{database_label(engine)}: case {case.case_id!r} is already stored as "
                    f"another case (its {field} differs); nothing was stored"
                )
    return [c for c in cases if c.case_id not in stored]


_ADD_NEW_ATTEMPTS = 3
"""How many times :func:`add_new_cases` looks at which cases are stored: once, then again
each time another writer stored some of them first."""


_COMPARED = tuple(c.name for c in CaseRow.__table__.columns if c.name not in ("id", "updated_at"))
"""The columns that make two stored cases the same case (not the row or the time it was
stored)."""


def _stored_rows(engine: Engine, case_ids: list[str]) -> dict[str, CaseRow]:
    """The stored rows of those of ``case_ids`` already stored, by id."""
    return {row.case_id: row for row in _selected_by_id(engine, CaseRow, case_ids)}


def _selected_by_id(engine: Engine, selected, case_ids: list[str]) -> list:
    """``selected`` (the rows, or a column) of the stored cases among ``case_ids``, asked
    500 ids at a time: within every database's limit on a statement's parameters."""
    found = []
    with reading_rows(engine) as session:
        for start in range(0, len(case_ids), 500):
            chunk = case_ids[start : start + 500]
            found += session.scalars(select(selected).where(CaseRow.case_id.in_(chunk)))
    return found


def _differing_field(stored: CaseRow, given: CaseRow) -> str | None:
    """The first column in which ``stored`` holds another value than ``given``, else None;
    times compared in UTC (SQLite keeps no zone)."""
    for name in _COMPARED:
        ours, theirs = getattr(stored, name), getattr(given, name)
        if isinstance(ours, datetime) and isinstance(theirs, datetime):
            ours, theirs = zoned(ours), zoned(theirs)  # aware times compare as instants
        if ours != theirs:
            return name
    return None


def _clash(engine: Engine, ids: list[str], error: IntegrityError) -> str:
    """Which case ids made the database refuse the rows of ``ids``: stored already (by
    another writer, or an earlier run), or given twice."""
    stored = existing_case_ids(engine, ids)
    if stored:
        first = next(i for i in ids if i in stored)
        given = counted(len(ids), "case")
        return f"case {first!r} is already stored ({len(stored)} of the {given} given)"
    twice = [i for i, count in Counter(ids).items() if count > 1]
    if twice:
        return f"case {twice[0]!r} is given twice"
    return f"a case id already exists ({str(error.orig).splitlines()[0]})"


def iter_cases(
    engine: Engine,
    *,
    batch: int = 2000,
    limit: int | None = None,
    shop: str | None = None,
    since: datetime | None = None,
    colour_code: str | None = None,
) -> Iterator[Case]:
    """Cases in insertion order, read in batches: those of ``shop`` made at or after ``since``
    (without a zone: UTC), for ``colour_code`` (None: any shop, any time, any colour), chosen
    by the database, so that one shop's cases are read without the rest
    (``cases.case.cases_at`` picks those a model of one geometry set reads)."""
    query = _chosen(select(CaseRow).order_by(CaseRow.id), shop, since, colour_code)
    if limit:
        query = query.limit(limit)
    with reading_rows(engine) as session:
        for row in session.scalars(query.execution_options(yield_per=batch)):
            yield _case(row, engine)


def stored_sprayouts(
    engine: Engine,
    geometries: tuple[str, ...],
    *,
    shop: str | None = None,
    colour_code: str | None = None,
    since: datetime | None = None,
) -> tuple[list[int], np.ndarray]:
    """The row ids and spray-outs ``[N, G, 31]`` of the cases (``shop``'s, for
    ``colour_code``, made at or after ``since``, where given) read at every one of
    ``geometries``, restricted to them in their order: those columns alone, without building
    each case (a fifth of the time; :func:`cases_by_rows` builds the few that are wanted)."""
    columns = (CaseRow.id, CaseRow.case_id, CaseRow.geometries, CaseRow.sprayout)
    query = _chosen(select(*columns).order_by(CaseRow.id), shop, since, colour_code)
    wanted, ids, spectra = set(geometries), [], []
    with reading_rows(engine) as session:
        for row_id, case_id, names, sprayout in session.execute(query):
            try:
                names = _geometry_names(names)
                if wanted <= set(names):
                    rows = [names.index(g) for g in geometries]
                    spectra.append(_stored_spectra(sprayout, "sprayout", len(names))[rows])
                    ids.append(row_id)
            except CaseError as error:
                raise _in_case(engine, case_id, error) from None
    shape = (0, len(geometries), 0)
    return ids, np.stack(spectra) if spectra else np.zeros(shape)


def cases_by_rows(engine: Engine, row_ids: list[int]) -> list[Case]:
    """The cases of these row ids (:func:`stored_sprayouts`), in their order."""
    with reading_rows(engine) as session:
        rows = {r.id: r for r in session.scalars(select(CaseRow).where(CaseRow.id.in_(row_ids)))}
    return [_case(rows[i], engine) for i in row_ids]


def latest_cases(
    engine: Engine,
    n: int,
    *,
    shop: str | None = None,
    colour_code: str | None = None,
    since: datetime | None = None,
) -> list[Case]:
    """The ``n`` cases made last, newest first, of ``shop``, for ``colour_code``, made at or
    after ``since`` (None: every shop, every colour, any time)."""
    query = select(CaseRow).order_by(CaseRow.created_at.desc(), CaseRow.id.desc()).limit(n)
    query = _chosen(query, shop, since, colour_code)
    with reading_rows(engine) as session:
        return [_case(row, engine) for row in session.scalars(query)]


def remove_case(engine: Engine, case_id: str) -> Case | None:
    """Delete the case ``case_id`` (one transaction) and return it, None where the row holds
    values that cannot be read (a damaged case is removed all the same: it is the way out);
    an unknown id is an error and deletes nothing."""
    with write_transaction(engine, f"remove case {case_id!r}", "nothing was removed") as session:
        row_id = session.scalar(select(CaseRow.id).where(CaseRow.case_id == case_id))
        if row_id is None:
            raise CaseError(f"{database_label(engine)}: no case {case_id!r}; nothing was removed")
        try:
            case = _case(session.get_one(CaseRow, row_id), engine)
        except (ValueError, TypeError):
            case = None
        session.execute(delete(CaseRow).where(CaseRow.id == row_id))
    return case


def synthetic_cases(engine: Engine, shop: str | None = None, *, recorded: bool = False) -> dict:
    """How many synthetic cases (of ``shop``; None: of every shop) the database holds, by
    shop; with ``recorded``, how many recorded ones (those that are not synthetic) instead."""
    with reading_rows(engine) as session:
        return _counted_by_shop(session, _synthetic_of(shop, not recorded))


def remove_synthetic_cases(engine: Engine, shop: str | None = None) -> dict[str, int]:
    """Delete every synthetic case (of ``shop``; None: of every shop) in one transaction and
    return how many, by shop: a generation stored by mistake among a shop's recorded cases,
    taken out again. No recorded case is among them."""
    where = _synthetic_of(shop)
    with write_transaction(engine, "remove the synthetic cases", "nothing was removed",
                           rows=(CaseRow, "case", "case_id")) as session:  # fmt: skip
        removed = _counted_by_shop(session, where)
        session.execute(delete(CaseRow).where(*where))
    return removed


def _synthetic_of(shop: str | None, synthetic: bool = True) -> tuple:
    """The conditions of the cases synthetic (or recorded) of ``shop`` (None: any shop)."""
    return (CaseRow.synthetic.is_(synthetic), *([CaseRow.shop == shop] if shop else []))


def _counted_by_shop(session: Session, where: tuple) -> dict[str, int]:
    """The cases that meet ``where``, counted by shop."""
    query = select(CaseRow.shop, func.count(CaseRow.id)).where(*where).group_by(CaseRow.shop)
    return dict(session.execute(query.order_by(CaseRow.shop)).all())


def short_id(case_id: str) -> str:
    """A case id as tables show it: its first :data:`SHORT_ID_LENGTH` characters."""
    return case_id[:SHORT_ID_LENGTH]


def find_case_id(engine: Engine, given: str) -> str:
    """The stored case id that ``given`` is, or the one it begins (a shortened id, as tables
    show it); a :class:`CaseError` naming the matches where none or several match."""
    if case_exists(engine, given):
        return given
    if not given.strip():
        raise CaseError(f"{database_label(engine)}: expected a case id, got {given!r}")
    escaped = given.replace("\\", "\\\\").replace("%", "\\%").replace("_", "\\_")
    query = select(CaseRow.case_id).where(CaseRow.case_id.like(f"{escaped}%", escape="\\"))
    with reading_rows(engine) as session:
        found = list(session.scalars(query.order_by(CaseRow.case_id).limit(6)))
    if not found:
        raise CaseError(f"{database_label(engine)}: no case {given!r}")
    if len(found) > 1:
        many = "more than five" if len(found) > 5 else str(len(found))
        raise CaseError(
            f"{database_label(engine)}: {given!r} begins the ids of {many} cases "
            f"({', '.join(found[:5])}): give more of it"
        )
    return found[0]


def case_exists(engine: Engine, case_id: str) -> bool:
    """Whether a case with this id is stored."""
    return bool(existing_case_ids(engine, [case_id]))


def existing_case_ids(engine: Engine, case_ids: Iterable[str]) -> set[str]:
    """Those of ``case_ids`` already stored."""
    return set(_selected_by_id(engine, CaseRow.case_id, list(case_ids)))


def count_cases(
    engine: Engine,
    *,
    shop: str | None = None,
    since: datetime | None = None,
    colour_code: str | None = None,
) -> int:
    """How many cases :func:`iter_cases` reads with the same ``shop``, ``since`` and
    ``colour_code``."""
    query = _chosen(select(func.count(CaseRow.id)), shop, since, colour_code)
    with Session(engine) as session:
        return int(session.scalar(query) or 0)


def count_stored_since(engine: Engine, since: datetime, geometries: Iterable[str]) -> int:
    """How many cases were stored in the database (recorded, imported or generated into it)
    at or after ``since`` (without a zone: UTC), read at every one of ``geometries``: those a
    model whose training read the database at ``since`` has not seen, whatever their own
    time (an imported history's cases were made long before), and could learn from (a
    spray-out known by its L*a*b* alone too: its colour is learnt)."""
    stored = CaseRow.updated_at >= zoned_here(since).astimezone(UTC)  # a case's storing
    query = select(CaseRow.case_id, CaseRow.geometries).where(stored)
    wanted, count = set(geometries), 0
    with reading_rows(engine) as session:
        for case_id, names in session.execute(query):
            try:
                count += wanted <= set(_geometry_names(names))
            except CaseError as error:
                raise _in_case(engine, case_id, error) from None
    return count


def _chosen(query, shop: str | None, since: datetime | None, colour_code: str | None):
    """``query`` restricted to the cases of ``shop`` made at or after ``since`` for
    ``colour_code`` (None: any), as :func:`~flakelab.cases.case.select_cases` chooses them."""
    if shop is not None:
        query = query.where(CaseRow.shop == shop)
    if since is not None:  # stored in UTC (SQLite keeps no zone)
        query = query.where(CaseRow.created_at >= zoned_here(since).astimezone(UTC))
    # stored as its words, each letters and digits alone: a word asked is ' WORD ' within
    # ' CODE ' (no LIKE wildcard can be among them)
    spaced = literal(" ") + CaseRow.colour_code + literal(" ")
    for word in colour_code_words(colour_code or ""):
        query = query.where(spaced.like(f"% {word} %"))
    return query


def colour_codes(engine: Engine, *, shop: str | None = None) -> list[str]:
    """The colour codes the cases (of ``shop``, where given) record, each once."""
    query = _chosen(select(CaseRow.colour_code).distinct(), shop, None, None)
    with reading_rows(engine) as session:
        return sorted(code for code in session.scalars(query) if code)


def shop_names(engine: Engine) -> list[str]:
    """The shops whose cases the database keeps, each once."""
    with reading_rows(engine) as session:
        return sorted(session.scalars(select(CaseRow.shop).distinct()))


def shop_summary(engine: Engine) -> list[dict]:
    """Every shop in the database: its cases by outcome, and the first and last case's time."""
    return case_summary(engine, "shop")


def code_summary(engine: Engine, *, shop: str | None = None) -> list[dict]:
    """Every colour code the cases (of ``shop``, where given) record: its cases by outcome, and
    the first and last case's time; cases without a code are left out."""
    return [s for s in case_summary(engine, "colour_code", shop=shop) if s["colour_code"]]


def case_summary(engine: Engine, by: str, *, shop: str | None = None) -> list[dict]:
    """The cases (of ``shop``, where given) grouped by the column ``by`` ('shop',
    'colour_code'): each group's cases by outcome, its first and last case's time (in UTC),
    and, grouped by another column than the shop, how many shops made them; in the order of
    ``by``."""
    column = getattr(CaseRow, by)
    query = select(
        column,
        CaseRow.outcome,
        func.count(CaseRow.id),
        func.min(CaseRow.created_at),
        func.max(CaseRow.created_at),
    ).group_by(column, CaseRow.outcome)
    groups: dict[str, dict] = {}
    with reading_rows(engine) as session:
        for key, outcome, n, first, last in session.execute(_chosen(query, shop, None, None)):
            first, last = zoned(first), zoned(last)  # SQLite keeps no zone: stored in UTC
            entry = groups.setdefault(
                key, {by: key, "cases": 0, "outcomes": {}, "first": first, "last": last}
            )
            entry["cases"] += n
            entry["outcomes"][outcome] = n
            entry["first"], entry["last"] = min(entry["first"], first), max(entry["last"], last)
        if by != "shop":
            shops = select(column, func.count(distinct(CaseRow.shop))).group_by(column)
            for key, n in session.execute(_chosen(shops, shop, None, None)):
                groups[key]["shops"] = n
    return [groups[key] for key in sorted(groups)]
