"""How much of each benchmark estimate's volume error is the capture's metric scale.

Usage: .venv/bin/python benchmarks/bench_scale_share.py [--scenario full_orbit]
       [--items apple orange ...] [--errors figures/rims_full_orbit.csv --column default_err_pct]

Per item, from the SfM stage the volume benchmark cached (data/bench-sfm/ITEM-SCENARIO/work/sfm,
reused when the current code made it, else recomputed) and the capture's exact camera poses
(ground truth, read only to score): the length scale of the metric SfM camera centres against
the exact ones (the RMS spread about their centroids), the same for the AR-reported centres
the scale was taken from, and the volume error that scale alone makes (scale^3 - 1). With
``--errors`` (a table with ``item`` and an error column in %), each error with that share
taken out: (1 + error) / scale^3 - 1, and both MAPEs and mean signed errors. Written to
figures/scale_share_SCENARIO.{csv,md}.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from volec.capture import read_transforms_json
from volec.estimate import EstimateConfig
from volec.experiments import benchmark_stages, scenarios
from volec.paths import experiment_dir, figures_dir
from volec.synth import item_names
from volec.tables import write_table


def spread_scale(centres: np.ndarray, reference: np.ndarray) -> float:
    """The RMS distance of ``centres`` (N, 3) from their centroid over that of
    ``reference``'s: a length scale free of where either frame's origin lies."""
    ours = np.linalg.norm(centres - centres.mean(axis=0), axis=1)
    theirs = np.linalg.norm(reference - reference.mean(axis=0), axis=1)
    return float(np.sqrt((ours**2).sum() / (theirs**2).sum()))


def scale_row(item: str, scenario_name: str) -> dict[str, float | str]:
    """One item: the SfM and AR length scales against the exact poses and their volume
    effect."""
    bench = benchmark_stages(item, scenario_name, EstimateConfig())
    folder = scenarios(False)[scenario_name].folder(experiment_dir(False), item)
    exact = read_transforms_json(folder / "ground_truth" / "transforms_exact.json")
    exact_by_name = {Path(f.name).stem: f.T_world_from_cam[:3, 3] for f in exact.frames}
    ar_by_name = {Path(f.name).stem: f.T_world_from_cam[:3, 3] for f in bench.capture.frames}
    sfm = bench.stages.sfm
    names = [Path(n).stem for n, ok in zip(sfm.frame_names, sfm.registered, strict=True) if ok]
    sfm_centres = sfm.T_world_from_cam[sfm.registered][:, :3, 3]
    truth = np.array([exact_by_name[n] for n in names])
    sfm_scale = spread_scale(sfm_centres, truth)
    ar_scale = spread_scale(np.array([ar_by_name[n] for n in names]), truth)
    return {"item": item, "sfm_scale": sfm_scale, "ar_scale": ar_scale,
            "scale_volume_err_pct": 100 * (sfm_scale**3 - 1),
            "ar_scale_volume_err_pct": 100 * (ar_scale**3 - 1)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="full_orbit")
    parser.add_argument("--items", nargs="+", default=item_names())
    parser.add_argument("--errors", type=Path, help="a table with item and error columns")
    parser.add_argument("--column", default="default_err_pct")
    args = parser.parse_args()
    raw = pd.DataFrame([scale_row(item, args.scenario) for item in args.items])
    if args.errors is not None:
        errors = pd.read_csv(args.errors).set_index("item")[args.column]
        raw["err_pct"] = raw["item"].map(errors)
        raw["err_without_scale_pct"] = 100 * ((1 + raw["err_pct"] / 100)
                                              / raw["sfm_scale"]**3 - 1)
        for column in ("err_pct", "err_without_scale_pct"):
            print(f"{column}: MAPE {raw[column].abs().mean():.2f} %, mean signed "
                  f"{raw[column].mean():+.2f} %")
    write_table(raw, figures_dir() / f"scale_share_{args.scenario}", float_digits=3)
    print(f"scale alone: MAPE {raw['scale_volume_err_pct'].abs().mean():.2f} %, mean signed "
          f"{raw['scale_volume_err_pct'].mean():+.2f} %; AR's own "
          f"{raw['ar_scale_volume_err_pct'].abs().mean():.2f} %")
    print(raw.round(3).to_string(index=False))


if __name__ == "__main__":
    main()
