"""The default estimate with and without the rim points (where the food masks' outlines place
the surface under an item's widest level, :mod:`volec.rims`).

Usage: .venv/bin/python benchmarks/bench_rims.py [--scenarios full_orbit half_orbit ...]
       [--items apple orange ...] [--workers 2] [--set section.field=value ...]

On the stages of the volume benchmark (data/bench-sfm/ITEM-SCENARIO/work, reused when the
notebooks or ``bench_volume.py`` made them with the current code, else recomputed), the default
estimate is made twice on one basis, with the rim points and without (the same support plane,
space and views). Per item: both volume errors against the ground truth (read only to score),
how many rim points were placed and kept, the median stretch along which a ray ran inside the
hull, the seconds they took, and where they lie against the true surface (signed distance,
median and p10/p90, after the masked cloud's own rigid alignment to the truth, which leaves
the capture's scale error in); per scenario both MAPEs and a paired t-test of the absolute
errors. Written to figures/rims_SCENARIO.{csv,md}.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from volec.experiments import benchmark_stages, on_off_arguments, on_off_table, paired_errors


def rims_row(item: str, scenario_name: str, settings: tuple[str, ...] = ()) -> dict[str, Any]:
    """One item: the default's volume error with the rim points and without, and where the
    rim points lie against the true surface."""
    from volec.estimate import (
        EstimateConfig,
        estimate_basis,
        estimate_from_basis,
        food_silhouettes,
        load_completion_model,
        with_settings,
    )
    from volec.metrics import rigid_alignment, signed_distances_to_surface
    from volec.synth import load_ground_truth_mesh

    cfg = with_settings(EstimateConfig(), settings)
    bench = benchmark_stages(item, scenario_name, cfg)
    capture, stages = bench.capture, bench.stages
    model = load_completion_model(cfg)
    silhouettes = food_silhouettes(capture, stages, cfg)
    basis = estimate_basis(capture, stages, cfg, silhouettes)
    with_rims = estimate_from_basis(capture, stages, model, cfg, basis)
    off = replace(cfg, rims=replace(cfg.rims, enabled=False))
    without = estimate_from_basis(capture, stages, model, off,
                                  replace(basis, rims=None, rims_record=None, meshes={},
                                          settings=(*basis.settings[:-1], off.rims)))
    record = basis.rims_record or {}
    row = {"item": item, "scenario": scenario_name, "gt_ml": bench.truth_ml,
           "without_rims_err_pct": 100 * (without.food.volume_ml / bench.truth_ml - 1),
           "default_err_pct": 100 * (with_rims.food.volume_ml / bench.truth_ml - 1),
           "rays": record.get("rays", 0), "placed": record.get("placed", 0),
           "kept": record.get("kept", 0), "median_stretch_mm": record.get("median_stretch_mm"),
           "rims_s": record.get("seconds")}
    if basis.rims is not None and len(basis.rims):
        truth = load_ground_truth_mesh(bench.folder)
        T = rigid_alignment(stages.masked.cloud.xyz[::5], truth)
        placed = basis.rims.xyz @ T[:3, :3].T + T[:3, 3]
        signed_mm = signed_distances_to_surface(placed, truth) * 1000
        row.update({f"rims_signed_{name}_mm": float(np.percentile(signed_mm, q))
                    for name, q in (("p10", 10), ("median", 50), ("p90", 90))})
    return row


def main() -> None:
    args = on_off_arguments(__doc__.splitlines()[0], "rims.max_contact_m=0.012", ["full_orbit"])
    for name in args.scenarios:
        raw = on_off_table(rims_row, name, args, "rims")
        e = paired_errors(raw["without_rims_err_pct"], raw["default_err_pct"])
        print(f"{name}: {len(raw)} items, MAPE without rims {e['mape_without']:.2f} %, with them "
              f"(default) {e['mape_with']:.2f} % (paired p {e['p']}); mean signed error "
              f"{e['mean_without']:+.2f} -> {e['mean_with']:+.2f} %")
        print(raw.drop(columns=["scenario", "gt_ml"]).round(2).to_string(index=False))

if __name__ == "__main__":
    main()
