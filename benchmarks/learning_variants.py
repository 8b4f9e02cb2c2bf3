"""Learned model: what buys held-out accuracy — cases, width, depth, epochs, batch.

One variant per call: a single fit (training + fine-tuning, no fold screening) on N
generated cases of the demo library without its two new toners (as the shipped model), then
ΔE00 on the 500 unseen cases of ``flakelab cases generate --n 500 --seed 987`` through the
matcher's forward (hybrid for the new toners), against the measured spray-outs and against
the nominal physics of the recipes (the model's own error, without the cases' noise).

    python benchmarks/learning_variants.py [--cases 20000] [--hidden 100,100,100]
        [--epochs 150] [--batch-size 128] [--learning-rate 2e-3]
        [--kinds metallic=0.6,pearl=0.25,solid=0.15] [--log-offset 0.01] [--json]

``--kinds`` sets the share of each paint family in the training cases (the evaluation
cases keep the generator's default mix), as ``scripts/train_shipped_models.py`` does.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from _matcher import parse_kinds
from flakelab.cases.generator import World, WorldSettings
from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E
from flakelab.io import read_library
from flakelab.library import PAINT_FAMILIES
from flakelab.match.judging import evaluate_recipes
from flakelab.match.models import forward_for
from flakelab.models.training import (
    TrainingConfig,
    _new_model,
    _Stages,
    generated_case_arrays,
)

NOVEL_TONERS = ("Perylene red", "Isoindoline yellow")
EVALUATION = (500, 987)
"""Cases and seed of issue 4's unseen evaluation set (docs/figures.md)."""


def train_once(library, cases: int, config: TrainingConfig, kinds: dict[str, float] | None = None):
    settings = WorldSettings(kinds=kinds) if kinds else WorldSettings()
    world = World(library, "five-angle", settings, exclude=NOVEL_TONERS)
    data = generated_case_arrays(world, cases, config.seed)
    rows = [np.arange(data.x.shape[0])]
    model = _new_model(data, config, rows[0])
    _Stages(None, None).train([model], data, rows, config, ["fit"])
    model.info["toner_cases"] = dict(zip(data.toners, (data.x > 0).sum(0).tolist(), strict=True))
    return model


def judge(library, model) -> dict[str, float]:
    world = World(library, model.instrument)
    n, seed = EVALUATION
    data = generated_case_arrays(world, n, seed)
    predicted, _ = evaluate_recipes(forward_for(model, library), data.x)
    nominal, _ = world.appearance(data.x, world.nominal(n))
    lab = reflectance_to_Lab(predicted)
    sprayout = delta_E(reflectance_to_Lab(data.R), lab)
    own = delta_E(reflectance_to_Lab(nominal), lab)
    family = library.paint_families(data.x)
    return {
        "de00_mean": float(sprayout.mean()),
        "de00_p95": float(np.percentile(sprayout, 95)),
        "model_vs_nominal_de00_mean": float(own.mean()),
        "model_vs_nominal_de00_p95": float(np.percentile(own, 95)),
        **{f"model_vs_nominal_{f}": float(own[family == f].mean()) for f in PAINT_FAMILIES},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=20_000)
    parser.add_argument("--hidden", default="100,100,100")
    parser.add_argument("--epochs", type=int, default=150, help="per stage (and fine-tuning)")
    parser.add_argument("--batch-size", type=int, default=128)
    parser.add_argument("--learning-rate", type=float, default=2e-3, help="fine-tuning: a tenth")
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--kinds", help="paint families' shares, e.g. metallic=0.6,pearl=0.25")
    parser.add_argument("--log-offset", type=float, default=0.0, help="log features (0: none)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    kinds = parse_kinds(args.kinds) if args.kinds else None
    config = TrainingConfig.per_stage(
        args.epochs,
        args.learning_rate,
        hidden=tuple(int(h) for h in args.hidden.split(",")),
        batch_size=args.batch_size,
        log_offset=args.log_offset,
        seed=args.seed,
    )
    library = read_library(None)
    start = time.perf_counter()
    model = train_once(library, args.cases, config, kinds)
    result = {
        **{k: v for k, v in vars(args).items() if k != "json"},
        "train_seconds": time.perf_counter() - start,
        **judge(library, model),
    }
    if args.json:
        print(json.dumps(result, indent=1))
    else:
        for key, value in result.items():
            print(f"{key:28s} {value:,.6g}" if isinstance(value, float) else f"{key:28s} {value}")


if __name__ == "__main__":
    main()
