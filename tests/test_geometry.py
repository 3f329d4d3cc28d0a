import numpy as np
import pytest

from volec.geometry import (
    azimuth_span_deg,
    invert_rigid,
    look_at_opencv,
    opencv_c2w_to_opengl,
    opengl_c2w_to_opencv,
    rigid_problem,
    rotation_angle_deg,
    rotvec_to_matrix,
    transform_points,
)


def random_pose(rng: np.random.Generator) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = rotvec_to_matrix(rng.normal(size=3))
    T[:3, 3] = rng.normal(size=3)
    return T


def test_gl_cv_conversion_is_an_involution():
    T = random_pose(np.random.default_rng(0))
    np.testing.assert_allclose(opencv_c2w_to_opengl(opengl_c2w_to_opencv(T)), T, atol=1e-15)


def test_gl_to_cv_flips_the_camera_y_and_z_axes():
    # An OpenGL camera with identity rotation looks along -z (world) with +y up.
    T_cv = opengl_c2w_to_opencv(np.eye(4))
    np.testing.assert_allclose(T_cv[:3, 2], [0, 0, -1])  # OpenCV forward = world -z
    np.testing.assert_allclose(T_cv[:3, 1], [0, -1, 0])  # OpenCV down = world -y
    np.testing.assert_allclose(T_cv[:3, 0], [1, 0, 0])


def test_invert_rigid_matches_the_general_inverse():
    T = random_pose(np.random.default_rng(1))
    np.testing.assert_allclose(invert_rigid(T), np.linalg.inv(T), atol=1e-12)


def test_look_at_points_the_optical_axis_at_the_target_with_image_down_along_gravity():
    eye, target = np.array([0.3, -0.2, 0.25]), np.array([0.0, 0.0, 0.03])
    T = look_at_opencv(eye, target, np.array([0.0, 0.0, 1.0]))
    assert rigid_problem(T) is None
    p_cam = transform_points(invert_rigid(T), target[None])[0]
    np.testing.assert_allclose(p_cam[:2], 0, atol=1e-12)
    assert p_cam[2] == pytest.approx(np.linalg.norm(target - eye))
    assert T[2, 1] < 0  # camera y (image down) has a negative world-z component


@pytest.mark.parametrize(
    "matrix, words",
    [
        (np.full((4, 4), np.nan), "NaN"),
        (np.zeros((4, 4)) + np.diag([0, 0, 0, 1.0]), "singular"),
        (np.diag([2.0, 2, 2, 1]), "not a proper rotation"),
        (np.diag([1.0, 1, -1, 1]), "not a proper rotation"),
        (np.eye(3), "shape"),
    ],
)
def test_rigid_problem_names_the_defect(matrix, words):
    assert words in rigid_problem(matrix)


def test_rotation_angle():
    R = rotvec_to_matrix(np.array([0.0, 0.0, np.radians(30)]))
    assert rotation_angle_deg(np.eye(3), R) == pytest.approx(30.0)


def test_azimuth_span_of_cameras_on_arcs():
    angles = np.radians(np.arange(0, 100, 5.0))
    arc = np.c_[np.cos(angles), np.sin(angles), np.full_like(angles, 0.5)]
    assert azimuth_span_deg(arc, np.zeros(3), np.array([0.0, 0.0, 1.0])) == pytest.approx(95)
    full = np.radians(np.arange(0, 360, 10.0))
    ring = np.c_[np.cos(full), np.sin(full), np.zeros_like(full)]
    assert azimuth_span_deg(ring, np.zeros(3), np.array([0.0, 0.0, 1.0])) == pytest.approx(350)


def test_ransac_plane_finds_a_tilted_plane_among_outliers_the_same_way_every_run():
    from volec.geometry import ransac_plane

    rng = np.random.default_rng(3)
    normal = np.array([0.1, -0.2, 1.0]) / np.linalg.norm([0.1, -0.2, 1.0])
    side = np.cross(normal, [1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)
    other = np.cross(normal, side)
    uv = rng.uniform(-0.1, 0.1, size=(30000, 2))
    on_plane = (uv[:, :1] * side + uv[:, 1:] * other + 0.05 * normal
                + rng.normal(scale=2e-4, size=(30000, 1)) * normal)
    clutter = rng.uniform(-0.1, 0.1, size=(20000, 3)) + [0.0, 0.0, 0.1]
    points = np.vstack([on_plane, clutter])
    first = ransac_plane(points, 0.001, 500, seed=0)
    found, offset, inliers = first
    if found @ normal < 0:
        found, offset = -found, -offset
    assert np.degrees(np.arccos(min(1.0, found @ normal))) < 0.1
    assert offset == pytest.approx(-0.05, abs=1e-4)  # the plane normal @ x = 0.05
    assert np.isin(np.arange(30000), inliers).mean() > 0.99
    again = ransac_plane(points, 0.001, 500, seed=0)
    assert np.array_equal(again[0], first[0]) and np.array_equal(again[2], first[2])
