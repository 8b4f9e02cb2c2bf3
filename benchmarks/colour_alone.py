"""A car known by its L*a*b* alone: what the spectra recovered from it cost and keep.

Reads the instrument's own L*a*b* of the 230 real MA-T12 samples (2,760 readings,
``../shared/data/ma-t12/all_samples_instrument_lab_d65_10.csv``) as a file of colour alone,
each reading's spectrum recovered from its colour
(:func:`~flakelab.core.colorimetry.reflectance_from_Lab`), and the same samples' measured
spectra (``all_samples_spectra.csv``). It prints:

* the time to read the colour file (the recovery within it), best of three, and readings/s;
* the largest ΔE00 between a recovered and a measured reading in D65/10, where the file's
  colour was stated: the recovery's error added to the instrument's own rounding;
* per other light (A, F11, LED-B3, D50/2°) the median, 95th percentile and largest ΔE00
  between the recovered and the measured reading: how far a colour under another light
  read from recovered spectra is an estimate (the metamerism that colour alone hides).

With ``--paint-basis N`` it also learns Otsu's basis afresh (colour-science's
``Tree_Otsu2018``) from N spectra of the demo library's paints, generated in the cases'
world (``--seed``), and prints the same figures per light for the real readings recovered
with it (``paint_*``), and, for 200 held-out generated formulations' readings, the median
ΔE00 under A with either basis (``generated_*``): whether a basis of paints would recover a
car's spectrum closer than one of surfaces in general.

With ``--shop N`` it also keeps a shop's history of N generated cases (``--seed``) with
habits (film +5 %, flakes 4 % flatter, gain +0.5 %) and one tin mixed up twice: as generated,
and with every spray-out known by its L*a*b* alone (spectra recovered from its colour in
D65/10, as a BYK-mac i's export is read), and prints the habits 'cases habits' reads and the
errors 'model evaluate' finds from each (``shop_*``): what a shop whose instrument exports no
spectra loses in both, which read colour in D65/10.

With ``--adapt N`` it adapts the shipped five-angle model to N cases of such a shop (its new
toners left out, ``--seed``), their spray-outs as measured, as known by their colour alone
(learnt for that colour, as ``flakelab model adapt`` learns them), and as recovered spectra
learnt as if measured, and prints each one's mean ΔE00 on 500 fresh cases of the shop in
D65/10 and under A/10 (``adapt_*``): what the colour term gains, and what learning a
recovered spectrum as measured would cost under another light.

With ``--train N`` it trains a model afresh (the protocol, 300 + 300 epochs) on N generated
cases with measured spray-outs, then on those and 2N more known by their colour alone, and,
for comparison, 2N more measured, and prints each one's mean ΔE00 on 1,000 fresh cases in
D65/10 and under A/10 (``train_*``): what a shop's history of colours adds to a few measured
spray-outs.

    python benchmarks/colour_alone.py [--paint-basis 800] [--shop 150] [--adapt 150]
        [--train 1000] [--seed 0] [--json]
"""

from __future__ import annotations

import argparse
import sys
import time
from functools import cache
from pathlib import Path

import numpy as np

from flakelab.core.colorimetry import D65_10, OBSERVERS, Conditions, reflectance_to_Lab
from flakelab.core.difference import delta_E
from flakelab.io import read_measurements
from timing import best_time, print_report

MA_T12 = Path(__file__).resolve().parents[2] / "shared" / "data" / "ma-t12"

OTHER_LIGHTS = ("A/10", "FL11/10", "LED-B3/10", "D50/2")
"""The lights under which a recovered reading's colour is an estimate."""


def paint_basis(spectra: int, seed: int):
    """Otsu's basis learnt from ``spectra`` readings of the demo library's paints, generated
    in the cases' world from ``seed`` (each scaled to its largest value: a shape)."""
    import colour
    from colour.recovery import Tree_Otsu2018

    from flakelab.core.spectra import WAVELENGTHS

    R = generated_readings(spectra // 5 + 1, seed)
    R = R[R.min(axis=1) > 0][:spectra]
    shapes = R / R.max(axis=1, keepdims=True)
    grid = colour.SpectralShape(WAVELENGTHS[0], WAVELENGTHS[-1], WAVELENGTHS[1] - WAVELENGTHS[0])
    tree = Tree_Otsu2018(  # under the colour-alone files' D65/10, as the recovery's default
        colour.MultiSpectralDistributions(shapes.T, WAVELENGTHS),
        colour.MSDS_CMFS[OBSERVERS[D65_10.observer]].copy().align(grid),
        colour.SDS_ILLUMINANTS[D65_10.illuminant].copy().align(grid),
    )
    tree.optimise(iterations=3, print_callable=lambda *_: None)
    return tree.to_dataset()


def generated_readings(formulations: int, seed: int) -> np.ndarray:
    """Five-angle readings ``[N·5, 31]`` of ``formulations`` of the demo library's paints,
    sprayed and measured in the cases' world from ``seed``."""
    from flakelab.cases.generator import World
    from flakelab.io import read_library

    world = World(read_library(None), "five-angle")
    rng = np.random.default_rng(seed)
    x = world.formulations(formulations, rng)
    R = world.measure(world.appearance(x, world.variation(formulations, rng))[0], rng)
    return R.reshape(-1, R.shape[-1])


def basis_report(spectra: int, seed: int, folder: Path = MA_T12) -> dict:
    """The figures of :func:`colour_alone_report` per other light for the real readings
    recovered with a basis of paints (:func:`paint_basis`), and the median ΔE00 under A of
    held-out generated readings recovered with either basis."""
    from flakelab.core.colorimetry import reflectance_from_Lab
    from flakelab.core.measurement import REFLECTANCE_RANGE

    start = time.perf_counter()
    basis = paint_basis(spectra, seed)
    report = {"paint_basis_spectra": spectra, "paint_basis_seconds": time.perf_counter() - start}
    measured = np.concatenate([m.reflectance for m in _measured(folder)])
    lab = reflectance_to_Lab(measured)
    recovered = reflectance_from_Lab(lab, floor=REFLECTANCE_RANGE[0], basis=basis)
    report |= _under_other_lights(recovered, measured, "paint_")
    held = generated_readings(200, seed + 1)
    held = held[held.min(axis=1) > 0]  # readings a noiseless colour gives
    A = Conditions("A", "10")
    for name, chosen in (("otsu", None), ("paint", basis)):
        again = reflectance_from_Lab(
            reflectance_to_Lab(held), floor=REFLECTANCE_RANGE[0], basis=chosen
        )
        report[f"generated_{name}_de00_a_10_median"] = float(np.median(_apart(again, held, A)))
    return report


SHOP_HABITS = ("--shop-film-build", "1.05", "--shop-spread", "0.96", "--shop-gain", "0.005")
"""The habits of the shop of ``--shop``."""


def shop_report(cases: int, seed: int) -> dict:
    """What a shop's habits and the model's errors read from its spray-outs as measured and
    as known by their colour alone, through the commands a shop runs."""
    import json
    import tempfile
    from dataclasses import replace

    from typer.testing import CliRunner

    from flakelab.cases.exchange import read_cases, write_cases
    from flakelab.cli.main import app
    from flakelab.core.colorimetry import reflectance_from_Lab
    from flakelab.core.measurement import REFLECTANCE_RANGE

    def run(*args) -> dict:
        done = CliRunner().invoke(app, [str(a) for a in args])
        assert done.exit_code == 0, done.output
        return json.loads(done.stdout)

    report: dict = {"shop_cases": cases}
    with tempfile.TemporaryDirectory() as folder:
        measured, by_colour = Path(folder, "measured.csv"), Path(folder, "by-colour.csv")
        generate = ("cases", "generate", "--n", cases, "--seed", seed, "--shop", "shop A")
        CliRunner().invoke(app, [str(a) for a in (*generate, *SHOP_HABITS, "--out", measured)])
        history = read_cases(measured)
        history[5] = replace(history[5], recipe=history[cases // 4].recipe)  # a tin mixed up
        write_cases(history, measured)
        sprayed = np.stack([c.sprayout for c in history])
        recovered = reflectance_from_Lab(reflectance_to_Lab(sprayed), floor=REFLECTANCE_RANGE[0])
        report["shop_recovered_reflectance_apart_max"] = float(np.abs(recovered - sprayed).max())
        write_cases([replace(c, sprayout=r, sprayout_recovered=True)
                     for c, r in zip(history, recovered, strict=True)], by_colour)  # fmt: skip
        for name, path in (("measured", measured), ("by_colour", by_colour)):
            habits, judged = (
                run("cases", "habits", path, "--json"),
                run("model", "evaluate", path, "--json"),
            )
            for key in ("film_build", "flake_spread", "instrument_gain"):
                report[f"shop_{name}_{key}"] = habits[key]
                report[f"shop_{name}_{key}_se"] = habits[f"{key}_se"]
            report[f"shop_{name}_mixed_up"] = len(habits["left_out_mismatched"])
            for key in ("de00_mean", "de00_p95", "de00_max"):
                report[f"shop_{name}_{key}"] = judged[key]
    return report


def adaptation_report(cases: int, seed: int) -> dict:
    """The shipped model's mean ΔE00 on 500 fresh cases of a shop with habits in D65/10 and
    under A/10, bare and adapted to ``cases`` of the shop's spray-outs: measured, known by
    their colour alone, and recovered spectra learnt as measured."""
    from dataclasses import replace

    from flakelab.cases.generator import SHOP_WITH_HABITS, World, WorldSettings
    from flakelab.io import read_library
    from flakelab.models.registry import shipped_model
    from flakelab.models.training import (
        adapt_model,
        adaptation_cases,
        generated_case_arrays,
        recorded_config,
    )

    model = shipped_model("five-angle")
    world = World(read_library(None), "five-angle", WorldSettings(**SHOP_WITH_HABITS),
                  exclude=model.new_toners)  # fmt: skip
    history, fresh = (generated_case_arrays(world, n, s, shop="shop A")
                      for n, s in ((cases, seed), (500, seed + 1)))  # fmt: skip
    by_colour = _known_by_colour(history)
    config = recorded_config(model)
    report: dict = {"adapt_cases": cases}
    adapted = {"bare": model}
    kinds = {
        "measured": history,
        "by_colour": by_colour,
        "recovered_as_measured": replace(by_colour, colour_alone=None),
    }
    for name, data in kinds.items():
        learn, validation, _ = adaptation_cases(model, data, 0.1, config)
        start = time.perf_counter()
        adapted[name] = adapt_model(model, learn, config, validation=validation)[0]
        report[f"adapt_{name}_seconds"] = time.perf_counter() - start
    for name, chosen in adapted.items():
        report |= _mean_errors(chosen, fresh, f"adapt_{name}")
    return report


def training_report(cases: int, seed: int) -> dict:
    """Mean ΔE00 on 1,000 fresh generated cases, in D65/10 and under A/10, of models trained
    afresh on ``cases`` measured spray-outs, with 2 × ``cases`` more known by their colour
    alone, and with as many more measured."""

    from flakelab.cases.generator import World
    from flakelab.io import read_library
    from flakelab.models.training import TrainingConfig, generated_case_arrays, train_protocol

    world = World(read_library(None), "five-angle")
    measured, more, fresh = (generated_case_arrays(world, n, seed + i)
                             for i, n in enumerate((cases, 2 * cases, 1000)))  # fmt: skip
    kinds = {
        "measured": measured,
        "with_by_colour": measured.joined(_known_by_colour(more)),
        "with_measured": measured.joined(more),
    }
    report: dict = {"train_cases": cases, "train_more_cases": 2 * cases}
    for name, data in kinds.items():
        start = time.perf_counter()
        model, _ = train_protocol(data, TrainingConfig(seed=seed))
        report[f"train_{name}_seconds"] = time.perf_counter() - start
        report |= _mean_errors(model, fresh, f"train_{name}")
    return report


def _known_by_colour(data):
    """Cases (:class:`~flakelab.models.training.CaseArrays`) with every spray-out known by
    its colour alone: spectra recovered from their L*a*b* in D65/10, flagged."""
    from dataclasses import replace

    from flakelab.core.colorimetry import reflectance_from_Lab
    from flakelab.core.measurement import REFLECTANCE_RANGE

    recovered = reflectance_from_Lab(reflectance_to_Lab(data.R), floor=REFLECTANCE_RANGE[0])
    return replace(data, R=recovered, colour_alone=np.ones(len(data.case_ids), bool))


def _mean_errors(model, fresh, prefix: str) -> dict:
    """A model's mean ΔE00 on ``fresh`` cases in D65/10 and under A/10, keyed
    ``{prefix}_de00_{light}_mean``."""
    predicted = model.predict(fresh.x)[0]
    lights = {"d65_10": D65_10, "a_10": Conditions.parse("A/10")}
    return {f"{prefix}_de00_{light}_mean": float(_apart(predicted, fresh.R, conditions).mean())
            for light, conditions in lights.items()}  # fmt: skip


def _apart(a: np.ndarray, b: np.ndarray, conditions: Conditions) -> np.ndarray:
    """ΔE00 between readings ``a`` and ``b`` ``[..., 31]`` under ``conditions``, flattened."""
    lab = (reflectance_to_Lab(R, conditions=conditions) for R in (a, b))
    return delta_E(*lab).ravel()


def _under_other_lights(recovered: np.ndarray, measured: np.ndarray, prefix: str = "") -> dict:
    """Median, 95th percentile and largest ΔE00 between ``recovered`` and ``measured``
    readings under each of :data:`OTHER_LIGHTS`, keyed ``{prefix}de00_{light}_{figure}``."""
    report = {}
    for light in OTHER_LIGHTS:
        found = _apart(recovered, measured, Conditions.parse(light))
        name = f"{prefix}de00_{light.replace('/', '_').replace('-', '_').lower()}"
        report |= {
            f"{name}_median": float(np.median(found)),
            f"{name}_p95": float(np.percentile(found, 95)),
            f"{name}_max": float(found.max()),
        }
    return report


@cache
def _measured(folder: Path) -> list:
    """The measured spectra of the real samples (``all_samples_spectra.csv``), read once."""
    return read_measurements(folder / "all_samples_spectra.csv")


def colour_alone_report(folder: Path = MA_T12) -> dict:
    colour_file = folder / "all_samples_instrument_lab_d65_10.csv"
    seconds = best_time(read_measurements, colour_file)
    recovered = read_measurements(colour_file)
    measured = _measured(folder)
    readings = sum(len(m.geometries) for m in recovered)

    assert [m.sample for m in recovered] == [m.sample for m in measured]
    R_recovered, R_measured = (
        np.stack([m.reflectance for m in ms]) for ms in (recovered, measured)
    )

    return {
        "samples": len(recovered),
        "readings": readings,
        "read_seconds": seconds,
        "readings_per_s": readings / seconds,
        "de00_d65_10_max": float(_apart(R_recovered, R_measured, D65_10).max()),
        **_under_other_lights(R_recovered, R_measured),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", action="store_true")
    parser.add_argument(
        "--paint-basis",
        type=int,
        default=0,
        metavar="N",
        help="also learn Otsu's basis from N generated paint readings",
    )
    parser.add_argument(
        "--shop",
        type=int,
        default=0,
        metavar="N",
        help="also read a shop's habits from N generated cases by their spray-outs' colours",
    )
    parser.add_argument(
        "--adapt",
        type=int,
        default=0,
        metavar="N",
        help="also adapt the shipped model to N cases of a shop by their spray-outs' colours",
    )
    parser.add_argument(
        "--train",
        type=int,
        default=0,
        metavar="N",
        help="also train afresh on N measured spray-outs, and with 2N more known by colour",
    )
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    if not MA_T12.is_dir():
        print(f"{MA_T12}: absent (the real MA-T12 data beside the checkout)", file=sys.stderr)
        return 1
    report = colour_alone_report()
    if args.paint_basis:
        report |= basis_report(args.paint_basis, args.seed)
    if args.shop:
        report |= shop_report(args.shop, args.seed)
    if args.adapt:
        report |= adaptation_report(args.adapt, args.seed)
    if args.train:
        report |= training_report(args.train, args.seed)
    print_report(report, args.json, ".4g")
    return 0


if __name__ == "__main__":
    sys.exit(main())
