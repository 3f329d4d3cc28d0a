"""Compare SfM settings on the same captures, in one run: by default the stage's two mappings,
triangulation from the AR poses plus bundle adjustment (``known_poses``, the default) against
COLMAP's incremental mapping from scratch (``incremental``, the default before); any of
:data:`VARIANTS` with ``--variants`` (fewer features, fewer pairs, no second mapping round,
fewer bundle-adjustment iterations).

Usage: .venv/bin/python benchmarks/bench_sfm_mapping.py [--items apple banana ...]
       [--scenarios full_orbit sparse ...] [--variants known_poses features_2048 ...]

Each (item, scenario) runs the whole stage (features, matching, mapping, alignment) once per
variant, from scratch in a temporary folder, one after the other, and is scored against the
exact poses (:func:`volec.sfm.evaluate_sfm`). A failed run is a row with its error. Prints the
table, the mean per variant and each variant's time over the first's; writes
figures/sfm_mapping.{csv,md}.
"""

from __future__ import annotations

import argparse
import logging
import tempfile
import time
from pathlib import Path

import pandas as pd

from volec.errors import VolecError
from volec.experiments import Scenario, ensure_capture, scenario_capture, scenarios
from volec.paths import experiment_dir, figures_dir
from volec.sfm import SfmConfig, evaluate_sfm, run_sfm
from volec.tables import write_table

VARIANTS: dict[str, SfmConfig] = {
    "incremental": SfmConfig(mapping="incremental"),
    "known_poses": SfmConfig(),
    "features_2048": SfmConfig(max_num_features=2048),
    "pairs_8": SfmConfig(pair_max_per_image=8),
    "neighbours_4": SfmConfig(sequential_overlap=4, pair_max_per_image=8),
    "neighbours_3": SfmConfig(sequential_overlap=3, pair_max_per_image=6),
    "features_2048_pairs_8": SfmConfig(max_num_features=2048, pair_max_per_image=8),
    "rounds_0": SfmConfig(known_pose_rounds=0),
    "ba_iterations_15": SfmConfig(ba_max_iterations=15),
}
"""Named SfM settings (``known_poses`` is the stage's default)."""


def variant_run(out: Path, scenario: Scenario, name: str) -> dict[str, object]:
    """One from-scratch SfM of the scenario's capture in ``out`` with the variant ``name``,
    scored."""
    reported = scenario_capture(out, scenario)
    exact = scenario_capture(out, scenario, exact=True)
    row: dict[str, object] = {"variant": name, "frames": len(reported)}
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        try:
            result = run_sfm(reported, Path(tmp), VARIANTS[name])
        except VolecError as error:
            return {**row, "error": f"{type(error).__name__}: {error}"[:120]}
        wall = time.perf_counter() - start
    errors = evaluate_sfm(result, exact, reported)
    return {**row, "wall_s": wall, **result.summary["timings_s"],
            "mapping_used": result.summary["mapping"],
            "registered": errors["registered_fraction"],
            "centre_err_mm": 1000 * errors["centre_err_median_m"],
            "ar_centre_err_mm": 1000 * errors["ar_centre_err_median_m"],
            "rot_err_deg": errors["rot_err_median_deg"],
            "scale_err_pct": errors["scale_err_pct"],
            "reprojection_px": result.summary["reprojection_error_px"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--items", nargs="+", default=["apple", "banana", "pear"])
    parser.add_argument("--scenarios", nargs="+", default=["full_orbit"])
    parser.add_argument("--variants", nargs="+", default=["incremental", "known_poses"],
                        choices=sorted(VARIANTS))
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    root = experiment_dir(False)
    rows = []
    for scenario_name in args.scenarios:
        scenario = scenarios(False)[scenario_name]
        for item in args.items:
            out = ensure_capture(root, item, scenario)
            for name in args.variants:
                row = {"item": item, "scenario": scenario_name,
                       **variant_run(out, scenario, name)}
                print(row, flush=True)
                rows.append(row)
    table = pd.DataFrame(rows)
    write_table(table, figures_dir() / "sfm_mapping", float_digits=3)
    numeric = ["wall_s", "extract_s", "match_s", "map_s", "centre_err_mm", "rot_err_deg",
               "scale_err_pct"]
    table["abs_scale_err_pct"] = table["scale_err_pct"].abs()
    means = table.groupby(["scenario", "variant"])[numeric + ["abs_scale_err_pct"]].mean()
    print(table.to_string(index=False, float_format=lambda x: f"{x:.3f}"))
    print(means.to_string(float_format=lambda x: f"{x:.3f}"))
    first = args.variants[0]
    for scenario_name in args.scenarios:
        wall = means.loc[scenario_name, "wall_s"]
        for name in args.variants[1:]:
            print(f"{scenario_name}: {name} / {first} wall time {wall[name] / wall[first]:.2f}")


if __name__ == "__main__":
    main()
