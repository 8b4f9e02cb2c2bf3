"""Tolerances from the shipped presets or from a user's TOML/JSON file.

A tolerance file::

    name = "my-shop"
    description = "tighter at 45as45"
    [default]
    de00 = 1.2
    [geometries."45as45"]
    de00 = 0.8
    [geometries."45as15"]
    dL = 2.0
    dC = 1.0
    dH = 0.8
"""

from __future__ import annotations

import json
import tomllib
from os import PathLike
from pathlib import Path

from flakelab.core.documents import json_value, toml_value
from flakelab.core.tolerance import TOLERANCE_PRESETS, Tolerance
from flakelab.errors import FlakelabError
from flakelab.io.records import STANDARD_STREAM, text_of

__all__ = ["read_tolerance"]


def read_tolerance(name_or_path: str | PathLike) -> Tolerance:
    """A preset by name (``refinish``, ``de00-1.0``, ``components``) or a TOML/JSON file."""
    if str(name_or_path) in TOLERANCE_PRESETS:
        return TOLERANCE_PRESETS[str(name_or_path)]
    path = Path(name_or_path)
    if not path.is_file() and str(path) != STANDARD_STREAM:
        raise FlakelabError(
            f"{name_or_path}: neither a tolerance preset ({', '.join(TOLERANCE_PRESETS)}) "
            f"nor a tolerance file"
        )
    try:
        text = text_of(path)
    except UnicodeDecodeError as error:
        raise FlakelabError(
            f"{path}: not a UTF-8 text (TOML or JSON) tolerance file ({error.reason})"
        ) from None
    try:
        data = json_value(text) if path.suffix.lower() == ".json" else toml_value(text)
    except (json.JSONDecodeError, tomllib.TOMLDecodeError) as error:
        raise FlakelabError(
            f"{path}: not valid {path.suffix.lstrip('.').upper() or 'TOML'} ({error})"
        ) from None
    try:
        return Tolerance.from_dict(data, source=str(path))
    except ValueError as error:
        raise FlakelabError(str(error)) from None
