"""Rim points: the food masks' outlines placing the surface where no depth reached."""

import numpy as np

from tests.test_meshing import _sphere_on_table
from volec.meshing import MeshingConfig, mesh_cloud
from volec.pointcloud import PointCloud
from volec.rims import RimConfig, longest_run, outline_rays, rim_points
from volec.space import observed_space
from volec.volume import volume_ml

UP = np.array([0.0, 0.0, 1.0])


def test_longest_run_is_the_first_longest_stretch_of_each_row():
    inside = np.array([[0, 1, 1, 0, 1, 1, 1, 0],
                       [1, 1, 0, 1, 1, 0, 0, 0],
                       [0, 0, 0, 0, 0, 0, 0, 0],
                       [1, 1, 1, 1, 1, 1, 1, 1]], bool)
    first, length = longest_run(inside)
    np.testing.assert_array_equal(first, [4, 0, 0, 0])
    np.testing.assert_array_equal(length, [3, 2, 0, 8])


def test_the_planes_of_a_sphere_s_outline_touch_the_sphere_and_face_away_from_it():
    r = 0.03
    centre, _, _, views = _sphere_on_table(r)
    for view in views[:4]:
        origins, directions, normals = outline_rays(view, UP, RimConfig(max_up=1.0))
        assert len(origins) > 100
        # the plane through the camera along the outline's tangent: at the sphere's radius
        # from its centre, within the pixel (about 1 mm there) that a binary mask's outline
        # is known to
        offset = np.einsum("ij,ij->i", centre - origins, normals)
        assert np.all(offset < 0)  # the sphere lies on the plane's inner side
        assert np.median(np.abs(-offset - r)) < 0.00035
        assert np.abs(-offset - r).max() < 0.001
        # and the ray lies in its plane, passing the sphere at its radius
        assert np.abs(np.einsum("ij,ij->i", directions, normals)).max() < 1e-6
        along = np.einsum("ij,ij->i", centre - origins, directions)
        miss = np.linalg.norm(centre - origins - along[:, None] * directions, axis=1)
        assert np.median(np.abs(miss - r)) < 0.00035
        assert np.abs(miss - r).max() < 0.001


def _seen_from_above(r: float):
    """The sphere on the table, its observed cloud (above a third of the way up from its
    lowest point, as a phone sees a round item), the table, its views and the space."""
    centre, d, table, views = _sphere_on_table(r)
    seen = d[:, 2] > -0.35
    cloud = PointCloud(centre + r * d[seen], None, d[seen])
    return centre, cloud, table, views, observed_space(cloud, views, table)


def test_rim_points_lie_on_the_sphere_below_its_widest_level_where_nothing_was_seen():
    r = 0.03
    centre, cloud, table, views, space = _seen_from_above(r)
    cfg = RimConfig()
    rims, record = rim_points(views, cloud, space, UP, cfg, (0.5, 2), table)
    assert record["rays"] > 800 and len(rims) > 200
    assert np.all(table.height_m(rims.xyz) >= 0)  # a ray's stretch ends at the table
    assert record["kept"] == len(rims) <= record["placed"]
    off_m = np.linalg.norm(rims.xyz - centre, axis=1) - r
    # off the surface by a fraction of a pixel (1 mm): the contact stretch's midpoint lies
    # just outside a convex surface, never inside it by more than the outline's precision
    assert np.median(off_m) < 0.0003
    assert np.percentile(off_m, 90) < 0.0008
    assert off_m.min() > -0.0003
    # below the widest level only, and not where the cloud was
    assert np.all(rims.xyz[:, 2] < centre[2])
    assert np.all(np.einsum("ij,ij->i", rims.normals, rims.xyz - centre) > 0)
    from scipy.spatial import cKDTree

    assert cKDTree(cloud.xyz).query(rims.xyz)[0].min() > cfg.min_gap_m


def test_rim_points_bring_the_carved_mesh_nearer_the_sphere_s_volume():
    # where no depth reached, the carved mesh is the visual hull of 24 views, which bulges
    # out between the views' outlines; the rims hold it to the points where they touch (most
    # of what is left is the gap at the table, below where any outline reaches)
    r = 0.03
    centre, cloud, table, views, space = _seen_from_above(r)
    rims, _ = rim_points(views, cloud, space, UP, RimConfig(), (0.5, 2), table)
    cfg = MeshingConfig(poisson_depth=7, grid_voxel_m=0.001, thinning_voxel_m=0.0)
    truth = 4 / 3 * np.pi * r**3 * 1e6
    hull_only = volume_ml(mesh_cloud(cloud, table, cfg, views).mesh)
    with_rims = mesh_cloud(cloud.joined(rims), table, cfg, views)
    assert with_rims.mesh.is_watertight
    assert hull_only - truth > 0.5  # mL: the hull's bulges under the sphere
    error = volume_ml(with_rims.mesh) - truth
    assert -0.3 < error < 0.9 * (hull_only - truth)


def test_only_the_outline_under_the_sphere_s_widest_level_is_followed():
    # each outline ray touches the sphere where the sphere's normal is the tangent plane's:
    # at centre + r n. The rays kept pass the sphere below its widest level, and they are
    # part of the outline, not all of it
    r = 0.03
    centre, _, _, views = _sphere_on_table(r)
    cfg = RimConfig()
    for view in views[:4]:
        every, _, _ = outline_rays(view, UP, RimConfig(max_up=1.0))
        origins, directions, normals = outline_rays(view, UP, cfg)
        assert 0 < len(origins) < 0.7 * len(every)
        touch = centre + r * normals
        along = np.einsum("ij,ij->i", touch - origins, directions)
        off_ray = np.linalg.norm(touch - origins - along[:, None] * directions, axis=1)
        # the normal is known to a few degrees (a binary mask's outline bends pixel by
        # pixel), and r times that is millimetres along the sphere
        assert np.median(off_ray) < 0.003
        # below the widest level: the ray itself passes the sphere under its centre
        assert np.median((origins + along[:, None] * directions - centre) @ UP) < -0.005
