"""How a report words things. It counts them, "1 case", "3 cases", in one place, so that no
message reads "1 cases" or hedges with "case(s)"; it hides the password of a database URL
(a shop's PostgreSQL server) wherever one is shown, and names a SQLite database by its file.
It imports nothing but the standard library, like :mod:`flakelab.core.defaults`."""

import difflib
import re
import unicodedata
from collections.abc import Callable, Iterable
from urllib.parse import unquote

_URL_PASSWORD = re.compile(r"\b([A-Za-z][A-Za-z0-9+.-]*://[^\s:/@]*:)[^\s/@]+@")
"""A URL's ``scheme://user:`` and the password after it, up to its ``@``."""


def counted(n: int, noun: str, plural: str | None = None) -> str:
    """``n`` and ``noun``, the noun plural unless ``n`` is 1: ``counted(1, "case")`` is
    "1 case", ``counted(2, "spray-out")`` "2 spray-outs"; ``plural`` where adding an "s"
    does not make it ("geometry", "geometries")."""
    return f"{n} {noun if n == 1 else plural or noun + 's'}"


def with_article(noun: str) -> str:
    """``noun`` after its indefinite article, by its first letter: "an aluminium", "a
    pearl"."""
    return f"{'an' if noun[:1].lower() in 'aeiou' else 'a'} {noun}"


def did_you_mean(name: str, choices: Iterable[str], key: Callable[[str], str] = str) -> str:
    """ " (did you mean 'Phthalo blue GS'?)": the one of ``choices`` that ``name`` most likely
    means, for the message that refuses it; "" where none is near. One whose ``key`` is
    ``name``'s (the same but for case and spaces, as ``key`` makes them alike) comes first,
    then the closest spelling of the keys."""
    keys = {key(c): c for c in choices}
    wanted = key(name)
    near = [wanted] if wanted in keys else difflib.get_close_matches(wanted, list(keys), 1, 0.6)
    return f" (did you mean {keys[near[0]]!r}?)" if near else ""


def shop_meant(name: str, shops: Iterable[str]) -> str:
    """ " (did you mean 'Dupont & Fils'?)": the one of ``shops`` that a shop's ``name`` which
    found none likely means, the same but for case, spaces and punctuation ('dupont-fils'),
    else the closest spelling; "" where ``name`` is among them or none is near."""
    shops = set(shops)
    if name in shops:
        return ""
    return did_you_mean(name, shops, lambda shop: re.sub(r"[\W_]+", "", shop.casefold()))


def hidden_passwords(text: str) -> str:
    """``text`` with the password of every URL in it shown as SQLAlchemy shows it
    (``postgresql://flakelab:***@server/shop``): a message may be read over a colorist's
    shoulder, pasted into a report or kept in a log."""
    return _URL_PASSWORD.sub(r"\1***@", text)


def database_label(engine) -> str:
    """How a message names the database of ``engine`` (a SQLAlchemy engine, or its URL): a
    SQLite file by its path, as every other file is named (``/home/anna/shop.db``, not the
    URL ``sqlite:////home/anna/shop.db`` that ``--database shop.db`` became); any other
    database by its URL, the password hidden as SQLAlchemy hides it."""
    url = getattr(engine, "url", engine)
    if isinstance(url, str):
        file = unquote(url.removeprefix("sqlite:///").partition("?")[0])
        return file if url.startswith("sqlite:///") and file else hidden_passwords(url)
    if url.get_backend_name() == "sqlite" and url.database not in (None, "", ":memory:"):
        return url.database
    if url.get_backend_name() == "sqlite" and url.database == ":memory:":
        return "sqlite:///:memory:"  # as typed; SQLAlchemy writes sqlite:///%3Amemory%3A
    return str(url)


def tidy_name(name: str) -> str:
    """A name a person typed (a shop's), as it is stored and looked for: spaces at its ends
    dropped and a run of them made one, in Unicode's composed form. "Dupont " and "Dupont"
    were two shops, shown alike in every table, and a shop's cases were split between them."""
    return " ".join(unicodedata.normalize("NFC", name).split())
