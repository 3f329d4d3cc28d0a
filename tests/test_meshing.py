"""Meshing: closed meshes of analytic shapes, the support plane cut, support plane fitting."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from volec.capture import Intrinsics
from volec.geometry import look_at_opencv
from volec.meshing import (
    MeshingConfig,
    MeshingError,
    SilhouetteView,
    SupportConfig,
    SupportPlane,
    behind_observed,
    closed_surface,
    consistent_views,
    fit_support_plane,
    mask_contradiction,
    mesh_cloud,
    oriented_normals,
    signed_distance_grid,
    signed_mask_distance,
    silhouette_field,
    silhouette_view,
    silhouette_views,
)
from volec.pointcloud import PointCloud
from volec.segment import given_masks
from volec.volume import volume_ml

FAST = MeshingConfig(poisson_depth=7, grid_voxel_m=0.002, thinning_voxel_m=0.0)


def _sphere_cloud(radius_m: float, n: int, centre=(0.1, -0.2, 0.3), normals: bool = True
                  ) -> PointCloud:
    rng = np.random.default_rng(0)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return PointCloud(np.asarray(centre) + radius_m * d, None, d if normals else None)


def test_a_sphere_cloud_meshes_to_the_sphere_volume():
    r = 0.04
    result = mesh_cloud(_sphere_cloud(r, 20000), None, FAST)
    assert result.mesh.is_watertight and result.mesh.is_winding_consistent
    truth = 4 / 3 * np.pi * r**3 * 1e6  # 268.1 mL
    assert volume_ml(result.mesh) == pytest.approx(truth, rel=0.02)


def test_the_support_plane_cuts_a_sphere_into_a_cap():
    # A sphere of radius r whose centre lies h above the plane: the part above is a spherical
    # segment of height r + h, volume pi k^2 (3 r - k) / 3 with k = r + h.
    r, h = 0.04, 0.01
    centre = np.array([0.0, 0.0, h])
    plane = SupportPlane((0.0, 0.0, 1.0), 0.0, 1000, 0.0)
    result = mesh_cloud(_sphere_cloud(r, 20000, centre), plane, FAST)
    k = r + h
    truth = np.pi * k**2 * (3 * r - k) / 3 * 1e6
    assert result.mesh.is_watertight
    assert volume_ml(result.mesh) == pytest.approx(truth, rel=0.02)
    assert result.mesh.vertices[:, 2].min() > -1e-3  # nothing below the table
    assert result.report["points_below_support"] > 0


def test_points_without_normals_are_turned_outwards():
    cloud = _sphere_cloud(0.03, 3000, normals=False)
    normals = oriented_normals(cloud)
    outward = cloud.xyz - cloud.xyz.mean(axis=0)
    assert (np.sum(normals * outward, axis=1) > 0).all()
    # given normals set the direction even when they point inwards
    flipped = PointCloud(cloud.xyz, None, -outward / np.linalg.norm(outward, axis=1)[:, None])
    assert (np.sum(oriented_normals(flipped) * outward, axis=1) < 0).all()


def test_closed_surface_of_a_field_touching_the_grid_border_is_still_closed():
    axes = np.arange(20) * 0.01
    x, y, z = np.meshgrid(axes, axes, axes, indexing="ij")
    mesh = closed_surface(z - 0.105, np.zeros(3), 0.01)  # inside: below z = 0.105
    assert mesh.is_watertight and mesh.is_winding_consistent
    # the border is forced outside, so the surface closes within a voxel beyond the grid
    assert 0.19 * 0.19 * 0.105 < mesh.volume < 0.21 * 0.21 * 0.115


def test_closed_surface_of_two_cones_touching_at_a_grid_point_is_two_closed_pieces():
    # an hourglass: two cones (radius and height 15 voxels) whose apexes meet on a grid point
    # where the field is 0; merging the vertices that lie there made the surface non-manifold
    # (the croissant carved from noisy masks lost its body that way)
    axes = np.arange(40) - 20.0
    x, y, z = np.meshgrid(axes, axes, axes, indexing="ij")
    r = np.hypot(x, y)
    field = np.maximum.reduce([(r - np.abs(z)) / np.sqrt(2), np.abs(z) - 15, r - 15]) * 0.001
    mesh = closed_surface(field, np.zeros(3), 0.001)
    assert mesh.is_watertight
    pieces = mesh.split(only_watertight=False)
    assert len(pieces) == 2 and all(p.is_watertight for p in pieces)
    cones_m3 = 2 * np.pi * 0.015**2 * 0.015 / 3
    assert mesh.volume == pytest.approx(cones_m3, rel=0.04)  # the grid blunts the tips


def test_fit_support_plane_finds_the_table_under_a_sphere():
    rng = np.random.default_rng(1)
    tilt = np.radians(3.0)
    normal = np.array([np.sin(tilt), 0.0, np.cos(tilt)])
    u = np.cross(normal, [0, 1, 0])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    a, b = rng.uniform(-0.1, 0.1, (2, 5000))
    noise = rng.normal(0, 2e-4, (5000, 1))
    table = (0.02 + noise) * normal + a[:, None] * u + b[:, None] * v
    food = _sphere_cloud(0.03, 5000, centre=0.02 * normal + 0.03 * normal)
    scene = PointCloud(np.concatenate([table, food.xyz]))
    plane = fit_support_plane(scene, food, up=np.array([0.0, 0.0, 1.0]))
    assert np.degrees(np.arccos(np.dot(plane.normal, normal))) < 0.5
    assert plane.height_m(np.array([[0.0, 0.0, 0.0]]))[0] == pytest.approx(-0.02, abs=5e-4)
    assert plane.tilt_deg == pytest.approx(3.0, abs=0.5)
    with pytest.raises(MeshingError, match="tilted"):
        fit_support_plane(scene, food, up=np.array([1.0, 0.0, 0.0]))
    with pytest.raises(MeshingError, match="not food"):
        fit_support_plane(food, food)


def test_the_support_search_widens_until_it_holds_enough_table():
    # the table is seen only in a ring 2.3-2.8 food radii from the food's centre (what SIFT
    # leaves beside a sparse capture): the plane is found there, at its true height
    rng = np.random.default_rng(2)
    r = 0.03
    food = _sphere_cloud(r, 5000, centre=np.array([0.0, 0.0, r]))
    radius_99 = float(np.percentile(np.linalg.norm(food.xyz - food.xyz.mean(axis=0), axis=1),
                                    99))
    angle = rng.uniform(0, 2 * np.pi, 1500)
    apart = rng.uniform(2.3, 2.8, 1500) * radius_99
    ring = np.stack([apart * np.cos(angle), apart * np.sin(angle),
                     rng.normal(0, 2e-4, 1500)], axis=1) + food.xyz.mean(axis=0) * [1, 1, 0]
    scene = PointCloud(np.concatenate([ring, food.xyz]))
    plane = fit_support_plane(scene, food, up=np.array([0.0, 0.0, 1.0]))
    assert plane.height_m(np.zeros((1, 3)))[0] == pytest.approx(0.0, abs=5e-4)
    assert plane.inliers > 1000
    narrow = SupportConfig(max_search_radius_factor=2.0)
    with pytest.raises(MeshingError, match="within 2 food radii"):
        fit_support_plane(scene, food, up=np.array([0.0, 0.0, 1.0]), cfg=narrow)


def test_a_stray_point_far_away_is_dropped_and_does_not_stretch_the_grid():
    r = 0.04
    sphere = _sphere_cloud(r, 20000)
    stray = PointCloud(np.vstack([sphere.xyz, [[5.0, 5.0, 5.0]]]), None,
                       np.vstack([sphere.normals, [[1.0, 0.0, 0.0]]]))
    result = mesh_cloud(stray, None, FAST)
    assert result.report["far_points_dropped"] == 1
    assert np.prod(result.report["grid_shape"]) < 2e5  # about the sphere, not 5 m across
    assert volume_ml(result.mesh) == pytest.approx(4 / 3 * np.pi * r**3 * 1e6, rel=0.02)


def test_a_cloud_too_large_for_one_item_is_a_clear_error():
    # two clouds 1.5 m apart: neither is a stray, and no food item spans them (at 2 mm the
    # grid would have 1.6e6 points; the limit here is 1e6)
    a, b = _sphere_cloud(0.04, 5000, (0, 0, 0)), _sphere_cloud(0.04, 5000, (1.5, 0, 0))
    both = PointCloud(np.vstack([a.xyz, b.xyz]), None, np.vstack([a.normals, b.normals]))
    with pytest.raises(MeshingError, match=r"spans 15\d\d x .* mm.*not one food item"):
        mesh_cloud(both, None, replace(FAST, max_grid_points=1_000_000))


def test_the_volume_of_dropped_pieces_is_reported():
    big, small = _sphere_cloud(0.04, 20000, (0, 0, 0)), _sphere_cloud(0.015, 5000, (0.07, 0, 0))
    cloud = PointCloud(np.vstack([big.xyz, small.xyz]), None,
                       np.vstack([big.normals, small.normals]))
    result = mesh_cloud(cloud, None, FAST)
    assert result.report["pieces_dropped"] == 1
    assert result.report["dropped_volume_ml"] == pytest.approx(
        4 / 3 * np.pi * 0.015**3 * 1e6, rel=0.1)
    assert volume_ml(result.mesh) == pytest.approx(4 / 3 * np.pi * 0.04**3 * 1e6, rel=0.02)


def test_too_few_points_are_refused():
    with pytest.raises(MeshingError, match="at least"):
        mesh_cloud(_sphere_cloud(0.03, 100), None, FAST)



def _sphere_silhouette(intr: Intrinsics, T_world_from_cam: np.ndarray, centre: np.ndarray,
                       radius_m: float) -> np.ndarray:
    """The exact mask of a sphere: pixels whose ray passes within the radius of its centre."""
    v, u = np.mgrid[0:intr.height, 0:intr.width]
    rays = np.stack([(u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, np.ones(u.shape)], -1)
    rays = rays @ T_world_from_cam[:3, :3].T
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    rel = centre - T_world_from_cam[:3, 3]
    along = rays @ rel
    return np.linalg.norm(rel - along[..., None] * rays, axis=-1) < radius_m


def test_silhouette_field_is_the_metric_distance_outside_the_mask():
    # One camera at the origin looking along +z at a disc mask of 50 px radius: a point at
    # (x, 0, z) projects f x / z px from the centre, so it lies x - (50 + margin) z / f metres
    # outside the margin-widened silhouette cone (measured across the ray, small angles).
    intr = Intrinsics(width=400, height=300, fx=500.0, fy=500.0, cx=200.0, cy=150.0)
    v, u = np.mgrid[0:300, 0:400]
    mask = np.hypot(u - 200.0, v - 150.0) <= 50.0
    view = silhouette_view(mask, intr, np.eye(4))
    z = 0.5
    x = np.array([0.0, 0.03, 0.06, 0.08])
    points = np.stack([x, np.zeros_like(x), np.full_like(x, z)], axis=1)
    field_m = silhouette_field(points, [view], margin_px=1.0, min_views=1)
    expected = x - 51.0 * z / 500.0
    assert field_m[1:] == pytest.approx(expected[1:], abs=0.6 * z / 500.0)  # EDT: < 0.6 px
    assert field_m[0] < 0  # the centre is inside
    # a point behind the camera or off the image is seen by no view: never carved
    unseen = silhouette_field(np.array([[0.0, 0.0, -1.0], [5.0, 0.0, 0.5]]), [view], 1.0, 1)
    assert np.isneginf(unseen).all()
    # two views must agree when min_views is 2: one view alone carves nothing
    assert np.isneginf(silhouette_field(points, [view], 1.0, 2)).all()


def test_signed_mask_distance_is_scipy_s_exact_transform_bit_for_bit():
    # Against SciPy's exact Euclidean transform, computed independently here: blobs that
    # touch the image's border, a hole, lone pixels, a thin line; and the masks with no
    # border at all (empty, full), which have nothing to measure to.
    import cv2
    from scipy import ndimage

    rng = np.random.default_rng(3)
    v, u = np.mgrid[0:240, 0:320]
    masks = [np.hypot(u - 20.0, v - 30.0) <= 60.0,  # cut by two sides of the image
             (np.hypot(u - 160.0, v - 120.0) <= 90.0) & (np.hypot(u - 170.0, v - 110.0) > 25.0),
             rng.random((240, 320)) < 0.001,
             np.zeros((240, 320), bool), np.ones((240, 320), bool)]
    masks.append(masks[0] | (u == 300))
    # OpenCV's threaded transform happens to give SciPy's roots; on one thread (a make paper
    # or batch worker) its square root is approximate, which the rounding must take out.
    threads = cv2.getNumThreads()
    try:
        for n in (1, threads):
            cv2.setNumThreads(n)
            for mask in masks:
                expected = (ndimage.distance_transform_edt(~mask)
                            - ndimage.distance_transform_edt(mask)).astype(np.float32)
                got = signed_mask_distance(mask)
                assert got.dtype == np.float32
                assert np.array_equal(got, expected)
    finally:
        cv2.setNumThreads(threads)


def test_a_share_of_the_views_must_agree_before_a_point_is_carved():
    # Ten views of one point, the same camera: three masks miss it (a chunk missed, as a
    # segmenter does), seven hold it. Two views carve it; 40 % of the ten do not.
    intr = Intrinsics(width=400, height=300, fx=500.0, fy=500.0, cx=200.0, cy=150.0)
    v, u = np.mgrid[0:300, 0:400]
    disc = np.hypot(u - 200.0, v - 150.0) <= 50.0
    views = [silhouette_view(~disc if k < 3 else disc, intr, np.eye(4)) for k in range(10)]
    point = np.array([[0.0, 0.0, 0.5]])
    assert silhouette_field(point, views, 1.0, 2)[0] > 0  # carved by the three bad masks
    assert silhouette_field(point, views, 1.0, 2, min_share=0.4)[0] < 0  # four needed: kept
    assert silhouette_field(point, views, 1.0, 2, min_share=0.3)[0] > 0  # three suffice
    # the share counts the views that see the point: one behind the camera does not count
    behind = silhouette_view(~disc, intr, np.diag([-1.0, 1.0, -1.0, 1.0]))  # looks along -z
    assert silhouette_field(point, [*views, behind], 1.0, 2, min_share=0.3)[0] > 0


def test_signed_distance_is_exact_near_the_surface_and_signed_everywhere():
    import trimesh

    radius_m, voxel_m = 0.03, 0.002
    sphere = trimesh.creation.icosphere(subdivisions=5, radius=radius_m)
    lower = np.full(3, -0.04)
    shape = (41, 41, 41)
    field_m = signed_distance_grid(sphere, lower, shape, voxel_m, band_voxels=3)
    axes = [lower[i] + voxel_m * np.arange(shape[i]) for i in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    exact = np.linalg.norm(grid, axis=-1) - radius_m
    # the icosphere's facets lie up to 0.03 mm inside the true sphere
    clear = np.abs(exact) > 1e-4
    assert np.array_equal(field_m[clear] < 0, exact[clear] < 0)
    near = np.abs(exact) < 3 * voxel_m
    assert np.abs(field_m[near] - exact[near]).max() < 5e-5
    # farther away, within a grid step (a distance transform of the inside/outside border)
    assert np.abs(field_m - exact).max() < voxel_m


def test_silhouette_views_are_evenly_spaced_registered_frames(tmp_path):
    from volec.capture import read_mask, read_transforms_json
    from volec.synth import PRESETS, write_synthetic_capture

    out = write_synthetic_capture("apple", tmp_path / "apple",
                                  PRESETS["quick"].with_(n_frames=6), progress=False)
    capture = read_transforms_json(out / "capture")
    poses = np.stack([f.T_world_from_cam for f in capture.frames])
    registered = np.array([True, True, False, True, True, True])
    views = silhouette_views(capture, given_masks(capture), poses, registered, max_views=3)
    assert len(views) == 3
    for view, frame in zip(views, [0, 3, 5], strict=True):
        np.testing.assert_allclose(view.T_cam_from_world @ poses[frame], np.eye(4), atol=1e-9)
        mask = read_mask(capture.frames[frame])
        assert (view.signed_distance_px[mask] <= 0).all()
        assert (view.signed_distance_px[~mask] > 0).all()
    assert len(silhouette_views(capture, given_masks(capture), poses, registered)) == 5


def test_silhouette_views_take_known_signed_distances_with_the_new_poses(tmp_path):
    # the visual hull from other poses (the AR ones) reuses the masks' transforms: the same
    # views, bit for bit, as transforming the masks again
    from volec.capture import read_transforms_json
    from volec.synth import PRESETS, write_synthetic_capture

    out = write_synthetic_capture("apple", tmp_path / "apple",
                                  PRESETS["quick"].with_(n_frames=5), progress=False)
    capture = read_transforms_json(out / "capture")
    masks = given_masks(capture)
    poses = np.stack([f.T_world_from_cam for f in capture.frames])
    other = poses.copy()
    other[:, :3, 3] += [0.01, -0.02, 0.005]
    registered = np.array([True, True, False, True, True])
    known = silhouette_views(capture, masks, poses, registered)
    fresh = silhouette_views(capture, masks, other, np.ones(5, bool))
    reused = silhouette_views(capture, masks, other, np.ones(5, bool), known=known)
    assert [v.name for v in reused] == [v.name for v in fresh]
    for a, b in zip(reused, fresh, strict=True):
        np.testing.assert_array_equal(a.signed_distance_px, b.signed_distance_px)
        np.testing.assert_array_equal(a.T_cam_from_world, b.T_cam_from_world)
    assert reused[0].signed_distance_px is known[0].signed_distance_px  # not made again


def _sphere_on_table(r: float = 0.03, n_views: int = 24):
    """A sphere of radius ``r`` resting on the table z = 0: its centre, 40 000 unit directions
    from it (seeded), the table, and the exact silhouettes from ``n_views`` cameras 0.3 m
    away, 20 and 50 degrees up (1 px is 1 mm at the sphere)."""
    centre = np.array([0.0, 0.0, r])
    d = np.random.default_rng(3).normal(size=(40000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    table = SupportPlane((0.0, 0.0, 1.0), 0.0, 1000, 0.0)
    intr = Intrinsics(width=320, height=240, fx=300.0, fy=300.0, cx=160.0, cy=120.0)
    views = []
    for k in range(n_views):
        azimuth, elevation = 2 * np.pi * k / n_views, np.radians(20.0 + 30.0 * (k % 2))
        eye = centre + 0.3 * np.array([np.cos(elevation) * np.cos(azimuth),
                                       np.cos(elevation) * np.sin(azimuth), np.sin(elevation)])
        T = look_at_opencv(eye, centre, np.array([0.0, 0.0, 1.0]))
        views.append(silhouette_view(_sphere_silhouette(intr, T, centre, r), intr, T))
    return centre, d, table, views


def test_views_together_give_what_views_one_by_one_give():
    # the batched (torch, float32 about the points' centre) distances against the plain
    # view-by-view float64 ones, on the sphere's 24 views placed 0.3 m from a centre that lies
    # far from the world's origin (where float32 coordinates would lose micrometres)
    from volec.meshing import _outside_distances_numpy, outside_distances

    centre, d, _, views = _sphere_on_table()
    offset = np.array([0.4, -0.6, 0.2])
    far_views = [SilhouetteView(v.intrinsics, v.T_cam_from_world @ _translation(-offset),
                                v.signed_distance_px) for v in views]
    rng = np.random.default_rng(5)
    points = centre + offset + rng.uniform(-0.2, 0.2, (20000, 3))  # some outside the images
    batched = outside_distances(points, far_views, 0.5)
    one_by_one = _outside_distances_numpy(points, far_views, 0.5)
    seen = np.isfinite(one_by_one)
    assert 0.2 < seen.mean() < 0.95
    np.testing.assert_array_equal(np.isfinite(batched), seen)
    assert np.abs(batched[seen] - one_by_one[seen]).max() < 1e-7  # metres
    # and the masks' contradiction of a cloud (nearest pixel): the same shares
    from volec.meshing import mask_contradictions

    cloud = centre + offset + 0.031 * d[:3000]  # just outside the sphere: some outside masks
    shares = mask_contradictions(far_views, cloud, 0.5)
    np.testing.assert_array_equal(shares, [mask_contradiction(v, cloud, 0.5) for v in far_views])
    assert shares.max() > 0
    # views of other sizes go one by one, with the same answer
    small = silhouette_view(np.ones((10, 12), bool), views[0].intrinsics, np.eye(4))
    mixed = outside_distances(points[:50], [*far_views[:2], small], 0.5)
    np.testing.assert_array_equal(mixed, _outside_distances_numpy(points[:50],
                                                                  [*far_views[:2], small], 0.5))


def _translation(t: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = t
    return T


def test_silhouettes_carve_the_unseen_gap_under_a_sphere_on_a_table():
    # A sphere resting on a table, seen only above a third of its height (as a phone sees a
    # round item on a plate): Poisson and the flat cut at the table fill the hidden gap between
    # the sphere's underside and the table; the exact silhouettes from cameras 20-50 degrees
    # above the table carve most of it away, towards the true volume 4/3 pi r^3.
    r = 0.03
    centre, d, table, views = _sphere_on_table(r)
    seen = d[:, 2] > -0.35
    cloud = PointCloud(centre + r * d[seen], None, d[seen])
    cfg = MeshingConfig(poisson_depth=7, grid_voxel_m=0.001, thinning_voxel_m=0.0)
    truth = 4 / 3 * np.pi * r**3 * 1e6  # 113.1 mL
    plain = volume_ml(mesh_cloud(cloud, table, cfg).mesh)
    carved = mesh_cloud(cloud, table, cfg, views)
    assert carved.mesh.is_watertight and carved.mesh.is_winding_consistent
    assert plain > 1.03 * truth  # the filled gap: a few per cent too much
    assert abs(volume_ml(carved.mesh) - truth) < 0.4 * (plain - truth)
    assert 0 < carved.report["carved_fraction"] < 0.25


def test_the_default_margin_neither_bites_the_seen_surface_nor_stands_a_pixel_off():
    # Exact silhouettes of a sphere on a table, 1 px = 1 mm at its distance. Where the cloud
    # covers the sphere, carving with no margin bites into it (a point is carved by its
    # second-largest distance outside the masks, and on the surface those scatter by the
    # pixels' quantization); the default half pixel leaves it as Poisson made it. Where the
    # cloud stops (the gap under the sphere) the hull binds, and the default stands half a
    # pixel nearer the sphere than a whole pixel's margin, still holding all of it.
    r = 0.03
    centre, d, table, views = _sphere_on_table(r)
    cfg = MeshingConfig(poisson_depth=7, grid_voxel_m=0.001, thinning_voxel_m=0.0)
    assert cfg.silhouette_margin_px == MeshingConfig().silhouette_margin_px

    def volume(cloud: PointCloud, margin_px: float | None) -> float:
        if margin_px is None:
            return volume_ml(mesh_cloud(cloud, table, cfg).mesh)
        return volume_ml(mesh_cloud(cloud, table, replace(cfg, silhouette_margin_px=margin_px),
                                    views).mesh)

    whole = PointCloud(centre + r * d, None, d)
    plain = volume(whole, None)
    assert plain - volume(whole, 0.0) > 0.3  # mL of 113: the bite of a zero margin
    assert abs(plain - volume(whole, cfg.silhouette_margin_px)) < 0.1
    seen = d[:, 2] > -0.35
    above = PointCloud(centre + r * d[seen], None, d[seen])
    default = volume(above, cfg.silhouette_margin_px)
    assert default < volume(above, 1.0) - 0.5
    assert default > 4 / 3 * np.pi * r**3 * 1e6


def test_silhouettes_placed_with_erring_poses_do_not_carve_the_measured_surface():
    # The exact silhouettes of a sphere on a table, each placed with its camera turned by
    # 0.2 degrees about a random axis (about 1 px here, as SfM poses err from frame to frame).
    # A point is carved by its second-largest distance outside the masks, which sits in the
    # tail of that error: without sparing, the carving cuts into the sphere the cloud covers.
    # Spared, the measured surface stands, and the gap under the sphere that the cloud does
    # not cover is still carved.
    from volec.geometry import invert_rigid, rotvec_to_matrix

    r = 0.03
    centre, d, table, views = _sphere_on_table(r)
    rng = np.random.default_rng(7)
    erring = []
    for view in views:
        T = invert_rigid(view.T_cam_from_world)
        turn = rng.normal(size=3)
        T[:3, :3] = rotvec_to_matrix(np.radians(0.2) * turn / np.linalg.norm(turn)) @ T[:3, :3]
        erring.append(replace(view, T_cam_from_world=invert_rigid(T)))
    cfg = MeshingConfig(poisson_depth=7, grid_voxel_m=0.001, thinning_voxel_m=0.0)
    assert cfg.spare_observed_m == MeshingConfig().spare_observed_m > 0
    whole = PointCloud(centre + r * d, None, d)
    plain = volume_ml(mesh_cloud(whole, table, cfg).mesh)  # 112.9 mL, truth 113.1
    bitten = volume_ml(mesh_cloud(whole, table, replace(cfg, spare_observed_m=0.0), erring,
                                  whole).mesh)
    spared = volume_ml(mesh_cloud(whole, table, cfg, erring, whole).mesh)
    assert plain - bitten > 0.5  # mL: about 0.1 mm all round
    assert abs(plain - spared) < 0.05
    seen = d[:, 2] > -0.35
    above = PointCloud(centre + r * d[seen], None, d[seen])
    truth = 4 / 3 * np.pi * r**3 * 1e6
    uncarved = volume_ml(mesh_cloud(above, table, cfg).mesh)
    carved = volume_ml(mesh_cloud(above, table, cfg, erring, above).mesh)
    assert uncarved > 1.1 * truth
    assert abs(carved - truth) < 0.1 * (uncarved - truth)


def test_behind_observed_is_negative_just_inside_a_surface_only():
    # The plane z = 0 observed from above (normals +z): points up to the reach below it are
    # behind it; points above it, or farther than the reach from it, are not.
    xy = np.stack(np.meshgrid(np.linspace(-0.01, 0.01, 41), np.linspace(-0.01, 0.01, 41)),
                  -1).reshape(-1, 2)
    plane = PointCloud(np.c_[xy, np.zeros(len(xy))], None, np.tile([0.0, 0.0, 1.0], (len(xy), 1)))
    points = np.array([[0.0, 0.0, -0.0005], [0.0, 0.0, 0.0005], [0.0, 0.0, -0.003],
                       [0.05, 0.0, -0.0005]])
    field = behind_observed(points, plane, reach_m=0.001)
    assert field[0] == pytest.approx(-0.0005, abs=1e-6)
    assert field[1] == pytest.approx(0.0005, abs=1e-6)
    assert field[2] > 0 and field[3] > 0
    assert (behind_observed(points, PointCloud(plane.xyz), 0.001) > 0).all()  # no normals


def test_masks_that_leave_out_part_of_the_food_do_not_carve():
    # 24 exact silhouettes of a sphere on a table; then one mask misses the half of the food
    # left of its centre, one is empty and one is eroded by 2 px (a segmenter's boundary
    # error, under the 4 px tolerance): the first two contradict the food cloud and are left
    # out, the eroded one is kept.
    from scipy import ndimage

    r = 0.03
    centre = np.array([0.0, 0.0, r])
    d = np.random.default_rng(5).normal(size=(20000, 3))
    food = centre + r * d / np.linalg.norm(d, axis=1, keepdims=True)
    intr = Intrinsics(width=320, height=240, fx=300.0, fy=300.0, cx=160.0, cy=120.0)
    masks, poses = [], []
    for k in range(24):
        azimuth, elevation = 2 * np.pi * k / 24, np.radians(30.0)
        eye = centre + 0.3 * np.array([np.cos(elevation) * np.cos(azimuth),
                                       np.cos(elevation) * np.sin(azimuth), np.sin(elevation)])
        poses.append(look_at_opencv(eye, centre, np.array([0.0, 0.0, 1.0])))
        masks.append(_sphere_silhouette(intr, poses[-1], centre, r))
    masks[3] = masks[3] & (np.arange(intr.width) >= intr.cx)[None, :]
    masks[7] = np.zeros_like(masks[7])
    masks[11] = ndimage.binary_erosion(masks[11], iterations=2)
    views = [silhouette_view(m, intr, T, f"frame_{k}")
             for k, (m, T) in enumerate(zip(masks, poses, strict=True))]
    cfg = MeshingConfig()
    assert mask_contradiction(views[0], food, cfg.silhouette_contradiction_px) < 0.001
    assert mask_contradiction(views[3], food, 4.0) == pytest.approx(0.5, abs=0.1)
    assert mask_contradiction(views[7], food, 4.0) == 1.0
    kept, left_out = consistent_views(views, food, cfg)
    assert [v.name for v in left_out] == ["frame_3", "frame_7"]
    assert len(kept) == 22 and "frame_11" in [v.name for v in kept]


def test_poisson_gives_the_same_surface_on_every_run():
    # open3d's multi-threaded Poisson differs in the last digits between runs (and now and then
    # segfaults); meshing runs it on one thread, so a capture's mesh is reproducible.
    from volec.meshing import _poisson

    cloud = _sphere_cloud(0.04, 20000)
    noisy = cloud.xyz + np.random.default_rng(1).normal(scale=3e-4, size=cloud.xyz.shape)
    runs = [np.asarray(_poisson(noisy, cloud.normals, MeshingConfig())[0].vertices)
            for _ in range(3)]
    assert all(np.array_equal(runs[0], run) for run in runs[1:])


def _ellipsoid_silhouette(intr: Intrinsics, T_world_from_cam: np.ndarray, centre: np.ndarray,
                          axes: np.ndarray) -> np.ndarray:
    """The exact mask of an axis-aligned ellipsoid: pixels whose ray meets it."""
    v, u = np.mgrid[0:intr.height, 0:intr.width]
    rays = np.stack([(u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, np.ones(u.shape)], -1)
    rays = (rays @ T_world_from_cam[:3, :3].T) / axes  # in the frame where it is a unit ball
    origin = (T_world_from_cam[:3, 3] - centre) / axes
    a = np.einsum("...i,...i", rays, rays)
    b = rays @ origin
    return b * b - a * (origin @ origin - 1.0) >= 0


def test_views_mirrored_in_the_food_s_plane_bound_the_side_a_half_orbit_never_saw():
    # An egg-shaped ellipsoid lying on a table, filmed from one side only (azimuths 0-180
    # degrees, 20-50 degrees up): its visual hull is far too large on the other side. It is
    # symmetric about the vertical plane y = 0 (which a half orbit from the +y side cannot
    # check); the views reflected in that plane see the far side as the filmed side, and their
    # hull is what the full orbit's views give (still above the truth: no view sees under it).
    from volec.completion.mirror import reflection_matrix
    from volec.meshing import mirrored_views
    from volec.space import SpaceConfig, visual_hull_mesh

    axes = np.array([0.035, 0.02, 0.018])
    centre = np.array([0.0, 0.0, axes[2]])
    intr = Intrinsics(width=320, height=240, fx=300.0, fy=300.0, cx=160.0, cy=120.0)
    orbit = []
    for k in range(30):  # 0, 12, ..., 348 degrees
        azimuth, elevation = 2 * np.pi * k / 30, np.radians(20.0 + 30.0 * (k % 2))
        eye = centre + 0.3 * np.array([np.cos(elevation) * np.cos(azimuth),
                                       np.cos(elevation) * np.sin(azimuth), np.sin(elevation)])
        T = look_at_opencv(eye, centre, np.array([0.0, 0.0, 1.0]))
        orbit.append(silhouette_view(_ellipsoid_silhouette(intr, T, centre, axes), intr, T))
    views = orbit[:16]  # 0-180 degrees
    d = np.random.default_rng(4).normal(size=(20000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    extent = PointCloud(centre + 1.3 * axes * d)  # only the grid's extent
    table = SupportPlane((0.0, 0.0, 1.0), 0.0, 1000, 0.0)
    space = SpaceConfig(pitch_m=0.001)
    truth = 4 / 3 * np.pi * axes.prod() * 1e6  # 52.8 mL
    one_side = volume_ml(visual_hull_mesh(extent, views, table, space))
    plane_y0 = reflection_matrix(np.array([0.0, 1.0, 0.0]), 0.0)
    mirrored = mirrored_views(views, plane_y0, 0.0, centre)
    # a mirrored view of a point samples the real view at the point's mirror image
    far = centre + np.array([0.01, -0.012, 0.0])  # on the far side, inside the egg
    assert silhouette_field(far[None], mirrored[:1], 0.0, 1)[0] == pytest.approx(
        silhouette_field((far * [1, -1, 1])[None], views[:1], 0.0, 1)[0], abs=1e-9)
    both = volume_ml(visual_hull_mesh(extent, [*views, *mirrored], table, space))
    full = volume_ml(visual_hull_mesh(extent, orbit, table, space))
    assert one_side > 1.12 * truth and one_side > full + 0.05 * truth
    assert abs(both - full) < 0.1 * (one_side - full)
    # a margin keeps the reflected silhouettes from carving within it: between the two
    wide = mirrored_views(views, plane_y0, 0.004, centre)
    assert both < volume_ml(visual_hull_mesh(extent, [*views, *wide], table, space)) < one_side


def test_prior_views_carve_only_where_they_may():
    # A sphere on a table, its whole surface observed, carved by its exact silhouettes; prior
    # views (as a shape prior makes them) show a concentric sphere of 0.8 the radius. Allowed
    # everywhere they carve the sphere down to about the small one's hull; allowed nowhere
    # they change nothing (the same field); allowed on the y < 0 half only, they carve that
    # half alone: by the views' symmetry about y = 0, half way between the two.
    from volec.meshing import PriorViews

    r, small_r = 0.03, 0.024
    centre, d, table, views = _sphere_on_table(r)
    small = [silhouette_view(_sphere_silhouette(v.intrinsics, np.linalg.inv(v.T_cam_from_world),
                                                centre, small_r),
                             v.intrinsics, np.linalg.inv(v.T_cam_from_world), f"{v.name} prior")
             for v in views]
    cloud = PointCloud(centre + r * d, None, d)

    def volume(may_carve) -> float:
        prior = PriorViews(tuple(small), may_carve)
        return volume_ml(mesh_cloud(cloud, table, FAST, views, None, prior).mesh)

    plain = volume_ml(mesh_cloud(cloud, table, FAST, views).mesh)
    nowhere = volume(lambda p: np.zeros(len(p), bool))
    everywhere = volume(lambda p: np.ones(len(p), bool))
    half = volume(lambda p: p[:, 1] < 0)
    assert nowhere == plain
    small_truth = 4 / 3 * np.pi * small_r**3 * 1e6  # 57.9 mL against 113.1
    assert small_truth < everywhere < 0.75 * plain
    assert half == pytest.approx((plain + everywhere) / 2, rel=0.03)


def test_uncovered_mask_rays_are_those_that_pass_the_mesh_by():
    # The sphere's exact masks against the meshes of the sphere itself (nothing uncovered)
    # and of a concentric one of 0.8 the radius: the uncovered share of each view is that of
    # its tested pixels (2 px inside the mask, every third row and column) whose ray passes
    # farther than 0.8 r from the centre, by the rays' geometry alone.
    import trimesh

    from volec.meshing import uncovered_mask_rays

    r = 0.03
    centre, _, _, views = _sphere_on_table(r, n_views=6)
    exact = trimesh.creation.icosphere(6, r * 1.001).apply_translation(centre)
    shares, rays = uncovered_mask_rays(exact, views)
    assert shares.max() < 0.002 and len(rays) == len(views)
    small = trimesh.creation.icosphere(6, 0.8 * r).apply_translation(centre)
    shares, rays = uncovered_mask_rays(small, views)
    for view, share, (eye, directions) in zip(views, shares, rays, strict=True):
        inner = view.signed_distance_px[::3, ::3] < -2.0
        rows, cols = np.nonzero(inner)
        T = np.linalg.inv(view.T_cam_from_world)
        d = np.stack([(cols * 3 - view.intrinsics.cx) / view.intrinsics.fx,
                      (rows * 3 - view.intrinsics.cy) / view.intrinsics.fy,
                      np.ones(len(rows))], -1) @ T[:3, :3].T
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        rel = centre - T[:3, 3]
        passing = np.linalg.norm(rel - (d @ rel)[:, None] * d, axis=1)
        assert share == pytest.approx(np.mean(passing > 0.8 * r), abs=0.01)
        assert 0.25 < share < 0.45  # about 1 - 0.8^2 of the disc
        np.testing.assert_allclose(eye, T[:3, 3], atol=1e-9)
        assert len(directions) == round(share * inner.sum())


def test_prior_points_that_leave_the_masks_uncovered_are_dropped():
    # A sphere on a table seen above a third of its height; a shape prior's points put its
    # lower part at 0.7 of the radius (a completion that pulled the unseen side in). The mesh
    # with them misses the lower part of every mask; the check drops them and the hull,
    # carved by the exact masks, closes the sphere again (without any prior points it is
    # within a few per cent of the sphere).
    r = 0.03
    centre, d, table, views = _sphere_on_table(r)
    seen = d[:, 2] > -1 / 3
    below = d[~seen][:4000]
    prior = centre + 0.7 * r * below
    cloud = PointCloud(np.vstack([centre + r * d[seen], prior]), None,
                       np.vstack([d[seen], np.full(prior.shape, np.nan)]))
    observed = PointCloud(centre + r * d[seen], None, d[seen])
    sphere_ml = 4 / 3 * np.pi * r**3 * 1e6
    unchecked = replace(FAST, mask_cover=replace(FAST.mask_cover, rounds=0))
    pulled = mesh_cloud(cloud, table, unchecked, views, observed)
    checked = mesh_cloud(cloud, table, FAST, views, observed)
    without = mesh_cloud(observed, table, FAST, views, observed)
    assert "mask_cover" not in pulled.report
    assert volume_ml(pulled.mesh) < 0.93 * sphere_ml
    cover = checked.report["mask_cover"]
    assert cover["first_uncovered_p90"] > 0.05 and cover["uncovered_p90"] < 0.01
    assert cover["repairs"] >= 1 and len(checked.dropped) == cover["prior_points_dropped"]
    assert (checked.dropped >= len(observed)).all()  # only the prior's points
    assert volume_ml(checked.mesh) == pytest.approx(volume_ml(without.mesh), rel=0.02)
    assert volume_ml(checked.mesh) == pytest.approx(sphere_ml, rel=0.04)


def _pulled_sphere(r: float = 0.03):
    """The sphere on the table (:func:`_sphere_on_table`) seen above a third of its height,
    with a shape prior's points that put its lower part at 0.7 of the radius (a completion
    that pulled the unseen side in): centre, table, views, the observed cloud and the cloud
    with the prior's points after it."""
    centre, d, table, views = _sphere_on_table(r)
    seen = d[:, 2] > -1 / 3
    prior = centre + 0.7 * r * d[~seen][:4000]
    observed = PointCloud(centre + r * d[seen], None, d[seen])
    cloud = PointCloud(np.vstack([observed.xyz, prior]), None,
                       np.vstack([d[seen], np.full(prior.shape, np.nan)]))
    return centre, table, views, observed, cloud


def test_prior_points_that_cut_into_enclosed_space_are_dropped():
    # The sphere of the masks' test, its lower part pulled to 0.7 of the radius by a prior's
    # points, with the masks' check off: the space the seen surface encloses (here the
    # sphere's interior within 0.95 of the radius) is partly outside that mesh. The check
    # drops the prior's points near what it misses and the mesh holds the space again.
    from volec.meshing import FoodCoverConfig, missed_points, near_points

    r = 0.03
    centre, table, views, observed, cloud = _pulled_sphere(r)
    axis = np.arange(-0.95 * r, 0.95 * r, 0.002)
    grid = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3)
    enclosed = centre + grid[np.linalg.norm(grid, axis=1) < 0.95 * r]
    deep = enclosed[~near_points(enclosed, observed.xyz, 0.003)]
    assert len(deep) < len(enclosed)  # those within 3 mm of the seen cap do not count
    deep = deep[deep[:, 2] > 0.002]  # nor those within 2 mm of the table
    no_masks = replace(FAST.mask_cover, rounds=0)
    pulled = mesh_cloud(cloud, table, replace(FAST, mask_cover=no_masks,
                                              food_cover=FoodCoverConfig(rounds=0)),
                        views, observed, food_points=enclosed)
    share, _ = missed_points(pulled.mesh, deep)
    assert share > 0.05 and "food_cover" not in pulled.report
    checked = mesh_cloud(cloud, table, replace(FAST, mask_cover=no_masks,
                                               food_cover=FoodCoverConfig(rounds=2)),
                         views, observed, food_points=enclosed)
    cover = checked.report["food_cover"]
    assert cover["first_missed_share"] == pytest.approx(share, abs=1e-5)
    assert cover["repairs"] >= 1 and cover["missed_share"] < 0.01
    assert len(checked.dropped) == cover["prior_points_dropped"]
    assert (checked.dropped >= len(observed)).all()  # only the prior's points
    sphere_ml = 4 / 3 * np.pi * r**3 * 1e6
    assert volume_ml(pulled.mesh) < 0.93 * sphere_ml
    assert volume_ml(checked.mesh) == pytest.approx(sphere_ml, rel=0.04)


def test_enclosed_space_at_the_contact_with_the_support_does_not_count():
    # The pulled sphere again: the only enclosed points given lie in the 2 mm under it, at
    # the table, which the plate's fit alone encloses. The mesh misses them all, but they
    # do not count (unless the check is told to count them from the table up).
    from volec.meshing import FoodCoverConfig

    r = 0.03
    centre, table, views, observed, cloud = _pulled_sphere(r)
    axis = np.arange(-r, r, 0.001)
    grid = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3)
    contact = centre + grid[np.linalg.norm(grid, axis=1) < r]
    contact = contact[contact[:, 2] < 0.0019]
    assert len(contact) > 100
    no_masks = replace(FAST.mask_cover, rounds=0)
    counted = mesh_cloud(cloud, table, replace(FAST, mask_cover=no_masks, food_cover=(
        FoodCoverConfig(rounds=2, above_support_m=0.0))), views, observed, food_points=contact)
    assert counted.report["food_cover"]["first_missed_share"] > 0.9
    skipped = mesh_cloud(cloud, table, replace(FAST, mask_cover=no_masks, food_cover=(
        FoodCoverConfig(rounds=2))), views, observed, food_points=contact)
    assert "food_cover" not in skipped.report and not len(skipped.dropped)


def test_missed_points_are_those_outside_the_mesh():
    import trimesh

    from volec.meshing import missed_points, near_points

    ball = trimesh.creation.icosphere(5, 0.01)
    points = np.array([[0.0, 0.0, 0.0], [0.005, 0.0, 0.0], [0.02, 0.0, 0.0], [0.0, 0.0, -0.03]])
    share, missed = missed_points(ball, points)
    assert share == 0.5
    np.testing.assert_allclose(missed, points[2:])
    near = near_points(np.array([[0.021, 0.0, 0.0], [0.0, 0.0, 0.0]]), missed, 0.002)
    np.testing.assert_array_equal(near, [True, False])
