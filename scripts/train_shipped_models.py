"""Regenerate the shipped learned models (src/flakelab/data/models/demo-*.pt).

Each is trained with the full protocol (five partitions, outlier screening, final training)
on synthetic cases of the demo library generated with a fixed seed. Two demo toners are
kept out of the training cases on purpose — they are the library's "new" toners, which the
matcher handles with the physics scaling (hybrid path).

    python scripts/train_shipped_models.py [--instrument five-angle] [--tins none|calibrated|known]

``--seed`` draws the cases and the network alike; ``--network-seed`` draws the network (its
weights, splits and batches) alone, on the same cases, and ``--screening`` changes the outlier
screen: how much a model owes to its network's draw (docs/cases-and-model.md);
``--members 1`` trains one network instead of the ensemble; ``--log-offset`` adds log
features (``flakelab train --log-offset``); ``--tins calibrated|known`` makes the training cases
record their tins and learns them at the standard tins, as ``flakelab train`` learns such
cases (:func:`~flakelab.match.lots.at_standard_tins`; default ``none``, the shipped files').
``--white-pearls SHARE`` sets the share of the training pearls that are white pearls (beside
the library's white; default the world's, three in ten, as the shipped files learned).
``--checkpoints DIR`` keeps each training after every stage: run again after an
interruption, it goes on from there to the same file (``flakelab train --checkpoint``).

Both models are ensembles of four networks, trained on more cases than the hybrid paper's
database (61,000): held-out accuracy grows with the cases far more than with the network's
width or the epochs, and pearls most (docs/cases-and-model.md). Both learned
from 150,000 cases, a third of them pearls: the five-angle model at stop 109 (25:25 here
with its cases, 3.6 GB peak), the MA-T12 model, whose 12 geometries make each case
costlier, at stop 110 (35:17 for the eight stages after the two its checkpoint kept, about
38 min whole; 6.8 GB peak).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from flakelab.cases.generator import World, WorldSettings
from flakelab.cli.common import exit_interrupted, progress_bar, stop_on_signals
from flakelab.io import read_library
from flakelab.io.records import write_atomically
from flakelab.library.lots import TIN_KNOWLEDGE
from flakelab.match.lots import at_standard_tins
from flakelab.models.checkpoint import TrainingCheckpoint
from flakelab.models.network import LOG_OFFSET_MAX
from flakelab.models.registry import shipped_model_path
from flakelab.models.training import (
    SCREENINGS,
    TrainingConfig,
    case_arrays,
    data_hash,
    protocol_epochs,
    train_protocol,
)

NOVEL_TONERS = ("Perylene red", "Isoindoline yellow")
"""Demo toners absent from the shipped models' training cases."""
SETTINGS = {
    "five-angle": (150_000, 150, 256, 4, "sequential"),
    "ma-t12": (150_000, 150, 256, 4, "sequential"),
}
"""For each shipped instrument: cases, epochs per stage, batch size (CPU time on a 2-core
machine; the learning rate scales with the batch, 2e-3 at 128), networks averaged as an
ensemble and the outlier screen it was trained with (kept, so that this script regenerates
the shipped files). The five-angle ensemble of four errs a fifth less than its members
alone (docs/cases-and-model.md)."""
TRAINING_KINDS = {
    instrument: {"metallic": 0.52, "pearl": 0.33, "solid": 0.15} for instrument in SETTINGS
}
"""Share of each paint family in an instrument's training cases (else the generator's
default mix, which the evaluation cases keep): pearls, whose interference colour changes
with angle, are the model's hardest family and get more cases: a third of each model's,
with 30,000 more cases (stops 109 and 110; the pearls' own error 0.45 → 0.39 ΔE00 median
at the five-angle, 0.53 → 0.46 at the MA-T12, and every family's lower:
``benchmarks/model_families.py``)."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--instrument", choices=sorted(SETTINGS), action="append")
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--network-seed", type=int, help="network's seed (default: --seed)")
    parser.add_argument("--screening", choices=SCREENINGS, help="default: the shipped model's")
    parser.add_argument("--out", type=Path, help="folder for the model files (default: shipped)")
    parser.add_argument(
        "--cases", type=int, help="number of training cases (default: the shipped model's)"
    )
    parser.add_argument(
        "--members", type=int, help="networks averaged as an ensemble (default: the shipped's)"
    )
    parser.add_argument(
        "--log-offset", type=float, default=0.0, help="log features, log(fraction + this)"
    )
    parser.add_argument(
        "--tins", choices=TIN_KNOWLEDGE, default="none", help="what the cases record of their tins"
    )
    parser.add_argument(
        "--white-pearls",
        type=float,
        default=WorldSettings.white_pearl_share,
        help="share of the training pearls that are white pearls, beside the library's white "
        "(default WorldSettings.white_pearl_share, the shipped files')",
    )
    parser.add_argument(
        "--checkpoints",
        type=Path,
        help="folder keeping each instrument's training after every stage (INSTRUMENT.ckpt): "
        "run again after an interruption, a training goes on from its last kept stage",
    )
    args = parser.parse_args()
    if not 0 <= args.log_offset <= LOG_OFFSET_MAX:
        parser.error(f"--log-offset: {args.log_offset} is not in [0, {LOG_OFFSET_MAX}]")
    if args.members is not None and args.members < 1:
        parser.error(f"--members: {args.members} is not a positive number of networks")
    if args.cases is not None and args.cases < 1:
        parser.error(f"--cases: {args.cases} is not a positive number of cases")
    library = read_library(None)
    stop_on_signals()
    written: list[Path] = []
    try:
        for instrument in args.instrument or sorted(SETTINGS):
            written.append(_train_shipped(instrument, args, library, parser))
    except KeyboardInterrupt as stopped:  # a traceback before
        exit_interrupted(_left(written, args.checkpoints), stopped)


def _left(written: list[Path], checkpoints: Path | None) -> str:
    """What an interrupted run leaves: the files it wrote whole, a training's kept stages."""
    kept = f"; wrote {', '.join(map(str, written))}" if written else "; no model file written"
    goes_on = (f"; run again with --checkpoints {checkpoints} to go on from the last kept stage"
               if checkpoints else "; --checkpoints DIR keeps a training's stages")  # fmt: skip
    return f"stopped before it finished{kept}{goes_on}"


def _train_shipped(instrument: str, args: argparse.Namespace, library, parser) -> Path:
    """Generate one instrument's cases, train its model with the full protocol and write
    it (whole or not at all); the file's path."""
    effect = [t.kind != "pigment" for t in library.toners]
    n, epochs, batch_size, members, screening = SETTINGS[instrument]
    n = args.cases if args.cases is not None else n
    kinds = TRAINING_KINDS.get(instrument)
    try:
        settings = WorldSettings(
            tins=args.tins,
            white_pearl_share=args.white_pearls,
            **({"kinds": kinds} if kinds else {}),
        )
    except ValueError as error:  # before any training
        parser.error(f"--white-pearls: {error}")
    world = World(library, instrument, settings, exclude=NOVEL_TONERS)
    rate = TrainingConfig.learning_rate * batch_size / TrainingConfig.batch_size
    config = TrainingConfig.per_stage(
        epochs,
        rate,
        batch_size=batch_size,
        seed=args.seed if args.network_seed is None else args.network_seed,
        screening=args.screening or screening,
        members=args.members or members,
        log_offset=args.log_offset,
    )
    with progress_bar() as progress:
        task = progress.add_task(f"{instrument}: generating cases", total=n)
        cases = []
        for batch in world.cases(n, args.seed):
            cases.extend(batch)
            progress.advance(task, len(batch))
        data = at_standard_tins(case_arrays(cases, library.names, effect), library)
        epochs_total = protocol_epochs(config)
        task = progress.add_task(f"{instrument}: training epochs", total=epochs_total)
        checkpoint = args.checkpoints and TrainingCheckpoint(
            args.checkpoints / f"{instrument}.ckpt", config, data_hash(data)
        )
        model, report = train_protocol(
            data,
            config,
            progress=lambda k, task=task: progress.advance(task, k),
            checkpoint=checkpoint,
        )
    model.learned = None  # generated cases, which no shop holds: kept out of the file
    model.info.update(
        {
            "name": f"demo-{instrument}",
            "novel_toners": list(NOVEL_TONERS),
            "generator_seed": args.seed,
            "network_seed": config.seed,
            "cases": n,
            "training_kinds": settings.kinds,
            **({"training_tins": args.tins} if args.tins != "none" else {}),
            **({"white_pearl_share": args.white_pearls} if args.white_pearls else {}),
        }
    )
    path = shipped_model_path(instrument)
    path = args.out / path.name if args.out else path
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomically(path, lambda temporary: temporary.write_bytes(model.to_bytes()))
    if checkpoint:
        checkpoint.remove()
    summary = {k: v for k, v in report.items() if k not in ("log", "outlier_case_ids")}
    print(json.dumps({"instrument": instrument, "file": str(path), **summary}))
    return path


if __name__ == "__main__":
    main()
