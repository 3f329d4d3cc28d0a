"""Where along its height a benchmark estimate's mesh leaves the true surface, with the poses'
misplacement and scale taken out.

Usage: .venv/bin/python benchmarks/bench_height_bands.py ITEM [ITEM ...] [--scenario full_orbit]
       [--mesh mesh_completion.ply] [--bands 0 1.5 4 8 15]

Per item, the mesh a volume benchmark left in the scenario's work folder
(data/bench-sfm/ITEM-SCENARIO/work; a subset of the full orbit's frames, such as ``sparse``,
has its own beside it: data/bench-sfm/ITEM-full_orbit/work-sparse) (``--mesh``:
``mesh_completion.ply`` is the default method's, ``mesh_no_completion.ply`` the baseline's) and
its masked cloud are mapped onto the ground truth by the similarity that lays the SfM camera
centres on the exact ones (read only to score), so that a reconstruction the poses moved or
scaled evenly does not count. Then, per band of height above the true lowest point (mm), split
into surface facing down (normal within 45 degrees of straight down) and the rest: the share
of the mesh's area, its signed distance to the true surface (median, p10, p90, mm; positive
outside) and the volume that offset implies (mean signed distance times the band's area, % of
the true volume); the share of the true surface within 1 mm of a masked point; and the mesh's
and the truth's horizontal cross-section 0.2 mm above the true lowest point (mm²), where a
floor that does not reach the plate shows. Writes figures/height_bands_SCENARIO.{csv,md}.

notebook 05's ``surface_bands`` bins by share of the height in the capture's own frame; this
removes the poses' share first, which on a flat item is most of a raw signed distance.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd
import trimesh
from scipy.spatial import cKDTree

from volec.capture import read_transforms_json
from volec.experiments import scenarios
from volec.metrics import sample_surface_with_normals, signed_distances_to_surface
from volec.paths import experiment_dir, figures_dir
from volec.pointcloud import read_ply
from volec.sfm import fit_similarity, load_sfm
from volec.synth import load_truth
from volec.tables import write_table


def truth_from_reconstruction(folder: Path, work: Path) -> np.ndarray:
    """(4, 4) the similarity that lays the SfM camera centres in ``work`` on the exact ones
    of ``folder/ground_truth``."""
    sfm = load_sfm(work)
    exact = read_transforms_json(folder / "ground_truth" / "transforms_exact.json")
    by_name = {Path(f.name).stem: f.T_world_from_cam[:3, 3] for f in exact.frames}
    names = [Path(n).stem for n, ok in zip(sfm.frame_names, sfm.registered, strict=True) if ok]
    return fit_similarity(sfm.T_world_from_cam[sfm.registered][:, :3, 3],
                          np.array([by_name[n] for n in names]))


def cross_section_mm2(mesh: trimesh.Trimesh, height_m: float, step_m: float = 0.0004) -> float:
    """Area (mm²) of ``mesh``'s horizontal section at ``height_m`` (world y), counted on a
    grid of ``step_m``."""
    lower, upper = mesh.bounds[0] - 2 * step_m, mesh.bounds[1] + 2 * step_m
    x, z = np.meshgrid(np.arange(lower[0], upper[0], step_m), np.arange(lower[2], upper[2], step_m))
    points = np.column_stack([x.ravel(), np.full(x.size, height_m), z.ravel()])
    return float(mesh.contains(points).sum() * step_m * step_m * 1e6)


def item_rows(item: str, scenario: str, mesh_name: str, edges_mm: list[float]) -> list[dict]:
    """One row per band and orientation of ``item``'s mesh (see the module docstring)."""
    chosen = scenarios(False)[scenario]
    folder = chosen.folder(experiment_dir(False), item)
    work = chosen.work(folder)  # a subset scenario's stages lie beside the full orbit's
    if not np.allclose(load_truth(folder)["world_up"], [0.0, 1.0, 0.0]):
        raise SystemExit(f"{item}: world_up is not +y; the sections here are horizontal in y")
    T = truth_from_reconstruction(folder, work)
    truth = trimesh.load(folder / "ground_truth" / "food_mesh.ply")
    mesh = trimesh.load(work / mesh_name)
    mesh.apply_transform(T)
    cloud = read_ply(work / "food_masked.ply").xyz @ T[:3, :3].T + T[:3, 3]
    points, normals = sample_surface_with_normals(mesh, 40000)
    signed = signed_distances_to_surface(points, truth)
    truth_points, truth_normals = sample_surface_with_normals(truth, 40000)
    covered = cKDTree(cloud).query(truth_points)[0] < 0.001
    bottom = float(truth.vertices[:, 1].min())
    floor = {"mesh_section_0p2_mm2": cross_section_mm2(mesh, bottom + 0.0002),
             "truth_section_0p2_mm2": cross_section_mm2(truth, bottom + 0.0002)}
    height, truth_height = points[:, 1] - bottom, truth_points[:, 1] - bottom
    edges = [e / 1000 for e in edges_mm] + [np.inf]
    rows = []
    for low, high in zip(edges[:-1], edges[1:], strict=True):
        for facing, down, truth_down in (("down", normals[:, 1] < -0.7,
                                          truth_normals[:, 1] < -0.7),
                                         ("other", normals[:, 1] >= -0.7,
                                          truth_normals[:, 1] >= -0.7)):
            here = (height >= low) & (height < high) & down
            truth_here = (truth_height >= low) & (truth_height < high) & truth_down
            if here.sum() < 50:
                continue
            p10, median, p90 = 1000 * np.percentile(signed[here], [10, 50, 90])
            rows.append({"item": item, "band_low_mm": 1000 * low, "band_high_mm": 1000 * high,
                         "facing": facing, "area_share": float(here.mean()),
                         "signed_median_mm": median, "signed_p10_mm": p10, "signed_p90_mm": p90,
                         "offset_implies_pct": float(100 * signed[here].mean() * mesh.area
                                                     * here.mean() / truth.volume),
                         "truth_covered_share": (float(covered[truth_here].mean())
                                                 if truth_here.any() else np.nan), **floor})
    rows.append({"item": item, "facing": "all", "area_share": 1.0,
                 "signed_median_mm": 1000 * float(np.median(signed)),
                 "volume_error_pct": 100 * (mesh.volume / truth.volume - 1), **floor})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("items", nargs="+")
    parser.add_argument("--scenario", default="full_orbit")
    parser.add_argument("--mesh", default="mesh_completion.ply")
    parser.add_argument("--bands", nargs="+", type=float, default=[0, 1.5, 4, 8, 15])
    args = parser.parse_args()
    table = pd.DataFrame([row for item in args.items
                          for row in item_rows(item, args.scenario, args.mesh, args.bands)])
    write_table(table, figures_dir() / f"height_bands_{args.scenario}", float_digits=3)
    print(table.to_string(index=False, float_format=lambda x: f"{x:.3f}"))


if __name__ == "__main__":
    main()
