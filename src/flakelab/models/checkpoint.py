"""A training protocol's progress kept in a file, so that an interrupted training goes on
where it stopped (``flakelab train --checkpoint FILE``).

After each stage of :func:`~flakelab.models.training.train_protocol` (a session's training
or its fine-tuning) the file holds the networks of that stage, the log of losses so far and,
once screened, the outliers. Each stage draws its batches from a generator seeded by the
length of the log, and starts a new optimiser, so a training that skips the stages the file
kept and restores the networks of the last ends with the model the uninterrupted one would
have. A file is kept for one training: the same settings on the same cases.
"""

from __future__ import annotations

import io
import json
from dataclasses import asdict
from os import PathLike
from pathlib import Path

import numpy as np
import torch
from numpy.typing import NDArray

from flakelab.core.documents import json_value
from flakelab.io.records import write_atomically
from flakelab.models.network import ForwardModel, ModelError

__all__ = ["TrainingCheckpoint"]

CHECKPOINT_FORMAT = "flakelab-training-checkpoint"


class TrainingCheckpoint:
    """The kept stages of one training (``config`` on cases of ``data_hash``) in ``path``;
    an empty one where the file is not there yet, or where it keeps the same training of
    other cases and ``restart_other_cases`` (a training on a schedule: the cases came in since
    it was interrupted; ``replaced`` then says so, and the first stage kept replaces the
    file)."""

    def __init__(
        self, path: str | PathLike, config, data_hash: str, restart_other_cases: bool = False
    ):
        self.path = Path(path)
        self.key = {"config": asdict(config), "data_hash": data_hash}
        self.stages = 0
        self.log: list[dict] = []
        self.outliers: NDArray[np.bool_] | None = None
        self._states: list[dict] = []
        self.replaced = False
        if self.path.exists():
            self._read(restart_other_cases)

    def _read(self, restart_other_cases: bool) -> None:
        try:
            saved = torch.load(self.path, weights_only=True)
            meta = json_value(saved["meta"])
            states = saved["states"]
            stages, log, outliers = meta["stages"], meta["log"], meta["outliers"]
        except Exception as error:  # a damaged file fails in any of torch's readers
            raise ModelError(
                f"{self.path}: not a flakelab training checkpoint ({type(error).__name__})"
            ) from None
        if not _holds_a_training(meta, states):
            raise ModelError(f"{self.path}: not a flakelab training checkpoint")
        other = self._other_training(meta)
        if other == "other cases" and restart_other_cases:
            self.replaced = True
            return
        if other:
            raise ModelError(
                f"{self.path}: the checkpoint of another training ({other}); name another "
                "--checkpoint file, or remove this one to start again"
            )
        self.stages, self.log, self._states = int(stages), list(log), states
        self.outliers = None if outliers is None else np.asarray(outliers, dtype=bool)

    def _other_training(self, meta: dict) -> str | None:
        """What makes the training that kept ``meta`` another than this one, else None."""
        if meta.get("data_hash") != self.key["data_hash"]:
            return "other cases"
        kept = meta.get("config") or {}
        for name, value in self.key["config"].items():
            theirs = kept.get(name)
            if (list(value) if isinstance(value, tuple) else value) != theirs:
                return f"{name} {theirs!r}, here {value!r}"
        return None

    def keep(self, stages: int, log: list[dict], models: list[ForwardModel], outliers) -> None:
        """The training after ``stages`` stages: its log, ``models`` (the networks the last
        stage trained) and the outliers once screened (else None), written whole or not at
        all."""
        meta = self.key | {
            "format": CHECKPOINT_FORMAT,
            "stages": stages,
            "log": log,
            "outliers": None if outliers is None else np.asarray(outliers).tolist(),
        }
        saved = {"meta": json.dumps(meta), "states": [m.network.state_dict() for m in models]}
        # serialised in memory first: torch's writer reports a full disk as a RuntimeError
        # without the file's name, a file write as an OSError that names it
        buffer = io.BytesIO()
        torch.save(saved, buffer)
        write_atomically(self.path, lambda temporary: temporary.write_bytes(buffer.getvalue()))
        self.stages = stages

    def check_fits(self, cases: int, stages: int) -> None:
        """Refuse a file that keeps more stages than the training has, or outliers of another
        number of cases (a file damaged where its readers cannot tell)."""
        if self.stages > stages:
            raise ModelError(f"{self.path}: keeps {self.stages} stages of a training of {stages}")
        if self.outliers is not None and self.outliers.shape != (cases,):
            raise ModelError(
                f"{self.path}: keeps the outliers of {self.outliers.size} cases, where the "
                f"training has {cases}"
            )

    def restore(self, models: list[ForwardModel]) -> None:
        """The networks of the last kept stage into ``models`` (the same stage's)."""
        if len(self._states) != len(models):
            raise ModelError(
                f"{self.path}: holds {len(self._states)} networks where its last stage "
                f"trained {len(models)}"
            )
        for model, state in zip(models, self._states, strict=True):
            try:
                model.network.load_state_dict(state)
            except (RuntimeError, KeyError, TypeError) as error:
                raise ModelError(f"{self.path}: its networks do not fit: {error}") from None

    def remove(self) -> None:
        self.path.unlink(missing_ok=True)


def _holds_a_training(meta: dict, states) -> bool:
    """Whether a checkpoint's contents are of the kinds :meth:`TrainingCheckpoint.keep`
    writes."""
    stages, log, outliers = meta["stages"], meta["log"], meta["outliers"]
    return (
        meta.get("format") == CHECKPOINT_FORMAT
        and isinstance(states, list)
        and all(isinstance(state, dict) for state in states)
        and isinstance(stages, int)
        and stages >= 0
        and isinstance(log, list)
        and all(isinstance(entry, dict) for entry in log)
        and (
            outliers is None
            or (isinstance(outliers, list) and all(isinstance(o, bool) for o in outliers))
        )
    )
