"""Times: stored in UTC, typed and shown in this machine's local time.

Every time is stored in UTC (SQLite keeps no zone, so a stored time without one is UTC) and
written in UTC, with its offset, to JSON reports and exchanged case files. A time read
without a zone from where a person or an instrument wrote it (a spray-out file's date, a
shop's case file, ``--since`` typed at the command line) is local time, and a report shows
times in local time: taken as UTC, a case recorded at 17:05 in Berlin read "16:05", and
``--since 2026-12-01`` began at 01:00 there. It imports nothing but the standard library,
like :mod:`flakelab.core.wording`.
"""

from datetime import UTC, datetime

__all__ = ["shown_time", "zoned", "zoned_here"]


def zoned(time: datetime) -> datetime:
    """A stored ``time``, taken as UTC where it has no zone."""
    return time if time.tzinfo is not None else time.replace(tzinfo=UTC)


def zoned_here(time: datetime) -> datetime:
    """A ``time`` as an instrument's clock, a shop's case file or a person at the command
    line writes it: taken as this machine's local time where it has no zone."""
    return time if time.tzinfo is not None else time.astimezone()


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
