"""Regenerate the fast model's flake atlas (src/flakelab/data/flake-atlas.npz).

Dye-free Monte Carlo runs of a flake layer (σ_f = 1, black primer) over a grid of
orientation spreads and optical depths, one per illumination angle of the MA-T12 geometries;
each run's path table is stored as its double Laplace transform (flakelab.physics.fast).

    python scripts/make_flake_atlas.py [--photons 100000] [--seed 2026]
"""

from __future__ import annotations

import argparse

from flakelab.cli.common import exit_interrupted, progress_bar, stop_on_signals
from flakelab.physics.fast import ATLAS_DEPTHS, ATLAS_SPREADS, atlas_path, build_atlas


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--photons", type=int, default=100_000)
    parser.add_argument("--seed", type=int, default=2026)
    args = parser.parse_args()
    stop_on_signals()
    try:
        with progress_bar() as progress:
            task = progress.add_task(
                "Monte Carlo runs", total=ATLAS_SPREADS.size * ATLAS_DEPTHS.size * 2
            )
            atlas = build_atlas(args.photons, args.seed, lambda: progress.advance(task))
        atlas.save(atlas_path())
    except KeyboardInterrupt as stopped:  # a traceback before; the file is written whole
        exit_interrupted(f"stopped before it finished; {atlas_path()} is as it was", stopped)
    print(f"wrote {atlas_path()} ({atlas_path().stat().st_size / 1024:.0f} KiB)")


if __name__ == "__main__":
    main()
