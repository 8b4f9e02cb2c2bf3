"""The shop's feedback loop: the learned model adapted to spray-outs of its own recipes.

A shop that uses the matcher stores a case for every recipe it mixes and sprays; those cases
lie where the matcher takes the model, which is where the optimiser finds the model's errors
(``benchmarks/matched_error.py``), not where the generator's cases lie. This simulates that
loop: for hidden targets made as in ``flakelab match evaluate`` (seeds apart from the
evaluation's), the matcher proposes its best candidates; each is sprayed once in the shop's
world (batches, application, instrument) and kept as a case; the model is then adapted to
those cases (``flakelab.models.training.adapt_model``) for ``--epochs`` at the protocol's
adaptation rate (its 150 ``adapt_epochs`` fit a few thousand cases too closely; with
``--validation`` a share of the cases chooses the epoch instead), mixed with fresh cases from its
own training mix (``--replay`` per feedback case) so that it keeps what it knew;
``--control`` adapts on as many fresh cases alone, to tell the feedback's effect from that of
more training. It reports the model's own error at matched recipes and at hidden formulas
(seeds 81 and 82, as ``matched_error.py``) before and after, and writes the adapted model for
the other benchmarks' ``--model``.

    python benchmarks/feedback.py [--targets 400] [--seed 501] [--out FILE] [--json]
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from _matcher import MODEL_HELP, seeds_from, shipped_matcher
from flakelab.cases.generator import World, WorldSettings
from flakelab.match.models import forward_for
from flakelab.models.network import ForwardModel
from flakelab.models.training import (
    CaseArrays,
    adapt_model,
    generated_case_arrays,
    recorded_config,
)
from matched_error import matched_and_hidden, measure


def sprayed_cases(world: World, x: np.ndarray, effect, rng: np.random.Generator) -> CaseArrays:
    """Recipes ``x[N, T]`` each sprayed once in ``world`` and measured, as training arrays."""
    R, texture = world.appearance(x, world.variation(len(x), rng))
    return CaseArrays(
        x,
        world.measure(R, rng),
        texture,
        tuple(f"feedback-{i}" for i in range(len(x))),
        ("feedback",) * len(x),
        world.library.names,
        tuple(g.name for g in world.geometries),
        world.instrument,
        np.asarray(effect, float),
    )


def replay_cases(model: ForwardModel, world: World, n: int, seed: int) -> CaseArrays:
    """``n`` fresh cases from the model's own training mix (its recorded family shares)."""
    kinds = model.info.get("training_kinds") or WorldSettings().kinds
    novel = model.new_toners
    training = World(world.library, world.instrument, WorldSettings(kinds=kinds), exclude=novel)
    return generated_case_arrays(training, n, seed)


def joined(a: CaseArrays, b: CaseArrays) -> CaseArrays:
    return replace(
        a,
        x=np.concatenate([a.x, b.x]),
        R=np.concatenate([a.R, b.R]),
        texture=np.concatenate([a.texture, b.texture]),
        case_ids=a.case_ids + b.case_ids,
        shops=a.shops + b.shops,
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--targets", type=int, default=400, help="feedback targets")
    parser.add_argument("--candidates", type=int, default=3, help="recipes sprayed per target")
    parser.add_argument(
        "--replay", type=float, default=30.0, help="fresh training-mix cases per feedback case"
    )
    parser.add_argument("--epochs", type=int, default=30, help="adaptation epochs")
    parser.add_argument(
        "--validation",
        type=float,
        default=0.0,
        help="share of the cases that choose the epoch (flakelab model adapt's default 0.2); "
        "0: every epoch runs, as the paper",
    )
    parser.add_argument("--seed", type=int, default=501, help="seed of the feedback targets")
    parser.add_argument("--eval-seed", default="81,82", help="matched_error.py's seeds")
    parser.add_argument("--eval-targets", type=int, default=60, help="per evaluation seed")
    parser.add_argument("--model", help=MODEL_HELP)
    parser.add_argument(
        "--control",
        action="store_true",
        help="adapt on fresh training-mix cases only, as many as feedback and replay together",
    )
    parser.add_argument("--out", type=Path, help="write the adapted model here")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    if args.seed in seeds_from(args.eval_seed):
        parser.error("--seed: the feedback targets must not be the evaluation's")
    world, forward, effect = shipped_matcher(model=args.model)
    model = forward.model
    evaluation = argparse.Namespace(seed=args.eval_seed, targets=args.eval_targets)
    before = measure(world, forward, effect, evaluation)

    x, _ = matched_and_hidden(world, forward, effect, [args.seed], args.targets, args.candidates)
    novel = np.isin(world.library.names, forward.novel)
    x = x[(x[:, novel] == 0).all(1)]  # the physics scales new toners; the network never sees them
    rng = np.random.default_rng([args.seed, 1])
    replay = round(args.replay * len(x))
    if args.control:
        data = replay_cases(model, world, len(x) + replay, seed=args.seed + 1)
    else:
        feedback = sprayed_cases(world, x, model.effect, rng)
        data = joined(feedback, replay_cases(model, world, replay, seed=args.seed + 1))
    config = replace(
        recorded_config(model),
        seed=args.seed,
        adapt_epochs=args.epochs,
        adapt_validation=args.validation,
    )
    new, adaptation = adapt_model(model, data, config, stage="feedback")
    after = measure(world, forward_for(new, world.library), effect, evaluation)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_bytes(new.to_bytes())

    report = {
        "model": args.model or "shipped",
        "control": args.control,
        "feedback_cases": 0 if args.control else len(x),
        "replay_cases": len(data.x) - (0 if args.control else len(x)),
        "adaptation": {k: v for k, v in adaptation.items() if k != "log"},
        "before": before,
        "after": after,
        "out": str(args.out) if args.out else None,
    }
    if args.json:
        print(json.dumps(report, indent=2))
        return
    print(
        f"{report['model']}: adapted to {report['feedback_cases']} spray-outs of its own "
        f"recipes and {report['replay_cases']} fresh cases; own ΔE00 against the nominal physics"
    )
    for name in ("before", "after"):
        r = report[name]
        print(
            f"  {name:6s} at matched recipes {r['at_matched_recipes']['de00_mean']:.3f}  "
            f"at hidden formulas {r['at_hidden_formulas']['de00_mean']:.3f}  "
            f"×{r['mean_ratio']:.2f}"
        )


if __name__ == "__main__":
    main()
