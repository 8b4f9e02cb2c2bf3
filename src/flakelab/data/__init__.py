"""Data shipped with flakelab: example measurements (synthetic: ``scripts/make_examples.py``)."""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

__all__ = ["EXAMPLES", "example_path"]

EXAMPLES = {
    "target": "blue-metallic-target.cxf",
    "sprayout": "blue-metallic-sprayout.cxf",
}
"""Example name → file: a synthetic blue metallic target and a first spray-out of it."""


def example_path(name: str) -> Path:
    if name not in EXAMPLES:
        raise ValueError(f"expected an example among {', '.join(EXAMPLES)}, got {name!r}")
    return Path(str(files("flakelab.data") / "examples" / EXAMPLES[name]))
