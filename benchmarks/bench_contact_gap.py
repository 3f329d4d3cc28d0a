"""How much of each item's volume error lies in the gap under it that no camera can see into.

Usage: .venv/bin/python benchmarks/bench_contact_gap.py [--scenarios full_orbit ...]
       [--items apple orange ...] [--workers 2] [--set section.field=value ...]

A benchmark item rests on its lowest point (the eight with a flat base settle 2 mm onto the
plate first: :data:`volec.synth.shapes.FLAT_BASE_SETTLE_MM`); where its underside is not
flat, a thin gap lies between it and the plate. Near the footprint's edge a camera's grazing
ray can slip into the gap and see the plate through it; farther in, a ray from the lowest
camera of the capture would have to fall more than the gap is high
(:func:`volec.metrics.hidden_columns`), so nothing tells that space from food. On the stages
of the volume benchmark (reused when the current code made them), the default estimate is
made once and its mesh rigidly aligned to the ground truth by the masked cloud (read only to
score). Per item: the volume error, the truth's whole gap under it and the hidden part of it
(% of the true volume), the part of the hidden gap the estimate fills, and the error with
that part taken off. Written to figures/contact_gap_SCENARIO.{csv,md}.
"""

from __future__ import annotations

from typing import Any

STEP_M = 0.0005
"""Spacing of the columns under the item, metres."""


def contact_gap_row(item: str, scenario_name: str, settings: tuple[str, ...] = ()
                    ) -> dict[str, Any]:
    """One item: the default's volume error and the share of it in the hidden gap."""
    import numpy as np

    from volec.estimate import (
        EstimateConfig,
        estimate_from_stages,
        food_silhouettes,
        load_completion_model,
        with_settings,
    )
    from volec.experiments import benchmark_stages
    from volec.metrics import (
        bottom_gap,
        elevations_deg,
        hidden_columns,
        rigid_alignment,
        volume_below_gap,
    )
    from volec.synth import load_ground_truth_mesh, load_truth

    cfg = with_settings(EstimateConfig(), settings)
    bench = benchmark_stages(item, scenario_name, cfg)
    capture, stages = bench.capture, bench.stages
    est = estimate_from_stages(capture, stages, load_completion_model(cfg), cfg,
                               food_silhouettes(capture, stages, cfg))
    truth = load_ground_truth_mesh(bench.folder)
    up = np.asarray(load_truth(bench.folder).get("world_up", [0.0, 0.0, 1.0]), float)
    masked = stages.masked.cloud.xyz
    mesh = est.food.mesh.mesh.copy()
    mesh.apply_transform(rigid_alignment(masked[::5], truth))
    sfm = stages.sfm
    centres = sfm.T_world_from_cam[sfm.registered][:, :3, 3]
    lowest = float(elevations_deg(centres, masked.mean(axis=0), est.view_up).min())
    base, gap, edge = bottom_gap(truth, up, STEP_M)
    hidden = hidden_columns(gap, edge, lowest)
    truth_m3 = truth.volume
    filled = volume_below_gap(mesh, base[hidden], gap[hidden], up, STEP_M)
    err = 100 * (est.food.volume_ml / bench.truth_ml - 1)
    return {"item": item, "scenario": scenario_name, "gt_ml": bench.truth_ml,
            "err_pct": err, "lowest_camera_deg": lowest,
            "gap_pct": 100 * gap.sum() * STEP_M**2 / truth_m3,
            "hidden_gap_pct": 100 * gap[hidden].sum() * STEP_M**2 / truth_m3,
            "hidden_area_pct": 100 * hidden.mean(),
            "filled_hidden_pct": 100 * filled / truth_m3,
            "err_without_hidden_pct": err - 100 * filled / truth_m3}


def main() -> None:
    from volec.experiments import on_off_arguments, on_off_table

    args = on_off_arguments(__doc__.splitlines()[0], "underside.enabled=false", ["full_orbit"])
    for name in args.scenarios:
        raw = on_off_table(contact_gap_row, name, args, "contact_gap")
        print(f"{name}: {len(raw)} items, MAPE {raw['err_pct'].abs().mean():.2f} %, with the "
              f"filled hidden gap taken off {raw['err_without_hidden_pct'].abs().mean():.2f} %; "
              f"mean signed {raw['err_pct'].mean():+.2f} -> "
              f"{raw['err_without_hidden_pct'].mean():+.2f} %")
        print(raw.drop(columns=["scenario", "gt_ml"]).round(2).to_string(index=False))


if __name__ == "__main__":
    main()
