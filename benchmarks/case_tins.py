"""A model judged on cases that record their tins: what a shop that reads its tins gains.

A generated case's spray-out is mixed from the shop's batches, each tin a few per cent off
the standard in strength and a nanometre or so in shade (``WorldSettings``). A shop that
records nothing of them asks the model to predict every case as poured from the standard,
and the batches' spread stays in the error (issue 4's cases: ΔE00 mean 0.627 against a noise
floor of 0.587). A case that records its tins (``cases generate --tins``, ``cases record
--lots``) is predicted for them, as ``match --lots`` weighs for them
(:func:`~flakelab.match.lots.poured_from`). This prints, on the issue's cases (``flakelab
cases generate --n 500 --seed 987``, the shipped model of each instrument, cases it never
saw), for what the cases record of their tins:

* ``none``: nothing (the issue's figure);
* ``calibrated``: each tin read from one panel against the model, to the error that reading has
  in the harness (1.11 % in strength, 0.75 nm in shade: docs/matching.md, *The shop's tins*);
* ``referenced``: against the paint maker's panel (0.59 %, 0.29 nm);
* ``known``: the world's own batches (the limit a reading approaches);

the model's ΔE00 mean, p95 and max over cases × geometries and its mean per paint family,
and the floor: the library's physics at the nominal application, poured from the same tins,
against the spray-outs (what an exact model of the world would score, the spray's
application and the instrument's noise left). The cases are the same in every row; only what
they record differs.

With ``--train N``, it also trains two models on N generated cases that record their tins
as read against the model (seed ``--train-seed``, the protocol at ``--epochs`` per stage):
one learning the cases as if poured from the standard tins, as a shop that records none
(``train --no-tins``), one learning them at the standard tins (``train``:
:func:`~flakelab.match.lots.at_standard_tins`); both are judged on the issue's cases, as
poured from their recorded tins and from the standard.

    python benchmarks/case_tins.py [--instrument five-angle|ma-t12|both] [--cases 500]
        [--seed 987] [--train N --epochs E --train-seed S] [--json]
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from flakelab.cases.generator import World, WorldSettings
from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E
from flakelab.io import read_library
from flakelab.match.forward import PhysicsForward
from flakelab.match.judging import evaluate_recipes
from flakelab.match.lots import at_standard_tins, poured_from
from flakelab.match.models import forward_for
from flakelab.models.registry import shipped_model
from flakelab.models.training import TrainingConfig, generated_case_arrays, train_protocol

RECORDED = {
    "none": WorldSettings(),
    "calibrated": WorldSettings(tins="calibrated"),
    "referenced": WorldSettings(tins="referenced"),
    "known": WorldSettings(tins="known"),
}
"""What the cases record of their tins, row by row (the harness's readings: docs/matching.md)."""


def tins_report(instrument: str, cases: int, seed: int) -> dict:
    library = read_library(None)
    matcher = forward_for(shipped_model(instrument), library)
    physics = PhysicsForward(library, matcher.geometries)
    rows = {}
    for name, settings in RECORDED.items():
        data = generated_case_arrays(World(library, instrument, settings), cases, seed)
        measured = reflectance_to_Lab(data.R)
        model, floor = (
            delta_E(measured, reflectance_to_Lab(_poured(forward, library, data)))
            for forward in (matcher, physics)
        )
        families = library.paint_families(data.x)
        rows[name] = {
            "cases_with_tins": int(data.tins_recorded.sum()),
            "de00_mean": round(float(model.mean()), 3),
            "de00_p95": round(float(np.percentile(model, 95)), 3),
            "de00_max": round(float(model.max()), 3),
            "de00_mean_by_family": {
                f: round(float(model[families == f].mean()), 3) for f in np.unique(families)
            },
            "floor_de00_mean": round(float(floor.mean()), 3),
            "floor_de00_p95": round(float(np.percentile(floor, 95)), 3),
        }
    return {
        "instrument": instrument,
        "cases": cases,
        "seed": seed,
        "model": matcher.model_id,
        "recorded": rows,
    }


def learning_report(instrument: str, cases: int, seed: int, train: int, epochs: int,
                    train_seed: int) -> dict:  # fmt: skip
    """Two models trained on ``train`` cases recording their tins (calibrated), learning them as
    poured from the standard or at the standard tins, judged on the issue's cases."""
    library = read_library(None)
    world = World(library, instrument, RECORDED["calibrated"])
    data = generated_case_arrays(world, train, train_seed)
    judged = generated_case_arrays(world, cases, seed)
    measured = reflectance_to_Lab(judged.R)
    config = TrainingConfig.per_stage(epochs, 2e-3, seed=train_seed)
    rows = {}
    for name, learned in (
        ("as_poured_from_the_standard", data.without_tins()),
        ("at_the_standard_tins", at_standard_tins(data, library)),
    ):
        model, report = train_protocol(learned, config)
        matcher = forward_for(model, library)
        rows[name] = {"train_seconds": round(report["seconds"], 1)}
        for poured, arrays in (("poured", judged), ("standard", judged.without_tins())):
            de = delta_E(measured, reflectance_to_Lab(_poured(matcher, library, arrays)))
            rows[name][f"{poured}_de00_mean"] = round(float(de.mean()), 3)
            rows[name][f"{poured}_de00_p95"] = round(float(np.percentile(de, 95)), 3)
    return {"train_cases": train, "epochs": epochs, "train_seed": train_seed, "models": rows}


def _poured(forward, library, data) -> np.ndarray:
    """Reflectance ``[N, G, 31]`` of the cases' recipes poured from the tins they record."""
    return evaluate_recipes(poured_from(forward, library, data.strength, data.shade), data.x)[0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--instrument", default="both", choices=("five-angle", "ma-t12", "both"))
    parser.add_argument("--cases", type=int, default=500)
    parser.add_argument("--seed", type=int, default=987)
    parser.add_argument("--train", type=int, default=0, help="cases to train two models on")
    parser.add_argument("--epochs", type=int, default=150, help="per stage, with --train")
    parser.add_argument("--train-seed", type=int, default=0)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    instruments = ("five-angle", "ma-t12") if args.instrument == "both" else (args.instrument,)
    reports = [tins_report(i, args.cases, args.seed) for i in instruments]
    if args.train:
        for report in reports:
            report["learning"] = learning_report(
                report["instrument"], args.cases, args.seed, args.train, args.epochs,
                args.train_seed,
            )  # fmt: skip
    if args.json:
        print(json.dumps(reports, indent=2))
        return
    for report in reports:
        print(f"{report['model']}, {report['cases']} cases of seed {report['seed']}:")
        print(f"  {'tins recorded':<24}{'mean':>7}{'p95':>7}{'max':>7}{'floor':>7}{'p95':>7}")
        for name, row in report["recorded"].items():
            print(
                f"  {name:<24}{row['de00_mean']:>7.3f}{row['de00_p95']:>7.3f}"
                f"{row['de00_max']:>7.2f}{row['floor_de00_mean']:>7.3f}{row['floor_de00_p95']:>7.3f}"
                f"   {row['de00_mean_by_family']}"
            )
        if "learning" in report:
            learning = report["learning"]
            print(
                f"  models trained on {learning['train_cases']} cases recording their tins "
                f"(calibrated; {learning['epochs']} epochs a stage, seed {learning['train_seed']}):"
            )
            for name, row in learning["models"].items():
                print(f"    learned {name.replace('_', ' ')}: {row}")


if __name__ == "__main__":
    main()
