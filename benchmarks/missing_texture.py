"""Cases without texture readings: what they cost the learned model's texture and colour.

A shop whose instrument reads no sparkle or graininess (or whose case history kept none)
brings cases with spectra alone. Training leaves their texture out of the loss and out of
the outputs' standardisation. This benchmark trains the same model three ways on the same
generated cases and judges each on the same held-out cases, which all read texture:

* ``all read``: every case carries its texture (the baseline);
* ``unread left out``: a share of the cases lacks texture and adds no texture error (today);
* ``unread as zeros``: the same cases with their texture taken as 0, as training read them
  before (``case_arrays`` filled a missing reading with 0.0).

    python benchmarks/missing_texture.py [--cases 2000] [--unread 0.5] [--seed 5] [--json]
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace

import numpy as np

from flakelab.cases.generator import World
from flakelab.core.measurement import TEXTURE_READINGS
from flakelab.io import read_library
from flakelab.models.training import (
    TrainingConfig,
    evaluate_model,
    generated_case_arrays,
    train_protocol,
)


def variants(data, unread: float, seed: int) -> dict:
    """The three case sets: texture as read, a share unread (NaN), the same share as zeros."""
    rows = np.random.default_rng(seed).random(data.x.shape[0]) < unread
    missing, zeros = data.texture.copy(), data.texture.copy()
    missing[rows], zeros[rows] = np.nan, 0.0
    return {
        "all read": data,
        "unread left out": replace(data, texture=missing),
        "unread as zeros": replace(data, texture=zeros),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=2000, help="training cases")
    parser.add_argument("--held-out", type=int, default=500, help="held-out cases")
    parser.add_argument("--unread", type=float, default=0.5, help="share without texture")
    parser.add_argument("--epochs", type=int, default=100, help="epochs per session")
    parser.add_argument("--seed", type=int, default=5)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()

    world = World(read_library(None), "five-angle")
    data = generated_case_arrays(world, args.cases, seed=args.seed)
    held = generated_case_arrays(world, args.held_out, seed=args.seed + 1000)
    config = TrainingConfig(
        hidden=(100, 100, 100), epochs=args.epochs, finetune_epochs=args.epochs // 3,
        batch_size=64, seed=args.seed,
    )  # fmt: skip
    spread = held.texture.std(0)
    report = {"cases": args.cases, "held_out": args.held_out, "unread": args.unread}
    for name, cases in variants(data, args.unread, args.seed).items():
        start = time.perf_counter()
        model, _ = train_protocol(cases, config)
        figures = evaluate_model(model, held)
        mae = np.array([figures["texture_mae"][k] for k in TEXTURE_READINGS])
        report[name] = {
            "texture_mae": figures["texture_mae"],
            "texture_mae_over_spread": float(np.mean(mae / spread)),
            "de00_mean": figures["de00_mean"],
            "seconds": time.perf_counter() - start,
        }
    base = report["all read"]
    for name in ("unread left out", "unread as zeros"):
        for key in ("texture_mae_over_spread", "de00_mean"):
            report[name][f"{key}_ratio"] = report[name][key] / base[key]
    if args.json:
        print(json.dumps(report, indent=2))
        return
    print(f"{args.cases} cases, {args.unread:.0%} without texture; {args.held_out} held out")
    print(f"{'':18}{'texture MAE / s.d.':>20}{'ratio':>8}{'ΔE00 mean':>11}{'ratio':>8}")
    for name in ("all read", "unread left out", "unread as zeros"):
        row = report[name]
        print(
            f"{name:18}{row['texture_mae_over_spread']:20.3f}"
            f"{row.get('texture_mae_over_spread_ratio', 1.0):8.2f}"
            f"{row['de00_mean']:11.3f}{row.get('de00_mean_ratio', 1.0):8.2f}"
        )


if __name__ == "__main__":
    main()
