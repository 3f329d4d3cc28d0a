"""The default estimate with and without the mirrored views, on the same stages.

Usage: .venv/bin/python benchmarks/bench_mirror_views.py [--scenarios full_orbit half_orbit ...]
       [--items apple orange ...] [--workers 2]

On the stages of the volume benchmark (data/bench-sfm/ITEM-SCENARIO/work, reused when
notebook 02/05/07 or ``bench_volume.py`` made them with the current code, else recomputed),
the default estimate (completion ``auto``) is made three times: without the views reflected
in the food's vertical mirror plane (``off``), with them carving wherever their hull allows
(``everywhere``, ``MirrorViewsConfig.spare_seen_food`` off: the code at a89e84b) and with
them carving only space the cameras did not show to be food (``on``, the default). Per item:
the volume errors against the ground truth (read only to score), the plane's fit and how
many reflected views carved; per scenario the MAPE of each and paired t-tests of the
absolute errors (``on`` against ``off`` and against ``everywhere``). Written to
figures/mirror_views_SCENARIO.{csv,md}.
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


def mirror_row(item: str, scenario_name: str) -> dict[str, Any]:
    """One item: the default estimate's volume error with and without the mirrored views."""
    from volec.estimate import (
        EstimateConfig,
        estimate_basis,
        estimate_from_basis,
        food_silhouettes,
        load_completion_model,
    )

    on = EstimateConfig()
    off = replace(on, mirror_views=replace(on.mirror_views, enabled=False))
    everywhere = replace(on, mirror_views=replace(on.mirror_views, spare_seen_food=False))
    bench = benchmark_stages(item, scenario_name, on)
    capture, stages, truth_ml = bench.capture, bench.stages, bench.truth_ml
    model = load_completion_model(on)
    silhouettes = food_silhouettes(capture, stages, on)
    row: dict[str, Any] = {"item": item, "scenario": scenario_name, "gt_ml": truth_ml}
    for tag, cfg in (("off", off), ("everywhere", everywhere), ("on", on)):
        est = estimate_from_basis(capture, stages, model, cfg,
                                  estimate_basis(capture, stages, cfg, silhouettes))
        row[f"{tag}_ml"] = est.food.volume_ml
        row[f"{tag}_err_pct"] = 100 * (est.food.volume_ml / truth_ml - 1)
        if tag == "on" and est.mirror_views is not None:
            fit = est.mirror_views["fit"] or {}
            row |= {"symmetric": fit.get("symmetric"),
                    "reflected_median_mm": fit.get("reflected_median_distance_mm"),
                    "views_carving": est.mirror_views["views_carving"]}
    return row


def summary(raw: pd.DataFrame) -> dict[str, Any]:
    """MAPE of each variant, and paired t-tests of the default's absolute errors against
    the other two's."""
    errors = {tag: raw[f"{tag}_err_pct"].abs() for tag in ("off", "everywhere", "on")}
    out: dict[str, Any] = {"items": len(raw)}
    for tag, error in errors.items():
        out[f"mape_{tag}_pct"] = error.mean()
    for other in ("off", "everywhere"):
        test = ttest_rel(errors["on"], errors[other]) if len(raw) > 1 else None
        out[f"p_{other}"] = None if test is None else float(test.pvalue)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", nargs="+", default=["full_orbit", "half_orbit", "sparse"])
    parser.add_argument("--items", nargs="+", default=item_names())
    parser.add_argument("--workers", type=int, default=1)
    args = parser.parse_args()
    for name in args.scenarios:
        jobs = [(item, name) for item in args.items]
        raw = pd.DataFrame(map_items(mirror_row, jobs, [f"{i} {name}" for i, _ in jobs],
                                     args.workers, progress=True))
        write_table(raw, figures_dir() / f"mirror_views_{name}", float_digits=2)
        s = summary(raw)
        print(f"{name}: {s['items']} items, default MAPE without mirrored views "
              f"{s['mape_off_pct']:.2f} %, carving everywhere {s['mape_everywhere_pct']:.2f} %,"
              f" sparing seen food (default) {s['mape_on_pct']:.2f} % (paired p against "
              f"without {s['p_off']}, against everywhere {s['p_everywhere']})")
        print(raw[["item", "off_err_pct", "everywhere_err_pct", "on_err_pct", "symmetric",
                   "reflected_median_mm", "views_carving"]].round(2).to_string(index=False))


if __name__ == "__main__":
    main()
