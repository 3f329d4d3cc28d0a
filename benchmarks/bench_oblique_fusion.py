"""Dense fusion with and without the oblique hole filling (``DenseConfig.min_oblique_cosine``
0.5, the default, against 0.2) on the same captures and the same SfM: dense time and the
volume error with and without network completion, per item.

Usage: OMP_NUM_THREADS=1 .venv/bin/python benchmarks/bench_oblique_fusion.py ITEM [ITEM ...]

The full-orbit captures and stages live under data/bench-sfm, as for bench_volume.py; each
item's stages are recomputed for both settings. Writes figures/oblique_fusion.{csv,md}. The
ground truth is read only to score.
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
from volec.paths import experiment_dir, figures_dir
from volec.pipeline import run_stages
from volec.scale import require_metric
from volec.synth import load_ground_truth_mesh
from volec.tables import write_table


def item_rows(item: str, base: EstimateConfig) -> list[dict]:
    """One row per setting of ``min_oblique_cosine`` for ``item``."""
    scenario = scenarios(False)["full_orbit"]
    out = ensure_capture(experiment_dir(False), item, scenario)
    capture = scenario_capture(out, scenario)
    truth_ml = load_ground_truth_mesh(out).volume * 1e6
    model = load_completion_model(replace(base, use_completion=True))
    rows = []
    for cosine in (base.dense.min_view_cosine, 0.2):
        cfg = replace(base, dense=replace(base.dense, min_oblique_cosine=cosine))
        stages = run_stages(capture, scenario.work(out), cfg.sfm, cfg.dense, cfg.masking,
                            stale="recompute", progress=False)
        silhouettes = food_silhouettes(capture, stages, cfg)
        scale = require_metric(capture, cfg.scale)
        row = {"item": item, "min_oblique_cosine": cosine, "dense_s": stages.seconds["dense_s"],
               "food_points": len(stages.masked.cloud.xyz)}
        for tag, net in (("no_completion", None), ("completion", model)):
            variant = replace(cfg, use_completion=net is not None, completion_method="network")
            food = estimate_from_stages(capture, stages, net, variant, silhouettes, scale).food
            row[f"{tag}_error_pct"] = 100 * (food.volume_ml - truth_ml) / truth_ml
        rows.append(row)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("items", nargs="+")
    args = parser.parse_args()
    table = pd.DataFrame([r for item in args.items for r in item_rows(item, EstimateConfig())])
    write_table(table, figures_dir() / "oblique_fusion", float_digits=2)
    print(table.to_string(index=False))
    by_setting = table.groupby("min_oblique_cosine")
    print("dense seconds, summed:", by_setting["dense_s"].sum().to_dict())
    for tag in ("no_completion", "completion"):
        print(f"{tag} MAPE %:", by_setting[f"{tag}_error_pct"].apply(lambda e: e.abs().mean())
              .round(2).to_dict())


if __name__ == "__main__":
    main()
