"""Time the benchmark renderer frame by frame, against older code, and check the bytes.

Usage: .venv/bin/python benchmarks/bench_render.py [ITEM ...] [--frames N] [--rounds R]
       [--before DIR]

Each item's first N frames (the default look, one process, one thread) are rendered to the
JPEG, mask and shadow bytes a capture stores, by this checkout and, with ``--before DIR`` (a
checkout of older code, e.g. ``git worktree add /tmp/before REV``), by that code
(``PYTHONPATH=DIR``), the two alternating in one run, each in a fresh process. Prints the
seconds per frame of each, their ratio and whether the bytes are the same.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import time
from pathlib import Path

from before_after import checkouts, child_result


def render_digest(item: str, frames: int) -> dict[str, float | str]:
    """Render ``item``'s first ``frames`` frames in this process: seconds per frame (the
    scene's set-up excluded) and one digest of every byte produced."""
    from volec.synth import PRESETS
    from volec.synth.generate import _init_worker, _render_frame, plan_capture

    cfg = PRESETS["default"].with_(workers=1)
    plan = plan_capture(item, cfg)
    _init_worker(plan.scene)
    digest = hashlib.sha256()
    start = time.perf_counter()
    for i in range(frames):
        jpg, mask, shadow = _render_frame((i, plan.exact_scene_poses[i], cfg))
        digest.update(jpg + mask + shadow.tobytes())
    return {"s_per_frame": (time.perf_counter() - start) / frames, "digest": digest.hexdigest()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("items", nargs="*", default=["apple", "banana", "chocolate_cake"])
    parser.add_argument("--frames", type=int, default=12)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--before", type=Path)
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(render_digest(args.child, args.frames)))
        return
    codes = checkouts(args.before)
    print(f"{'item':<18} " + " ".join(f"{k + ' s/frame':>16}" for k in codes)
          + (f" {'ratio':>6} {'same bytes':>10}" if args.before else ""))
    for item in args.items:
        runs: dict[str, list[dict]] = {k: [] for k in codes}
        for _ in range(args.rounds):
            for name, code in codes.items():
                runs[name].append(child_result(__file__, code,
                                               [item, "--frames", str(args.frames)]))
        best = {k: min(r["s_per_frame"] for r in v) for k, v in runs.items()}
        line = f"{item:<18} " + " ".join(f"{best[k]:16.3f}" for k in codes)
        if args.before:
            same = {r["digest"] for v in runs.values() for r in v}
            line += f" {best['after'] / best['before']:6.2f} {str(len(same) == 1):>10}"
        print(line, flush=True)


if __name__ == "__main__":
    main()
