"""A learned model's own error per paint family, against the world's nominal physics.

Formulations are drawn as the generator draws them, one family at a time, from the toners
the model learned (its new toners left out, as in its training), and made by the world's
physics at the nominal application: no batch, application or instrument noise, so what is
left is the model's error alone. Each is judged by its worst geometry's ΔE00. The pearls are
split by how much of the library's white they hold: none (over aluminium apart), a trace
(under 5 %), a tint (5–20 %) and white pearls (20 % or more; ``WorldSettings.
white_pearl_share`` of the pearls hold the white at that level).

``--against FILE`` judges a second model on the same formulations in the same run (the
baseline: a model trained before, e.g. stop 106's five-angle model, ``git show
e671928:src/flakelab/data/models/demo-five-angle.pt > old.pt``) and prints each figure's
ratio to it.

    python benchmarks/model_families.py [--instrument five-angle] [--model FILE]
        [--against FILE] [--formulations 1500] [--seed 6] [--white-pearls SHARE] [--json]
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from _matcher import add_white_pearls_argument
from flakelab.cases.generator import World, WorldSettings
from flakelab.errors import ModelError
from flakelab.io import read_library
from flakelab.match.models import forward_for
from flakelab.models.registry import load_model_file, shipped_model
from matched_error import own_error

FAMILIES = ("metallic", "solid", "pearl")
WHITE_BANDS = (
    ("no white", 0.0, 0.0),
    ("a trace of white", 0.0, 0.05),
    ("white as a tint", 0.05, 0.2),
    ("white pearls", 0.2, 1.0),
)
"""The pearls' bands of white share (name, above, up to); ``no white`` is exactly none."""


def pearl_bands(library, x: np.ndarray) -> dict[str, np.ndarray]:
    """Which pearl recipes ``x[N, T]`` lie over aluminium, and which in each band of white."""
    names = list(library.names)
    aluminium = [names.index(t.name) for t in library.of_kind("aluminium")]
    over_aluminium = x[:, aluminium].sum(1) > 0
    white = x[:, library.solid_bases()[0]] / x.sum(1)  # the world's white
    bands = {"over aluminium": over_aluminium}
    for name, above, upto in WHITE_BANDS:
        within = white == 0 if upto == 0 else (white > above) & (white <= upto)
        bands[name] = within & ~over_aluminium
    return bands


def summary(errors: np.ndarray) -> dict:
    if errors.size == 0:
        return {"n": 0}
    return {
        "n": int(errors.size),
        "median": float(np.median(errors)),
        "mean": float(errors.mean()),
        "p95": float(np.percentile(errors, 95)),
        "max": float(errors.max()),
    }


def family_errors(library, models: dict, instrument: str, n: int, seed: int, share: float):
    """Each model's worst-geometry ΔE00 summaries per family and pearl band
    (:func:`matched_error.own_error`: against the world's nominal physics)."""
    novel = set().union(*(m.new_toners for m in models.values()))
    forwards = {k: forward_for(m, library) for k, m in models.items()}
    rows = {}
    for family in FAMILIES:
        settings = WorldSettings(kinds={family: 1.0}, white_pearl_share=share)
        world = World(library, instrument, settings, exclude=novel)
        x = world.formulations(n, np.random.default_rng(seed))
        errors = {k: own_error(world, f, x).max(axis=1) for k, f in forwards.items()}
        groups = {family: np.ones(n, bool)}
        if family == "pearl":
            groups |= {f"pearl, {band}": m for band, m in pearl_bands(library, x).items()}
        for group, mask in groups.items():
            rows[group] = {k: summary(e[mask]) for k, e in errors.items()}
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--instrument", default="five-angle")
    parser.add_argument("--model", help="model file (default: the shipped one)")
    parser.add_argument("--against", help="a second model file, judged on the same paints")
    parser.add_argument("--formulations", type=int, default=1500, help="per family")
    parser.add_argument("--seed", type=int, default=6)
    add_white_pearls_argument(parser, "the pearls", WorldSettings.white_pearl_share)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    if args.formulations < 1:
        parser.error(f"--formulations: {args.formulations} is not a positive number")
    library = read_library(None)
    try:
        models = {
            "model": load_model_file(args.model) if args.model else shipped_model(args.instrument)
        }
        if args.against:
            models["against"] = load_model_file(args.against)
    except ModelError as error:
        parser.error(str(error))
    for name, model in models.items():
        if model.instrument != args.instrument:
            parser.error(f"--{name}: a model of {model.instrument}, not {args.instrument}")
    rows = family_errors(
        library, models, args.instrument, args.formulations, args.seed, args.white_pearls
    )
    report = {
        "instrument": args.instrument,
        "formulations": args.formulations,
        "seed": args.seed,
        "white_pearls": args.white_pearls,
        "models": {k: m.identity for k, m in models.items()},
        "rows": rows,
    }
    if args.json:
        print(json.dumps(report, indent=2))
        return
    print(f"worst-geometry ΔE00 against the world's nominal physics, {args.instrument}, "
          f"{args.formulations} formulations per family, seed {args.seed}")  # fmt: skip
    for group, by_model in rows.items():
        figures = []
        for name, s in by_model.items():
            if s["n"]:
                figures.append(
                    f"{name} median {s['median']:.2f} p95 {s['p95']:.2f} max {s['max']:.2f}"
                )
        if "against" in by_model and by_model["model"]["n"]:
            a, b = by_model["model"], by_model["against"]
            figures.append(
                f"÷ against: median {a['median'] / b['median']:.2f}, p95 {a['p95'] / b['p95']:.2f}"
            )
        print(f"  {group:24s} n={by_model['model']['n']:5d}  " + "; ".join(figures))


if __name__ == "__main__":
    main()
