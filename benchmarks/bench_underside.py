"""The default estimate with and without the underside's horizontal mirror (the food's upper part
reflected below its mirror level where no camera constrained the space, :mod:`volec.underside`).

Usage: .venv/bin/python benchmarks/bench_underside.py [--scenarios full_orbit half_orbit ...]
       [--items apple orange ...] [--workers 2] [--set section.field=value ...]

On the stages of the volume benchmark (data/bench-sfm/ITEM-SCENARIO/work, reused when the
notebooks or ``bench_volume.py`` made them with the current code, else recomputed), the default
estimate is made twice on one basis (the same support plane, space, views and rim points),
with the underside's points and without. Per item: both volume errors against the ground truth
(read only to score), the mirror level found, how well the reflection met the cloud and how
many points were kept; per scenario both MAPEs and a paired t-test of
the absolute errors. Written to figures/underside_SCENARIO.{csv,md}.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from volec.experiments import benchmark_stages, on_off_arguments, on_off_table, paired_errors


def underside_row(item: str, scenario_name: str, settings: tuple[str, ...] = ()
                  ) -> dict[str, Any]:
    """One item: the default's volume error with the underside's points and without, and the
    mirror's fit."""
    from volec.estimate import (
        EstimateConfig,
        estimate_basis,
        estimate_from_basis,
        food_silhouettes,
        load_completion_model,
        with_settings,
    )

    cfg = with_settings(EstimateConfig(), settings)
    bench = benchmark_stages(item, scenario_name, cfg)
    capture, stages = bench.capture, bench.stages
    model = load_completion_model(cfg)
    basis = estimate_basis(capture, stages, cfg, food_silhouettes(capture, stages, cfg))
    with_it = estimate_from_basis(capture, stages, model, cfg, basis)
    off = replace(cfg, underside=replace(cfg.underside, enabled=False))
    without = estimate_from_basis(capture, stages, model, off, basis)
    record = (with_it.food.completion_summary or {}).get("underside", {})
    return {"item": item, "scenario": scenario_name, "gt_ml": bench.truth_ml,
            "without_err_pct": 100 * (without.food.volume_ml / bench.truth_ml - 1),
            "default_err_pct": 100 * (with_it.food.volume_ml / bench.truth_ml - 1),
            "mirror_height_mm": record.get("mirror_height_mm"),
            "reflected_median_mm": record.get("reflected_median_distance_mm"),
            "symmetric": record.get("symmetric"), "squash": record.get("squash"),
            "kept": record.get("kept", 0), "seconds": record.get("seconds")}


def main() -> None:
    args = on_off_arguments(__doc__.splitlines()[0], "underside.min_facing_out=0.5",
                            ["full_orbit"])
    for name in args.scenarios:
        raw = on_off_table(underside_row, name, args, "underside")
        e = paired_errors(raw["without_err_pct"], raw["default_err_pct"])
        print(f"{name}: {len(raw)} items, MAPE without the underside {e['mape_without']:.2f} %, "
              f"with it (default) {e['mape_with']:.2f} % (paired p {e['p']}); mean signed error "
              f"{e['mean_without']:+.2f} -> {e['mean_with']:+.2f} %")
        print(raw.drop(columns=["scenario", "gt_ml"]).round(2).to_string(index=False))

if __name__ == "__main__":
    main()
