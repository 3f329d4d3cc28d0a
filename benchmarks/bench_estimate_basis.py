"""The experiments' five completion methods per item, estimated separately (as before) and on
one shared basis (carving views, support plane, sorted space made once; a completed cloud
meshed once): wall time of each and whether the volumes agree to the last digit.

Usage: .venv/bin/python benchmarks/bench_estimate_basis.py [ITEM ...]

Uses the full-orbit benchmark captures and their finished stages under data/bench-sfm
(computed if missing), in one process; prints one line per item.
"""

from __future__ import annotations

import argparse
import time

from volec.estimate import (
    EstimateConfig,
    estimate_basis,
    estimate_from_basis,
    estimate_from_stages,
    food_silhouettes,
    load_completion_model,
)
from volec.experiments import (
    ensure_capture,
    method_variants,
    run_stages,
    scenario_capture,
    scenarios,
)
from volec.paths import experiment_dir


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("items", nargs="*", default=["apple", "pear", "chocolate_croissant",
                                                     "banana"])
    args = parser.parse_args()
    scenario = scenarios(False)["full_orbit"]
    cfg = EstimateConfig()
    model = load_completion_model(cfg)
    variants = list(method_variants(cfg, model).values())
    for item in args.items:
        out = ensure_capture(experiment_dir(False), item, scenario)
        capture = scenario_capture(out, scenario)
        stages = run_stages(capture, scenario.work(out), cfg.sfm, cfg.dense, cfg.masking,
                            stale="recompute", progress=False)
        views = food_silhouettes(capture, stages, cfg)
        start = time.perf_counter()
        separate = [estimate_from_stages(capture, stages, net, variant, views).food.volume_ml
                    for variant, net in variants]
        separate_s = time.perf_counter() - start
        start = time.perf_counter()
        basis = estimate_basis(capture, stages, cfg, views)
        shared = [estimate_from_basis(capture, stages, net, variant, basis).food.volume_ml
                  for variant, net in variants]
        shared_s = time.perf_counter() - start
        print(f"{item}: five estimates separately {separate_s:.1f} s, on one basis "
              f"{shared_s:.1f} s (ratio {shared_s / separate_s:.2f}); meshes made "
              f"{len(basis.meshes)}; same volumes {separate == shared}", flush=True)


if __name__ == "__main__":
    main()
