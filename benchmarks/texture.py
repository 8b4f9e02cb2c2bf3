"""Texture rendering speed and the closed loop of the appearance-based processes.

Speed: a 1024 × 1024 curved panel with texture (the shipped example target), against a
baseline measured in the same run: the same panel without texture (colour interpolation and
composition only). Paper 001 reports 1.5 s per image, single-threaded; the goal is ≤ 1 s.
Also times the parts (texture images, composition) and peak memory (tracemalloc).

    python benchmarks/texture.py [--size 1024] [--repeats 3] [--json]
"""

from __future__ import annotations

import argparse
import json

from flakelab.data import example_path
from flakelab.io import read_measurement
from flakelab.render.appearance import appearance_of, render_curved, texture_images
from flakelab.texture.calibration import shipped_processes
from timing import best_time, measure_peak


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", type=int, default=1024)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    appearance = appearance_of(read_measurement(example_path("target")))
    shipped_processes()  # load once, outside the timings
    shape = (args.size, args.size)
    textured = best_time(render_curved, appearance, shape, repeat=args.repeats)
    plain = best_time(lambda: render_curved(appearance, shape, texture=False), repeat=args.repeats)
    images = best_time(texture_images, 2.0, 8.0, shape, repeat=args.repeats)
    _, _, peak_mb = measure_peak(render_curved, appearance, shape)
    report = {
        "size_px": args.size,
        "curved_textured_s": round(textured, 3),
        "curved_plain_s": round(plain, 3),
        "texture_images_s": round(images, 3),
        "texture_overhead_ratio": round(textured / plain, 2),
        "goal_s": 1.0,
        "paper_s": 1.5,
        "peak_memory_mb": round(peak_mb, 1),
    }
    if args.json:
        print(json.dumps(report, indent=2))
        return
    print(f"{args.size}² curved panel with texture: {textured:.3f} s (goal ≤ 1 s, paper 1.5 s)")
    print(f"  without texture (baseline): {plain:.3f} s; texture costs ×{textured / plain:.1f}")
    print(f"  texture images alone: {images:.3f} s; peak memory {peak_mb:.0f} MB")


if __name__ == "__main__":
    main()
