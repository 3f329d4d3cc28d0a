"""Time the synthetic capture generator: mesh, plan, render, write.

Usage: .venv/bin/python benchmarks/bench_synth.py [ITEM ...] [--frames N] [--workers W]
Prints one line per item and the mean render time per frame; writes nothing outside a
temporary folder.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from volec.synth import PRESETS, write_synthetic_capture
from volec.synth.generate import plan_capture, render_frames
from volec.synth.shapes import _item_mesh_cached


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("items", nargs="*", default=["apple", "banana", "chocolate_cake"])
    parser.add_argument("--frames", type=int, default=100)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    cfg = PRESETS["default"].with_(n_frames=args.frames, workers=args.workers)
    per_frame = []
    print(f"{'item':<20} {'mesh_s':>7} {'render_s':>9} {'s/frame':>8} {'total_s':>8}")
    for item in args.items:
        _item_mesh_cached.cache_clear()
        t0 = time.perf_counter()
        plan = plan_capture(item, cfg)
        t1 = time.perf_counter()
        render_frames(plan.scene, plan.exact_scene_poses, cfg, progress=False)
        t2 = time.perf_counter()
        with tempfile.TemporaryDirectory() as tmp:
            _item_mesh_cached.cache_clear()
            t3 = time.perf_counter()
            write_synthetic_capture(item, Path(tmp) / item, cfg, progress=False)
            t4 = time.perf_counter()
        per_frame.append((t2 - t1) / args.frames)
        print(f"{item:<20} {t1 - t0:7.2f} {t2 - t1:9.2f} {per_frame[-1]:8.3f} {t4 - t3:8.2f}")
    print(f"mean render time per {cfg.width}x{cfg.height} frame with {args.workers} workers: "
          f"{sum(per_frame) / len(per_frame):.3f} s")


if __name__ == "__main__":
    main()
