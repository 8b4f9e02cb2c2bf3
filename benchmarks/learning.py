"""Learned model: the full training protocol at the paper's database size, and inference.

Generates N synthetic cases (default 61,000, the size of the paper's real database), runs
the whole protocol (five partitions × (300 + 300) epochs, outlier screening, final
training), and reports wall time, peak memory (max RSS) and batched inference throughput,
with held-out ΔE00 on 500 fresh cases.

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
    config = TrainingConfig(
        epochs=args.epochs,
        finetune_epochs=args.epochs,
        batch_size=args.batch_size,
        learning_rate=args.learning_rate,
        finetune_learning_rate=args.learning_rate / 10,
        seed=args.seed,
    )
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
