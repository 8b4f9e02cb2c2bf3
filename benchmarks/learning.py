"""Learned model: the full training protocol at the paper's database size, and inference.

Generates N synthetic cases (default 61,000, the size of the paper's real database), runs
the whole protocol (five partitions × (300 + 300) epochs, outlier screening, final
training), and reports wall time, peak memory (max RSS) and batched inference throughput,
with held-out ΔE00 on 500 fresh cases. Baseline in the same run: a fold-stage epoch with the
five fold models side by side (as the protocol trains them) against one at a time.

    python benchmarks/learning.py [--cases 61000] [--epochs 300] [--batch-size 1024]
        [--learning-rate 4e-3] [--json]
"""

from __future__ import annotations

import argparse
import json
import resource
import time

import numpy as np

from flakelab.cases.generator import World
from flakelab.io import read_library
from flakelab.models.training import TrainingConfig, case_arrays, evaluate_model, train_protocol
from timing import best_time


def inference_rate(model, toners: int, n: int = 200_000) -> float:
    """Formulations per second through ``model.predict`` (batched), best of three."""
    x = np.random.default_rng(0).dirichlet(np.ones(toners) * 0.2, n)
    model.predict(x[:1000])
    return n / best_time(model.predict, x)


def fold_stage_rates(data, config: TrainingConfig, epochs: int = 2) -> dict[str, float]:
    """Seconds per epoch of the five fold models trained side by side (one batched network,
    as the protocol does) against one at a time: the baseline measured in the same run."""
    from flakelab.models.training import _new_model, fit, fold_rows

    _, rows = fold_rows(data.x.shape[0], config)
    models = [_new_model(data, config, r) for r in rows]
    names = [f"fold {k}" for k in range(config.folds)]
    warm = [r[:4096] for r in rows]  # first calls pay one-off costs
    fit(models, data, warm, 1, config.learning_rate, config, [], names)
    fit(models[:1], data, warm[:1], 1, config.learning_rate, config, [], names[:1])
    start = time.perf_counter()
    fit(models, data, rows, epochs, config.learning_rate, config, [], names)
    together = (time.perf_counter() - start) / epochs
    start = time.perf_counter()
    for model, r, name in zip(models, rows, names, strict=True):
        fit([model], data, [r], epochs, config.learning_rate, config, [], [name])
    alone = (time.perf_counter() - start) / epochs
    return {
        "fold_epoch_seconds_side_by_side": together,
        "fold_epoch_seconds_one_at_a_time": alone,
        "fold_stage_speedup": alone / together,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=61_000)
    parser.add_argument("--epochs", type=int, default=300)
    parser.add_argument("--batch-size", type=int, default=1024)
    parser.add_argument(
        "--learning-rate", type=float, default=4e-3, help="fine-tuning uses a tenth of it"
    )
    parser.add_argument("--instrument", default="five-angle")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--inference-only",
        action="store_true",
        help="only the inference rate, with the shipped model",
    )
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    if args.inference_only:
        from flakelab.models.registry import shipped_model

        model = shipped_model(args.instrument)
        result = {"inference_formulations_per_s": inference_rate(model, len(model.toners))}
        print(json.dumps(result, indent=1) if args.json else result)
        return

    library = read_library(None)
    effect = [t.kind != "pigment" for t in library.toners]
    world = World(library, args.instrument)
    start = time.perf_counter()
    cases = [c for batch in world.cases(args.cases, args.seed) for c in batch]
    generate_s = time.perf_counter() - start
    data = case_arrays(cases, library.names, effect)
    config = TrainingConfig.per_stage(
        args.epochs, args.learning_rate, batch_size=args.batch_size, seed=args.seed
    )
    rates = fold_stage_rates(data, config)
    start = time.perf_counter()
    model, report = train_protocol(data, config)
    train_s = time.perf_counter() - start
    held = case_arrays(
        [c for b in world.cases(500, args.seed + 1) for c in b], library.names, effect
    )
    metrics = evaluate_model(model, held)
    result = {
        "cases": args.cases,
        "epochs_per_stage": args.epochs,
        "batch_size": args.batch_size,
        "learning_rate": args.learning_rate,
        "colour_weight": config.colour_weight,
        "generate_seconds": generate_s,
        "protocol_seconds": train_s,
        "protocol_minutes": train_s / 60,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "outliers_dropped": report["outliers"],
        **rates,
        "inference_formulations_per_s": inference_rate(model, len(library.names)),
        "held_out_de00_mean": metrics["de00_mean"],
        "held_out_de00_p95": metrics["de00_p95"],
    }
    if args.json:
        print(json.dumps(result, indent=1))
    else:
        for key, value in result.items():
            print(f"{key:32s} {value:,.6g}")


if __name__ == "__main__":
    main()
