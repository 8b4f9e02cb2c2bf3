"""Loss logs: every epoch of a training or an adaptation as a CSV table, one row an epoch of
one stage (:func:`~flakelab.models.training.train_protocol`'s ``log``)::

    stage,epoch,loss,validation_de00
    partition 1,0,0.8712,
    …
    adapt Dupont,149,0.0131,0.412

``validation_de00`` is the held-out cases' mean ΔE00 where a stage judged them (an
adaptation with a validation share), else empty.
"""

from __future__ import annotations

import csv
from collections.abc import Iterable, Mapping
from os import PathLike

from flakelab.io.records import write_atomically

__all__ = ["LOSS_LOG_COLUMNS", "write_loss_log"]

LOSS_LOG_COLUMNS = ("stage", "epoch", "loss", "validation_de00")


def write_loss_log(log: Iterable[Mapping], path: str | PathLike) -> None:
    """``log``'s entries (stage, epoch, loss and, where judged, validation_de00) as CSV,
    written whole or not at all."""
    rows = [[entry.get(column, "") for column in LOSS_LOG_COLUMNS] for entry in log]

    def write(temporary) -> None:
        with open(temporary, "w", newline="", encoding="utf-8") as handle:
            table = csv.writer(handle)
            table.writerow(LOSS_LOG_COLUMNS)
            table.writerows(rows)

    write_atomically(path, write)
