"""CLI: ``flakelab train`` and ``flakelab model``: training and the model registry."""

from __future__ import annotations

from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer
from rich import box
from rich.table import Table

from flakelab.cli.common import (
    COUNT_MAX,
    WEIGHT_MAX,
    JsonOption,
    check_figure_file,
    check_output_file,
    command_group,
    console,
    errors,
    interrupted,
    print_report,
    progress_bar,
    reports_errors,
    seed_option,
)
from flakelab.cli.sources import (
    CasesArgument,
    DatabaseOption,
    InstrumentOption,
    LibraryOption,
    ModelFileOption,
    NoTinsOption,
    ShopModelOption,
    SinceOption,
    UnseenOption,
    case_database,
    cases_hint_in,
    chosen_model,
    existing_engine,
    instrument_key,
    load_cases,
    name_and_version,
    named_model,
    recorded_tins_used,
    shop_cases,
    shop_spelled,
    source_arrays,
    unseen_cases,
    which_cases,
)
from flakelab.core.geometry import DEFAULT_INSTRUMENT, INSTRUMENT_GEOMETRIES
from flakelab.core.times import shown_time
from flakelab.core.wording import counted, database_label, hidden_passwords
from flakelab.errors import FlakelabError

DE00_STATISTICS = ("de00_mean", "de00_p95", "de00_max")
"""What a ΔE00 summary of a model against cases shows (``evaluate_model``'s keys)."""


def _checked_device(name: str) -> str:
    """``--device`` read before any work, so that a GPU this machine lacks is named at once."""
    from flakelab.models.network import ModelError
    from flakelab.models.training import training_device

    try:
        training_device(name)
    except ModelError as error:
        raise typer.BadParameter(str(error).removeprefix("device: ")) from None
    return name


DeviceOption = Annotated[
    str,
    typer.Option(
        help="Where the networks train: cpu, cuda, cuda:N, mps, or auto (a GPU if torch sees "
        "one). The seed gives the same batches and starting weights on every device; the "
        "trained weights agree to float rounding.",
        callback=_checked_device,
    ),
]


def split_held_out(data, source: str, holdout: float, seed: int):
    """:func:`~flakelab.models.training.held_out_split`, its refusal naming ``source``."""
    from flakelab.models.network import ModelError
    from flakelab.models.training import held_out_split

    try:
        return held_out_split(data, holdout, seed)
    except ModelError as error:
        raise FlakelabError(f"{source}: {error}") from None


def check_shop_split(source: str, shop: str, data, held_out) -> None:
    """Refuse to adapt to ``shop`` unless some of its cases are left to adapt to and some are
    held out to judge the adapted model."""
    counts = {name: part.shops.count(shop) for name, part in (("data", data), ("held", held_out))}
    if not any(counts.values()):
        raise FlakelabError(
            f"{source}: --adapt: no cases from shop {shop!r}{cases_hint_in(source, shop)}"
        )
    if not all(counts.values()):
        where = "held out" if counts["held"] else "left to adapt to"
        raise FlakelabError(
            f"{source}: --adapt: all {sum(counts.values())} of shop {shop!r}'s cases were "
            f"{where}; it needs some of each (--holdout sets the share held out)"
        )


def judged_before_and_after(base, adapted, held_out) -> dict:
    """ΔE00 statistics of a model ``before`` and ``after`` its adaptation, on ``held_out``."""
    from flakelab.models.training import evaluate_model

    before, after = (evaluate_model(m, held_out) for m in (base, adapted))
    return {
        "cases": after["cases"],
        "before": {k: before[k] for k in DE00_STATISTICS},
        "after": {k: after[k] for k in DE00_STATISTICS},
    }


def de00_table(title: str, label: str, stats: dict, names=None, total: bool = True) -> Table:
    """ΔE00 mean, p95 and max per row of ``stats`` (``names``, default all; the last bold
    where it is the ``total``)."""
    names = list(stats) if names is None else list(names)
    table = Table(title=title, box=box.SIMPLE_HEAD)
    for column in (label, "ΔE00 mean", "p95", "max"):
        table.add_column(column, justify="right")
    for name in names:
        v = stats[name]
        table.add_row(
            name,
            *(f"{v[k]:.3f}" for k in DE00_STATISTICS),
            style="bold" if total and name == names[-1] else None,
        )
    return table


model_app = command_group(
    "Learned forward models: list, show, evaluate, adapt to a shop; register a model file; "
    "promote and retire."
)


LossLogOption = Annotated[
    Path | None,
    typer.Option(
        "--loss-log",
        help="Also write every epoch's loss, stage by stage, as CSV (stage, epoch, loss, "
        "validation_de00).",
    ),
]
LossPlotOption = Annotated[
    Path | None,
    typer.Option(
        "--plot",
        help="Also draw every stage's loss per epoch, and the held-out cases' ΔE00 where a "
        "stage judged them (PNG, PDF or SVG).",
    ),
]


def _check_outputs(out: Path | None, loss_log: Path | None, plot: Path | None, reads: dict,
                   checkpoint: Path | None = None) -> None:  # fmt: skip
    """Before the training: a model file, a checkpoint, a loss log or a figure that could not
    be written, or would be written over a file it ``reads`` or another it writes, is
    refused."""
    check_output_file(out, "--out", reads=reads)
    check_output_file(checkpoint, "--checkpoint", reads=reads, writes={"--out": out})
    check_output_file(loss_log, "--loss-log", reads=reads,
                      writes={"--out": out, "--checkpoint": checkpoint})  # fmt: skip
    check_figure_file(
        plot,
        "--plot",
        reads=reads,
        writes={"--out": out, "--checkpoint": checkpoint, "--loss-log": loss_log},
    )


def _write_losses(log: list[dict], loss_log: Path | None, plot: Path | None, title: str,
                  summary: dict) -> None:  # fmt: skip
    """The whole log of losses to ``loss_log`` (CSV) and drawn to ``plot``, each named in
    the ``summary``."""
    if loss_log is not None:
        from flakelab.io.loss_log import write_loss_log

        write_loss_log(log, loss_log)
        summary["loss_log"] = str(loss_log)
    if plot is not None:
        from flakelab.render.plots import plot_losses

        plot_losses(log, plot, title=title)
        summary["plot"] = str(plot)


def train(
    cases: CasesArgument,
    instrument: InstrumentOption = DEFAULT_INSTRUMENT,
    library: LibraryOption = None,
    out: Annotated[
        Path | None, typer.Option("--out", "-o", help="Also write the model here.")
    ] = None,
    database: DatabaseOption = None,
    register_model: Annotated[
        bool, typer.Option("--register/--no-register", help="Store and maybe promote it.")
    ] = True,
    epochs: Annotated[
        int, typer.Option(min=1, max=COUNT_MAX, help="Epochs per stage (then as many fine-tuning).")
    ] = 300,
    hidden: Annotated[str, typer.Option(help="Hidden layer sizes.")] = "100,100,100",
    batch_size: Annotated[
        int, typer.Option(min=1, max=COUNT_MAX, help="Cases per optimiser step.")
    ] = 128,
    colour_weight: Annotated[
        float | None,
        typer.Option(
            min=0.0,
            max=WEIGHT_MAX,
            help="Weight of the mean squared ΔE94 loss term (default: 0.02).",
        ),
    ] = None,
    holdout: Annotated[
        float, typer.Option(min=0.01, max=0.9, help="Share of cases held out to judge it.")
    ] = 0.1,
    adapt: Annotated[
        str | None,
        typer.Option(
            callback=shop_spelled,
            help="Then adapt a copy to this shop's cases: registered as the shop's own model "
            "(the general one is registered too) and written to --out.",
        ),
    ] = None,
    adapt_epochs: Annotated[
        int | None,
        typer.Option(
            min=1,
            max=COUNT_MAX,
            help="Epochs of the adaptation (default: the paper's 150).",
        ),
    ] = None,
    adapt_validation: Annotated[
        float,
        typer.Option(
            min=0.0,
            max=0.9,
            help="Share of the shop's cases held out to choose the adaptation's epoch; the "
            "model keeps its best there (0: run every epoch, as the paper).",
        ),
    ] = 0.2,
    screening: Annotated[
        str,
        typer.Option(
            help="Outlier screen: sequential (the paper's: one model, four partitions in turn, "
            "the fifth as yardstick) or cross-validation (five fold models, 5x the work)."
        ),
    ] = "sequential",
    members: Annotated[
        int,
        typer.Option(
            min=1,
            max=COUNT_MAX,
            help="Networks trained side by side on the cleaned cases and averaged (an "
            "ensemble: less error where the cases are few, and their disagreement reported "
            "with every prediction; costs that many times the inference).",
        ),
    ] = 1,
    log_offset: Annotated[
        float,
        typer.Option(
            min=0.0,
            help="Also feed the network log(fraction + this): a strong pigment's small "
            "amounts spread out (0: fractions and amounts per unit effect pigment only).",
        ),
    ] = 0.0,
    seed: Annotated[int, seed_option("Seed of splits and weights.")] = 0,
    device: DeviceOption = "cpu",
    no_tins: NoTinsOption = False,
    loss_log: LossLogOption = None,
    plot: LossPlotOption = None,
    checkpoint: Annotated[
        Path | None,
        typer.Option(
            "--checkpoint",
            help="Keep the protocol's progress in this file after each stage (a session's "
            "training or its fine-tuning): the same command again, after an interruption, "
            "goes on from the last stage kept, to the model it would have trained. Removed "
            "once the command is done.",
        ),
    ] = None,
    when_new: Annotated[
        int | None,
        typer.Option(
            "--when-new",
            min=1,
            max=COUNT_MAX,
            help="Train only where CASES, a database, has stored at least this many cases at "
            "the instrument's geometries since the newest version registered (in --database) "
            "read its cases; else say how many and stop (exit 0): a nightly job retrains as "
            "the shop's cases come in. A --checkpoint kept for other cases (a night "
            "interrupted before more came in) is started again.",
        ),
    ] = None,
    json_output: JsonOption = False,
) -> None:
    """Train the learned forward model with the hybrid paper's protocol.

    It learns from every case read at the instrument's geometries, whatever read it (an
    MA-T12 case trains the five-angle model too). A case that records the tins its recipe
    was poured from is learned as the standard tins would have sprayed it: the film its tins
    put down, its spray-out without their shades."""
    from flakelab.cases.case import cases_at
    from flakelab.cases.database import open_database
    from flakelab.io import read_library
    from flakelab.models.checkpoint import TrainingCheckpoint
    from flakelab.models.registry import register
    from flakelab.models.training import (
        adapt_to_shop,
        data_hash,
        evaluate_model,
        protocol_epochs,
        protocol_stages,
        train_protocol,
        withhold_for_adaptation,
    )

    reads = {"CASES": cases, "--library": library, "--database": database}
    _check_outputs(out, loss_log, plot, reads, checkpoint)
    # the settings are checked before the cases are read
    config = _training_config(hidden, epochs, batch_size, screening, adapt_validation, members,
                              log_offset, seed, device, colour_weight, adapt_epochs)  # fmt: skip
    lib = read_library(library)
    instrument = instrument_key(instrument)
    geometries = INSTRUMENT_GEOMETRIES[instrument]
    read_at = datetime.now(UTC)  # before reading: a case stored while it trains is new next time
    gate, registry = (
        _new_cases(cases, database, register_model, instrument, when_new) if when_new
        else (None, None)
    )  # fmt: skip
    if gate and gate["new_cases"] is not None and gate["new_cases"] < when_new:
        _print_not_trained(cases, instrument, gate, json_output)
        return
    loaded = load_cases(cases)
    chosen = cases_at(loaded, geometries)
    if not chosen:
        raise FlakelabError(f"{cases}: no cases read at the {instrument}'s geometries {geometries}")
    by_colour = measured_enough(cases, chosen, 2 * config.folds)
    arrays = source_arrays(cases, chosen, lib, effect=True)
    arrays, tinned = recorded_tins_used(arrays, lib, no_tins)
    data, held_out = (
        replace(part, instrument=instrument)  # ma-t6 and byk-mac-i share their geometries
        for part in split_held_out(arrays, cases, holdout, seed)
    )
    validation = None
    if adapt is not None:  # before the long training
        check_shop_split(cases, adapt, data, held_out)
        data, validation = withhold_for_adaptation(data, adapt, config)
    # the registry before the long training: one it cannot store in is refused now, not after
    if register_model:
        engine = registry if registry is not None else open_database(database)
    else:
        engine = None
    # on a schedule, a checkpoint kept for fewer cases is of a training the cases came in after
    kept = checkpoint and TrainingCheckpoint(
        checkpoint, config, data_hash(data), restart_other_cases=bool(gate)
    )
    resumed = kept.stages if kept else 0

    def left() -> str:  # what a Ctrl-C leaves
        if not kept:
            return "nothing was written or registered (--checkpoint FILE keeps a training's stages)"
        if not kept.stages and kept.replaced:
            return (
                f"no stage was done: {kept.path} still keeps a training of other cases, which "
                "the next run with --when-new starts again; nothing was written or registered"
            )
        if not kept.stages:
            return f"no stage was done: {kept.path} keeps none; nothing was written or registered"
        return (
            f"{kept.path} keeps {kept.stages} of the protocol's {protocol_stages(config)} stages; "
            "the same command again goes on from there"
        )

    epochs = protocol_epochs(config, adapt is not None)
    with interrupted(left), progress_bar(disable=json_output) as bar:
        task = bar.add_task(f"training on {data.x.shape[0]} cases", total=epochs)
        advance = lambda k: bar.advance(task, k)  # noqa: E731
        model, report = train_protocol(data, config, progress=advance, checkpoint=kept)
        model.info["name"] = instrument
        if adapt is not None:  # step 5 on a copy: the general model is kept too
            shop_model, adaptation = adapt_to_shop(
                model,
                data,
                adapt,
                config,
                leave_out=report["outlier_case_ids"],
                validation=validation,
                progress=advance,
            )
    metrics = evaluate_model(model, held_out)
    summary: dict[str, Any] = {k: v for k, v in report.items() if k != "log"}
    summary["held_out"] = {k: metrics[k] for k in ("cases", *DE00_STATISTICS)}
    summary["cases_left_out"] = len(loaded) - len(chosen)  # not at its geometries
    summary["cases_known_by_colour_alone"] = by_colour
    summary["cases_with_tins"] = int(tinned.sum())
    if kept:
        summary["stages_resumed"] = resumed  # kept by an earlier, interrupted run
        summary["checkpoint_of_other_cases_replaced"] = kept.replaced
    if gate:
        summary["when_new"] = gate
    if engine is not None:
        summary["registry"] = register(
            engine, model, held_out, metrics=summary["held_out"], cases_read_at=read_at
        )
    log = report["log"]
    if adapt is not None:
        shop_held_out = held_out.of_shop(adapt)
        summary["adaptation"] = {k: v for k, v in adaptation.items() if k != "log"} | {
            "shop": adapt,
            "held_out": judged_before_and_after(model, shop_model, shop_held_out),
        }
        if engine is not None:
            summary["adaptation"]["registry"] = register(
                engine,
                shop_model,
                shop_held_out,
                shop=adapt,
                metrics=summary["adaptation"]["held_out"],
                cases_read_at=read_at,
            )
        log = log + adaptation["log"]
        model = shop_model  # --out: the shop's model
    if out is not None:
        _write_model(model, out)
        summary["file"] = str(out)
    summary["loss_log_tail"] = log[-3:]
    title = f"Training on {data.x.shape[0]} cases of {hidden_passwords(cases)}"
    _write_losses(log, loss_log, plot, title, summary)
    if kept:
        kept.remove()  # the model is written and registered: nothing left to go on with
    if json_output:
        print_report(summary, default=str)
        return
    _print_training(summary, title)


def _print_training(summary: dict, title: str) -> None:
    """A training's held-out error, what it left out, its registration and adaptation, in
    tables and words (``--json`` gives them all, with the losses' tail). It printed the JSON
    report itself."""
    held_out = {f"{summary['held_out']['cases']} cases": summary["held_out"]}
    console.print(de00_table(title, "held out", held_out, total=False))
    said = [f"{summary['seconds']:.1f} s on {summary['device']}; final loss "
            f"{summary['final_loss']:.4g} (--loss-log writes every epoch's)"]  # fmt: skip
    if dropped := summary["outlier_case_ids"]:
        said.append(f"{counted(len(dropped), 'outlier')} dropped: {', '.join(dropped[:5])}"
                    + (" …" if len(dropped) > 5 else ""))  # fmt: skip
    if summary["cases_left_out"]:
        said.append(f"{counted(summary['cases_left_out'], 'case')} left out, not read at the "
                    "model's geometries")  # fmt: skip
    if by_colour := summary["cases_known_by_colour_alone"]:
        said.append(learnt_by_colour(by_colour))
    if summary.get("stages_resumed"):
        said.append(f"went on from {summary['stages_resumed']} stages its checkpoint kept")
    if "file" in summary:
        said.append(f"wrote {summary['file']}")
    if "registry" in summary:
        said.append(_registry_verdict(summary["registry"]))
    for line in said:
        errors.print(line, highlight=False)
    if adaptation := summary.get("adaptation"):
        title = f"adapted to shop {adaptation['shop']!r}, {counted(adaptation['cases'], 'case')}"
        before_after = adaptation["held_out"]
        console.print(de00_table(title, "held out", before_after, ("before", "after")))
        errors.print(_kept_epoch_text(adaptation), highlight=False)
        if "registry" in adaptation:
            errors.print(_registry_verdict(adaptation["registry"]), highlight=False)


def _new_cases(cases: str, database: str | None, register: bool, instrument: str,
               when_new: int) -> tuple[dict, Any]:  # fmt: skip
    """``train --when-new``: how many cases the database ``cases`` stored at ``instrument``'s
    geometries since the newest version registered as its model read its cases (None where
    none is: every case is new), and the registry it looked in (opened, or created where
    ``register``: the training registers there; None where none is)."""
    from flakelab.cases.database import count_stored_since, open_database
    from flakelab.cases.exchange import is_case_file
    from flakelab.models.registry import newest_training, shop_model_name

    if is_case_file(Path(cases)):
        raise FlakelabError(
            f"--when-new: counts the cases a database stored since the last training; {cases} "
            "is a case file (import it: 'flakelab cases import')"
        )
    registry = open_database(database) if register else existing_engine(database)
    name = shop_model_name(instrument)
    newest = registry and newest_training(registry, name)
    gate: dict[str, Any] = {"when_new": when_new, "model": name, "since_version": None}
    if not newest:
        return gate | {"new_cases": None}, registry
    version, read_at, known = newest
    stored = count_stored_since(case_database(cases), read_at, INSTRUMENT_GEOMETRIES[instrument])
    since = "cases read" if known else "registration"  # a model file trained elsewhere
    return gate | {"since_version": version, "since": read_at.isoformat(), "since_what": since,
                   "new_cases": stored}, registry  # fmt: skip


def _print_not_trained(cases: str, instrument: str, gate: dict, json_output: bool) -> None:
    """What ``train --when-new`` says where too few cases came in to train again."""
    if json_output:
        print_report({"trained": False, "when_new": gate})
        return
    console.print(
        f"{hidden_passwords(cases)}: {counted(gate['new_cases'], 'case')} at the {instrument}'s "
        f"geometries stored since {gate['model']} v{gate['since_version']} "
        + ("read its cases" if gate["since_what"] == "cases read" else "was registered")
        + f" ({shown_time(gate['since'])}), fewer than --when-new {gate['when_new']}: nothing "
        "trained"
    )


def _training_config(hidden: str, epochs: int, batch_size: int, screening: str,
                     adapt_validation: float, members: int, log_offset: float, seed: int,
                     device: str, colour_weight: float | None,
                     adapt_epochs: int | None):  # fmt: skip
    """``train``'s options as a :class:`~flakelab.models.training.TrainingConfig`, each
    checked (the config refuses its own); the options left unset keep its defaults."""
    from flakelab.models.network import LOG_OFFSET_MAX, ModelError
    from flakelab.models.training import SCREENINGS, TrainingConfig

    if screening not in SCREENINGS:
        raise FlakelabError(
            f"--screening: expected one of {', '.join(SCREENINGS)}, got {screening!r}"
        )
    if log_offset > LOG_OFFSET_MAX:
        raise FlakelabError(f"--log-offset: expected at most {LOG_OFFSET_MAX}, got {log_offset}")
    try:
        sizes = tuple(int(v) for v in hidden.split(",") if v.strip())
    except ValueError:
        raise FlakelabError(
            f"--hidden: expected layer sizes such as 100,100,100, got {hidden!r}"
        ) from None
    try:
        config = TrainingConfig(
            hidden=sizes,
            epochs=epochs,
            finetune_epochs=epochs,
            batch_size=batch_size,
            screening=screening,
            adapt_validation=adapt_validation,
            members=members,
            log_offset=log_offset,
            seed=seed,
            device=device,
        )
    except ModelError as error:  # "hidden: …", "members: …": named as they were typed
        raise FlakelabError(f"--{error}") from None
    if colour_weight is not None:
        config = replace(config, colour_weight=colour_weight)
    if adapt_epochs is not None:
        config = replace(config, adapt_epochs=adapt_epochs)
    return config


@model_app.command("list")
@reports_errors
def list_models(database: DatabaseOption = None, json_output: JsonOption = False) -> None:
    """Registered model versions."""
    from flakelab.cases.database import open_database
    from flakelab.models.files import model_file_description
    from flakelab.models.registry import SHIPPED, list_models, shipped_model_path

    rows = list_models(open_database(database, must_exist=True))
    promoted = {r["name"]: f"v{r['version']}" for r in rows if r["status"] == "promoted"}
    current = {name: promoted.get(name, "shipped") for name in sorted({*SHIPPED, *promoted})}
    if json_output:
        print_report({"registered": rows, "shipped": list(SHIPPED), "current": current})
        return
    table = Table(title="Models", box=box.SIMPLE_HEAD)
    for column in ("name", "version", "status", "held-out ΔE00", "toners", "data", "created"):
        table.add_column(column)
    for r in rows:
        table.add_row(
            r["name"],
            str(r["version"]),
            r["status"],
            f"{r['held_out_de00']:.3f}",
            str(r["toners"]),
            r["data_hash"],
            shown_time(r["created_at"]),
        )
    for name in SHIPPED:  # the current model while none of its name is promoted
        status = "current" if current[name] == "shipped" else "fallback"
        shipped = model_file_description(shipped_model_path(name))  # its toners and data
        toners, data = str(len(shipped["toners"])), shipped["info"].get("data_hash", "")[:12]
        table.add_row(name, "shipped", status, "", toners, data, "")
    console.print(table)


@model_app.command("show")
@reports_errors
def show_model(
    model: Annotated[
        str,
        typer.Argument(
            help="A model file, a registered version NAME:VERSION (see 'flakelab model list'), "
            "or an instrument (five-angle, ma-t12) for its current model."
        ),
    ],
    database: DatabaseOption = None,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            "-o",
            help="Also write the model to this file: a registered version taken out of the "
            "database, for --model or another shop.",
        ),
    ] = None,
    json_output: JsonOption = False,
) -> None:
    """What a model is and what it learned from: network, toners and their cases, training."""
    from flakelab.models.registry import model_card

    check_output_file(out, "--out", reads={"MODEL": model, "--database": database})
    chosen, source = named_model(model, database)
    card = {"source": hidden_passwords(source), **model_card(chosen)}
    if out is not None:
        _write_model(chosen, out)
        card["file"] = str(out)
    if json_output:
        print_report(card, default=str)
        return
    console.print(_model_card_table(card))


VersionArgument = Annotated[
    str, typer.Argument(help="A registered version NAME:VERSION (see 'flakelab model list').")
]


@model_app.command("promote")
@reports_errors
def promote_model(version: VersionArgument, database: DatabaseOption = None) -> None:
    """Make a registered version the current model by hand, retiring the one before.

    An override of the automatic promotion (a version is promoted when it beats the current
    one on the same held-out cases): a rollback after a new version misbehaves in the shop."""
    from flakelab.cases.database import open_database
    from flakelab.models.registry import promote

    engine = open_database(database, must_exist=True)
    done = promote(engine, *_registered_version(version))
    retired = f"; v{done['retired']} retired" if done["retired"] else ""
    errors.print(f"{database_label(engine)}: {done['name']} v{done['version']} promoted{retired}")


@model_app.command("retire")
@reports_errors
def retire_model(version: VersionArgument, database: DatabaseOption = None) -> None:
    """Take a registered version out of use; a promoted one leaves the next in line current (a
    shop's own model the instrument's, the instrument's the shipped one)."""
    from flakelab.cases.database import open_database
    from flakelab.models.registry import retire

    engine = open_database(database, must_exist=True)
    done = retire(engine, *_registered_version(version))
    now = "the shipped model" if done["current"] == "shipped" else done["current"]
    whose = f" for shop {done['shop']!r}" if done["shop"] else ""
    current = f"; {now} is current{whose} again" if done["was"] == "promoted" else ""
    errors.print(f"{database_label(engine)}: {done['name']} v{done['version']} retired{current}")


@model_app.command("register")
@reports_errors
def register_file(
    model_file: Annotated[
        Path,
        typer.Argument(
            help="A model file ('train --out', 'model adapt --out', 'model show --out'), "
            "trained elsewhere: at a central lab, on a GPU machine, at another workplace."
        ),
    ],
    cases: Annotated[
        str | None,
        typer.Argument(
            help="Case file (CSV/CxF) or database URL/file: the cases it is judged on.",
            show_default="the cases recorded in --database",
        ),
    ] = None,
    shop: Annotated[
        str | None,
        typer.Option(
            "--shop",
            callback=shop_spelled,
            help="Register it as this shop's own model, judged on the shop's cases against the "
            "model current for the shop (default: the instrument's, on every case given).",
        ),
    ] = None,
    since: SinceOption = None,
    library: LibraryOption = None,
    database: DatabaseOption = None,
    no_tins: NoTinsOption = False,
    json_output: JsonOption = False,
) -> None:
    """Register a model file as a new version, promoted only if it beats the current model.

    Both are judged on the cases given (by default those the database records) that neither
    learned from and whose toners both learned, as 'train' judges a model it registers; a
    model file registered before is refused, the registry unchanged."""
    from flakelab.cases.database import default_url, open_database, url_for
    from flakelab.io import read_library
    from flakelab.models.registry import (
        held_already,
        load_model_file,
        register,
        shop_model_name,
    )

    model = load_model_file(model_file)
    lib = read_library(library)
    cases = cases or (url_for(database) if database else default_url())
    chosen = shop_cases(cases, shop, model.geometries, since)
    data, tinned = recorded_tins_used(source_arrays(cases, chosen, lib), lib, no_tins)
    engine = open_database(database)
    name = shop_model_name(model.instrument, shop)
    if held := held_already(engine, name, model):
        raise FlakelabError(
            f"{model_file}: the same weights as {held} in {database_label(engine)}: "
            "nothing was stored"
        )
    done = register(engine, model, data, shop=shop)
    report = {
        "file": str(model_file),
        "model": model.identity,
        "shop": shop,
        "cases": len(chosen),
        "cases_with_tins": int(tinned.sum()),
        "learned_from": int(model.learned_from(data.case_ids).sum()),
        "registry": done,
        "database": str(engine.url),
    }
    if json_output:
        print_report(report)
        return
    errors.print(_registry_verdict(done), highlight=False)


def _registered_version(spec: str) -> tuple[str, int]:
    registered = name_and_version(spec)
    if registered is None:
        raise FlakelabError(f"VERSION: expected NAME:VERSION, such as five-angle:2, got {spec!r}")
    return registered


def _model_card_table(card: dict) -> Table:
    training = card["training"]
    cases = card["toner_cases"]
    rows = {
        "source": card["source"],
        "instrument": f"{card['instrument']}: {', '.join(card['geometries'])}",
        "network": f"{' × '.join(map(str, card['hidden']))} SiLU"
        + (f", an ensemble of {card['members']}" if card["members"] > 1 else "")
        + (f", log features (offset {card['log_offset']:g})" if card["log_offset"] else ""),
        "trained on": f"{card['trained_cases']:,} cases "
        f"({counted(card['outliers_dropped'], 'outlier')} dropped), data {card['data_hash'][:12]}"
        if card["trained_cases"] is not None
        else "not recorded",
        "training": ", ".join(f"{k} {v}" for k, v in training.items()) or "not recorded",
        "toners": ", ".join(f"{t} ({cases[t]})" if t in cases else t for t in card["toners"]),
        "new toners (physics scaling)": ", ".join(card["novel_toners"]) or "none",
    }
    if card["adaptation"]:
        adaptation = card["adaptation"]
        rows["adapted"] = (
            f"{adaptation.get('stage', '')}: {adaptation.get('cases')} cases, kept epoch "
            f"{adaptation.get('kept_epochs')} of {adaptation.get('epochs')}"
            + (f", from {adaptation['from']}" if adaptation.get("from") else "")
        )
    learned = card["learned_cases"]
    rows["cases it learned from"] = "not recorded" if learned is None else f"{learned:,}, recorded"
    if "file" in card:
        rows["written to"] = card["file"]
    table = Table(title=f"Model {card['name']}", show_header=False, box=box.SIMPLE)
    table.add_column(style="bold")
    table.add_column(overflow="fold")
    for key, value in rows.items():
        table.add_row(key, str(value))
    return table


@model_app.command("evaluate")
@reports_errors
def evaluate(
    cases: CasesArgument,
    model: ModelFileOption = None,
    instrument: InstrumentOption = DEFAULT_INSTRUMENT,
    shop: ShopModelOption = None,
    since: SinceOption = None,
    library: LibraryOption = None,
    database: DatabaseOption = None,
    habits: Annotated[
        Path | None,
        typer.Option(
            "--habits",
            help="A shop's habits file ('flakelab cases habits --out'): its offset is added "
            "to the predictions, as the matcher aims off for it.",
        ),
    ] = None,
    unseen: UnseenOption = False,
    no_tins: NoTinsOption = False,
    plot: Annotated[
        Path | None,
        typer.Option(
            "--plot",
            help="Also draw the ΔE00 at each geometry per paint family, the predicted minus "
            "the measured L*, and each case's worst ΔE00 (PNG, PDF or SVG).",
        ),
    ] = None,
    json_output: JsonOption = False,
) -> None:
    """ΔE00 of the model's predictions against the measured spray-outs.

    Cases that record the tins their recipe was poured from are predicted for those tins
    (their strengths and shades, as 'flakelab match --lots' weighs for them). How the current
    model (the shop's own with --shop, where one was adapted to it) does on
    all the cases, on a shop's (--shop), on those since a date (--since), or on those it never
    learned from (--unseen)."""
    from flakelab.cases.case import cases_at
    from flakelab.io import read_library
    from flakelab.match.mixups import SPRAYOUT_MISMATCH
    from flakelab.models.training import error_summary, prediction_errors

    check_figure_file(plot, "--plot")
    lib = read_library(library)
    forward = chosen_model(model, instrument, database, shop)
    loaded = load_cases(cases, shop, since)
    chosen = cases_at(loaded, forward.geometries)
    if not chosen:
        raise FlakelabError(
            f"{cases}: no cases {which_cases(shop, since)}{cases_hint_in(cases, shop)} read at "
            f"the model's geometries {forward.geometries}"
        )
    at_geometries = len(chosen)
    if unseen:
        which = f"{which_cases(shop, since)} read at its geometries"
        chosen, learned = unseen_cases(forward, chosen, cases, which)
    from flakelab.cli.matcher import habits_for
    from flakelab.match.forward import LearnedForward, film_of
    from flakelab.match.judging import evaluate_recipes
    from flakelab.match.lots import poured_from
    from flakelab.match.models import forward_for

    matcher = forward_for(forward, lib)
    data = source_arrays(cases, chosen, lib)
    if no_tins:
        data = data.without_tins()
    shop_habits = habits_for(
        habits, None, database, matcher, with_tins=bool(data.tins_recorded.any())
    )

    def habits_offset(x, R):
        # at the film each case's tins put down, where habits act and were read
        film = film_of(poured_from(matcher, lib, data.strength, data.shade), x)
        return shop_habits.offset(lib, film, R, matcher.geometries)

    offset = habits_offset if shop_habits else None
    hybrid = isinstance(matcher, LearnedForward) and matcher.novel
    # a hybrid forward predicts its new toners by the physics, which the network alone lacks
    predict = (lambda x: evaluate_recipes(matcher, x)) if hybrid else None

    families = lib.paint_families(data.x)
    # the mix-ups judged by the model evaluated, as the habits' screen judges them
    found = prediction_errors(
        forward,
        data,
        predict,
        offset,
        poured=lambda x, strength, shade: evaluate_recipes(
            poured_from(matcher, lib, strength, shade), x
        ),
    )
    report = error_summary(found, families, leave_out_above=SPRAYOUT_MISMATCH)
    if plot is not None:
        from flakelab.render.plots import plot_model_errors

        plot_model_errors(found, plot, families=families, mismatch=SPRAYOUT_MISMATCH,
                          title=f"{matcher.model_id} on {hidden_passwords(cases)}")  # fmt: skip
        report["plot"] = str(plot)
        errors.print(f"wrote {plot}", highlight=False)
    report["cases_with_tins"] = int(data.tins_recorded.sum())
    if hybrid:
        novel = np.isin(np.array(lib.names), matcher.novel)
        report["cases_with_new_toners"] = int((data.x[:, novel] > 0).any(1).sum())
        report["new_toners"] = list(matcher.novel)
    report["likely_mix_ups"] = [
        {"case_id": data.case_ids[row], "de00": round(de00, 3)} for row, de00 in report.pop("above")
    ]
    report["without_mix_ups"] = report.pop("without_above")
    report["model"] = model or f"current {instrument}"
    report["forward"] = matcher.name
    report["model_id"] = matcher.model_id
    report["habits"] = shop_habits and shop_habits.report()
    report["cases_left_out"] = len(loaded) - at_geometries
    # with --unseen, those left out; else those among the cases judged
    report["cases_learned"] = learned if unseen else int(forward.learned_from(data.case_ids).sum())
    report["unseen"] = unseen
    report["shop"], report["since"] = shop, since and since.isoformat()
    if json_output:
        print_report(report)
        return
    _print_evaluation(report, len(loaded))


def _print_evaluation(report: dict, loaded: int) -> None:
    """The model's errors as tables by geometry and by paint family, with what the figures
    leave out or flatter: cases it learned from, cases at other geometries, likely mix-ups
    (``loaded``: the cases read)."""
    from flakelab.match.mixups import SPRAYOUT_MISMATCH

    if report["cases_learned"] and report["unseen"]:
        errors.print(
            f"note: left out {report['cases_learned']} cases the model learned from",
            highlight=False,
        )
    elif report["cases_learned"]:
        errors.print(
            f"[yellow]warning:[/] the model learned from {report['cases_learned']} of these "
            f"{report['cases']} cases: its error on them flatters it (--unseen judges it on "
            "the others)",
            highlight=False,
        )
    if report["cases_left_out"]:
        errors.print(
            f"note: {report['cases_left_out']} of the {loaded} cases were not read at the "
            f"model's geometries and are left out",
            highlight=False,
        )
    rows = {**report["per_geometry"], "all": report}
    count = report["cases"]
    title = f"{report['model']} on {counted(count, 'case')}"
    console.print(de00_table(title, "geometry", rows))
    families = {f"{name} ({row['cases']})": row for name, row in report["per_family"].items()}
    console.print(de00_table("by paint family", "family (cases)", families, total=False))
    if mixed := report["likely_mix_ups"]:
        named = ", ".join(m["case_id"] for m in mixed[:5]) + (" …" if len(mixed) > 5 else "")
        without = report["without_mix_ups"]
        rest = (
            f"; without them ΔE00 mean {without['de00_mean']:.3f}, p95 "
            f"{without['de00_p95']:.3f}, max {without['de00_max']:.3f}"
            if without
            else ""
        )
        errors.print(
            f"[yellow]warning:[/] {counted(len(mixed), 'case')} further than ΔE00 "
            f"{SPRAYOUT_MISMATCH:g} from the model's prediction, likely mix-ups (another panel, "
            f"recipe or target): {named}; the figures above include them{rest}",
            highlight=False,
        )


@model_app.command("adapt")
@reports_errors
def adapt(
    cases: CasesArgument,
    shop: Annotated[
        str | None,
        typer.Option(
            callback=shop_spelled,
            help="Only this shop's cases; the model is then the shop's own, adapted from its "
            "current one (default: every case given, the instrument's model).",
        ),
    ] = None,
    since: SinceOption = None,
    model: ModelFileOption = None,
    instrument: InstrumentOption = DEFAULT_INSTRUMENT,
    library: LibraryOption = None,
    database: DatabaseOption = None,
    epochs: Annotated[
        int | None,
        typer.Option(min=1, max=COUNT_MAX, help="Adaptation epochs (default: the paper's 150)."),
    ] = None,
    validation: Annotated[
        float,
        typer.Option(
            min=0.0,
            max=0.9,
            help="Share of the cases held out to choose the epoch; the model keeps its best "
            "there, never worse than it started (0: run every epoch, as the paper).",
        ),
    ] = 0.2,
    holdout: Annotated[
        float, typer.Option(min=0.01, max=0.9, help="Share of cases held out to judge it.")
    ] = 0.1,
    seed: Annotated[int, seed_option("Seed of the splits and the adaptation.")] = 0,
    device: DeviceOption = "cpu",
    out: Annotated[
        Path | None, typer.Option("--out", "-o", help="Also write the model here.")
    ] = None,
    register_model: Annotated[
        bool, typer.Option("--register/--no-register", help="Store and maybe promote it.")
    ] = True,
    no_tins: NoTinsOption = False,
    loss_log: LossLogOption = None,
    plot: LossPlotOption = None,
    json_output: JsonOption = False,
) -> None:
    """Adapt a trained model (default: the current one) to one shop's cases.

    Cases that record their tins are learned as the standard tins would have sprayed them,
    as 'train' learns them.

    The training protocol's adaptation phase, for the sprayers and instrument of one shop. With
    --shop the model is registered as that shop's own ('INSTRUMENT @ SHOP'): promoted, it is
    current for that shop alone (match, correct, cases record and model evaluate with its
    --shop), and another adaptation to the shop starts from it."""
    from flakelab.cases.database import open_database
    from flakelab.io import read_library
    from flakelab.models.network import ModelError
    from flakelab.models.registry import current_model, register
    from flakelab.models.training import (
        adapt_model,
        adaptation_cases,
        outlying_cases,
        recorded_config,
    )

    reads = {"CASES": cases, "--model": model, "--library": library, "--database": database}
    _check_outputs(out, loss_log, plot, reads)
    lib = read_library(library)
    engine = open_database(database) if register_model else existing_engine(database)
    if model:
        base = named_model(model, database, "--model")[0]
    else:  # the database the new version goes to holds the current model, the shop's own
        base = current_model(engine, instrument, shop)
    chosen = shop_cases(cases, shop, base.geometries, since)
    novel = set(base.new_toners)
    known = [c for c in chosen if not novel & set(c.recipe)]
    if not known:
        raise FlakelabError(
            f"{cases}: every one of the {counted(len(chosen), 'case')} uses a toner the model "
            f"knows from too few cases ({', '.join(sorted(novel))}); nothing to adapt it to"
        )
    config = replace(recorded_config(base), adapt_validation=validation, seed=seed, device=device)
    arrays = source_arrays(cases, known, lib, effect=True)
    arrays, tinned = recorded_tins_used(arrays, lib, no_tins)
    outlying = outlying_cases(base, arrays, config.outlier_threshold)
    dropped = [c.case_id for c, out in zip(known, outlying, strict=True) if out]
    screened = arrays.subset(np.flatnonzero(~outlying))
    try:
        data, validation, held_out = adaptation_cases(base, screened, holdout, config)
    except ModelError as error:  # too few cases, or only those it learned
        raise FlakelabError(f"{cases}: {error}") from None
    if epochs is not None:
        config = replace(config, adapt_epochs=epochs)
    stage = f"adapt {shop or cases}"
    with progress_bar(disable=json_output) as bar:
        total = config.adapt_epochs * base.members  # an ensemble's members adapt side by side
        task = bar.add_task(_adapting_label(data, validation, config), total=total)
        new, report = adapt_model(
            base,
            data,
            config,
            stage=stage,
            shop=shop,
            validation=validation,
            progress=lambda k: bar.advance(task, k),
        )
    summary: dict[str, Any] = {k: v for k, v in report.items() if k != "log"}
    summary |= {
        "model": model or f"current {instrument}",
        "from": base.identity,
        "shop": shop,
        "left_out_new_toners": len(chosen) - len(known),
        "known_by_colour_alone": int(screened.known_by_colour.sum()),
        "outliers": len(dropped),
        "outlier_case_ids": dropped,
        "learned_before": int(base.learned_from(screened.case_ids).sum()),
        "cases_with_tins": int(tinned.sum()),
        "held_out": judged_before_and_after(base, new, held_out),
    }
    if out is not None:
        _write_model(new, out)
        summary["file"] = str(out)
    if register_model:
        summary["registry"] = register(
            engine, new, held_out, shop=shop, metrics=summary["held_out"]
        )
    _write_losses(report["log"], loss_log, plot, f"{stage}, {data.x.shape[0]} cases", summary)
    if json_output:
        print_report(summary)
        return
    _print_adaptation(summary, stage, config.outlier_threshold)


def measured_enough(source: str, cases: list, minimum: int) -> int:
    """How many of the ``cases`` of ``source`` know their spray-out by its L*a*b* alone (a
    model learns that colour, not the recovered spectra); fewer than ``minimum`` measured
    spray-outs, from which a model trained afresh learns spectra, is an error that says
    why."""
    by_colour = sum(c.sprayout_recovered for c in cases)
    if len(cases) - by_colour < minimum:
        raise FlakelabError(
            f"{hidden_passwords(source)}: {by_colour} of the {counted(len(cases), 'case')} know "
            f"their spray-out by its L*a*b* alone: a model trained afresh learns spectra from "
            f"measured spray-outs, at least {minimum}, and the colour of the others; record "
            "spray-outs from the instrument's spectral export, or adapt the shipped model to "
            "these cases ('flakelab model adapt', which learns their colour)"
        )
    return by_colour


def learnt_by_colour(count: int) -> str:
    """What a training or an adaptation says of the cases whose spray-outs are known by
    their L*a*b* alone."""
    return (
        f"{counted(count, 'case')} whose spray-out is known by its L*a*b* alone, learnt and "
        "judged by that colour in D65/10 alone"
    )


def _adapting_label(data, validation, config) -> str:
    """The progress bar's words: the cases adapted on and those that choose the epoch (split
    off by the adaptation itself where ``validation`` is None), as its report counts them."""
    from flakelab.models.training import adaptation_split

    n = data.x.shape[0]
    if validation is None:
        choosing = adaptation_split(np.arange(n), config)[1]
        k = 0 if choosing is None else choosing.size
        n -= k
    else:
        k = validation.x.shape[0]
    return f"adapting to {counted(n, 'case')}" + (f" ({k} more choose the epoch)" if k else "")


def _print_adaptation(summary: dict, stage: str, threshold: float) -> None:
    """An adaptation's held-out error before and after, the cases it left out (further than
    ``threshold`` robust s.d.) or had learned before, the epoch it kept and its
    registration."""
    title = f"{summary['model']} adapted to {summary['cases']} cases ({stage})"
    console.print(de00_table(title, "held out", summary["held_out"], ("before", "after")))
    if dropped := summary["outlier_case_ids"]:
        errors.print(
            f"[yellow]warning:[/] left out {counted(len(dropped), 'case')} whose error by the "
            f"model lies more than {threshold:g} robust s.d. above the shop's, likely "
            f"mix-ups: {', '.join(dropped[:5])}" + (" …" if len(dropped) > 5 else ""),
            highlight=False,
        )
    if by_colour := summary["known_by_colour_alone"]:
        errors.print(
            f"note: {learnt_by_colour(by_colour)}: the model keeps the spectra it knew",
            highlight=False,
        )
    if summary["learned_before"]:
        errors.print(
            f"note: the model learned from {summary['learned_before']} of these cases: adapted "
            "on, but held out and choosing the epoch only among the others",
            highlight=False,
        )
    errors.print(_kept_epoch_text(summary), highlight=False)
    if "registry" in summary:
        errors.print(_registry_verdict(summary["registry"]), highlight=False)


def _registry_verdict(r: dict) -> str:
    """A registration as :func:`~flakelab.models.registry.register` reports it, in words."""
    if r["promoted"]:
        verdict = "promoted"
    elif r["cases_judged"]:
        verdict = "kept as a candidate (no better than the current one)"
    else:
        verdict = (
            "kept as a candidate: no held-out case that both models could be judged on "
            "(whose toners both learned, that neither learned from)"
        )
    scores = ""
    if r["cases_judged"] and r["incumbent_de00"] is not None:
        scores = (
            f" (ΔE00 mean {r['held_out_de00']:.3f} against the current one's "
            f"{r['incumbent_de00']:.3f} on {r['cases_judged']} cases neither learned from)"
        )
    return f"registered {r['name']} v{r['version']}: {verdict}{scores}"


def _kept_epoch_text(summary: dict) -> str:
    """Which of an adaptation's epochs it kept, and on how many of the shop's cases that was
    chosen (every epoch run where none were held out); epoch 0 is the model as it was."""
    kept, epochs, judged = summary["kept_epochs"], summary["epochs"], summary["validation_cases"]
    if not judged:
        return f"kept epoch {kept} of {epochs}"
    if kept == 0:
        return (
            f"kept the model as it was: none of its {counted(epochs, 'epoch')} did better on the "
            f"{counted(judged, 'case')} held out to choose"
        )
    return f"kept epoch {kept} of {epochs} (chosen on {counted(judged, 'case')})"


def _write_model(model, out: Path) -> None:
    """A model file at ``out``, written whole or not at all."""
    from flakelab.io.records import write_atomically  # the file formats: not at start-up

    write_atomically(out, lambda p: p.write_bytes(model.to_bytes()))
