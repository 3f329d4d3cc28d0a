"""The underside by a horizontal mirror: the food's upper part reflected into the wedge above the
plate that no camera constrained."""

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from tests.test_meshing import _sphere_on_table
from tests.test_rims import _seen_from_above
from volec.meshing import SupportPlane
from volec.pointcloud import PointCloud
from volec.space import EMPTY, FOOD, UNKNOWN, SpaceGrid, observed_space
from volec.underside import (
    UndersideConfig,
    facing_out,
    fit_level,
    hole_above,
    underside_points,
)

UP = np.array([0.0, 0.0, 1.0])


def test_a_sphere_s_underside_is_its_upper_half_reflected():
    r = 0.03
    centre, cloud, table, _, space = _seen_from_above(r)
    points, record = underside_points(cloud, table, space, UndersideConfig())
    assert record["symmetric"]
    assert abs(record["mirror_height_mm"] - 1000 * r) < 0.3
    assert len(points) > 300
    radius = np.linalg.norm(points.xyz - centre, axis=1)
    assert np.median(np.abs(radius - r)) < 0.0003
    assert np.abs(radius - r).max() < 0.0015
    # only in the wedge nothing was seen: below the lowest observed point, above the table
    lowest = cloud.xyz[:, 2].min()
    assert points.xyz[:, 2].max() < lowest + 0.001 and points.xyz[:, 2].min() > 0
    outward = (points.xyz - centre) / radius[:, None]
    assert np.median(np.einsum("ij,ij->i", outward, points.normals)) > 0.99


def test_a_fuller_top_is_laid_on_the_bottom_the_cameras_saw():
    # the upper half bulges 0.6 mm beyond the sphere the lower part follows (seen down to a
    # tenth of its height, as the rim points reach): mirrored at the mid-height it would lie
    # 0.6 mm outside at the bottom; the level is chosen where it lands on the seen bottom
    r, bulge = 0.03, 0.0006
    centre, d, table, views = _sphere_on_table(r)
    d = d[d[:, 2] > -0.8]
    fuller = PointCloud(centre + np.where(d[:, 2:] > 0, r + bulge, r) * d, None, d)
    space = observed_space(PointCloud(centre + r * d, None, d), views, table)
    points, record = underside_points(fuller, table, space, UndersideConfig())
    assert record["symmetric"] and len(points) > 50
    radius = np.linalg.norm(points.xyz - centre, axis=1)
    assert abs(np.median(radius - r)) < 0.3 * bulge


def _dome(r: float) -> tuple[PointCloud, SupportPlane, SpaceGrid]:
    """A hemisphere of radius ``r`` lying on its flat face on the table z = 0, its dome seen
    (with outward normals), and a space where everything but the dome's inside was seen
    empty."""
    d = np.random.default_rng(4).normal(size=(20000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d = d[d[:, 2] > 0.02]
    pitch = 0.002
    lower = np.array([-1.5 * r, -1.5 * r, 0.0])
    axes = [lower[i] + pitch * np.arange(int(3 * r / pitch) + 1) for i in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    state = np.where(np.linalg.norm(grid, axis=-1) < r, FOOD, EMPTY).astype(np.int8)
    return (PointCloud(r * d, None, d), SupportPlane((0.0, 0.0, 1.0), 0.0, 1000, 0.0),
            SpaceGrid(lower, pitch, state))


def test_a_dome_on_its_flat_face_is_not_taken_as_symmetric():
    cloud, table, space = _dome(0.03)
    fit = fit_level(cloud.xyz, cloud.normals, table.height_m(cloud.xyz), UP, space,
                    UndersideConfig())
    assert not fit.symmetric
    points, record = underside_points(cloud, table, space, UndersideConfig())
    assert len(points) == 0 and not record["symmetric"]


def test_only_surface_facing_away_from_the_vertical_axis_bounds_the_wedge():
    centre = np.array([0.01, 0.02, 0.0])
    points = centre + np.array([[0.02, 0.0, 0.005], [0.0, -0.02, 0.005], [0.02, 0.0, 0.005],
                                [0.0, 0.02, 0.01]])
    normals = np.array([[1.0, 0.0, 0.0],  # straight out
                        [0.0, -0.6, -0.8],  # out and down
                        [-1.0, 0.0, 0.0],  # towards the axis: a hollow
                        [0.0, 0.2, -0.98]])  # nearly straight down: too little out
    np.testing.assert_array_equal(facing_out(points, normals, centre, UP, 0.3),
                                  [True, True, False, False])


def _lens(r: float, top_m: float, bottom_m: float, seen_down_to: float
          ) -> tuple[PointCloud, SupportPlane, SpaceGrid, Callable[[np.ndarray], np.ndarray]]:
    """A lens resting on its lowest point on the table z = 0: horizontal radius ``r``, its
    upper half an ellipsoid's ``top_m`` high, its lower half ``bottom_m`` deep (the upper one
    squashed). Its surface seen (outward normals) down to ``seen_down_to`` of the lower half's
    depth below the widest level; a space where nothing below that was seen (unknown), food
    inside, empty elsewhere; and the lens's implicit function (negative inside, scaled to about
    metres near its lower surface)."""
    centre = np.array([0.0, 0.0, bottom_m])
    d = np.random.default_rng(6).normal(size=(40000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    depth = np.where(d[:, 2] > 0, top_m, bottom_m)
    axes = np.stack([np.full(len(d), r), np.full(len(d), r), depth], axis=1)
    normals = d / axes
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    seen = d[:, 2] > -seen_down_to
    cloud = PointCloud(centre + (axes * d)[seen], None, normals[seen])

    def inside(p: np.ndarray) -> np.ndarray:
        q = p - centre
        c = np.where(q[:, 2] > 0, top_m, bottom_m)
        return bottom_m * (np.sqrt((q[:, 0] / r) ** 2 + (q[:, 1] / r) ** 2 + (q[:, 2] / c) ** 2)
                           - 1.0)

    pitch = 0.001
    lower = np.array([-1.3 * r, -1.3 * r, 0.0])
    axes_m = [lower[i] + pitch * np.arange(int(2.6 * r / pitch) + 1) for i in range(2)]
    axes_m.append(pitch * np.arange(int((bottom_m + top_m) * 1.2 / pitch) + 1))
    grid = np.stack(np.meshgrid(*axes_m, indexing="ij"), axis=-1).reshape(-1, 3)
    state = np.where(inside(grid) < 0, FOOD, EMPTY).astype(np.int8)
    lowest_seen = bottom_m * (1.0 - seen_down_to)
    rim_reach = r * np.sqrt(1.0 - seen_down_to ** 2)
    wedge = (grid[:, 2] < lowest_seen) & (np.linalg.norm(grid[:, :2], axis=1) < rim_reach + pitch)
    state[wedge] = UNKNOWN
    shape = tuple(len(a) for a in axes_m)
    return (cloud, SupportPlane((0.0, 0.0, 1.0), 0.0, 1000, 0.0),
            SpaceGrid(lower, pitch, state.reshape(shape)), inside)


def test_a_lens_flatter_below_rests_on_the_squashed_reflection_of_its_top():
    # an empanadilla's lens: the lower half 0.7 of the upper's depth. Reflected plainly at its
    # widest level, the top would reach 3.6 mm below the plate; cut there it lays a flat disc
    # over the plate, outside the lens. Squashed to rest on the plate, it is the lower half.
    top_m, bottom_m = 0.012, 0.0084
    cloud, table, space, inside = _lens(0.03, top_m, bottom_m, 0.5)
    points, record = underside_points(cloud, table, space, UndersideConfig())
    assert record["symmetric"] and len(points) > 100
    assert abs(record["squash"] - bottom_m / top_m) < 0.05
    assert abs(record["mirror_height_mm"] - 1000 * bottom_m) < 0.5
    assert np.median(np.abs(inside(points.xyz))) < 0.0001
    plain, plain_record = underside_points(cloud, table, space,
                                           UndersideConfig(rest_on_plate=False))
    assert plain_record["squash"] == 1.0
    assert np.median(inside(plain.xyz)) > 0.0004  # the cut reflection lies outside the lens


def test_a_lens_fuller_below_rests_on_the_stretched_reflection_of_its_top():
    # the lower half 1.15 times the upper's depth: reflected plainly at the level the fit
    # finds (13.5 mm, the widest at 13.8), the top hovers above the plate and lies 0.38 mm
    # inside the lower half (median); stretched down to rest on the plate, 0.06 mm outside
    top_m, bottom_m = 0.012, 0.0138
    cloud, table, space, inside = _lens(0.03, top_m, bottom_m, 0.5)
    plain, plain_record = underside_points(cloud, table, space,
                                           UndersideConfig(stretch_to_plate=False))
    points, record = underside_points(cloud, table, space, UndersideConfig())
    assert record["symmetric"] and len(points) > 100
    assert record["mirror_height_mm"] == plain_record["mirror_height_mm"]  # the same level
    assert plain_record["squash"] == 1.0 and record["squash"] > 1.05
    assert np.median(inside(plain.xyz)) < -0.0003
    assert np.median(np.abs(inside(points.xyz))) < 0.6 * np.median(np.abs(inside(plain.xyz)))
    assert points.xyz[:, 2].min() < plain.xyz[:, 2].min() - 0.001


def test_a_symmetric_item_is_reflected_plainly():
    # a sphere's mirror lands its top on the plate: nothing to squash
    _, cloud, table, _, space = _seen_from_above(0.03)
    _, record = underside_points(cloud, table, space, UndersideConfig())
    assert record["symmetric"] and abs(record["squash"] - 1.0) < 0.03


def test_a_stalk_on_top_does_not_lift_the_reflection_off_the_plate():
    # an apple's stalk: a thin stem 6 mm above the body. Were its tip the food's top, the
    # reflection would be squashed to rest the stalk's mirror image on the plate, lifting the
    # reflected body off it (inside the sphere); the body's own top rests there
    from volec.underside import body_top

    r = 0.03
    centre, cloud, table, _, space = _seen_from_above(r)
    rng = np.random.default_rng(8)
    angle, height = rng.uniform(0, 2 * np.pi, 1500), rng.uniform(0, 0.006, 1500)
    side = np.column_stack([np.cos(angle), np.sin(angle), np.zeros(1500)])
    stalk = PointCloud(centre + [0.0, 0.0, r] + 0.0013 * side + np.outer(height, UP), None,
                       side)
    with_stalk = cloud.joined(stalk)
    heights = table.height_m(with_stalk.xyz)
    assert np.percentile(heights, 99.5) > 2 * r + 0.004  # the stalk sets the top
    assert abs(body_top(with_stalk.xyz, heights, UP, UndersideConfig()) - 2 * r) < 0.001
    points, record = underside_points(with_stalk, table, space, UndersideConfig())
    assert record["symmetric"] and record["squash"] == 1.0
    assert np.median(np.abs(np.linalg.norm(points.xyz - centre, axis=1) - r)) < 0.0003
    _, tip_record = underside_points(with_stalk, table, space,
                                     UndersideConfig(min_top_width_share=0.0))
    assert tip_record["squash"] < 0.95  # by the stalk's tip: lifted


def _noisy_cylinder(radius_m: float, height_m: float, noise_m: float, seed: int
                    ) -> PointCloud:
    """Samples of a cylinder standing on z = 0 (its top disc and its wall, about 4 points per
    square millimetre), each moved along its normal by Gaussian noise: stereo's scatter."""
    rng = np.random.default_rng(seed)
    n_top = int(4e6 * np.pi * radius_m**2)
    n_wall = int(4e6 * 2 * np.pi * radius_m * height_m)
    r, a = radius_m * np.sqrt(rng.uniform(0, 1, n_top)), rng.uniform(0, 2 * np.pi, n_top)
    top = np.column_stack([r * np.cos(a), r * np.sin(a), np.full(n_top, height_m)])
    a = rng.uniform(0, 2 * np.pi, n_wall)
    out = np.column_stack([np.cos(a), np.sin(a), np.zeros(n_wall)])
    wall = radius_m * out + np.outer(rng.uniform(0, height_m, n_wall), UP)
    normals = np.vstack([np.tile(UP, (n_top, 1)), out])
    xyz = np.vstack([top, wall]) + normals * rng.normal(0, noise_m, (len(normals), 1))
    return PointCloud(xyz, None, normals)


def test_the_body_top_is_the_surface_s_not_its_noise_s():
    # a cake's flat top, its points scattered by half a millimetre: the highest half-percent
    # of the raw heights is the scatter's tail, a millimetre above the top
    from volec.underside import body_top

    top_m = 0.04
    cloud = _noisy_cylinder(0.03, top_m, 0.0005, seed=3)
    heights = cloud.xyz[:, 2]
    raw = body_top(cloud.xyz, heights, UP, UndersideConfig(top_neighbours=1))
    assert raw > top_m + 0.0008
    assert abs(body_top(cloud.xyz, heights, UP, UndersideConfig()) - top_m) < 0.0003


def _ring_on_table(ring_m: float, tube_m: float
                   ) -> tuple[PointCloud, SupportPlane, SpaceGrid]:
    """A ring (a torus: ``ring_m`` from its axis to its tube's centre, its tube ``tube_m``
    thick) lying on the table z = 0, seen from low cameras: its upper half and the outer side
    down to 30 degrees below its widest level, not the lower inner quarter nor the bottom of
    the hole. The space: food inside the tube, unknown in the lower half of the hole (the
    unseen quarter with it) and under the outer wedge, empty elsewhere (the hole's upper half
    seen through)."""
    rng = np.random.default_rng(7)
    theta, phi = rng.uniform(0, 2 * np.pi, (2, 60000))
    out = np.stack([np.cos(theta), np.sin(theta), np.zeros_like(theta)], axis=1)
    normals = np.cos(phi)[:, None] * out + np.sin(phi)[:, None] * UP
    xyz = ring_m * out + tube_m * UP + tube_m * normals
    seen = (np.sin(phi) > 0) | ((np.cos(phi) > 0) & (np.sin(phi) > -0.5))
    pitch = 0.001
    reach = ring_m + tube_m * 1.3
    lower = np.array([-reach, -reach, 0.0])
    axes_m = [lower[i] + pitch * np.arange(int(2 * reach / pitch) + 1) for i in range(2)]
    axes_m.append(pitch * np.arange(int(2.6 * tube_m / pitch) + 1))
    grid = np.stack(np.meshgrid(*axes_m, indexing="ij"), axis=-1).reshape(-1, 3)
    across = np.linalg.norm(grid[:, :2], axis=1)
    in_tube = np.hypot(across - ring_m, grid[:, 2] - tube_m) < tube_m
    state = np.where(in_tube, FOOD, EMPTY).astype(np.int8)
    lowest_seen = tube_m * 0.5
    state[(grid[:, 2] < tube_m) & (across < ring_m)] = UNKNOWN
    state[(grid[:, 2] < lowest_seen) & (across >= ring_m) & (across < reach)] = UNKNOWN
    shape = tuple(len(a) for a in axes_m)
    return (PointCloud(xyz[seen], None, normals[seen]),
            SupportPlane((0.0, 0.0, 1.0), 0.0, 1000, 0.0),
            SpaceGrid(lower, pitch, state.reshape(shape)))


def test_a_ring_s_unseen_inner_wall_is_the_reflection_of_its_seen_one():
    ring_m, tube_m = 0.03, 0.012
    cloud, table, space = _ring_on_table(ring_m, tube_m)
    centre = cloud.xyz.mean(axis=0)
    # the ring's axis is unknown in the hole's lower half and meets its seen air above
    heights = np.array([0.1, 0.5, 0.9, 1.5]) * tube_m
    on_wall = np.outer(heights, UP) + [ring_m, 0, 0]
    np.testing.assert_array_equal(hole_above(on_wall, centre, table, space),
                                  [True, True, True, False])
    seen_through = space.states_at(space.points()) == UNKNOWN
    seen_through &= np.linalg.norm(space.points()[:, :2], axis=1) < ring_m - tube_m
    state = space.state.copy().reshape(-1)
    state[seen_through] = EMPTY
    whole_hole_seen = replace(space, state=state.reshape(space.state.shape))
    assert not hole_above(on_wall, centre, table, whole_hole_seen).any()

    kept, record = underside_points(cloud, table, space, UndersideConfig())
    assert record["symmetric"] and abs(record["mirror_height_mm"] - 1000 * tube_m) < 0.5
    across = np.linalg.norm(kept.xyz[:, :2], axis=1)
    off_tube = np.hypot(across - ring_m, kept.xyz[:, 2] - tube_m) - tube_m
    assert np.abs(off_tube).max() < 0.001
    inner = across < ring_m - tube_m * 0.3
    assert inner.sum() > 200  # the hole's wall is kept: its normals face the axis
    assert np.all(kept.xyz[inner, 2] < tube_m)

    without, _ = underside_points(cloud, table, space, UndersideConfig(through_holes=False))
    assert not (np.linalg.norm(without.xyz[:, :2], axis=1) < ring_m - tube_m * 0.3).any()


def test_under_a_body_the_axis_meets_food_before_air():
    r = 0.03
    centre, cloud, table, _, space = _seen_from_above(r)
    bottom = centre + np.array([[0.0, 0.0, -0.8 * r], [0.01, 0.0, -0.7 * r]])
    assert not hole_above(bottom, centre, table, space).any()
