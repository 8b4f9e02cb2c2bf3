"""Toner library files: JSON (``format: flakelab-library``) or the same structure in TOML.

The shipped demo library is ``flakelab/data/demo-library.json``
(regenerate with ``python scripts/make_demo_library.py``).
"""

from __future__ import annotations

import json
import tomllib
from importlib.resources import files
from os import PathLike
from pathlib import Path

from flakelab.core.documents import json_value, toml_value
from flakelab.io.records import (
    other_format,
    text_of,
    write_atomically,
)
from flakelab.library.toners import Library, LibraryError

__all__ = ["read_library", "write_library", "demo_library_path"]


def demo_library_path() -> Path:
    return Path(str(files("flakelab.data") / "demo-library.json"))


def read_library(path: str | PathLike | None = None) -> Library:
    """Read and check a toner library; ``None`` gives the shipped demo library."""
    path = demo_library_path() if path is None else Path(path)
    try:
        text = text_of(path)
    except FileNotFoundError:
        raise LibraryError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise LibraryError(f"{path}: a folder, not a toner library") from None
    except (OSError, UnicodeDecodeError) as error:
        if isinstance(error, UnicodeDecodeError) and (kind := other_format(path)):
            raise LibraryError(f"{path}: expected a toner library; this is {kind}") from None
        raise LibraryError(f"{path}: cannot be read ({error})") from None
    if not text.strip():
        raise LibraryError(f"{path}: empty file; expected a toner library")
    try:
        data = toml_value(text) if path.suffix.lower() == ".toml" else json_value(text)
    except json.JSONDecodeError as error:
        if kind := other_format(path):
            raise LibraryError(f"{path}: expected a toner library; this is {kind}") from None
        raise LibraryError(
            f"{path}: line {error.lineno}, column {error.colno}: invalid JSON ({error.msg})"
        ) from None
    except tomllib.TOMLDecodeError as error:
        raise LibraryError(f"{path}: invalid TOML ({error})") from None
    if not isinstance(data, dict):
        raise LibraryError(f"{path}: expected an object at the top level")
    return Library.from_dict(data, source=str(path))


def write_library(library: Library, path: str | PathLike) -> None:
    text = json.dumps(library.to_dict(), indent=1, ensure_ascii=False)
    write_atomically(path, lambda temporary: temporary.write_text(text, encoding="utf-8"))
