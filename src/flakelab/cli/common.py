"""Shared pieces of the command line: consoles, error reporting, common options."""

from __future__ import annotations

import contextlib
import errno
import functools
import json
import math
import os
import select
import signal
import stat
import sys
import warnings
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from datetime import timedelta
from pathlib import Path
from typing import Annotated, Any, TypeVar

import typer
import typer.core
from rich import box
from rich.console import Console
from rich.markup import escape
from rich.measure import Measurement
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TaskID,
    TextColumn,
    TimeRemainingColumn,
)
from rich.segment import Segments
from rich.table import Table

from flakelab.core.wording import hidden_passwords
from flakelab.errors import FlakelabError, MeasurementFileError, Note


def command_group(help: str, **settings: Any) -> typer.Typer:
    """A group of commands as flakelab builds each: run alone, it shows its help; its help is
    click's plain text, wrapped to the terminal. Typer's Rich panels gave each option's type
    a column of its own and squeezed what the option does into 16 characters of an
    80-column terminal: ``match --help`` ran to 394 lines, against 167 as plain text."""
    return typer.Typer(
        help=help, no_args_is_help=True, rich_markup_mode=None, cls=_PlainHelpGroup, **settings
    )


class _PlainHelpGroup(typer.core.TyperGroup):
    """A group whose help lists each command and group under it by its whole first paragraph,
    and names each argument and what each option takes (:func:`_name_value`). Click's list
    cut each at its first full stop or 45-60 characters ("Generate synthetic refinish cases
    (labelled synthetic) and...", "Paper 001 Fig."); click wraps it, as it wraps every
    paragraph of a help to the terminal."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        for param in self.params:
            _name_value(param)
        for command in self.commands.values():
            command.short_help = command.short_help or _first_paragraph(command.help)
            for param in command.params:
                _name_value(param)


_VALUE_NAMES = {int: "N", float: "NUMBER"}
"""What a number option takes, named in its help: ``--seed N``, ``--resolution NUMBER``."""


def _name_value(param: Any) -> None:
    """Name the value of a parameter that has no name for it of its own, as argparse does:
    an argument by its name in capitals (``[TARGET]``, as messages name it: "TARGET: …");
    an option's value by its kind where a number, by its choices (``[panel|curved]``), else
    by the option's name in capitals (``--library LIBRARY``). Typer showed ``[target]``,
    ``<int range>``, ``<float>``, ``<str>`` and ``<path>``. Left as typer names it where
    the parameter carries no ``type_descriptor`` (typer before 0.2x)."""
    kind = getattr(param, "type_descriptor", None)
    if kind is None or param.metavar:
        return
    if isinstance(param, typer.core.TyperArgument):
        param.metavar = param.name.upper()
        param.__class__ = _PlainArgument
        return
    if not isinstance(param, typer.core.TyperOption) or param.is_flag or param.count:
        return
    if kind.choices:
        param.metavar = "[" + "|".join(str(c) for c in kind.choices) + "]"
    else:
        param.metavar = _VALUE_NAMES.get(kind.annotation) or param.name.upper()


class _PlainArgument(typer.core.TyperArgument):
    """An argument shown as argparse and click show one: ``SOURCE`` where it is required and
    ``[TARGET]`` where not, with no type beside its name. Typer wrote ``{SOURCE}``, which
    reads as a choice among values, and ``SOURCE <path>``."""

    def _usage_display_name(self) -> str:
        name = self.display_name_raw if self.required else f"[{self.display_name_raw}]"
        return name + ("..." if self.nargs != 1 else "")

    def display_type_rich(self, ctx: Any) -> str | None:
        return None


def _open_closed_streams() -> None:
    """A standard stream the caller closed (``flakelab … >&-``, a service started without
    one) opened on ``/dev/null``: Python leaves it None, where the reports stopped with a
    traceback, and the next file opened would take its descriptor, where stray output would
    land."""
    for fd, name, mode in ((0, "stdin", "r"), (1, "stdout", "w"), (2, "stderr", "w")):
        if getattr(sys, name) is None:
            with contextlib.suppress(OSError):
                os.fstat(fd)
                continue
            null = os.open(os.devnull, os.O_RDWR)  # the lowest free descriptor: often fd
            if null != fd:
                os.dup2(null, fd)
                os.close(null)
            setattr(sys, name, open(fd, mode, encoding="utf-8", closefd=False))


def _encodable_output() -> None:
    """Output written as UTF-8 where its encoding cannot write the reports' ΔE00, ° and ±
    (a redirected stream on Windows, whose locale encoding is cp1252; a legacy terminal): the
    report stopped half written, "'charmap' codec can't encode character 'Δ'". A terminal
    keeps its encoding, with "?" for what it cannot show."""
    for stream in (sys.stdout, sys.stderr):
        try:
            "ΔE00 ° ± × – ‰".encode(stream.encoding or "ascii")
        except (UnicodeEncodeError, LookupError):
            with contextlib.suppress(AttributeError, OSError):  # not a text stream of ours
                encoding = stream.encoding if stream.isatty() else "utf-8"
                stream.reconfigure(encoding=encoding, errors="replace")


class _Console(Console):
    """A console whose reader gone (``| head``) stops the command as every command stops
    then: :func:`reports_errors` meets a :class:`BrokenPipeError` and exits 141. Rich's own
    exits 1, and points stdout at ``/dev/null`` even where the pipe broken is stderr's."""

    def on_broken_pipe(self) -> None:
        self.quiet = True
        raise BrokenPipeError(errno.EPIPE, os.strerror(errno.EPIPE))

    def print(self, *objects: Any, **kwargs: Any) -> None:
        """Print as Rich does, but cut no table's cell: a table too wide for the terminal
        has its widest wrapping columns narrowed down to their longest word, and no more;
        one that still does not fit is drawn past the terminal's edge. Rich cut cells with
        an ellipsis: in a 70-column terminal the match's L*a*b* read "62.…" and "-1…", and in
        80 a model's data hash and the correction's "spray-out" row were cut. A message on a
        stderr that is no terminal (a log file) is not wrapped: at 80 columns "shop.db:
        five-angle v1 promoted" was split after "five-angle" where the path was 68 long."""
        if any(isinstance(o, Table) for o in objects):
            objects = tuple(self._drawn_uncut(o) for o in objects)
            kwargs["crop"] = False
        if self.stderr and not self.is_terminal:  # a log's message on one line, for grep
            kwargs.setdefault("soft_wrap", True)
        super().print(*objects, **kwargs)
        if reader_gone(self.file):  # what it wrote may be lost without a word: see there
            self.on_broken_pipe()

    def _drawn_uncut(self, renderable: Any) -> Any:
        if not isinstance(renderable, Table) or renderable.expand or renderable.width:
            return renderable
        with _columns_fitted(self, renderable) as width:
            return Segments(self.render(renderable, self.options.update_width(width)))


def print_report(report: Any, *, indent: int = 2, default: Callable | None = None) -> None:
    """A ``--json`` report on stdout, a number that is none (NaN, ±∞) written ``null``: JSON
    has no NaN, and a strict reader refuses Python's ``NaN``. Its reader gone half way, the
    command stops as a table's does (:func:`reader_gone`)."""
    print(json.dumps(_finite(report), indent=indent, default=default, allow_nan=False))
    if reader_gone(sys.stdout):
        console.on_broken_pipe()


def _finite(value: Any) -> Any:
    """``value`` with every float in it that is not finite made None, through its dicts,
    lists and tuples."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


def reader_gone(stream: Any) -> bool:
    """Whether ``stream`` is a pipe whose reader has gone. A write the reader leaves half
    way returns the part written (POSIX), and CPython's buffered stream counts the rest
    written: ``flakelab cases list --last 3000 | head`` ended with status 0, its table lost
    past the pipe's 64 KiB. Linux flags such a pipe's writing end as errored (POLLERR); where
    a system does not, or has no ``poll`` (Windows), this says no, as before."""
    try:
        descriptor = stream.fileno()
        if not stat.S_ISFIFO(os.fstat(descriptor).st_mode) or not hasattr(select, "poll"):
            return False
    except (AttributeError, OSError, ValueError):  # no descriptor: a StringIO, a test's
        return False
    poller = select.poll()
    poller.register(descriptor, select.POLLOUT)
    return any(events & select.POLLERR for _, events in poller.poll(0))


@contextmanager
def _columns_fitted(console: Console, table: Table) -> Iterator[int]:
    """``table`` with each column's width fixed for the console, as :meth:`_Console.print`
    says; yields the table's width."""
    wide = console.options.update_width(100_000)
    most, least = [], []
    for column in table.columns:
        sizes = [Measurement.get(console, wide, cell) for cell in (column.header, *column.cells)]
        most.append(max(m.maximum for m in sizes))
        least.append(most[-1] if column.no_wrap else max(m.minimum for m in sizes))
    paddings, counted = _cell_paddings(table)
    borders = (2 if table.box and table.show_edge else 0) + (len(paddings) - 1 if table.box else 0)
    widths = _narrowed(most, least, console.width - sum(paddings) - borders)
    kept = [column.width for column in table.columns]
    for column, width, padding, padded in zip(
        table.columns, widths, paddings, counted, strict=True
    ):
        column.width = width + padding - padded
    try:
        yield sum(widths) + sum(paddings) + borders
    finally:
        for column, width in zip(table.columns, kept, strict=True):
            column.width = width


def _narrowed(widths: list[int], least: list[int], room: int) -> list[int]:
    """``widths`` narrowed, the widest first, to fit ``room``, none below its ``least``."""
    widths = list(widths)
    while sum(widths) > room:
        slack = [k for k, (w, low) in enumerate(zip(widths, least, strict=True)) if w > low]
        if not slack:
            break
        widths[max(slack, key=widths.__getitem__)] -= 1
    return widths


def _cell_paddings(table: Table) -> tuple[list[int], list[int]]:
    """The left and right padding of each column's cells as Rich pads them, and as its
    column widths count them: where padding collapses, Rich's ``_get_padding_width`` counts
    the first column's right padding alone, whose cells have their left one too."""
    _, right, _, left = table.padding
    last = len(table.columns) - 1
    paddings, counted = [], []
    for index in range(last + 1):
        lead = max(0, left - right) if table.collapse_padding and index > 0 else left
        counted_lead = 0 if table.collapse_padding else left
        if index == 0 and not table.pad_edge:
            lead = counted_lead = 0
        trail = 0 if index == last and not table.pad_edge else right
        paddings.append(lead + trail)
        counted.append(counted_lead + trail)
    return paddings, counted


_open_closed_streams()
_encodable_output()


def _drawing_width(stream: Any, piped: int) -> int | None:
    """The width a console draws ``stream`` at: Rich's own (``COLUMNS`` where it is set, else
    the terminal's), ``piped`` columns for a file or a pipe without ``COLUMNS``, and never
    0: Rich took ``COLUMNS=0`` for a width and printed nothing, not even an error."""
    columns = os.environ.get("COLUMNS", "")
    if columns.isdigit() and int(columns) > 0:
        return None
    if not stream.isatty():
        return piped
    if not columns.isdigit():
        return None
    try:
        return os.get_terminal_size(stream.fileno()).columns or piped
    except (OSError, ValueError):
        return piped


console = _Console(width=_drawing_width(sys.stdout, 110))
"""Tables and reports: ``COLUMNS``, else the terminal's width, else 110 columns (piped
output that wraps no row of the main job's tables)."""
errors = _Console(stderr=True, width=_drawing_width(sys.stderr, 80))


def _show_note(message, category, filename, lineno, file=None, line=None) -> None:
    """A :class:`~flakelab.errors.Note` from the library, on stderr as a command's note (not
    in its report, which may be JSON); any other warning as Python shows it."""
    if issubclass(category, Note):
        with contextlib.suppress(OSError):
            errors.print(f"[yellow]note:[/] {escape(str(message))}", highlight=False)
        return
    _python_shows_warning(message, category, filename, lineno, file, line)


_python_shows_warning = warnings.showwarning
warnings.showwarning = _show_note

F = TypeVar("F", bound=Callable[..., Any])
T = TypeVar("T")


MODEL_SPREAD_LEGEND = (
    "± model: how far the networks of the model's ensemble disagree (ΔE00 about their mean); "
    "where it is large, the prediction deserves less trust."
)
"""The line under a table with a ``± model`` column or row (``match``, ``correct``)."""


def print_notes(notes: list[str]) -> None:
    """A report's notes, one line each, as every command prints them."""
    for note in notes:
        console.print(f"[yellow]note:[/] {note}", highlight=False)


SIGHUP = getattr(signal, "SIGHUP", None)
SIGPIPE = getattr(signal, "SIGPIPE", 13)
"""Signals Windows lacks: no SIGHUP to stop on there, and its broken pipe is given the status
the shell's tools give one elsewhere."""


class Terminated(KeyboardInterrupt):
    """SIGTERM (``kill``, ``timeout``, a scheduler or service manager stopping the command)
    or SIGHUP (its terminal closed, its SSH session dropped), raised where the command is,
    so that it stops as a Ctrl-C stops it: what it was writing removed, a transaction rolled
    back, the line saying what it left. Python's default ends the process on the spot, and
    left a temporary file the size of what was written."""

    def __init__(self, signum: int = signal.SIGTERM) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def stop_on_signals() -> None:
    """Make SIGTERM and SIGHUP raise :class:`Terminated` in the main thread; a SIGHUP that
    ``nohup`` ignores stays ignored."""

    def terminated(signum, _frame):
        raise Terminated(signum)

    signal.signal(signal.SIGTERM, terminated)
    if SIGHUP is not None and signal.getsignal(SIGHUP) is not signal.SIG_IGN:  # none on Windows
        signal.signal(SIGHUP, terminated)


def reports_errors(command: F) -> F:
    """Turn user-input problems into one line on stderr and exit status 2 (never a traceback)."""

    @functools.wraps(command)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            result = command(*args, **kwargs)
            sys.stdout.flush()  # a reader gone (| head) is met here, not at the exit
            return result
        except (typer.Exit, typer.Abort):
            raise
        except KeyboardInterrupt:
            stop_interrupted("stopped before it finished")
        except BrokenPipeError:  # stop quietly, as the shell's tools do (Python docs, signal)
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            raise typer.Exit(128 + SIGPIPE) from None
        except (FlakelabError, ValueError, OSError) as error:  # not KeyError: see errors
            _stop("error", _message(error), 2)
        except MemoryError as error:  # a size or count this machine cannot hold
            _stop("error", f"not enough memory for this job ({error}); ask for less: a "
                  "smaller size, count or batch", 2)  # fmt: skip
        except Exception as error:  # pragma: no cover - a bug, reported without a traceback
            if os.environ.get("FLAKELAB_DEBUG"):
                raise
            _stop("internal error", f"{type(error).__name__}: {error} (set FLAKELAB_DEBUG=1 "
                  "for a traceback and please report it)", 70)  # fmt: skip

    return wrapper  # type: ignore[return-value]


@contextmanager
def interrupted(left: str | Callable[[], str]) -> Iterator[None]:
    """A Ctrl-C in the block stops the command with one line saying what it left behind
    (``left``, or what it returns then) (:func:`stop_interrupted`)."""
    try:
        yield
    except KeyboardInterrupt:
        stop_interrupted(left() if callable(left) else left)


def stop_interrupted(message: str, stopped: BaseException | None = None) -> None:
    """Stop a command that a Ctrl-C cut short (``stopped``, by default the exception being
    handled): one line, exit status 130 (128 + SIGINT), as the shell's tools stop; 143
    (128 + SIGTERM) and "terminated" for a SIGTERM, 129 and "hung up" for a SIGHUP."""
    stopped = stopped or sys.exc_info()[1]
    if isinstance(stopped, Terminated):
        label = "hung up" if stopped.signum == SIGHUP else "terminated"
        _stop(label, message, 128 + stopped.signum)
    _stop("interrupted", message, 128 + signal.SIGINT)


def run_command_line(app: typer.Typer, prog_name: str) -> None:
    """Run ``app`` as the console's command. Typer turns a Ctrl-C (or SIGTERM, SIGHUP) met
    outside the command, while it reads the options, into exit status 130 and no word: an
    option's check can take seconds (``--shop``'s imports colour-science), and such a SIGTERM
    left a silent 130. It stops as a command stops (:func:`stop_interrupted`)."""
    try:
        app(prog_name=prog_name)
    except SystemExit as exit:  # Typer: raise Exit(130) from the interrupt, then sys.exit
        stopped = getattr(exit.__context__, "__cause__", None)
        if not isinstance(stopped, KeyboardInterrupt):
            raise
        exit_interrupted("stopped before it began; nothing was done", stopped)


def exit_interrupted(message: str, stopped: KeyboardInterrupt) -> None:
    """Leave the process as :func:`stop_interrupted` stops a command, outside Typer's app
    (the console's entry point, a script of ``scripts/``)."""
    try:
        stop_interrupted(message, stopped)
    except typer.Exit as said:
        raise SystemExit(said.exit_code) from None


def _message(error: Exception) -> str:
    """A user error's one line: a file's name first ("x.png: No such file or directory", not
    "[Errno 2] No such file or directory: 'x.png'"), a missing key without its quotes."""
    if isinstance(error, OSError) and error.filename is not None and error.strerror:
        return f"{error.filename}: {error.strerror}"
    if isinstance(error, KeyError) and error.args:
        return str(error.args[0])
    return str(error)


def refuse_a_removed_folder() -> None:
    """Stop, saying why, where the folder the command runs in was removed under its shell
    (``rm -r`` from another terminal, a USB stick taken out): no file named without a whole
    path can be there, and torch's import dies in it ("Intel oneMKL FATAL ERROR: Cannot
    load libtorch_cpu.so") where 'match' began; an output named so was "[Errno 2] No such
    file or directory", naming none."""
    try:
        os.getcwd()
    except FileNotFoundError:
        with contextlib.suppress(OSError):
            errors.print(
                "[bold red]error:[/] the folder this runs in no longer exists (removed, or its "
                "disk taken out): cd to another",
                highlight=False,
                soft_wrap=True,
            )
        sys.exit(2)


def _stop(label: str, message: str, status: int) -> None:
    """One line on stderr, then exit with ``status``; the message is escaped, since it may
    quote brackets (a CSV cell, "flakelab[postgres]") that are not terminal markup, and a
    database URL it names shows no password (:func:`hidden_passwords`)."""
    message = escape(hidden_passwords(message))
    with contextlib.suppress(OSError):  # stderr gone too (its terminal closed, | head)
        errors.print(f"[bold red]{label}:[/] {message}", highlight=False, soft_wrap=True)
    raise typer.Exit(status) from None


def _checked_conditions(text: str) -> str:
    """``--conditions`` read before any work, so that a wrong one is named by its option."""
    from flakelab.core.colorimetry import Conditions

    try:
        Conditions.parse(text)
    except ValueError as error:
        raise typer.BadParameter(str(error)) from None
    return text


ConditionsOption = Annotated[
    str,
    typer.Option(
        "--conditions",
        "-c",
        help="Illuminant/observer, e.g. D65/10, A/10, F11/10.",
        callback=_checked_conditions,
    ),
]
JsonOption = Annotated[bool, typer.Option("--json", help="Print machine-readable JSON.")]

SEED_MAX = 2**64 - 1
"""The largest seed a command takes: torch's generators read 64 bits, and a seed past them was
refused "Overflow when unpacking long long", naming no option."""


def seed_option(help: str) -> Any:
    """A ``--seed`` option's settings: a whole number from 0 to :data:`SEED_MAX`."""
    return typer.Option(min=0, max=SEED_MAX, help=help)


WEIGHT_MAX = 100.0
"""The largest weight a term of the search's or the correction's objective takes from the
command line (``--model-risk``, ``--metamerism``, ``--model-sd``, ``--colour-weight``): at a
hundred times the colour's own it has long swamped it; an infinite one made every recipe's
loss infinite, refused as "amounts that are not a number" or "amounts sum to zero"."""

COUNT_MAX = 10**9
"""The most of anything a command counts (cases, targets, formulations, spray-outs, photons,
colour codes): far past a day's work, and within numpy's 64-bit integers, where a count past
them was an internal error ("Python int too large to convert to C long"). A job that large
may still be refused for the memory it would take, as any job too large is."""


LightsOption = Annotated[
    str | None,
    typer.Option(
        "--lights",
        help="Test illuminants of the metamerism index, comma-separated: any of "
        "colour-science's (a US booth: A,F2,F12).",
        show_default="A,F11,LED-B3",
    ),
]


def lights_option(text: str | None, conditions=None) -> tuple[str, ...] | None:
    """The test illuminants ``--lights`` names (None: the default ones), against the
    reference ``conditions`` (default D65/10)."""
    from flakelab.core.colorimetry import D65_10
    from flakelab.core.difference import parse_lights

    return None if text is None else parse_lights(text, conditions or D65_10)


ToleranceOption = Annotated[
    str,
    typer.Option(
        "--tolerance", "-t", help="Preset (refinish, de00-1.0, components) or TOML/JSON file."
    ),
]
SampleOption = Annotated[
    str | None, typer.Option("--sample", "-s", help="Sample name in a multi-sample file.")
]
AverageOption = Annotated[
    bool,
    typer.Option(
        "--average",
        help="Average every reading in the target file (the car read at a few spots beside "
        "the repair) and use their mean; says how far each lies from it.",
    ),
]
AverageSprayedOption = Annotated[
    bool,
    typer.Option(
        "--average-sprayed",
        help="Average every reading in the spray-out's file (the panel read at a few spots) "
        "and use their mean.",
    ),
]
PlotOption = Annotated[
    Path | None,
    typer.Option(
        "--plot",
        help="Also draw the multi-angle difference chart: ΔL*, ΔC*, ΔH* and the share of the "
        "tolerance used at every geometry (PNG, PDF or SVG).",
    ),
]
SprayedSampleOption = Annotated[
    str | None,
    typer.Option(
        "--sprayed-sample",
        help="The spray-out's sample name in a multi-sample file (default: its first).",
    ),
]


class LoggedProgress(Progress):
    """Rich's live bar on a terminal; elsewhere (a log file, ``nohup``, CI) one plain line per
    tenth of each task on the same console, so that a long run is never blind."""

    def __init__(self, *columns: Any, log: bool, **kwargs: Any) -> None:
        super().__init__(*columns, **kwargs)
        self.log_lines = log
        self._tenths_logged: dict[TaskID, int] = {}

    def advance(self, task_id: TaskID, advance: float = 1) -> None:
        super().advance(task_id, advance)
        if self.log_lines:
            self._log_tenth(task_id)

    def _log_tenth(self, task_id: TaskID) -> None:
        task = next(t for t in self.tasks if t.id == task_id)
        if not task.total:
            return
        tenth = int(10 * min(task.completed, task.total) / task.total)
        if tenth <= self._tenths_logged.get(task_id, 0):
            return
        self._tenths_logged[task_id] = tenth
        line = (
            f"{task.description}: {task.completed:g}/{task.total:g} "
            f"({100 * task.completed / task.total:.0f} %), "
            f"{timedelta(seconds=round(task.elapsed or 0))} elapsed"
        )
        if task.completed < task.total and task.time_remaining is not None:
            line += f", about {timedelta(seconds=round(task.time_remaining))} left"
        self.console.print(line, highlight=False, markup=False, soft_wrap=True)


def progress_bar(disable: bool = False) -> LoggedProgress:
    """Progress on stderr: a live bar on a terminal, a line per tenth of the work elsewhere,
    nothing when ``disable`` (machine-readable output)."""
    return LoggedProgress(
        TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
        TimeRemainingColumn(), console=errors, disable=disable or not errors.is_terminal,
        transient=True, log=not disable and not errors.is_terminal,
    )  # fmt: skip


def tracked(
    items: Iterable[T], description: str, disable: bool = False, total: int | None = None
) -> Iterator[T]:
    """``items`` one by one, with :func:`progress_bar`'s progress; ``total`` counts them
    where ``items`` has no length (a generator)."""
    with progress_bar(disable) as bar:
        task = bar.add_task(description, total=len(items) if total is None else total)
        for item in items:
            yield item
            bar.advance(task)


def shares_text(recipe: dict[str, float], shown: int = 3) -> str:
    """A recipe's largest ``shown`` mass shares for a table cell, ``Al medium 57%, …``, and
    how many more it holds (``+2``)."""
    shares = sorted(recipe.items(), key=lambda item: -item[1])
    text = ", ".join(f"{name} {share:.0%}" for name, share in shares[:shown])
    return text + (f" +{len(shares) - shown}" if len(shares) > shown else "")


def read_sample(path, sample: str | None, option: str = "--sample"):
    """One measurement of a file, as :func:`flakelab.io.read_measurement` reads it; when the
    file holds several and none was named, says which one was taken (the standard it names,
    else its first)."""
    from flakelab.io import read_measurements

    return sample_of(read_measurements(path), path, sample, option)


def sample_of(measurements: list, path, sample: str | None, option: str = "--sample"):
    """:func:`read_sample`'s choice among the ``measurements`` read from ``path``, with its
    note."""
    from flakelab.io import pick_sample, standard_of

    chosen = pick_sample(measurements, sample, path)
    if sample is None and len(measurements) > 1:
        which = "QC job's standard" if chosen is standard_of(measurements) else "first"
        errors.print(
            f"[yellow]note:[/] {escape(str(path))} holds {len(measurements)} samples; read its "
            f"{which}, {escape(repr(chosen.sample))} ({option} names another)",
            highlight=False,
        )
    return chosen


def read_reading_at(path, sample: str | None, average: bool, geometries, instrument: str):
    """The reading of ``path`` (:func:`read_readings`), refused where it was not read at every
    one of ``geometries`` (``instrument``'s, which ``--instrument`` chooses)."""
    reading = read_readings(path, sample, average)[0]
    if missing := [g for g in geometries if g not in reading.geometry_names]:
        raise FlakelabError(
            f"{path}: not read at {', '.join(missing)} ({instrument}'s geometries; "
            "--instrument chooses)"
        )
    return reading


def read_readings(
    path,
    sample: str | None,
    average: bool,
    option: str = "--sample",
    average_option: str = "--average",
):
    """The measurement to use from ``path`` and the readings it stands for: with
    ``average`` the mean of every reading in the file, else the one sample (its only
    reading); ``option`` and ``average_option`` name the two in messages."""
    if not average:
        chosen = read_sample(path, sample, option)
        return chosen, [chosen]
    from flakelab.core.measurement import mean_reading
    from flakelab.io import read_measurements

    if sample is not None:
        raise FlakelabError(f"{option} and {average_option}: expected one of them, not both")
    readings = read_measurements(path)
    try:
        return mean_reading(readings), readings
    except FlakelabError as error:
        raise MeasurementFileError(path, str(error)) from None


def readings_note(spread: dict, what: str = "target") -> str | None:
    """A note where one of several readings lies far from their mean."""
    from flakelab.core.comparison import READINGS_SPREAD_SHARE

    if spread["limit_share_max"] <= READINGS_SPREAD_SHARE:
        return None
    return (
        f"the {what}'s readings differ: {spread['furthest']} lies {spread['limit_share_max']:.0%} "
        "of the tolerance from their mean at worst; the paint is uneven there, or a reading "
        "was off: read it again"
    )


def add_readings_spread(
    report: dict, key: str, readings: list, mean, tolerance, what: str = "target"
) -> None:
    """With ``readings`` averaged into ``mean``: how far each lies from it, as
    ``report[key]``, and a note in ``report["notes"]`` where one lies far."""
    from flakelab.core.comparison import spread_of_readings

    report[key] = spread = spread_of_readings(readings, mean, tolerance)
    if note := readings_note(spread, what):
        report["notes"].append(note)


def check_one_for_each(
    option: str, given: list, panels: list, noun: str, optional: bool = False
) -> None:
    """Refuse ``option`` given other than once for each of ``panels`` (each a ``noun``: "panel",
    "spray-out"), or, where ``optional``, not at all."""
    if len(given) == len(panels) or (optional and not given):
        return
    none = " or none" if optional else ""
    raise FlakelabError(
        f"{option}: expected one for each {noun} ({len(panels)}){none}, got {len(given)}"
    )


def check_output_file(
    path,
    option: str,
    format_of: Callable | None = None,
    *,
    reads: dict[str, Any] | None = None,
    writes: dict[str, Any] | None = None,
) -> None:
    """An output file's folder exists and can be written, and the path is not a folder,
    checked before any work (nothing to check without a file): a long job never ends in a
    file it cannot write. ``format_of`` checks the suffix too (an image's, a figure's).

    Nor is it one of the files the command ``reads`` or another it ``writes`` (argument or
    option name → path, paths or None): a car's measurement overwritten by its own recipe
    would be lost."""
    if path is None:
        return
    from flakelab.io import STANDARD_STREAM  # not at start-up
    from flakelab.io.records import is_no_regular_file, unwritable_folder

    if str(path) == STANDARD_STREAM:  # it wrote a file named "-", where a reader reads stdin
        raise FlakelabError(
            f"{option}: - is standard output, which carries this command's report: name a "
            "file (by its whole path where it is named -)"
        )

    if format_of is not None:
        try:
            format_of(path)
        except ValueError as error:  # named by its option, as every other refusal here
            raise FlakelabError(f"{option}: {error}") from None
    target = Path(path).resolve()
    if target.is_dir():
        raise FlakelabError(f"{option}: {path}: is a folder, expected a file name")
    if is_no_regular_file(path):  # /dev/null, a pipe: written into, whatever its folder
        if not os.access(path, os.W_OK):
            raise FlakelabError(f"{option}: {path}: cannot be written")
    elif problem := unwritable_folder(target):
        raise FlakelabError(f"{option}: {path}: {problem}")
    if what := _named_same_file(path, reads or {}, _existing_same_file):
        raise FlakelabError(
            f"{option}: {path} is also {what}, which this command reads: writing it would lose "
            "what it holds; choose another file"
        )
    if what := _named_same_file(path, writes or {}, _same_path):
        raise FlakelabError(
            f"{option}: {path} is also {what}, which this command writes too: one would "
            "replace the other; choose another file"
        )


def _named_paths(files: dict[str, Any]) -> Iterator[tuple[str, Any]]:
    """Each path of ``files`` (name → path, paths or None) with its name."""
    for name, given in files.items():
        for path in given if isinstance(given, list | tuple) else [given]:
            if path is not None:
                yield name, path


def _named_same_file(path, files: dict[str, Any], same: Callable[[Any, Any], bool]) -> str | None:
    """The name of the first of ``files`` (name → path, paths or None) that is ``path``."""
    return next((name for name, other in _named_paths(files) if same(path, other)), None)


def _existing_same_file(a, b) -> bool:
    """Whether two files that exist are one (through links too); False where one does not,
    or is no path (a library's or a database's name)."""
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):
        return False


def _same_path(a, b) -> bool:
    """Whether two paths, written or not yet, name one file."""
    try:
        return _existing_same_file(a, b) or Path(a).resolve() == Path(b).resolve()
    except (OSError, ValueError, RuntimeError):
        return False


def check_figure_file(path, option: str = "--render", **others: dict[str, Any]) -> None:
    """A figure file's suffix and folder, checked before any work (nothing to check without
    one), and the ``others`` of :func:`check_output_file`."""
    if path is not None:
        from flakelab.render.plots import figure_format

        check_output_file(path, option, figure_format, **others)


def draw_differences(geometries, reference_lab, samples: dict, tolerance, path, title: str,
                     **options) -> None:  # fmt: skip
    """``--plot``: the multi-angle difference chart of ``samples`` (label → CIELAB
    ``[G, 3]``) against the reference (:func:`~flakelab.render.plots.plot_differences`)."""
    from flakelab.render.plots import plot_differences

    plot_differences(geometries, reference_lab, samples, tolerance, path, title=title, **options)
    errors.print(f"wrote {path}", highlight=False)


RenderLampsOption = Annotated[
    str | None,
    typer.Option(
        "--render-lamps",
        help="With --render: the lamps to draw under, comma-separated angles from the normal "
        "(45,25; default: each the readings were read under, an MA-T12's 45 and 15). A lamp "
        "not read is drawn from each reading's 45° readings interpolated over flake tilt, "
        "and labelled so.",
    ),
]


def render_lamps(text: str | None, render) -> tuple[float, ...] | None:
    """The lamps ``--render-lamps`` names (None: the default), refused without ``--render``
    or where they are no angles from 0 to 89°."""
    from flakelab.render.appearance import parse_lamps

    if text is None:
        return None
    if render is None:
        raise FlakelabError("--render-lamps: the lamps of the --render figure; give --render")
    try:
        return parse_lamps(text)
    except ValueError as error:
        raise FlakelabError(str(error)) from None


def draw_side_by_side(readings, labels: list[str], path, title: str, **options) -> None:
    """``--render``: readings as curved panels one above the other
    (:func:`~flakelab.render.plots.plot_side_by_side`); a reading the renderer cannot draw is
    refused naming the option."""
    from flakelab.render import plot_side_by_side

    try:
        plot_side_by_side(readings, labels, path, title=title, **options)
    except ValueError as error:
        raise FlakelabError(f"--render: {error}") from None
    errors.print(f"wrote {path}", highlight=False)


def texture_table(
    label: str, delta: dict[str, float], limits: dict[str, float], failing: list[str]
) -> Table:
    """Texture differences ``delta`` under a row ``label``, the tolerance's ``limits`` below
    the readings it bounds, failing readings in red (the match's and compare's tables)."""
    table = Table(box=box.SIMPLE, show_header=True)
    table.add_column("texture")
    for name in delta:
        table.add_column(name, justify="right")
    table.add_row(
        label, *(f"[red]{v:+.2f}[/]" if k in failing else f"{v:+.2f}" for k, v in delta.items())
    )
    if limits:
        table.add_row("limit ±", *(f"{limits[k]:.2f}" if k in limits else "" for k in delta))
    return table


def _first_paragraph(text: str | None) -> str | None:
    return " ".join(text.split("\n\n")[0].split()) if isinstance(text, str) else None


def file_name_for(sample: str, taken: set[str]) -> str:
    """A sample's name as a file name: what a file system takes, nothing else, and not one
    already ``taken`` (two samples named alike get ``-2``, ``-3`` …); it joins them."""
    import re

    base = re.sub(r"[^\w.-]+", "_", sample).strip("._") or "sample"
    name, k = base, 1
    while name.lower() in taken:  # a file system may not tell the cases apart
        k += 1
        name = f"{base}-{k}"
    taken.add(name.lower())
    return name


def names_read_in(folder: Path | None, reads: dict[str, Any], suffix: str = ".json") -> set[str]:
    """The names (:func:`file_name_for`'s, without ``suffix``) of the files a command
    ``reads`` (name → path, paths or None) that lie in ``folder``, where it writes a file per
    sample as NAME``suffix``: taken, so that none of them is written over."""
    if folder is None:
        return set()
    files = [Path(path) for _, path in _named_paths(reads)]
    return {
        f.stem.lower()
        for f in files
        if f.suffix.lower() == suffix and f.is_file() and _existing_same_file(f.parent, folder)
    }
