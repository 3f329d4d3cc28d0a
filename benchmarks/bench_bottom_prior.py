"""Try priors for the unseen band under an item against the default (neither is in volec).

Usage: .venv/bin/python benchmarks/bench_bottom_prior.py [--items apple orange ...]
       [--scenario full_orbit]

On the stages of the volume benchmark (data/bench-sfm/ITEM-SCENARIO/work, reused when
notebook 02 or ``bench_volume.py`` made them with the current code, else recomputed), the
default estimate is made four times on one basis: as volec does it; with points added before
meshing that continue each azimuth sector's observed side profile (radius about the vertical
axis against height above the support plane, fitted to the lowest 10 mm seen) down to the
plate, by a quadratic and by a straight line, never widening downwards; and with the
completion network's points below the observed floor (the 1st percentile of the masked
cloud's heights) dropped. Prints the volume error (%) of each, against the ground truth (read
only to score). The priors are functions here, patched into ``volec.estimate`` for the run,
because they measured worse than the default (docs/measurements.md, "Where the remaining
error lies").
"""

from __future__ import annotations

import argparse

import numpy as np

import volec.estimate as estimate
from volec.experiments import scenario_capture, scenarios
from volec.geometry import horizontal_axes
from volec.meshing import SupportPlane
from volec.paths import experiment_dir
from volec.pipeline import run_stages
from volec.pointcloud import PointCloud
from volec.synth import load_ground_truth_mesh


def profile_continuation(masked: PointCloud, plane: SupportPlane, degree: int,
                         fit_m: float = 0.010, sectors: int = 72, bin_m: float = 0.001,
                         step_m: float = 0.0005) -> np.ndarray:
    """Points (N, 3) continuing each sector's observed outer profile (the 90th percentile of
    the radius per ``bin_m`` of height) from its lowest observed height down to the plate."""
    up = np.asarray(plane.normal, float)
    height = plane.height_m(masked.xyz)
    e1, e2 = horizontal_axes(up)
    flat = np.stack([masked.xyz @ e1, masked.xyz @ e2], axis=1)
    centre = np.median(flat, axis=0)
    rel = flat - centre
    radius, azimuth = np.hypot(rel[:, 0], rel[:, 1]), np.arctan2(rel[:, 1], rel[:, 0])
    sector = ((azimuth + np.pi) / (2 * np.pi) * sectors).astype(int) % sectors
    top = np.percentile(height, 99.5)
    added = []
    for s in range(sectors):
        profile = _sector_profile(height[sector == s], radius[sector == s], bin_m)
        if profile is None or not 2 * bin_m <= profile[0, 0] <= 0.5 * top:
            continue
        lowest = profile[0, 0]
        fit = profile[profile[:, 0] <= lowest + fit_m]
        if len(fit) < 4:
            continue
        coef = np.polyfit(fit[:, 0] - lowest, fit[:, 1], degree)
        heights = np.arange(lowest - step_m, 0.0, -step_m)
        radii = np.minimum.accumulate(np.clip(np.polyval(coef, heights - lowest), 0.0,
                                              np.polyval(coef, 0.0)))
        angles = -np.pi + (s + np.linspace(0.1, 0.9, 4)) * 2 * np.pi / sectors
        a, h = np.meshgrid(angles, heights)
        r = np.repeat(radii[:, None], len(angles), axis=1)
        x, y = centre[0] + r * np.cos(a), centre[1] + r * np.sin(a)
        added.append(x.reshape(-1, 1) * e1 + y.reshape(-1, 1) * e2
                     + (h.reshape(-1, 1) - plane.offset_m) * up)
    return np.concatenate(added) if added else np.zeros((0, 3))


def _sector_profile(height: np.ndarray, radius: np.ndarray, bin_m: float) -> np.ndarray | None:
    """(bins, 2): height bin centre and the 90th percentile radius, lowest first."""
    if len(height) < 20:
        return None
    bins = np.floor(height / bin_m).astype(int)
    return np.array([[(b + 0.5) * bin_m, np.percentile(radius[bins == b], 90)]
                     for b in np.unique(bins)])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--items", nargs="+", default=["apple", "orange", "lemon", "pear",
                                                        "chocolate_croissant", "yellow_cane"])
    parser.add_argument("--scenario", default="full_orbit")
    args = parser.parse_args()
    original_mesh, original_completion = estimate.mesh_cloud, estimate.complete_cloud
    degree: list[int | None] = [None]
    floor_m: list[float | None] = [None]

    def with_profile(cloud, plane, cfg, silhouettes=None, masked=None):  # noqa: ANN001, ANN202
        if degree[0] is not None and plane is not None and masked is not None:
            extra = profile_continuation(masked, plane, degree[0])
            cloud = PointCloud(np.concatenate([cloud.xyz, extra]), None,
                               np.concatenate([_normals(cloud), np.full(extra.shape, np.nan)]))
        return original_mesh(cloud, plane, cfg, silhouettes, masked)

    def above_floor(partial, model, cfg=None, up=None):  # noqa: ANN001, ANN202
        done = original_completion(partial, model, cfg, up)
        if floor_m[0] is None or up is None:
            return done
        keep = done.predicted_xyz @ np.asarray(up, float) >= floor_m[0]
        cloud = done.cloud.subset(np.concatenate([np.ones(len(partial), bool), keep]))
        return estimate.Completion(cloud, done.predicted_xyz[keep], done.normalization,
                                   {**done.summary, "predicted_kept": int(keep.sum())})

    estimate.mesh_cloud, estimate.complete_cloud = with_profile, above_floor
    cfg = estimate.EstimateConfig()
    model = estimate.load_completion_model(cfg)
    scenario = scenarios(False)[args.scenario]
    for item in args.items:
        out = scenario.folder(experiment_dir(False), item)
        capture = scenario_capture(out, scenario)
        stages = run_stages(capture, scenario.work(out), cfg.sfm, cfg.dense, cfg.masking,
                            stale="recompute", progress=False)
        basis = estimate.estimate_basis(capture, stages, cfg,
                                        estimate.food_silhouettes(capture, stages, cfg))
        truth_ml = load_ground_truth_mesh(out).volume * 1e6
        plane = basis.support[0]
        floor = (None if plane is None else
                 float(np.percentile(stages.masked.cloud.xyz @ np.asarray(plane.normal), 1.0)))
        errors = []
        for degree[0], floor_m[0] in ((None, None), (2, None), (1, None), (None, floor)):
            basis.meshes.clear()
            est = estimate.estimate_from_basis(capture, stages, model, cfg, basis)
            errors.append(100 * (est.food.volume_ml / truth_ml - 1))
        print(f"{item:22s} default {errors[0]:+.2f} %  quadratic {errors[1]:+.2f} %  "
              f"straight {errors[2]:+.2f} %  network above floor {errors[3]:+.2f} %", flush=True)


def _normals(cloud: PointCloud) -> np.ndarray:
    """The cloud's normals, NaN where it has none (as meshing reads them)."""
    if cloud.normals is None:
        return np.full((len(cloud), 3), np.nan)
    return cloud.normals


if __name__ == "__main__":
    main()
