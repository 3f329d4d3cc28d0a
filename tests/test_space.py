"""Space around the food: empty where the cameras saw through, food behind what they saw,
unknown where nobody looked; the bounds it gives an estimate, against a sphere's volume."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from tests.test_meshing import _sphere_silhouette
from volec.capture import Intrinsics
from volec.geometry import look_at_opencv
from volec.meshing import SupportPlane, silhouette_view
from volec.pointcloud import PointCloud
from volec.space import (
    EMPTY,
    FOOD,
    UNKNOWN,
    SpaceConfig,
    SpaceGrid,
    observed_space,
    through_hole,
    visual_hull_mesh,
    volume_bounds,
)
from volec.volume import volume_ml

R = 0.03
CENTRE = np.array([0.0, 0.0, R])
TABLE = SupportPlane((0.0, 0.0, 1.0), 0.0, 1000, 0.0)
INTR = Intrinsics(width=320, height=240, fx=300.0, fy=300.0, cx=160.0, cy=120.0)
TRUTH_ML = 4 / 3 * np.pi * R**3 * 1e6


def _scene(arc_deg: float) -> tuple[PointCloud, list]:
    """A sphere resting on a table, filmed from 24 cameras over ``arc_deg`` of azimuth at
    20-50 degrees of elevation; the observed cloud is what those cameras see of it (points
    facing at least one camera, above a third of its height)."""
    rng = np.random.default_rng(3)
    d = rng.normal(size=(60000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    views, eyes = [], []
    for k in range(24):
        azimuth = np.radians(arc_deg) * k / (24 if arc_deg >= 360 else 23)
        elevation = np.radians(20.0 + 30.0 * (k % 2))
        eye = CENTRE + 0.3 * np.array([np.cos(elevation) * np.cos(azimuth),
                                       np.cos(elevation) * np.sin(azimuth), np.sin(elevation)])
        T = look_at_opencv(eye, CENTRE, np.array([0.0, 0.0, 1.0]))
        views.append(silhouette_view(_sphere_silhouette(INTR, T, CENTRE, R), INTR, T))
        eyes.append(eye)
    surface = CENTRE + R * d
    facing = np.zeros(len(d), bool)
    for eye in eyes:
        facing |= np.einsum("ij,ij->i", eye - surface, d) > 0.5 * np.linalg.norm(
            eye - surface, axis=1)
    seen = facing & (d[:, 2] > -0.35)
    return PointCloud(surface[seen], None, d[seen]), views


def _inside_sphere(points: np.ndarray) -> np.ndarray:
    return np.linalg.norm(points - CENTRE, axis=1) < R


def _sorted_space(arc_deg: float) -> tuple[SpaceGrid, np.ndarray, np.ndarray, np.ndarray]:
    """The space of :func:`_scene`, its grid points, their states and distances to the
    sphere's centre."""
    cloud, views = _scene(arc_deg)
    space = observed_space(cloud, views, TABLE, SpaceConfig())
    points = space.points()
    return space, points, space.state.reshape(-1), np.linalg.norm(points - CENTRE, axis=1)


def _azimuth_deg(points: np.ndarray) -> np.ndarray:
    rel = points - CENTRE
    return np.degrees(np.arctan2(rel[:, 1], rel[:, 0])) % 360


def test_a_full_orbit_leaves_little_unknown_and_its_bounds_hold_the_truth():
    space, points, states, radius = _sorted_space(360.0)
    assert (states[radius < 0.5 * R] == FOOD).all()  # the inside of a seen item is food
    assert (states[(radius > 1.1 * R) & (points[:, 2] > 0)] == EMPTY).mean() > 0.99
    assert (states[points[:, 2] < -0.002] == EMPTY).all()  # nothing below the table
    # the exact solid as the estimate: most of it known (the unknown part is the gap under
    # the sphere that no camera saw), and the bounds hold the truth
    bounds = volume_bounds(space, radius < R, TRUTH_ML)
    assert bounds.unknown_share < 0.2 and bounds.empty_share < 0.05
    assert bounds.low_ml <= TRUTH_ML <= bounds.high_ml
    assert bounds.high_ml - bounds.low_ml < 0.25 * TRUTH_ML
    assert not bounds.high_open


def test_a_half_orbit_leaves_the_far_side_unknown_and_the_bounds_say_so():
    space, points, states, radius = _sorted_space(180.0)
    azimuth = _azimuth_deg(points)
    # cameras at azimuths 0-180 and stereo on surfaces seen within 60 degrees leave the side
    # facing azimuth 240-300 unseen: just inside the surface there, space is unknown; just
    # inside the seen surface it is food
    shell = (np.abs(radius - 0.85 * R) < 0.003) & (points[:, 2] > R)
    far = shell & (azimuth > 240) & (azimuth < 300)
    near = shell & (azimuth > 60) & (azimuth < 120)
    assert (states[far] == UNKNOWN).mean() > 0.3
    assert (states[near] == FOOD).mean() > 0.9
    assert not (states[far] == EMPTY).any()  # never seen through: not empty
    full = volume_bounds(space, radius < R, TRUTH_ML)
    assert full.unknown_share > 0.3  # the shape prior decides much of it: a trust reason
    assert full.low_ml <= TRUTH_ML <= full.high_ml
    # an estimate that left out all the unknown space (closed the unseen side tightly) is
    # told that the truth may lie above it, by as much as it left out
    seen_only = (radius < R) & (states != UNKNOWN)
    left_out_ml = ((radius < R) & (states == UNKNOWN)).sum() * space.cell_ml
    tight = volume_bounds(space, seen_only, TRUTH_ML - left_out_ml)
    assert tight.unknown_share == 0 and tight.low_ml == pytest.approx(TRUTH_ML - left_out_ml)
    assert tight.high_ml >= TRUTH_ML


def test_without_views_nothing_is_seen_empty_but_below_the_table():
    cloud, _ = _scene(360.0)
    space = observed_space(cloud, [], TABLE, SpaceConfig(pitch_m=0.003))
    points = space.points()
    states = space.state.reshape(-1)
    assert (states[points[:, 2] < -0.003] == EMPTY).all()
    assert np.isin(states, [EMPTY, FOOD, UNKNOWN]).all()
    assert pytest.approx(space.cell_ml) == 0.003**3 * 1e6


def test_the_visual_hull_holds_the_sphere_and_is_closed():
    cloud, views = _scene(360.0)
    hull = visual_hull_mesh(cloud, views, TABLE)
    hull_ml = volume_ml(hull)  # raises on an open mesh
    # the hull holds the sphere, and adds the space under it that no view could carve (the
    # cameras look down from 20-50 degrees): more than the sphere, less than its bounding box
    assert TRUTH_ML < hull_ml < (2 * R) ** 3 * 1e6
    rng = np.random.default_rng(0)
    d = rng.normal(size=(2000, 3))
    inner = CENTRE + 0.9 * R * d / np.linalg.norm(d, axis=1, keepdims=True)
    assert hull.contains(inner).all()
    # and it is cut at the table
    assert hull.bounds[0, 2] > -SpaceConfig().pitch_m


def _holed_sphere() -> tuple[PointCloud, list, np.ndarray]:
    """The full orbit's sphere with a patch 35 degrees across that dense stereo missed, the
    views, and the unit direction of the patch's centre from the sphere's."""
    cloud, views = _scene(360.0)
    patch_centre = np.array([0.0, np.cos(np.radians(30)), np.sin(np.radians(30))])
    holed = cloud.subset(~(cloud.normals @ patch_centre > np.cos(np.radians(35))))
    return holed, views, patch_centre


def test_a_patch_stereo_missed_leaves_the_food_behind_it_unknown_not_empty():
    # The cameras saw the sphere there (the pixels are inside its masks) but dense stereo
    # found no point: the space behind that patch was not seen through, whatever lies
    # beyond it in the picture.
    holed, views, patch_centre = _holed_sphere()
    space = observed_space(holed, views, TABLE, SpaceConfig())
    points = space.points()
    states = space.state.reshape(-1)
    radius = np.linalg.norm(points - CENTRE, axis=1)
    behind_patch = (radius < 0.85 * R) & ((points - CENTRE) @ patch_centre > 0.5 * R)
    assert behind_patch.sum() > 50
    assert not (states[behind_patch] == EMPTY).any()
    assert (states[radius < 0.85 * R] == EMPTY).mean() == 0


def _holed_sphere_on_a_plate() -> tuple[PointCloud, PointCloud, list]:
    """The full orbit's sphere with a patch stereo missed (:func:`_holed_sphere`), the plate
    around it seen as the rest of the scene (points facing up), and the views."""
    holed, views, _ = _holed_sphere()
    rng = np.random.default_rng(5)
    radius = R * np.sqrt(rng.uniform(0.25, 16.0, 40000))
    angle = rng.uniform(0, 2 * np.pi, len(radius))
    plate = np.stack([radius * np.cos(angle), radius * np.sin(angle), np.zeros_like(radius)], 1)
    up = np.tile([0.0, 0.0, 1.0], (len(plate), 1))
    scene = PointCloud(np.concatenate([holed.xyz, plate]), None,
                       np.concatenate([holed.normals, up]))
    return holed, scene, views


def test_the_plate_behind_a_hole_does_not_empty_the_food_in_front_of_it():
    # Through the missed patch a view's depth reaches the plate beyond the sphere (its points
    # face the camera): drawn into the view, the whole scene says the space inside the sphere
    # was seen through. Inside the food masks only the food cloud's depth counts.
    holed, scene, views = _holed_sphere_on_a_plate()
    states = {}
    for only_food in (False, True):
        cfg = SpaceConfig(food_depth_in_masks=only_food)
        space = observed_space(holed, views, TABLE, cfg, scene=scene)
        points = space.points()
        inner = np.linalg.norm(points - CENTRE, axis=1) < 0.85 * R
        states[only_food] = space.state.reshape(-1)[inner]
    assert (states[False] == EMPTY).sum() > 20  # what the scene's depth did
    assert not (states[True] == EMPTY).any()


def test_space_seen_through_by_too_few_views_is_not_emptied():
    cloud, views = _scene(360.0)
    two = observed_space(cloud, views, TABLE, SpaceConfig(depth_min_views=2))
    many = observed_space(cloud, views, TABLE, SpaceConfig(depth_min_views=len(views) + 1))
    # More views than there are cannot agree: what the depths alone emptied is no longer
    # empty, and only the hull and the surface's front side empty space.
    assert (many.state == EMPTY).sum() < (two.state == EMPTY).sum()
    assert ((many.state == EMPTY) <= (two.state == EMPTY)).all()


def test_the_points_of_a_state_are_those_the_whole_grid_gives():
    state = np.random.default_rng(0).choice([EMPTY, FOOD, UNKNOWN], size=(4, 5, 6)).astype(np.int8)
    grid = SpaceGrid(np.array([0.1, -0.2, 0.3]), 0.002, state)
    for s in (EMPTY, FOOD, UNKNOWN):
        np.testing.assert_allclose(grid.points_in(s), grid.points()[state.ravel() == s])


@pytest.mark.parametrize(("normal", "plate_z_m"), [((0.0, 0.0, 1.0), 0.0007),
                                                  ((0.08, -0.05, 1.0), 0.0007),
                                                  ((0.0, 0.0, -1.0), 0.0013)])
def test_a_point_above_the_plate_never_takes_the_empty_state_of_the_grid_below_it(
        normal, plate_z_m):
    # the plate lies between two layers of the grid (z = 0 and 2 mm), 0.7 mm past the layer
    # below it; below it all is empty, above it nothing was seen (unknown): a point a fraction
    # of a step above the plate is unknown, not empty
    n = np.asarray(normal) / np.linalg.norm(normal)
    plate = SupportPlane(tuple(n), -plate_z_m * n[2], 1000, 0.0)
    lower, pitch = np.array([-0.02, -0.02, -0.02]), 0.002
    grid = SpaceGrid(lower, pitch, np.zeros((21, 21, 21), np.int8))
    state = np.where(plate.height_m(grid.points()) < 0, EMPTY, UNKNOWN).astype(np.int8)
    with_floor = SpaceGrid(lower, pitch, state.reshape(grid.state.shape), plate)
    without = SpaceGrid(lower, pitch, with_floor.state)
    rng = np.random.default_rng(3)
    points = rng.uniform(-0.015, 0.015, size=(20000, 3))
    height = plate.height_m(points)
    above, below = (height >= 0) & (height < 0.015), height < -0.002
    assert (with_floor.states_at(points[above]) == UNKNOWN).all()
    near = above & (height < 0.0003)  # what the floor mends
    assert (without.states_at(points[near]) == EMPTY).mean() > 0.3
    assert (with_floor.states_at(points[below]) == EMPTY).all()
    # away from the plate the floor changes nothing
    far = np.abs(height) > 0.004
    np.testing.assert_array_equal(with_floor.states_at(points[far]),
                                  without.states_at(points[far]))


def test_the_space_knows_its_plate():
    cloud, views = _scene(360.0)
    assert observed_space(cloud, views, TABLE, SpaceConfig(pitch_m=0.003)).floor == TABLE
    assert observed_space(cloud, views, None, SpaceConfig(pitch_m=0.003)).floor is None


def test_a_hole_seen_into_from_above_has_a_footprint_under_its_narrowest_seen_level():
    from tests.test_underside import _ring_on_table

    ring_m, tube_m = 0.03, 0.012
    cloud, table, space = _ring_on_table(ring_m, tube_m)
    hole = through_hole(space, cloud.xyz.mean(axis=0), table)
    assert hole is not None
    # the ring's axis is unknown up to its mid-height and seen empty above
    assert tube_m - 0.001 <= hole.level_m <= tube_m + 0.002
    points = np.array([[0.0, 0.0, 0.3 * tube_m],  # the hole's unseen floor, on the axis
                       [ring_m - 1.3 * tube_m, 0.0, 0.002],  # near its wall
                       [ring_m, 0.0, 0.3 * tube_m],  # in the tube
                       [ring_m + 1.2 * tube_m, 0.0, 0.002],  # outside the ring
                       [0.0, 0.0, 1.5 * tube_m]])  # in the hole, above the level
    np.testing.assert_array_equal(hole.below(points, table), [True, True, False, False, False])


def test_no_footprint_where_the_hole_was_seen_through_or_is_open_or_there_is_none():
    from tests.test_rims import _seen_from_above
    from tests.test_underside import _ring_on_table

    ring_m, tube_m = 0.03, 0.012
    cloud, table, space = _ring_on_table(ring_m, tube_m)
    grid = space.points()
    state = space.state.reshape(-1)

    def with_state(where: np.ndarray, value: int) -> SpaceGrid:
        changed = state.copy()
        changed[where] = value
        return replace(space, state=changed.reshape(space.state.shape))  # keeps its floor

    seen_to_the_plate = with_state(np.linalg.norm(grid[:, :2], axis=1) < ring_m - tube_m, EMPTY)
    assert through_hole(seen_to_the_plate, cloud.xyz.mean(axis=0), table) is None
    # a crescent: the ring cut open on one side is no hole, its inside is open to the air
    cut = with_state((np.abs(grid[:, 1]) < 0.004) & (grid[:, 0] > 0), EMPTY)
    assert through_hole(cut, cloud.xyz.mean(axis=0), table) is None
    centre, sphere, plate, _, sphere_space = _seen_from_above(0.03)
    assert through_hole(sphere_space, centre, plate) is None
