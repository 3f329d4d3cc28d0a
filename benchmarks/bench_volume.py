"""The whole pipeline on the benchmark for one capture scenario: Table I and where the surface
lies, as notebooks 04-05 write them for the full orbit.

Usage: .venv/bin/python benchmarks/bench_volume.py [--scenario full_orbit_sharp]
       [--items apple banana ...] [--workers 2] [--set dense.ncc_window_px=9 ...]

The captures and stage results live under data/bench-sfm (shared with the notebooks; keyed on
the config and the code, so nothing stale is reused). Writes
figures/table1_volume_SCENARIO.{csv,md}, figures/surface_offset_SCENARIO.{csv,md} and
figures/table2_SCENARIO.{csv,md} (the methods side by side, as notebook 07), and prints
them. ``full_orbit_sharp`` is the full orbit rendered with the first benchmark's look
(one ray per pixel, a point light, no blur), for comparison with the phone look of
``full_orbit``. ``--set SECTION.FIELD=VALUE`` (repeatable) runs a changed default config
(:func:`volec.estimate.with_setting`); its stages and rows replace the default's in the work
folders, so compare in a copy of data/ (``VOLEC_DATA_DIR``) to keep both.
"""

from __future__ import annotations

import argparse

from volec.estimate import EstimateConfig, with_setting
from volec.experiments import (
    method_table,
    pose_scale_errors,
    scenarios,
    surface_offset_table,
    volume_experiment,
    volume_table,
)
from volec.paths import experiment_dir, figures_dir
from volec.synth import item_names
from volec.tables import write_table


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="full_orbit_sharp")
    parser.add_argument("--items", nargs="+", default=item_names())
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.FIELD=VALUE",
                        help="change one setting of the default config (repeatable)")
    args = parser.parse_args()
    cfg = EstimateConfig()
    for setting in args.set:
        cfg = with_setting(cfg, setting)
    scenario = scenarios(False)[args.scenario]
    raw = volume_experiment(experiment_dir(False), args.items, scenario, cfg,
                            workers=args.workers)
    scale_err_pct = pose_scale_errors(experiment_dir(False), args.items, scenario)
    for name, table in (("table1_volume", volume_table(raw)),
                        ("surface_offset", surface_offset_table(raw, scale_err_pct=scale_err_pct)),
                        ("table2", method_table(raw))):
        write_table(table, figures_dir() / f"{name}_{args.scenario}", float_digits=3)
        print(table.to_string(index=False, float_format=lambda x: f"{x:.3f}"))


if __name__ == "__main__":
    main()
