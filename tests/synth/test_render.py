import numpy as np
import pytest
from scipy.spatial import cKDTree

from volec.geometry import look_at_opencv
from volec.synth.render import Renderer
from volec.synth.scene import FOOD, PLATE, build_scene
from volec.synth.shapes import item_mesh


@pytest.fixture(scope="module")
def scene():
    return build_scene(item_mesh("lemon", 64), "lemon", seed=3, yaw_rad=0.4)


def test_food_depth_unprojects_onto_the_true_surface(scene):
    # Pixel centres at integer coordinates (OpenCV): a half-pixel slip would put the
    # unprojected points about 0.5 mm off the surface at this distance.
    K = np.array([[300.0, 0, 79.5 + 1.3], [0, 300.0, 99.5 - 0.7], [0, 0, 1]])
    eye = np.array([0.18, -0.12, 0.16])
    T = look_at_opencv(eye, np.array([0.0, 0.0, 0.02]), np.array([0.0, 0.0, 1.0]))
    view = Renderer(scene).render(K, 160, 200, T)
    v, u = np.nonzero(view.food_mask)
    assert len(u) > 500
    z = view.depth_m[v, u]
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(z)], 1)
    points = (rays * z[:, None]) @ T[:3, :3].T + T[:3, 3]
    surface = scene.food.sample(200_000, seed=0)
    dist, _ = cKDTree(surface).query(points)
    assert np.median(dist) < 2e-4
    assert np.abs(points[:, 2]).min() < 0.05  # sanity: the food is near the plate


def test_labels_and_image_content(scene):
    K = np.array([[200.0, 0, 63.5], [0, 200.0, 63.5], [0, 0, 1]])
    T = look_at_opencv(np.array([0.0, -0.05, 0.35]), np.zeros(3), np.array([0.0, 0.0, 1.0]))
    view = Renderer(scene).render(K, 128, 128, T)
    assert view.label[64, 64] == FOOD  # looking down at the lemon
    assert (view.label == PLATE).sum() > 1000
    assert view.rgb.min() >= 0 and view.rgb.max() <= 1
    assert np.isinf(view.depth_m[view.label < 0]).all()


def _sphere_scene(radius: float = 0.03):
    import trimesh

    food = trimesh.creation.icosphere(subdivisions=5, radius=radius)
    food.apply_translation([0.0, 0.0, radius])
    return build_scene(food, "apple", seed=1)


def test_the_phone_look_masks_pixels_by_the_share_the_food_covers():
    from volec.synth.render import LOOKS

    radius = 0.03
    scene = _sphere_scene(radius)
    K = np.array([[250.0, 0, 79.5], [0, 250.0, 79.5], [0, 0, 1]])
    eye = np.array([0.0, -0.02, 0.3])
    T = look_at_opencv(eye, np.array([0.0, 0.0, radius]), np.array([0.0, 0.0, 1.0]))
    view = Renderer(scene).render(K, 160, 160, T, LOOKS["phone"])
    cov = view.food_coverage
    partial = (cov > 0) & (cov < 1)
    assert partial.sum() > 100  # the rim is integrated over each pixel's area
    # analytic: a pixel is mostly food when its centre ray passes within the sphere
    u, v = np.meshgrid(np.arange(160.0), np.arange(160.0))
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], -1)
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    centre = T[:3, :3].T @ (np.array([0.0, 0.0, radius]) - eye)
    along = rays @ centre
    inside = np.linalg.norm(rays * along[..., None] - centre, axis=-1) <= radius
    assert (view.food_mask != inside).sum() <= 0.02 * partial.sum() + 4
    # away from the rim the share is all or nothing
    from scipy import ndimage

    rim = ndimage.binary_dilation(inside ^ ndimage.binary_erosion(inside), iterations=2)
    assert set(np.unique(cov[~rim])) <= {0.0, 1.0}


def test_the_phone_look_has_soft_shadows_and_blur():
    from volec.synth.render import LOOKS

    scene = _sphere_scene()
    K = np.array([[200.0, 0, 99.5], [0, 200.0, 99.5], [0, 0, 1]])
    T = look_at_opencv(np.array([0.05, -0.25, 0.35]), np.zeros(3), np.array([0.0, 0.0, 1.0]))
    renderer = Renderer(scene)
    sharp = renderer.render(K, 200, 200, T, LOOKS["sharp"])
    phone = renderer.render(K, 200, 200, T, LOOKS["phone"])
    plate = (sharp.label == PLATE) & (phone.label == PLATE)
    # on the plate, the sharp look's shadow has two levels; the phone's shades in between
    levels = np.unique(np.round(sharp.rgb[plate][:, 0], 2))
    between = (phone.rgb[plate][:, 0] > levels.min() + 0.05) & (
        phone.rgb[plate][:, 0] < levels.max() - 0.05)
    assert between.sum() > 5 * (np.diff(np.sort(sharp.rgb[plate][:, 0])) > 0.05).sum()
    # the optical blur lowers the pixel-to-pixel differences
    assert np.abs(np.diff(phone.rgb[..., 1], axis=1)).mean() < 0.8 * np.abs(
        np.diff(sharp.rgb[..., 1], axis=1)).mean()


def test_a_second_object_is_rendered_but_is_not_food():
    from volec.synth.render import LOOKS
    from volec.synth.scene import OTHER, Setup

    food = item_mesh("apple", 48)
    cup_scene = build_scene(food, "apple", seed=1, setup=Setup(second_object="cup"))
    K = np.array([[200.0, 0, 99.5], [0, 200.0, 79.5], [0, 0, 1]])
    T = look_at_opencv(np.array([0.0, -0.45, 0.3]), np.array([0.1, 0.0, 0.02]),
                       np.array([0.0, 0.0, 1.0]))
    view = Renderer(cup_scene).render(K, 200, 160, T, LOOKS["phone"])
    assert (view.label == OTHER).sum() > 200
    assert not (view.food_mask & (view.label == OTHER)).any()
    # the food across the rim: the plate moves, the food stays where it was
    rim = build_scene(food, "apple", seed=1, setup=Setup(food_offset=0.85))
    np.testing.assert_allclose(rim.food.bounds, cup_scene.food.bounds)


def test_row_norms_are_numpys_bit_for_bit():
    # The renderer's bytes must not depend on which of the two computes a ray's length.
    from volec.synth.render import _row_norms

    rng = np.random.default_rng(0)
    for n in (1, 7, 8193, 100_000):
        v = rng.normal(size=(n, 3)) * 10.0 ** rng.integers(-5, 3, size=(n, 3))
        assert np.array_equal(_row_norms(v), np.linalg.norm(v, axis=1))
