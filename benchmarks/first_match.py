"""The first match in a fresh process, as every ``flakelab match`` makes it, against a later one.

Each run is a new Python process that loads the shipped five-angle model and the demo
library, then matches the shipped example target ``--repeat`` + 1 times; the first match
pays whatever torch does once per process. The baseline, in the same run: the same process,
with one ``torch.optim.Adam`` built inside the first match's time, which is what the search's
first step cost while it stepped through the optimiser class (its first construction imports
``torch._dynamo`` and sympy; :mod:`flakelab.match.adam`).

    python benchmarks/first_match.py [--runs 3] [--repeat 3] [--json]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys

import numpy as np

from timing import print_report

PROCESS = """
import json, sys, time
import torch
from flakelab.data import example_path
from flakelab.io import read_library, read_measurement
from flakelab.match.models import effect_mask, forward_for
from flakelab.match.search import match
from flakelab.models.registry import shipped_model

library = read_library(None)
forward = forward_for(shipped_model("five-angle"), library)
effect = effect_mask(library, forward.toners)
target = read_measurement(example_path("target"))
seconds = []
for i in range({repeat} + 1):
    start = time.perf_counter()
    if i == 0 and {with_class}:
        torch.optim.Adam([torch.zeros(1, requires_grad=True)])
    match(target, forward, effect)
    seconds.append(time.perf_counter() - start)
print(json.dumps({{"seconds": seconds, "compiler": "torch._dynamo" in sys.modules}}))
"""


def one_process(repeat: int, with_class: bool) -> dict:
    """Seconds of each match in a fresh process, and whether it imported torch's compiler."""
    script = PROCESS.format(repeat=repeat, with_class=with_class)
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    if run.returncode:
        raise SystemExit(run.stderr)
    return json.loads(run.stdout.splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=3, help="fresh processes of each kind")
    parser.add_argument("--repeat", type=int, default=3, help="later matches in each")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()

    report: dict = {"runs": args.runs, "repeat": args.repeat}
    for name, with_class in (("optimiser_class", True), ("functional_adam", False)):
        runs = [one_process(args.repeat, with_class) for _ in range(args.runs)]
        first = np.array([r["seconds"][0] for r in runs])
        later = np.array([s for r in runs for s in r["seconds"][1:]])
        report |= {
            f"{name}_first_match_s_median": float(np.median(first)),
            f"{name}_later_match_s_median": float(np.median(later)),
            f"{name}_first_over_later": float(np.median(first) / np.median(later)),
            f"{name}_imports_compiler": all(r["compiler"] for r in runs),
        }
    report["first_match_saved_s"] = (
        report["optimiser_class_first_match_s_median"]
        - report["functional_adam_first_match_s_median"]
    )
    print_report(report, args.json, ",.4g")


if __name__ == "__main__":
    main()
