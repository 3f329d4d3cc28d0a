"""How far the masked food cloud lies from the true surface, and the volume, as the food masks
are grown by more or fewer pixels before the masking test (``MaskingConfig.mask_dilation_px``).

Usage: .venv/bin/python benchmarks/bench_masking.py [--scenario full_orbit]
       [--items pear apple ...] [--dilations 1 2 3]

The same SfM and dense stages (run or reused under data/bench-sfm, as the notebooks do) are
masked once per dilation, then estimated with and without completion. Per item and dilation:
the masked cloud's median signed distance to the true surface (mm; + outside), the volume
error without and with completion (percent) and whether the estimate is trusted. Writes
figures/masking_dilation_SCENARIO.{csv,md} and prints it.
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import pandas as pd

from volec.estimate import (
    EstimateConfig,
    estimate_from_stages,
    food_silhouettes,
    load_completion_model,
)
from volec.experiments import ensure_capture, scenario_capture, scenarios
from volec.masking import mask_cloud
from volec.metrics import signed_distances_to_surface, signed_summary
from volec.paths import experiment_dir, figures_dir
from volec.pipeline import run_stages
from volec.scale import require_metric
from volec.synth import load_ground_truth_mesh
from volec.tables import write_table


def item_rows(item: str, scenario_name: str, dilations: list[int]) -> list[dict]:
    """One row per dilation for ``item``: cloud offset and volume errors."""
    cfg = EstimateConfig()
    scenario = scenarios(False)[scenario_name]
    out = ensure_capture(experiment_dir(False), item, scenario)
    capture = scenario_capture(out, scenario)
    stages = run_stages(capture, scenario.work(out), cfg.sfm, cfg.dense, cfg.masking,
                        stale="recompute", progress=False)
    truth = load_ground_truth_mesh(out)  # scoring only
    true_ml = float(truth.volume * 1e6)
    scale = require_metric(capture, cfg.scale)
    model = load_completion_model(cfg)
    rows = []
    for dilation in dilations:
        masked = mask_cloud(stages.dense.cloud, capture, stages.masks,
                            stages.sfm.T_world_from_cam, stages.sfm.registered,
                            replace(cfg.masking, mask_dilation_px=dilation))
        these = replace(stages, masked=masked)
        silhouettes = food_silhouettes(capture, these, cfg)
        bare = estimate_from_stages(capture, these, None, replace(cfg, use_completion=False),
                                    silhouettes, scale)
        full = estimate_from_stages(capture, these, model, cfg, silhouettes, scale)
        offset = signed_summary(signed_distances_to_surface(masked.cloud.xyz, truth), "cloud")
        rows.append({"item": item, "dilation_px": dilation, "food_points": len(masked.cloud),
                     **{k[:-2] + "_mm": 1000 * v for k, v in offset.items()},
                     "no_completion_error_pct": 100 * (bare.food.volume_ml / true_ml - 1),
                     "completion_error_pct": 100 * (full.food.volume_ml / true_ml - 1),
                     "trusted": full.trusted})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="full_orbit")
    parser.add_argument("--items", nargs="+", default=["pear", "apple", "banana", "empanadilla",
                                                       "chocolate_croissant", "lemon"])
    parser.add_argument("--dilations", nargs="+", type=int, default=[1, 2, 3])
    args = parser.parse_args()
    table = pd.DataFrame([row for item in args.items
                          for row in item_rows(item, args.scenario, args.dilations)])
    errors = ["no_completion_error_pct", "completion_error_pct"]
    mape = table.groupby("dilation_px")[errors].agg(lambda e: e.abs().mean()).reset_index()
    mape.insert(0, "item", "MAPE")
    table = pd.concat([table, mape], ignore_index=True)
    write_table(table, figures_dir() / f"masking_dilation_{args.scenario}", float_digits=3)
    print(table.to_string(index=False, float_format=lambda x: f"{x:.3f}"))


if __name__ == "__main__":
    main()
