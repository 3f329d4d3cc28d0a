"""Measure what the trust checks see on benchmark captures, and what masking's tolerance of one
outlying view changes.

Usage: .venv/bin/python benchmarks/bench_trust.py [--items apple banana ...] [--scenario NAME]
       [--workers 2]

Per item (the capture and its stages under data/bench-sfm, shared with notebooks 01-05, run or
reused by the volume experiment): the true volume; the estimate with completion under the
default masking rule (a point may fall outside one view's mask) and under the paper's strict
rule (outside none); the masked points each rule keeps; the spread of the three SfM scale
estimates; the share of the volume the network's points decide; the carved fraction; and the
trust reasons. Written to figures/trust_benchmark.{csv,md}.
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import pandas as pd

from volec.capture import read_transforms_json
from volec.estimate import (
    EstimateConfig,
    estimate_from_stages,
    food_silhouettes,
    load_completion_model,
)
from volec.experiments import ensure_capture, scenarios, volume_experiment
from volec.masking import mask_cloud
from volec.paths import experiment_dir, figures_dir
from volec.pipeline import run_stages
from volec.scale import require_metric
from volec.synth import item_names
from volec.tables import write_table
from volec.trust import scale_disagreement_pct


def item_row(root, item: str, scenario, cfg: EstimateConfig, model) -> dict:
    """The measurements of one item (its stages are reused from the volume experiment)."""
    out = ensure_capture(root, item, scenario)
    capture = read_transforms_json(out / "capture")
    scale = require_metric(capture, cfg.scale)
    stages = run_stages(capture, out / "work", cfg.sfm, cfg.dense, cfg.masking,
                        stale="recompute", progress=False)
    strict_cfg = replace(cfg.masking, max_outside_views=0)
    strict = mask_cloud(stages.dense.cloud, capture, stages.masks, stages.sfm.T_world_from_cam,
                        stages.sfm.registered, strict_cfg)
    silhouettes = food_silhouettes(capture, stages, cfg)
    default = estimate_from_stages(capture, stages, model, cfg, silhouettes, scale)
    strict_stages = replace(stages, masked=strict)
    strict_est = estimate_from_stages(capture, strict_stages, model, cfg, silhouettes, scale)
    s = stages.sfm.summary
    return {
        "item": item,
        "default_rule_kept": stages.masked.report["kept"],
        "strict_rule_kept": strict.report["kept"],
        "default_rule_ml": default.food.volume_ml,
        "strict_rule_ml": strict_est.food.volume_ml,
        "scale_spread_pct": scale_disagreement_pct(
            (s["scale_drift_model"], s["scale_short_baseline"], s["scale_sim3_all"])),
        "completion_share": default.food.completion_share,
        "carved_fraction": default.food.mesh.report.get("carved_fraction", 0.0),
        "dropped_volume_ml": default.food.mesh.report.get("dropped_volume_ml", 0.0),
        "far_points_dropped": default.food.mesh.report.get("far_points_dropped", 0),
        "reasons": ",".join(r.code for r in default.reasons) or "-",
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--items", nargs="+", default=item_names())
    parser.add_argument("--scenario", default="full_orbit")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    root = experiment_dir(False)
    scenario = scenarios(False)[args.scenario]
    cfg = EstimateConfig()
    raw = volume_experiment(root, args.items, scenario, cfg, workers=args.workers)
    model = load_completion_model(cfg)
    rows = pd.DataFrame([item_row(root, item, scenario, cfg, model) for item in args.items])
    rows.insert(1, "gt_ml", raw["gt_ml"].to_numpy())
    for rule in ("default_rule", "strict_rule"):
        rows[f"{rule}_err_pct"] = 100 * (rows[f"{rule}_ml"] / rows["gt_ml"] - 1)
    print(rows.to_string(index=False))
    print("mean absolute error: default rule "
          f"{rows['default_rule_err_pct'].abs().mean():.2f} %, strict rule "
          f"{rows['strict_rule_err_pct'].abs().mean():.2f} %")
    write_table(rows, figures_dir() / f"trust_benchmark_{args.scenario}", float_digits=3)


if __name__ == "__main__":
    main()
