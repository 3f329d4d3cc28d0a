"""How much the completed volume depends on the completion's resampling seed, on the same
finished stages: the network sees a random subset of the masked cloud (1024 of some 70,000
points for the ``cpu`` checkpoint), so another seed predicts other points.

Usage: .venv/bin/python benchmarks/bench_completion_seeds.py [--scenario full_orbit]
       [--seeds 3] ITEM...

Reads the stages of ``data/bench-sfm/ITEM-SCENARIO`` (run ``bench_volume.py`` first; a stage
made by other code or settings is refused, never reused), meshes the food without completion
and with network completion once per seed, and writes figures/completion_seeds.{csv,md}:
per item the volume error without completion and per seed, and the spread over the seeds.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace

import numpy as np
import pandas as pd

from volec.capture import read_transforms_json
from volec.estimate import (
    EstimateConfig,
    capture_up,
    food_mesh,
    food_silhouettes,
    load_completion_model,
    support_scene,
)
from volec.meshing import consistent_views
from volec.paths import experiment_dir, figures_dir
from volec.pipeline import run_stages
from volec.tables import write_table


def item_row(item: str, scenario: str, seeds: int) -> dict[str, float | str]:
    """Volume errors (%) of ``item`` without completion and with each seed."""
    root = experiment_dir(False) / f"{item}-{scenario}"
    truth_ml = json.loads((root / "ground_truth" / "truth.json").read_text())["volume_ml"]
    capture = read_transforms_json(root / "capture")
    cfg = EstimateConfig()
    stages = run_stages(capture, root / "work", cfg.sfm, cfg.dense, cfg.masking,
                        progress=False)
    views, _ = consistent_views(food_silhouettes(capture, stages, cfg),
                                stages.masked.cloud.xyz, cfg.meshing)
    scene, up = support_scene(stages, cfg.support), capture_up(capture)
    model = load_completion_model(cfg)
    without = food_mesh(stages.masked.cloud, scene, up, None,
                        replace(cfg, use_completion=False), views)
    row: dict[str, float | str] = {"item": item,
                                   "without_pct": (without.volume_ml / truth_ml - 1) * 100}
    errors = []
    for seed in range(seeds):
        seeded = replace(cfg, completion=replace(cfg.completion, seed=seed))
        food = food_mesh(stages.masked.cloud, scene, up, model, seeded, views)
        errors.append((food.volume_ml / truth_ml - 1) * 100)
        row[f"seed{seed}_pct"] = errors[-1]
    row["spread_pct"] = float(np.ptp(errors))
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("items", nargs="+")
    parser.add_argument("--scenario", default="full_orbit")
    parser.add_argument("--seeds", type=int, default=3)
    args = parser.parse_args()
    table = pd.DataFrame([item_row(item, args.scenario, args.seeds) for item in args.items])
    write_table(table, figures_dir() / "completion_seeds", float_digits=2)
    print(table.to_string(index=False, float_format=lambda x: f"{x:+.2f}"))
    print(f"mean spread over {args.seeds} seeds: {table['spread_pct'].mean():.2f} % "
          f"(largest {table['spread_pct'].max():.2f} %)")


if __name__ == "__main__":
    main()
