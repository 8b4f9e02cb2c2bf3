"""What the matcher benchmarks share: the five-angle model (shipped, or a file) on the demo
library."""

from __future__ import annotations

from flakelab.io import read_library
from flakelab.match.evaluate import harness_world
from flakelab.match.models import effect_mask, forward_for
from flakelab.models.registry import load_model_file, shipped_model


def shipped_matcher(world: str = "shop", model: str | None = None):
    """The demo library's harness world (``flakelab match evaluate --world``), the forward of
    the shipped model (or of the model file ``model``) and its effect-toner mask."""
    library = read_library(None)
    forward = forward_for(load_model_file(model) if model else shipped_model("five-angle"), library)
    return (
        harness_world(library, "five-angle", world),
        forward,
        effect_mask(library, forward.toners),
    )
