"""Rotational-symmetry completion: the axis of a solid of revolution seen from one side, and
the far side of a half-orbit sphere filled where nobody saw."""

from __future__ import annotations

import numpy as np
import pytest

from tests.test_space import CENTRE, TABLE, TRUTH_ML, R, _azimuth_deg, _scene
from volec.completion.complete import rotation_completion
from volec.completion.rotation import fit_rotation_axis, turned
from volec.meshing import mesh_cloud
from volec.space import UNKNOWN, SpaceConfig, SpaceGrid, observed_space
from volec.volume import volume_ml

UP = np.array([0.0, 0.0, 1.0])


def lying_cone(taper_m: float, points: int = 30000) -> np.ndarray:
    """(N, 3) a cone lying along x, 80 mm long, its radius 21 mm in the middle, tapering by
    ``taper_m`` towards +x (and growing as much towards -x)."""
    rng = np.random.default_rng(2)
    x = rng.uniform(-0.04, 0.04, points)
    theta = rng.uniform(0, 2 * np.pi, points)
    radius = 0.021 - taper_m * x / 0.04
    return np.stack([x, radius * np.cos(theta), radius * np.sin(theta)], axis=1)


def test_a_half_turn_is_undone_by_another_and_keeps_height_and_radius():
    rng = np.random.default_rng(0)
    xyz = rng.normal(size=(50, 3))
    centre = np.array([0.3, -0.2, 5.0])
    once = turned(xyz, centre, UP, np.pi)
    assert np.allclose(turned(once, centre, UP, np.pi), xyz)
    assert np.allclose(once[:, 2], xyz[:, 2])
    assert np.allclose(np.linalg.norm((once - centre)[:, :2], axis=1),
                       np.linalg.norm((xyz - centre)[:, :2], axis=1))
    # a quarter turn counter-clockwise seen from above takes +x to +y
    assert np.allclose(turned(np.array([[1.0, 0.0, 0.0]]), np.zeros(3), UP, np.pi / 2),
                       [[0.0, 1.0, 0.0]])


def test_the_axis_of_a_spheroid_seen_from_one_side_is_found():
    # an oblate spheroid (radii 40, 40, 25 mm) standing on its axis at x = 12, y = -7 mm,
    # seen over 240 degrees of azimuth: the half-turn maps a third of it onto seen surface
    rng = np.random.default_rng(1)
    d = rng.normal(size=(40000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    axis = np.array([0.012, -0.007, 0.0])
    xyz = axis + d * np.array([0.04, 0.04, 0.025])
    azimuth = np.degrees(np.arctan2(d[:, 1], d[:, 0]))
    seen = xyz[np.abs(azimuth) < 120]
    centre, score = fit_rotation_axis(seen, UP)
    assert np.linalg.norm((centre - axis)[:2]) < 0.001
    # without a space to tell them apart, the half that lands on the unseen third costs the
    # truncation (4 spacings) and the half that lands on seen surface about half a spacing
    assert score < 2.75


def test_the_far_side_of_a_half_orbit_sphere_is_filled_and_its_volume_comes_closer():
    cloud, views = _scene(180.0)
    space = observed_space(cloud, views, TABLE, SpaceConfig())
    done = rotation_completion(cloud, UP, space)
    added = done.predicted_xyz
    assert len(added) > 500
    assert (space.states_at(added) == UNKNOWN).all()  # nothing where the cameras saw
    assert np.median(np.abs(np.linalg.norm(added - CENTRE, axis=1) - R)) < 0.001
    azimuth = _azimuth_deg(added)
    assert ((azimuth > 240) & (azimuth < 300)).mean() > 0.3  # the side nobody filmed
    assert np.linalg.norm(np.array(done.summary["axis_point_m"])[:2] - CENTRE[:2]) < 0.001
    without = volume_ml(mesh_cloud(cloud, TABLE, silhouettes=views).mesh)
    with_turn = volume_ml(mesh_cloud(done.cloud, TABLE, silhouettes=views).mesh)
    assert abs(with_turn - TRUTH_ML) < abs(without - TRUTH_ML)
    assert with_turn == pytest.approx(TRUTH_ML, rel=0.05)


def test_without_seen_space_to_check_it_against_no_axis_is_taken():
    # every turned point would land in unknown space: the fit cannot be told from a wrong one
    cloud, _ = _scene(180.0)
    lower = cloud.xyz.min(axis=0) - 0.05
    unknown = SpaceGrid(lower, 0.005, np.full((40, 40, 40), UNKNOWN, np.int8))
    done = rotation_completion(cloud, UP, unknown)
    assert len(done.predicted_xyz) == 0
    assert done.summary["axis_score_spacings"] is None
    assert len(done.cloud) == len(cloud)


def test_a_pear_lying_on_its_side_is_not_symmetric_under_a_half_turn():
    # a cone lying along x, 80 mm long, its radius tapering from 30 to 12 mm: a half-turn
    # about any vertical axis puts the wide end where the narrow one is, so no copies are made
    from volec.completion.rotation import fit_rotation, rotated_points

    xyz = lying_cone(0.009)
    fit = fit_rotation(xyz, UP)
    assert not fit.symmetric and fit.median_distance_m > 0.003
    assert len(rotated_points(xyz, UP)[0]) == 0
    # the same cone with no taper (a cylinder lying down) is two-fold symmetric
    assert fit_rotation(lying_cone(0.0), UP).symmetric
