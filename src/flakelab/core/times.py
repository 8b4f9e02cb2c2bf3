"""Times: stored in UTC, typed and shown in this machine's local time.

Every time is stored in UTC (SQLite keeps no zone, so a stored time without one is UTC) and
written in UTC, with its offset, to JSON reports and exchanged case files. A time read
without a zone from where a person or an instrument wrote it (a spray-out file's date, a
shop's case file, ``--since`` typed at the command line) is local time, and a report shows
times in local time: taken as UTC, a case recorded at 17:05 in Berlin read "16:05", and
``--since 2026-12-01`` began at 01:00 there. It imports nothing but the standard library,
like :mod:`flakelab.core.wording`.
"""

import re
from datetime import UTC, datetime, timedelta

__all__ = ["TIME_EXPECTED", "read_time", "shown_time", "zoned", "zoned_here"]

TIME_EXPECTED = "a date and time such as 2026-11-22T09:30 or 22.11.2026 09:30"
"""What a refused time cell should have held, in the words of every message."""

_DAY_FIRST = re.compile(r"(\d{1,2})\.(\d{1,2})\.(\d{4})(?:[ T](\d{1,2}):(\d{2})(?::(\d{2}))?)?")


def zoned(time: datetime) -> datetime:
    """A stored ``time``, taken as UTC where it has no zone."""
    return time if time.tzinfo is not None else time.replace(tzinfo=UTC)


def zoned_here(time: datetime) -> datetime:
    """A ``time`` as an instrument's clock, a shop's case file or a person at the command
    line writes it: taken as this machine's local time where it has no zone."""
    if time.tzinfo is not None:
        return time
    local = time.astimezone()
    if local.replace(tzinfo=None) == time:
        return local
    # A wall time the clocks skipped (02:30 on the night summer time begins): read, as PEP
    # 495 reads it, with the offset before the change, 03:30 summer time; astimezone gave
    # 01:30, an hour before the time typed. A day before is before the change.
    before = (time - timedelta(days=1)).astimezone().utcoffset()
    return (time - before).replace(tzinfo=UTC).astimezone()


def shown_time(when: datetime | str | None, *, day: bool = False) -> str:
    """A stored time (or its ISO 8601 text) as a report shows it: in local time, to the
    minute, or to the ``day``; "" for none. A date alone, or text that is no ISO 8601 time
    (a tin's "calibrated" as a person wrote it), is shown as written: a date has no hour to
    move into another zone."""
    if not when:
        return ""
    if isinstance(when, str):
        try:
            moment = datetime.fromisoformat(when)
        except ValueError:
            return when
        if len(when) <= len("2026-12-03"):
            return when
        when = moment
    local = zoned(when).astimezone()
    return f"{local:%Y-%m-%d}" if day else f"{local:%Y-%m-%d %H:%M}"


def read_time(text: str) -> datetime:
    """A date and time as a person or a spreadsheet writes one in a file: ISO 8601
    (``2026-11-22T09:30``), or day first with dots, as a spreadsheet in most of Europe shows
    and saves a date typed into it (``22.11.2026 09:30``; refused before as no ISO 8601).
    Anything else is a :class:`ValueError`, slashes among them: ``11/12/2026`` is the 12th of
    November in one country and the 11th of December in the next."""
    text = text.strip()
    try:
        return datetime.fromisoformat(text)
    except ValueError:
        found = _DAY_FIRST.fullmatch(text)
        if found is None:
            raise ValueError(f"expected {TIME_EXPECTED}, got {text!r}") from None
        day, month, year, hour, minute, second = (int(g or 0) for g in found.groups())
        return datetime(year, month, day, hour, minute, second)  # 31.02. refused here
