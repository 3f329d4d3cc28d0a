"""Meshing: closed meshes of analytic shapes, the support plane cut, support plane fitting."""

from __future__ import annotations

import numpy as np
import pytest

from volec.meshing import (
    MeshingConfig,
    MeshingError,
    SupportPlane,
    closed_surface,
    fit_support_plane,
    mesh_cloud,
    oriented_normals,
)
from volec.pointcloud import PointCloud
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


def test_too_few_points_are_refused():
    with pytest.raises(MeshingError, match="at least"):
        mesh_cloud(_sphere_cloud(0.03, 100), None, FAST)

