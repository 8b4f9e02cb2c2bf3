"""The README's first command as a colorist runs it: ``flakelab match --example`` in a fresh
process on a machine with no database, end to end, against what its dependencies alone cost.

Each run is a new process. The figures: the command's wall time; the match itself (the
``seconds`` its JSON reports); and the baseline, measured in the same run, a fresh process
that imports only the third-party packages the command needs (torch, colour-science,
numba, SciPy, SQLAlchemy, Typer, Rich, colour-cxf), the floor no change of flakelab's can
go below. One more run under ``python -X importtime`` names the packages whose import takes
longest, each with all it imports, and says whether torch was among them.

``--command model-list`` times ``flakelab model list`` (its table) on that fresh machine (the
shipped models alone) the same way, against SQLAlchemy, Typer, Rich and colour-science, which
flakelab's case and measurement types import; it loaded torch until stop 127.

    python benchmarks/cli_start.py [--command match|model-list] [--runs 5] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from timing import print_report

COMMANDS = {
    "match": (
        ["match", "--example", "--json"],
        "torch, colour, numba, scipy.optimize, sqlalchemy.orm, typer, rich.table, colour_cxf",
    ),
    "model-list": (["model", "list"], "colour, sqlalchemy.orm, typer, rich.table"),
}
"""Each command timed: its arguments, and what it imports of others' code (the baseline's
imports)."""


def fresh_environment(folder: str) -> dict:
    """The user's environment with an empty data folder and no database named: the
    Quickstart's fresh machine."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("FLAKELAB_")}
    return env | {"XDG_DATA_HOME": folder}


def timed(command: list[str], env: dict) -> tuple[float, str, str]:
    """Wall time [s], stdout and stderr of ``command`` in a fresh process."""
    start = time.perf_counter()
    run = subprocess.run(command, capture_output=True, text=True, env=env)
    seconds = time.perf_counter() - start
    if run.returncode:
        raise SystemExit(f"{' '.join(command)}: exit {run.returncode}\n{run.stderr}")
    return seconds, run.stdout, run.stderr


def slowest_imports(stderr: str, most: int = 8) -> dict[str, float]:
    """The third-party packages of an ``-X importtime`` log whose import took longest [s],
    each with what it imported itself (a package imported by another counts in both;
    flakelab's own modules, which import them, are left out)."""
    cumulative: dict[str, float] = {}
    for line in stderr.splitlines():
        if not line.startswith("import time:") or "|" not in line:
            continue
        _, total, name = line.split("|")
        if total.strip().isdigit():
            top = name.strip().split(".")[0]
            if top == "flakelab":
                continue
            cumulative[top] = max(cumulative.get(top, 0.0), int(total) / 1e6)
    ranked = sorted(cumulative.items(), key=lambda item: -item[1])[:most]
    return {name: round(seconds, 3) for name, seconds in ranked}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--command", choices=list(COMMANDS), default="match")
    parser.add_argument("--runs", type=int, default=5, help="fresh processes of each kind")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()

    entry = shutil.which("flakelab") or str(Path(sys.executable).parent / "flakelab")
    arguments, dependencies = COMMANDS[args.command]
    command = [sys.executable, entry, *arguments]
    baseline = [sys.executable, "-c", f"import {dependencies}"]
    with tempfile.TemporaryDirectory() as folder:
        env = fresh_environment(folder)
        walls, matches, floors = [], [], []
        for _ in range(args.runs):  # interleaved, so a change of the machine's pace hits both
            seconds, stdout, _ = timed(command, env)
            walls.append(seconds)
            if args.command == "match":
                matches.append(json.loads(stdout)["seconds"])
            floors.append(timed(baseline, env)[0])
        _, _, log = timed([sys.executable, "-X", "importtime", *command[1:]], env)
        made_database = any(Path(folder).rglob("*.sqlite*")) or any(Path(folder).rglob("*.db"))
    wall, floor = float(np.median(walls)), float(np.median(floors))
    match = float(np.median(matches)) if matches else None  # model list matches nothing
    report = {
        "command": " ".join(["flakelab", *arguments]),
        "runs": args.runs,
        "command_wall_s_median": wall,
        "match_s_median": match,
        "dependencies_import_s_median": floor,
        "command_over_dependencies": wall / floor,
        "rest_s": wall - floor - (match or 0.0),
        "made_a_database": made_database,
        "slowest_imports_s": slowest_imports(log),
        "imported_torch": any(line.split("|")[-1].strip() == "torch" for line in log.splitlines()),
    }
    print_report(report, args.json, ",.4g")


if __name__ == "__main__":
    main()
