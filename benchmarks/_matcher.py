"""What the matcher benchmarks share: the shipped five-angle model, or any model file judged in
its own instrument's world, on the demo library."""

from __future__ import annotations

from flakelab.io import read_library
from flakelab.match.evaluate import harness_world
from flakelab.match.models import effect_mask, forward_for
from flakelab.models.registry import load_model_file, shipped_model

MODEL_HELP = (
    "model file, judged in the world of its own instrument (default: the shipped five-angle one)"
)


def shipped_matcher(world: str = "shop", model: str | None = None):
    """The demo library's harness world (``flakelab match evaluate --world``) for the
    instrument of the shipped five-angle model (or of the model file ``model``), the model's
    forward and its effect-toner mask."""
    library = read_library(None)
    learned = load_model_file(model) if model else shipped_model("five-angle")
    forward = forward_for(learned, library)
    return (
        harness_world(library, learned.instrument, world),
        forward,
        effect_mask(library, forward.toners),
    )


def seeds_from(text: str) -> list[int]:
    """``"77"``, ``"77,78"`` or ``"81-86"`` (and mixtures) → seeds."""
    seeds = []
    for part in filter(None, (p.strip() for p in text.split(","))):
        first, _, last = part.partition("-")
        try:
            seeds.extend(range(int(first), int(last or first) + 1))
        except ValueError:
            raise SystemExit(f"--seed: {part!r} is not a seed or a range of seeds") from None
    return seeds
