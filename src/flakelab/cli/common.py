"""Shared pieces of the command line: consoles, error reporting, common options."""

from __future__ import annotations

import functools
import os
import sys
from collections.abc import Callable
from typing import Annotated, Any, TypeVar

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

from flakelab.errors import FlakelabError

console = Console(width=None if sys.stdout.isatty() else 110)
errors = Console(stderr=True)

F = TypeVar("F", bound=Callable[..., Any])


def reports_errors(command: F) -> F:
    """Turn user-input problems into one line on stderr and exit status 2 (never a traceback)."""

    @functools.wraps(command)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return command(*args, **kwargs)
        except (typer.Exit, typer.Abort):
            raise
        except (FlakelabError, ValueError, KeyError, OSError) as error:
            message = error.args[0] if isinstance(error, KeyError) and error.args else error
            errors.print(f"[bold red]error:[/] {message}", highlight=False, soft_wrap=True)
            raise typer.Exit(2) from None
        except Exception as error:  # pragma: no cover - a bug, reported without a traceback
            if os.environ.get("FLAKELAB_DEBUG"):
                raise
            errors.print(
                f"[bold red]internal error:[/] {type(error).__name__}: {error} "
                "(set FLAKELAB_DEBUG=1 for a traceback and please report it)",
                highlight=False,
                soft_wrap=True,
            )
            raise typer.Exit(70) from None

    return wrapper  # type: ignore[return-value]


ConditionsOption = Annotated[
    str, typer.Option("--conditions", "-c", help="Illuminant/observer, e.g. D65/10, A/10, F11/10.")
]
JsonOption = Annotated[bool, typer.Option("--json", help="Print machine-readable JSON.")]
SampleOption = Annotated[
    str | None, typer.Option("--sample", "-s", help="Sample name in a multi-sample file.")
]


def progress_bar(disable: bool = False) -> Progress:
    """A progress bar on stderr (hidden when stderr is not a terminal or ``disable``)."""
    return Progress(
        TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
        TimeRemainingColumn(), console=errors, disable=disable or not errors.is_terminal,
        transient=True,
    )  # fmt: skip
