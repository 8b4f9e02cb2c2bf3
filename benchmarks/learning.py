"""Learned model: the full training protocol at the paper's database size, and inference.

Generates N synthetic cases (default 61,000, the size of the paper's real database), runs
the whole protocol (five partitions, the outlier screen, final training, each session
300 + 300 epochs), and reports wall time, peak memory (max RSS) and batched inference
throughput, with held-out ΔE00 on 500 fresh cases. Baselines in the same run, per screening
epoch: the cross-validation screen (five fold models side by side, each on four partitions)
against the paper's sequential screen (one model on one partition per session, four
sessions), and the fold models side by side against one at a time. With ``--device`` (a
GPU), the protocol trains there, and an epoch of the final training there is timed against
the same epoch on this machine's CPU.

    python benchmarks/learning.py [--cases 61000] [--epochs 300] [--batch-size 1024]
        [--learning-rate 4e-3] [--screening sequential|cross-validation] [--members 1]
        [--device cpu|cuda|auto] [--json]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
import torch

from flakelab.cases.generator import World
from flakelab.io import read_library
from flakelab.models.network import reflectance_from_log
from flakelab.models.training import (
    SCREENINGS,
    TrainingConfig,
    evaluate_model,
    generated_case_arrays,
    train_protocol,
    training_device,
)
from timing import best_time, peak_rss_mb


def inference_rates(model, n: int = 200_000) -> dict[str, float]:
    """Formulations per second through ``model.predict`` (batched, the folded network), best
    of three, against the baseline of the same run: the network layer by layer as trained
    (standardise, each member, de-standardise, average) in batches of 16,384, as ``predict``
    ran until the folded network."""
    x = np.random.default_rng(0).dirichlet(np.ones(len(model.toners)) * 0.2, n)
    model.predict(x[:1000])
    folded = n / best_time(model.predict, x)
    layer_by_layer = n / best_time(layer_by_layer_predict, model, x)
    return {
        "inference_formulations_per_s": folded,
        "inference_layer_by_layer_formulations_per_s": layer_by_layer,
        "inference_speedup": folded / layer_by_layer,
    }


def layer_by_layer_predict(
    model, x: np.ndarray, batch: int = 16384
) -> tuple[np.ndarray, np.ndarray]:
    """Reflectance and texture as ``predict`` computed them before the folded network."""
    x = torch.from_numpy(x.astype(np.float32))
    spectral = model.spectral_outputs
    with torch.no_grad():
        y = [model.member_outputs(x[s : s + batch]).mean(dim=0) for s in range(0, len(x), batch)]
        y = torch.cat(y)
    return reflectance_from_log(y[:, :spectral]).double().numpy(), y[:, spectral:].double().numpy()


def screening_rates(data, config: TrainingConfig, epochs: int = 2) -> dict[str, float]:
    """Seconds per epoch of the cross-validation screen's five fold models side by side (one
    batched network, as the protocol trains them) and one at a time, and of one session of
    the sequential screen (one model, one partition): the baselines of the same run."""
    from flakelab.models.training import _new_model, fit, fold_rows

    partitions, rows = fold_rows(data.x.shape[0], config)
    models = [_new_model(data, config, r) for r in rows]
    names = [f"fold {k}" for k in range(config.folds)]
    rate = config.learning_rate
    runs = (
        lambda n: fit(models, data, rows, n, rate, config, [], names),
        lambda n: [
            fit([m], data, [r], n, rate, config, [], [k])
            for m, r, k in zip(models, rows, names, strict=True)
        ],
        lambda n: fit(models[:1], data, partitions[:1], n, rate, config, [], ["s"]),
    )
    for run in runs:
        run(1)  # first calls pay one-off costs: on a GPU, the step compiled for each batch shape

    def seconds(run) -> float:
        start = time.perf_counter()
        run(epochs)
        return (time.perf_counter() - start) / epochs

    together, alone, session = (seconds(run) for run in runs)
    sessions = config.folds - 1
    return {
        "fold_epoch_seconds_side_by_side": together,
        "fold_epoch_seconds_one_at_a_time": alone,
        "fold_stage_speedup": alone / together,
        "sequential_session_epoch_seconds": session,
        "screen_cross_validation_vs_sequential": together / (sessions * session),
    }


def device_rates(data, config: TrainingConfig, epochs: int = 3) -> dict[str, float]:
    """Seconds per epoch of the final training (``config.members`` networks side by side on
    every case) on the CPU and on ``config.device``, the baseline of the same run, and each
    fit's setup (standardising the cases, their CIELAB, moving them): a run of one epoch is
    timed against one of ``1 + epochs``, after a first run that compiles the step."""
    from dataclasses import replace

    from flakelab.models.training import _new_model, fit

    rows = [np.arange(data.x.shape[0])] * config.members
    names = [f"final {k}" for k in range(config.members)]

    def seconds(device: str, n: int) -> float:
        on = replace(config, device=device)
        models = [_new_model(data, on, r) for r in rows]
        start = time.perf_counter()
        fit(models, data, rows, n, config.learning_rate, on, [], names)
        return time.perf_counter() - start

    result = {}
    for side, device in (("cpu", "cpu"), ("device", config.device)):
        first = seconds(device, 1)
        one, more = seconds(device, 1), seconds(device, 1 + epochs)
        per_epoch = (more - one) / epochs
        result |= {
            f"final_epoch_seconds_{side}": per_epoch,
            f"final_fit_setup_seconds_{side}": one - per_epoch,
            f"final_first_fit_seconds_{side}": first,
        }
    return result | {
        "device_speedup": result["final_epoch_seconds_cpu"] / result["final_epoch_seconds_device"]
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=61_000)
    parser.add_argument("--epochs", type=int, default=300)
    parser.add_argument("--batch-size", type=int, default=1024)
    parser.add_argument(
        "--learning-rate", type=float, default=4e-3, help="fine-tuning uses a tenth of it"
    )
    parser.add_argument("--screening", choices=SCREENINGS, default=TrainingConfig.screening)
    parser.add_argument("--instrument", default="five-angle")
    parser.add_argument(
        "--members", type=int, default=1, help="networks of the final training (an ensemble)"
    )
    parser.add_argument("--device", default="cpu", help="cpu, cuda, cuda:N, mps or auto")
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
        result = {"instrument": args.instrument, **inference_rates(model)}
        print(json.dumps(result, indent=1) if args.json else result)
        return

    library = read_library(None)
    world = World(library, args.instrument)
    start = time.perf_counter()
    data = generated_case_arrays(world, args.cases, args.seed)
    generate_s = time.perf_counter() - start
    config = TrainingConfig.per_stage(
        args.epochs,
        args.learning_rate,
        batch_size=args.batch_size,
        seed=args.seed,
        screening=args.screening,
        members=args.members,
        device=str(training_device(args.device)),
    )
    rates = screening_rates(data, config)
    if config.device != "cpu":
        rates |= device_rates(data, config)
    start = time.perf_counter()
    model, report = train_protocol(data, config)
    train_s = time.perf_counter() - start
    held = generated_case_arrays(world, 500, args.seed + 1)
    metrics = evaluate_model(model, held)
    result = {
        "cases": args.cases,
        "epochs_per_stage": args.epochs,
        "batch_size": args.batch_size,
        "learning_rate": args.learning_rate,
        "screening": config.screening,
        "members": config.members,
        "device": config.device,
        "device_name": torch.cuda.get_device_name() if config.device.startswith("cuda") else "",
        "torch": torch.__version__,
        "colour_weight": config.colour_weight,
        "generate_seconds": generate_s,
        "protocol_seconds": train_s,
        "protocol_minutes": train_s / 60,
        "peak_rss_mb": peak_rss_mb(),
        "outliers_dropped": report["outliers"],
        **rates,
        **inference_rates(model),
        "held_out_de00_mean": metrics["de00_mean"],
        "held_out_de00_p95": metrics["de00_p95"],
    }
    if args.json:
        print(json.dumps(result, indent=1))
    else:
        for key, value in result.items():
            print(f"{key:38s} {value:,.6g}" if not isinstance(value, str) else f"{key:38s} {value}")


if __name__ == "__main__":
    main()
