"""The default estimate with and without the meshing's checks on the shape prior's points.

Usage: .venv/bin/python benchmarks/bench_mask_cover.py [--scenarios full_orbit half_orbit ...]
       [--items apple orange ...] [--workers 2] [--set meshing.food_cover.rounds=0]

On the stages of the volume benchmark (data/bench-sfm/ITEM-SCENARIO/work, reused when the
notebooks or ``bench_volume.py`` made them with the current code, else recomputed), the
default estimate is made once: its mesh report (``mask_cover``, see
:class:`volec.meshing.MaskCoverConfig`) holds the volume and the uncovered share of the mesh
made before the check (the default without it) beside the final ones, so both come from one
run on the same stages. Per item: both volume errors against the ground truth (read only to
score), the 90th-percentile view's uncovered share of the food masks before and after, how
many repairs were kept and how many prior points they dropped;
per scenario both MAPEs and a paired t-test of the absolute errors. The check that the mesh
holds the space the seen surface encloses (:class:`volec.meshing.FoodCoverConfig`, on by
default; ``--set meshing.food_cover.rounds=0`` turns it off) runs after it; its record gives
the volume before it (``before_enclosed_check_err_pct``), the missed share before and after,
and its repairs.
Written to figures/mask_cover_SCENARIO.{csv,md}.
"""

from __future__ import annotations

from typing import Any

from volec.experiments import benchmark_stages, on_off_arguments, on_off_table, paired_errors


def cover_row(item: str, scenario_name: str, settings: tuple[str, ...] = ()
              ) -> dict[str, Any]:
    """One item: the default's volume error with the masks' check and without it, and
    with the enclosed space's check (when ``settings`` turn it on) and without it."""
    from volec.estimate import (
        EstimateConfig,
        estimate_from_stages,
        food_silhouettes,
        load_completion_model,
        with_settings,
    )

    cfg = with_settings(EstimateConfig(), settings)
    bench = benchmark_stages(item, scenario_name, cfg)
    capture, stages, truth_ml = bench.capture, bench.stages, bench.truth_ml
    est = estimate_from_stages(capture, stages, load_completion_model(cfg), cfg,
                               food_silhouettes(capture, stages, cfg))
    cover = est.food.mesh.report.get("mask_cover") or {}
    enclosed = est.food.mesh.report.get("food_cover") or {}
    before_ml = cover.get("first_volume_ml", est.food.volume_ml)
    before_enclosed_ml = enclosed.get("first_volume_ml", est.food.volume_ml)
    return {"item": item, "scenario": scenario_name, "gt_ml": truth_ml,
            "before_enclosed_check_err_pct": 100 * (before_enclosed_ml / truth_ml - 1),
            "enclosed_missed_before_pct": 100 * enclosed.get("first_missed_share", float("nan")),
            "enclosed_missed_after_pct": 100 * enclosed.get("missed_share", float("nan")),
            "enclosed_repairs": enclosed.get("repairs", 0),
            "unchecked_err_pct": 100 * (before_ml / truth_ml - 1),
            "default_err_pct": 100 * (est.food.volume_ml / truth_ml - 1),
            "uncovered_before_pct": 100 * cover.get("first_uncovered_p90", float("nan")),
            "uncovered_after_pct": 100 * cover.get("uncovered_p90", float("nan")),
            "repairs": cover.get("repairs", 0),
            "prior_points_dropped": cover.get("prior_points_dropped", 0)}


def main() -> None:
    args = on_off_arguments(__doc__.splitlines()[0],
                            "meshing.food_cover.rounds=0 (no enclosed space's check)",
                            ["full_orbit", "half_orbit", "sparse"])
    for name in args.scenarios:
        raw = on_off_table(cover_row, name, args, "mask_cover")
        e = paired_errors(raw["unchecked_err_pct"], raw["default_err_pct"])
        print(f"{name}: {len(raw)} items, MAPE without the check {e['mape_without']:.2f} %, "
              f"with it (default) {e['mape_with']:.2f} % (paired p {e['p']}); repaired "
              f"{int((raw['repairs'] > 0).sum())}")
        enclosed = raw["before_enclosed_check_err_pct"].abs()
        print(f"  before the enclosed space's check {enclosed.mean():.2f} %; repaired "
              f"{int((raw['enclosed_repairs'] > 0).sum())}")
        print(raw.drop(columns=["scenario", "gt_ml"]).round(2).to_string(index=False))

if __name__ == "__main__":
    main()
