"""What the matcher benchmarks share: the shipped five-angle model on the demo library."""

from __future__ import annotations

from flakelab.io import read_library
from flakelab.match.evaluate import harness_world
from flakelab.match.models import effect_mask, forward_for
from flakelab.models.registry import shipped_model


def shipped_matcher(world: str = "shop"):
    """The demo library's harness world (``flakelab match evaluate --world``), the shipped
    model's forward and its effect-toner mask."""
    library = read_library(None)
    forward = forward_for(shipped_model("five-angle"), library)
    return (
        harness_world(library, "five-angle", world),
        forward,
        effect_mask(library, forward.toners),
    )
