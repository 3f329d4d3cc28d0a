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

import argparse
from typing import Any

import pandas as pd
from scipy.stats import ttest_rel

from volec.experiments import benchmark_stages, map_items
from volec.paths import figures_dir
from volec.synth import item_names
from volec.tables import write_table


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
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", nargs="+", default=["full_orbit", "half_orbit", "sparse"])
    parser.add_argument("--items", nargs="+", default=item_names())
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.FIELD=VALUE",
                        help="change a setting of the default, e.g. "
                             "meshing.food_cover.rounds=0 (no enclosed space's check)")
    args = parser.parse_args()
    for name in args.scenarios:
        jobs = [(item, name, tuple(args.set)) for item in args.items]
        raw = pd.DataFrame(map_items(cover_row, jobs, [f"{i} {name}" for i, _, _ in jobs],
                                     args.workers, progress=True))
        write_table(raw, figures_dir() / f"mask_cover_{name}", float_digits=2)
        before, after = raw["unchecked_err_pct"].abs(), raw["default_err_pct"].abs()
        p = ttest_rel(after, before).pvalue if len(raw) > 1 and (after != before).any() else None
        print(f"{name}: {len(raw)} items, MAPE without the check {before.mean():.2f} %, "
              f"with it (default) {after.mean():.2f} % (paired p {p}); repaired "
              f"{int((raw['repairs'] > 0).sum())}")
        enclosed = raw["before_enclosed_check_err_pct"].abs()
        print(f"  before the enclosed space's check {enclosed.mean():.2f} %; repaired "
              f"{int((raw['enclosed_repairs'] > 0).sum())}")
        print(raw.drop(columns=["scenario", "gt_ml"]).round(2).to_string(index=False))


if __name__ == "__main__":
    main()
