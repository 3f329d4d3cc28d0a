"""Dense stereo's coverage and where its cloud lies, the default against a changed setting.

Usage: .venv/bin/python benchmarks/bench_dense_coverage.py [--scenario smooth]
       [--items banana pear ...] [--set dense.fill_min_views=1 ...] [--workers 2]

Per item of the full-size benchmark's scenario, on its SfM stage (reused from
data/bench-sfm/ITEM-SCENARIO/work, or run there), dense stereo and masking are run in memory
(nothing in the work folder changes) with the given masks, once with the default settings
and, when given, once with the ``--set`` ones (``SECTION.FIELD=VALUE`` of
:class:`volec.estimate.EstimateConfig`, as ``bench_volume.py``). Scored against the true
surface (read only to score): the share of the surface at least two cameras see that the
masked cloud covers within 2 mm (``coverage_pct``), the dense stage's time (``dense_s``), the
masked cloud's signed distance
(median, 10th and 90th percentile, mm), the same median after a rigid alignment to the truth
(what is the shape's own, not the poses' misplacement), and the fused cloud's median signed
distance near the surface (within 3 mm) before masking. Written to
figures/dense_coverage_compare_SCENARIO.{csv,md} (notebook 07 writes dense_coverage_smooth).
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np
import pandas as pd

from volec.dense import run_dense
from volec.estimate import EstimateConfig, with_settings
from volec.experiments import map_items, scenario_capture, scenarios
from volec.masking import mask_cloud
from volec.metrics import cloud_scores, rigid_alignment, signed_distances_to_surface
from volec.paths import experiment_dir, figures_dir
from volec.pipeline import run_sfm_stage
from volec.segment import given_masks
from volec.synth import load_ground_truth_mesh
from volec.tables import write_table

NEAR_SURFACE_M = 0.003


def coverage_rows(item: str, scenario_name: str, settings: tuple[str, ...]
                  ) -> list[dict[str, Any]]:
    """One row per config (the default, then ``settings``) for ``item``."""
    scenario = scenarios(False)[scenario_name]
    out = scenario.folder(experiment_dir(False), item)
    capture = scenario_capture(out, scenario)
    exact = scenario_capture(out, scenario, exact=True)
    truth = load_ground_truth_mesh(out)
    base = EstimateConfig()
    sfm, _ = run_sfm_stage(capture, scenario.work(out), base.sfm, stale="recompute")
    masks = given_masks(capture)
    changed = with_settings(base, settings)
    rows = []
    configs = [("default", base)] + ([(" ".join(settings), changed)] if settings else [])
    for name, cfg in configs:
        dense = run_dense(capture, masks, sfm.T_world_from_cam, sfm.registered, sfm.points_xyz,
                          cfg.dense, progress=False)
        masked = mask_cloud(dense.cloud, capture, masks, sfm.T_world_from_cam, sfm.registered,
                            cfg.masking)
        scores = cloud_scores(masked.cloud.xyz, truth, exact)
        fused = signed_distances_to_surface(dense.cloud.xyz, truth)
        fused = fused[np.abs(fused) < NEAR_SURFACE_M]
        T = rigid_alignment(masked.cloud.xyz, truth)
        aligned = signed_distances_to_surface(masked.cloud.xyz @ T[:3, :3].T + T[:3, 3], truth)
        rows.append({
            "item": item, "config": name, "food_points": len(masked.cloud),
            "dense_s": float(sum(dense.summary["timings_s"].values())),
            "coverage_pct": 100 * scores["completeness_visible"],
            "signed_median_mm": 1000 * scores["cloud_signed_median_m"],
            "signed_p10_mm": 1000 * scores["cloud_signed_p10_m"],
            "signed_p90_mm": 1000 * scores["cloud_signed_p90_m"],
            "aligned_signed_median_mm": 1000 * float(np.median(aligned)),
            "fused_signed_median_mm": 1000 * float(np.median(fused)),
        })
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="smooth")
    parser.add_argument("--items", nargs="+", default=["banana", "capsicum", "pear", "orange"])
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.FIELD=VALUE")
    parser.add_argument("--workers", type=int, default=1)
    args = parser.parse_args()
    jobs = [(item, args.scenario, tuple(args.set)) for item in args.items]
    per_item = map_items(coverage_rows, jobs, args.items, args.workers, progress=True)
    table = pd.DataFrame([row for rows in per_item for row in rows])
    write_table(table, figures_dir() / f"dense_coverage_compare_{args.scenario}", float_digits=3)
    print(table.to_string(index=False, float_format=lambda x: f"{x:.3f}"))
    means = table.groupby("config", sort=False)[["coverage_pct", "signed_median_mm",
                                                  "aligned_signed_median_mm"]].mean()
    print(means.to_string(float_format=lambda x: f"{x:.3f}"))


if __name__ == "__main__":
    main()
