"""Model files: the format :meth:`~flakelab.models.network.ForwardModel.to_bytes` writes, and
its description read without torch.

A model file is torch's zip archive of one dictionary: ``meta`` (a JSON text: the format
name, :data:`~flakelab.core.documents.MODEL_FORMAT`, then toners, geometries, instrument,
layer widths, ``info``), the network's ``state``, the normalisation and the learned spreads.
This module holds the check that a file is one, for both readers: the whole model (torch,
:mod:`flakelab.models.network`) and its description alone (here, without torch, for
``flakelab model list``).
"""

from __future__ import annotations

import pickle
import zipfile
from pathlib import Path

from flakelab.core.documents import MODEL_FORMAT, json_value
from flakelab.errors import ModelError

__all__ = [
    "model_file",
    "model_file_description",
    "not_a_model_file",
    "stored_meta",
]


def not_a_model_file(source: str, error: BaseException) -> ModelError:
    return ModelError(f"{source}: not a flakelab model file ({type(error).__name__})")


def stored_meta(stored: object, source: str) -> dict:
    """The description (``meta``) of a model file's unpickled dictionary, refused where it is
    not a flakelab model's (its fields are checked where they are used)."""
    try:
        meta = json_value(stored["meta"])  # type: ignore[index]
    except Exception as error:  # whatever ``stored`` is: a tensor, a list, a text, None
        raise not_a_model_file(source, error) from None
    if not isinstance(meta, dict) or meta.get("format") != MODEL_FORMAT:
        raise ModelError(f"{source}: format: expected {MODEL_FORMAT!r}")
    return meta


def model_file(path: str | Path) -> Path:
    """``path``, refused where no model file can be: nothing there, or a folder."""
    path = Path(path)
    if not path.exists():
        raise ModelError(f"{path}: no such model file")
    if path.is_dir():
        raise ModelError(f"{path}: a folder, not a model file")
    return path


def model_file_description(path: str | Path) -> dict:
    """A model file's description (its toners, geometries, instrument and ``info``) read
    without its weights and without torch, whose import for the shipped models' toner counts
    was a third of ``flakelab model list``'s time and half its memory (stop 127). The
    archive's ``data.pkl`` names each tensor's storage by a persistent id; those and torch's
    classes are read as nothing, so no code of the file's runs."""
    path = model_file(path)
    try:
        with zipfile.ZipFile(path) as archive:
            pickled = next(n for n in archive.namelist() if n.endswith("/data.pkl"))
            stored = _WithoutTensors(archive.open(pickled)).load()
    except (OSError, zipfile.BadZipFile, StopIteration, pickle.UnpicklingError, EOFError,
            KeyError, IndexError, AttributeError, TypeError, ValueError) as error:  # fmt: skip
        raise not_a_model_file(str(path), error) from None
    meta = stored_meta(stored, str(path))
    # what a listing reads; loading the model checks every field (ForwardModel.from_bytes)
    for field, kind, expected in (("toners", list, "a list"), ("info", dict, "a table")):
        if not isinstance(meta.get(field), kind):
            raise ModelError(f"{path}: {field}: expected {expected}")
    return meta


class _Nothing:
    """What a tensor, a storage or any class of torch's reads as in :class:`_WithoutTensors`."""

    def __init__(self, *args, **kwargs) -> None:
        pass


class _StateDict(dict):
    """A state dict's ``OrderedDict``, which pickle gives attributes (its ``_metadata``)."""


class _WithoutTensors(pickle.Unpickler):
    """A model file's ``data.pkl`` with its tensors and every class but the state dict's read
    as nothing (:func:`model_file_description`)."""

    def find_class(self, module: str, name: str):
        return _StateDict if (module, name) == ("collections", "OrderedDict") else _Nothing

    def persistent_load(self, pid) -> None:
        return None
