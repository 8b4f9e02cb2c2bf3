"""Exceptions every layer raises, so the CLI and the server can report them in one line."""

from __future__ import annotations

from os import PathLike

__all__ = [
    "FlakelabError",
    "MeasurementFileError",
    "MissingGeometryError",
    "ModelError",
    "Note",
    "shown",
]


def shown(value: object, limit: int = 60) -> str:
    """A bad value as a message quotes it: its repr, cut to ``limit`` characters (a whole
    spectrum or object would bury the message).

    Examples
    --------
    >>> shown("x"), shown(list(range(40)))
    ("'x'", '[0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16…')
    """
    text = repr(value)
    return text if len(text) <= limit else f"{text[: limit - 3]}…"


class FlakelabError(ValueError):
    """A problem with user input that flakelab can state in one line."""


class MissingGeometryError(FlakelabError, KeyError):
    """A geometry asked of a measurement that was not read there: a user's error (a file read
    at other angles), and a :class:`KeyError` as a lookup that finds nothing is. The command
    line takes a plain KeyError for a fault of the code: a library's (Pillow's ``KeyError('TIF')``
    read "error: TIF", blaming the user)."""

    __str__ = Exception.__str__  # the message as written, not quoted as KeyError quotes it


class ModelError(FlakelabError):
    """A model file or a model input that is wrong."""


class Note(UserWarning):
    """Something the user of a command should know that stops nothing (raised with
    :func:`warnings.warn`); the command line prints it as a note."""


class MeasurementFileError(FlakelabError):
    """A measurement file that cannot be read: names the file, the field and the problem.

    Examples
    --------
    >>> str(MeasurementFileError("a.csv", "not a number: 'x'", field="row 3, R450"))
    "a.csv: row 3, R450: not a number: 'x'"
    """

    def __init__(self, path: str | PathLike[str], problem: str, *, field: str | None = None):
        self.path = str(path)
        self.field = field
        self.problem = problem
        where = f"{self.path}: {field}" if field else self.path
        super().__init__(f"{where}: {problem}")
