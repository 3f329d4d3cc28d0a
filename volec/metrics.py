"""Geometric scores of a reconstruction against a ground-truth surface.

In: point clouds (metres), a closed ground-truth mesh (trimesh, same frame) and, for what a
capture could see, the exact cameras of the capture. Out: distances and scores as floats and
arrays: accuracy (cloud to surface), completeness (surface to cloud) split into the part the
cameras saw and the part they could not (the bottom), and the Chamfer distance; and signed
distances (positive outside the true surface), which show a systematic offset that unsigned
ones hide, with the volume an offset of a mesh implies.
"""

from __future__ import annotations

import numpy as np
import trimesh
from scipy import ndimage
from scipy.spatial import cKDTree

from volec.capture import Capture
from volec.geometry import horizontal_axes
from volec.meshing import ray_scene


def distances_to_surface(points: np.ndarray, mesh: trimesh.Trimesh) -> np.ndarray:
    """Unsigned distance (N,) from each point to the mesh surface, metres (open3d's exact
    point-triangle distance)."""
    import open3d as o3d

    scene = ray_scene(mesh)
    query = o3d.core.Tensor(np.asarray(points, np.float32).reshape(-1, 3))
    return scene.compute_distance(query).numpy().astype(float)


def signed_distances_to_surface(points: np.ndarray, mesh: trimesh.Trimesh) -> np.ndarray:
    """Signed distance (N,) from each point to a closed mesh's surface, metres: positive
    outside, negative inside. Computed in millimetres about the mesh's centre, so float32
    keeps sub-micrometre precision (open3d works in float32)."""
    import open3d as o3d

    centre = np.asarray(mesh.bounds, float).mean(axis=0)
    local = trimesh.Trimesh((np.asarray(mesh.vertices) - centre) * 1000.0, mesh.faces,
                            process=False)
    scene = ray_scene(local)
    query = o3d.core.Tensor(((np.asarray(points, float).reshape(-1, 3) - centre) * 1000.0)
                            .astype(np.float32))
    return scene.compute_signed_distance(query).numpy().astype(float) / 1000.0


def signed_summary(signed_m: np.ndarray, prefix: str) -> dict[str, float]:
    """Median, 10th and 90th percentile of signed distances, as ``{prefix}_signed_*_m``."""
    p10, median, p90 = np.percentile(signed_m, [10, 50, 90]) if len(signed_m) else [np.nan] * 3
    return {f"{prefix}_signed_median_m": float(median), f"{prefix}_signed_p10_m": float(p10),
            f"{prefix}_signed_p90_m": float(p90)}


def rigid_alignment(points: np.ndarray, truth: trimesh.Trimesh, max_distance_m: float = 0.003,
                    seed: int = 0) -> np.ndarray:
    """The rigid transform (4x4, no scale) that best lays ``points`` (samples of a closed
    reconstruction) onto the true surface: point-to-plane ICP from the identity. A
    reconstruction that is offset evenly all round needs none; one misplaced by its poses
    does."""
    import open3d as o3d

    target_xyz, faces = trimesh.sample.sample_surface(truth, 4 * len(points), seed=seed)
    target = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(target_xyz)))
    target.normals = o3d.utility.Vector3dVector(np.asarray(truth.face_normals[faces]))
    source = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points)))
    result = o3d.pipelines.registration.registration_icp(
        source, target, max_distance_m, np.eye(4),
        o3d.pipelines.registration.TransformationEstimationPointToPlane(),
        o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=50))
    return np.asarray(result.transformation)


def mesh_offset_scores(mesh: trimesh.Trimesh, truth: trimesh.Trimesh, n_samples: int = 20000,
                       seed: int = 0, prefix: str = "mesh") -> dict[str, float]:
    """How far a reconstructed closed mesh lies outside (+) or inside (-) the true surface:
    the signed distances of area-uniform samples of it (median, p10, p90), and the volume
    that offset implies, mean signed distance times the mesh's area (``_offset_ml``), also
    as a percentage of the true volume. The same after the rigid alignment
    (:func:`rigid_alignment`) that takes away a misplacement by the poses (``_aligned_*``;
    ``_misplacement_m``: how far the alignment moved the mesh's centre): what is left is the
    shape's own offset, and the scale's."""
    samples = sample_surface(mesh, n_samples, seed)
    signed = signed_distances_to_surface(samples, truth)
    implied_ml = float(signed.mean() * mesh.area * 1e6)
    T = rigid_alignment(samples, truth, seed=seed)
    aligned = signed_distances_to_surface(samples @ T[:3, :3].T + T[:3, 3], truth)
    centre = np.asarray(mesh.centroid)
    return {**signed_summary(signed, prefix), f"{prefix}_offset_ml": implied_ml,
            f"{prefix}_offset_pct": 100.0 * implied_ml / float(truth.volume * 1e6),
            **signed_summary(aligned, f"{prefix}_aligned"),
            f"{prefix}_misplacement_m": float(np.linalg.norm(T[:3, :3] @ centre + T[:3, 3]
                                                             - centre))}


def sample_surface(mesh: trimesh.Trimesh, n: int, seed: int = 0) -> np.ndarray:
    """``n`` points spread uniformly by area over the mesh surface (seeded)."""
    points, _ = trimesh.sample.sample_surface(mesh, n, seed=seed)
    return np.asarray(points, float)


def sample_surface_with_normals(mesh: trimesh.Trimesh, n: int, seed: int = 0
                                ) -> tuple[np.ndarray, np.ndarray]:
    """(``n`` points spread uniformly by area over the mesh surface, their faces' unit
    normals), both (n, 3), seeded."""
    points, faces = trimesh.sample.sample_surface(mesh, n, seed=seed)
    return np.asarray(points, float), np.asarray(mesh.face_normals[faces], float)


def views_seeing(points: np.ndarray, mesh: trimesh.Trimesh, capture: Capture,
                 tolerance_m: float = 5e-4, normals: np.ndarray | None = None,
                 min_cosine: float = 0.0) -> np.ndarray:
    """Per surface point (N,), how many of the capture's cameras see it: it projects into the
    image and the ray from the camera meets the mesh no earlier than the point itself. With
    the points' outward ``normals``, a camera counts only where the cosine between the normal
    and the direction to the camera is at least ``min_cosine`` (dense stereo's limit on how
    obliquely a surface may be seen)."""
    from trimesh.ray.ray_pyembree import RayMeshIntersector

    rays = RayMeshIntersector(mesh)
    count = np.zeros(len(points), int)
    for frame in capture.frames:
        T = frame.T_cam_from_world
        cam = points @ T[:3, :3].T + T[:3, 3]
        uv = frame.intrinsics.project(cam)
        w, h = frame.intrinsics.width, frame.intrinsics.height
        ok = np.all(np.isfinite(uv), axis=1)
        ok[ok] = ((uv[ok, 0] >= -0.5) & (uv[ok, 0] < w - 0.5)
                  & (uv[ok, 1] >= -0.5) & (uv[ok, 1] < h - 0.5))
        idx = np.flatnonzero(ok)
        if not len(idx):
            continue
        origin = frame.camera_centre
        offset = points[idx] - origin
        dist = np.linalg.norm(offset, axis=1)
        direction = offset / dist[:, None]
        if normals is not None:
            frontal = np.einsum("ij,ij->i", normals[idx], -direction) >= min_cosine
            idx, dist, direction = idx[frontal], dist[frontal], direction[frontal]
            if not len(idx):
                continue
        hits, ray_idx, _ = rays.intersects_location(
            np.repeat(origin[None], len(idx), axis=0), direction, multiple_hits=False
        )
        first = np.full(len(idx), np.inf)
        first[ray_idx] = np.linalg.norm(hits - origin, axis=1)
        count[idx] += first >= dist - tolerance_m
    return count


def nearest_distances(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Distance (N,) from each source point to its nearest target point, metres."""
    if len(target) == 0:
        return np.full(len(source), np.inf)
    return cKDTree(target).query(source, workers=-1)[0]


def chamfer_distance(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """(Chamfer-L1, Chamfer-L2) between two point sets: the mean of the two directions' mean
    nearest-neighbour distances, and the same with squared distances."""
    ab, ba = nearest_distances(a, b), nearest_distances(b, a)
    return float((ab.mean() + ba.mean()) / 2), float(((ab**2).mean() + (ba**2).mean()) / 2)


def cloud_scores(cloud_xyz: np.ndarray, mesh: trimesh.Trimesh, exact: Capture,
                 threshold_m: float = 0.002, n_samples: int = 30000, min_views: int = 2,
                 seed: int = 0) -> dict[str, float]:
    """Accuracy and completeness of a food cloud against the true food surface.

    Accuracy: median and 95th percentile of the cloud's distances to the surface, and the
    median, 10th and 90th percentile of its signed distances (``cloud_signed_*``).
    Completeness: the fraction of surface samples within ``threshold_m`` of the cloud, over
    the samples at least ``min_views`` exact cameras see (``visible``) and over the rest
    (``unseen``: what completion has to supply).
    """
    d_acc = distances_to_surface(cloud_xyz, mesh)
    signed = signed_distances_to_surface(cloud_xyz, mesh)
    samples = sample_surface(mesh, n_samples, seed)
    seen = views_seeing(samples, mesh, exact) >= min_views
    d_comp = nearest_distances(samples, cloud_xyz)
    close = d_comp <= threshold_m
    return {
        "points": float(len(cloud_xyz)),
        "accuracy_median_m": float(np.median(d_acc)),
        "accuracy_p95_m": float(np.percentile(d_acc, 95)),
        **signed_summary(signed, "cloud"),
        "completeness_visible": float(close[seen].mean()) if seen.any() else float("nan"),
        "completeness_unseen": float(close[~seen].mean()) if (~seen).any() else float("nan"),
        "completeness_all": float(close.mean()),
        "visible_surface_fraction": float(seen.mean()),
    }


def height_band_offsets(mesh: trimesh.Trimesh, truth: trimesh.Trimesh, cloud_xyz: np.ndarray,
                        up: np.ndarray, edges: tuple[float, ...] = (0.0, 0.1, 0.2, 0.35, 0.5,
                                                                    0.75, 1.0),
                        coverage_m: float = 0.0015, n_samples: int = 20000, seed: int = 0
                        ) -> list[dict[str, float]]:
    """Where on the item a mesh's offset lies, by height above the item's lowest point.

    The true item's height along ``up`` is cut into bands at ``edges`` (fractions of that
    height). Per band: the share of the true surface in it, the share of that surface within
    ``coverage_m`` of a point of ``cloud_xyz`` (what stereo reconstructed there), the median
    signed distance of the mesh's area-uniform samples in the band (metres, + outside) and
    the volume those samples' offset implies (signed distance times their share of the mesh's
    area) as a percentage of the true volume. The bands' volume shares add up to the whole
    mesh's implied offset (:func:`mesh_offset_scores`), so the rows say which band the volume
    error comes from: on an orbit, the lower bands are the ones no camera sees face-on."""
    up = np.asarray(up, float) / np.linalg.norm(up)
    heights = np.asarray(truth.vertices) @ up
    bottom, height = heights.min(), heights.max() - heights.min()
    truth_samples = sample_surface(truth, n_samples, seed)
    covered = nearest_distances(truth_samples, np.asarray(cloud_xyz, float)) <= coverage_m
    mesh_samples = sample_surface(mesh, n_samples, seed)
    signed = signed_distances_to_surface(mesh_samples, truth)
    sample_area = mesh.area / n_samples
    true_band = np.digitize((truth_samples @ up - bottom) / height, edges[1:-1])
    mesh_band = np.digitize((mesh_samples @ up - bottom) / height, edges[1:-1])
    rows = []
    for band, (low, high) in enumerate(zip(edges[:-1], edges[1:], strict=True)):
        in_truth, in_mesh = true_band == band, mesh_band == band
        rows.append({
            "band_low": float(low), "band_high": float(high),
            "true_area_share": float(in_truth.mean()),
            "cloud_coverage": float(covered[in_truth].mean()) if in_truth.any() else np.nan,
            "mesh_signed_median_m": (float(np.median(signed[in_mesh])) if in_mesh.any()
                                     else np.nan),
            "mesh_offset_pct": float(100.0 * signed[in_mesh].sum() * sample_area
                                     / truth.volume)})
    return rows


def bottom_gap(mesh: trimesh.Trimesh, up: np.ndarray, step_m: float = 0.0005
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The space between a resting item's underside and the plane of its lowest point.

    Per column of a horizontal grid ``step_m`` apart under ``mesh``'s footprint: the point (M,
    3) where the column meets that plane, the height (M,) of the mesh's lowest surface above
    it, and the column's distance (M,) to the footprint's edge (metres). A vertical ray from
    below finds each column's lowest surface."""
    up = np.asarray(up, float) / np.linalg.norm(up)
    side, other = horizontal_axes(up)
    vertices = np.asarray(mesh.vertices, float)
    bottom = float((vertices @ up).min())
    u, v = vertices @ side, vertices @ other
    us = np.arange(u.min() + step_m / 2, u.max(), step_m)
    vs = np.arange(v.min() + step_m / 2, v.max(), step_m)
    grid_u, grid_v = (a.ravel() for a in np.meshgrid(us, vs, indexing="ij"))
    base = np.outer(grid_u, side) + np.outer(grid_v, other) + bottom * up
    below = base - 0.01 * up
    hits, rays, _ = mesh.ray.intersects_location(below, np.tile(up, (len(base), 1)),
                                                 multiple_hits=False)
    gap = np.full(len(base), np.nan)
    gap[rays] = hits @ up - bottom
    footprint = np.isfinite(gap).reshape(len(us), len(vs))
    edge = ndimage.distance_transform_edt(footprint).ravel() * step_m
    inside = footprint.ravel()
    return base[inside], gap[inside], edge[inside]


def elevations_deg(points: np.ndarray, centre: np.ndarray, up: np.ndarray) -> np.ndarray:
    """The elevation (N,) in degrees of each of ``points`` (N, 3) seen from ``centre``: the
    angle of the direction to it above the plane through ``centre`` normal to ``up``."""
    up = np.asarray(up, float) / np.linalg.norm(up)
    rel = np.asarray(points, float) - centre
    return np.degrees(np.arcsin(np.clip(rel @ up / np.linalg.norm(rel, axis=1), -1.0, 1.0)))


def hidden_columns(gap_m: np.ndarray, edge_m: np.ndarray, lowest_elevation_deg: float
                   ) -> np.ndarray:
    """(M,) True where no camera at ``lowest_elevation_deg`` above the plane or higher can see
    into a column of :func:`bottom_gap`: a ray that slips under the footprint's edge and
    reaches the column falls by more than the column's gap on its way in (the underside
    taken no lower than the column's own gap all the way to the edge)."""
    return edge_m * np.tan(np.radians(lowest_elevation_deg)) > gap_m


def volume_below_gap(estimate: trimesh.Trimesh, base: np.ndarray, gap_m: np.ndarray,
                     up: np.ndarray, step_m: float, depth_m: float = 0.003,
                     dz_m: float = 0.0001) -> float:
    """Volume (m^3) of the closed ``estimate`` inside the columns of :func:`bottom_gap`
    (``base`` points, ``step_m`` wide) between ``depth_m`` below the plane and the true
    underside ``gap_m`` above it: what the estimate puts where the item is not, under it."""
    up = np.asarray(up, float) / np.linalg.norm(up)
    total = 0.0
    heights = np.arange(-depth_m + dz_m / 2, float(np.max(gap_m, initial=0.0)), dz_m)
    for part in np.array_split(np.arange(len(base)), max(1, len(base) * len(heights) // 2_000_000)):
        points = base[part, None] + heights[None, :, None] * up
        under = heights[None] < gap_m[part, None]
        inside = estimate.contains(points[under])
        total += float(inside.sum())
    return total * dz_m * step_m**2
