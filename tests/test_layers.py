"""The package's layers (DESIGN.md §8; ``flakelab.__doc__``): each imports only from its own
layer and those below it, at the top of a module or within a function alike."""

from __future__ import annotations

import ast
from pathlib import Path

import flakelab

LAYERS = {
    "cli": 4,
    **dict.fromkeys(("match", "render"), 3),
    **dict.fromkeys(("models", "physics", "texture"), 2),
    **dict.fromkeys(("cases", "library"), 1),
    **dict.fromkeys(("io", "core", "errors", "data"), 0),
}
"""Each subpackage (and top-level module) by its height: an arrow points down or across."""

UPWARD = {("cases.generator", "physics"), ("cases.generator", "texture"), ("io", "library")}
"""The arrows that point up, as ``flakelab.__doc__`` says: the case generator makes its cases
with the physics (and their texture readings), and io reads library and tin files into the
library's types."""


def _imports(path: Path) -> set[str]:
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
        elif isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
    return {name for name in found if name.startswith("flakelab.")}


def test_every_import_points_down_or_across_but_the_two_the_package_names():
    root = Path(flakelab.__file__).parent
    upward = set()
    for path in root.rglob("*.py"):
        module = ".".join(path.relative_to(root).with_suffix("").parts)
        layer = module.split(".")[0]
        if module == "__init__":  # the package's own: its version and errors
            continue
        assert layer in LAYERS, f"{module}: a layer DESIGN.md §8 does not name"
        for name in _imports(path):
            target = name.split(".")[1]
            if LAYERS[target] > LAYERS[layer]:
                arrow = next((a, t) for a, t in [*UPWARD, (module, target)]
                             if t == target and f"{module}.".startswith(f"{a}."))  # fmt: skip
                assert arrow in UPWARD, f"{module} imports {name}: a higher layer"
                upward.add(arrow)
    assert upward == UPWARD, f"allowed arrows no module takes any more: {UPWARD - upward}"
