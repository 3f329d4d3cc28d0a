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

import argparse
from dataclasses import replace
from typing import Any

import pandas as pd
from scipy.stats import ttest_rel

from volec.experiments import benchmark_stages, map_items
from volec.paths import figures_dir
from volec.synth import item_names
from volec.tables import write_table


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
            "symmetric": record.get("symmetric"),
            "kept": record.get("kept", 0), "seconds": record.get("seconds")}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", nargs="+", default=["full_orbit"])
    parser.add_argument("--items", nargs="+", default=item_names())
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.FIELD=VALUE",
                        help="change a setting of the default, e.g. underside.min_facing_out=0.5")
    args = parser.parse_args()
    for name in args.scenarios:
        jobs = [(item, name, tuple(args.set)) for item in args.items]
        raw = pd.DataFrame(map_items(underside_row, jobs, [f"{i} {name}" for i, _, _ in jobs],
                                     args.workers, progress=True))
        write_table(raw, figures_dir() / f"underside_{name}", float_digits=2)
        before, after = raw["without_err_pct"].abs(), raw["default_err_pct"].abs()
        p = ttest_rel(after, before).pvalue if len(raw) > 1 and (after != before).any() else None
        print(f"{name}: {len(raw)} items, MAPE without the underside {before.mean():.2f} %, "
              f"with it (default) {after.mean():.2f} % (paired p {p}); mean signed error "
              f"{raw['without_err_pct'].mean():+.2f} -> {raw['default_err_pct'].mean():+.2f} %")
        print(raw.drop(columns=["scenario", "gt_ml"]).round(2).to_string(index=False))


if __name__ == "__main__":
    main()
