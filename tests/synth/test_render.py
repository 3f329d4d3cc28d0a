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
