"""Time the estimate's silhouette work against older code, and check the values: the masks'
signed distances (:func:`volec.estimate.food_silhouettes`, once per estimate) and the visual
hull's field at grid points (:func:`volec.meshing.silhouette_field`, which the carving calls
for every method's mesh).

Usage: .venv/bin/python benchmarks/bench_silhouettes.py [ITEM ...] [--points N]
       [--rounds R] [--before DIR]

Each item's full-orbit capture and finished stages (data/bench-sfm, made as the benchmark
scripts make them if missing) are timed by this checkout and, with ``--before DIR`` (a checkout
of older code, e.g. ``git worktree add /tmp/before REV``), by that code (``PYTHONPATH=DIR``),
alternating in one run, each in a fresh process on one thread as a ``make paper`` worker runs.
The field is taken at ``--points`` points drawn uniformly in a 9 cm cube about the food (the
carving's grid points are of that order: 0.2-0.25 million a mesh). Prints the best seconds of
each, their ratio and whether every value came out the same bits.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import time
from pathlib import Path

from before_after import checkouts, child_result


def silhouette_times(item: str, points: int) -> dict[str, float | str]:
    """In this process: seconds to make ``item``'s silhouettes and to take the field at
    ``points`` points, and one digest of every value."""
    import numpy as np

    from volec.batch import limit_threads

    limit_threads(1)
    from volec.estimate import EstimateConfig, food_silhouettes
    from volec.experiments import benchmark_stages
    from volec.meshing import silhouette_field

    cfg = EstimateConfig()
    made = benchmark_stages(item, "full_orbit", cfg)
    stages = made.stages
    start = time.perf_counter()
    views = food_silhouettes(made.capture, stages, cfg)
    silhouettes_s = time.perf_counter() - start
    food = stages.masked.cloud.xyz
    grid = food.mean(axis=0) + np.random.default_rng(0).uniform(-0.045, 0.045, (points, 3))
    start = time.perf_counter()
    field_m = silhouette_field(grid, views, cfg.meshing.silhouette_margin_px,
                               cfg.meshing.silhouette_min_views,
                               cfg.meshing.silhouette_min_share)
    field_s = time.perf_counter() - start
    digest = hashlib.sha256(field_m.tobytes())
    for view in views:
        digest.update(view.signed_distance_px.tobytes())
    return {"silhouettes_s": silhouettes_s, "field_s": field_s, "digest": digest.hexdigest()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("items", nargs="*", default=["apple", "banana", "pear"])
    parser.add_argument("--points", type=int, default=250_000)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--before", type=Path)
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(silhouette_times(args.child, args.points)))
        return
    codes = checkouts(args.before)
    parts = ("silhouettes_s", "field_s")
    print(f"{'item':<12} " + " ".join(f"{k + ' ' + p:>22}" for k in codes for p in parts)
          + (f" {'ratios':>11} {'same bits':>9}" if args.before else ""))
    for item in args.items:
        runs: dict[str, list[dict]] = {k: [] for k in codes}
        for rnd in range(args.rounds):
            order = list(codes.items())
            for name, code in order if rnd % 2 == 0 else order[::-1]:  # alternating
                runs[name].append(child_result(__file__, code,
                                               [item, "--points", str(args.points)]))
        best = {(k, p): min(r[p] for r in v) for k, v in runs.items() for p in parts}
        line = f"{item:<12} " + " ".join(f"{best[k, p]:22.3f}" for k in codes for p in parts)
        if args.before:
            ratios = [best["after", p] / best["before", p] for p in parts]
            same = {r["digest"] for v in runs.values() for r in v}
            line += f" {ratios[0]:5.2f} {ratios[1]:5.2f} {str(len(same) == 1):>9}"
        print(line, flush=True)


if __name__ == "__main__":
    main()
