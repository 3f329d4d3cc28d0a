"""Normalization round trip and its invariances."""

import numpy as np
import pytest

from volec.completion.preprocess import (
    fit_normalization,
    fit_upright_normalization,
    frame_normalization,
    remove_statistical_outliers,
    resample,
)
from volec.geometry import rotvec_to_matrix


def _cloud(seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.normal(size=(500, 3)) * [0.05, 0.02, 0.01] + [0.3, -0.2, 1.0]


def test_the_inverse_is_exact():
    xyz = _cloud()
    norm = fit_normalization(xyz)
    np.testing.assert_allclose(norm.invert(norm.apply(xyz)), xyz, atol=1e-12)


def test_normalized_cloud_is_centred_in_the_unit_sphere_on_its_principal_axes():
    y = fit_normalization(_cloud()).apply(_cloud())
    np.testing.assert_allclose(y.mean(axis=0), 0.0, atol=1e-12)
    assert np.linalg.norm(y, axis=1).max() == pytest.approx(1.0)
    cov = np.cov(y.T)
    np.testing.assert_allclose(cov - np.diag(np.diag(cov)), 0.0, atol=1e-12)
    assert cov[0, 0] > cov[1, 1] > cov[2, 2]


def test_the_same_shape_in_any_pose_normalizes_to_the_same_cloud():
    xyz = _cloud()
    R = rotvec_to_matrix(np.array([0.4, -1.1, 2.0]))
    moved = 2.5 * xyz @ R.T + [1.0, 2.0, 3.0]
    a = fit_normalization(xyz).apply(xyz)
    b = fit_normalization(moved).apply(moved)
    np.testing.assert_allclose(a, b, atol=1e-9)
    assert np.linalg.det(fit_normalization(moved).rotation) == pytest.approx(1.0)


def test_the_upright_frame_puts_the_table_normal_on_z_whatever_the_shape():
    # the cloud's largest spread is vertical: PCA would put it on x; upright keeps it on z,
    # with x along its longer horizontal side, in any pose about any up
    rng = np.random.default_rng(1)
    local = rng.normal(size=(2000, 3)) * [0.02, 0.01, 0.05]
    R = rotvec_to_matrix(np.array([0.4, -1.1, 2.0]))
    up = R[:, 2]
    xyz = local @ R.T + [0.3, -0.2, 1.0]
    norm = fit_upright_normalization(xyz, 3.0 * up)
    np.testing.assert_allclose(norm.rotation[2], up, atol=1e-12)
    assert abs(norm.rotation[0] @ R[:, 0]) == pytest.approx(1.0, abs=1e-2)
    assert np.linalg.det(norm.rotation) == pytest.approx(1.0)
    np.testing.assert_allclose(norm.rotation @ norm.rotation.T, np.eye(3), atol=1e-12)
    y = norm.apply(xyz)
    np.testing.assert_allclose(norm.invert(y), xyz, atol=1e-12)
    assert np.linalg.norm(y, axis=1).max() == pytest.approx(1.0)
    np.testing.assert_allclose(y[:, 2], (xyz - xyz.mean(axis=0)) @ up / norm.scale, atol=1e-12)


def test_resample_gives_exactly_n_points_from_the_cloud():
    xyz = _cloud()
    rng = np.random.default_rng(0)
    for n in (100, 500, 1300):
        out = resample(xyz, n, rng)
        assert out.shape == (n, 3)
        assert set(map(tuple, out)) <= set(map(tuple, xyz))
    assert len(set(map(tuple, resample(xyz, 1300, rng)))) == 500  # every point kept


def test_statistical_outliers_are_removed():
    xyz = np.vstack([_cloud(), [[5.0, 5.0, 5.0]]])
    kept = remove_statistical_outliers(xyz)
    assert len(kept) >= 480 and not np.any(np.all(kept == [5.0, 5.0, 5.0], axis=1))


def test_the_frame_switch_refuses_an_unknown_frame_and_upright_without_up():
    from volec.errors import DataError

    xyz = _cloud()
    np.testing.assert_allclose(frame_normalization(xyz, "pca", None).rotation,
                               fit_normalization(xyz).rotation)
    with pytest.raises(DataError, match="support plane"):
        frame_normalization(xyz, "upright", None)
    with pytest.raises(DataError, match="unknown input frame"):
        frame_normalization(xyz, "sideways", np.array([0.0, 0.0, 1.0]))
    from volec.completion.preprocess import FRAMES, frame_needs_up

    assert [f for f in FRAMES if frame_needs_up(f)] == ["upright"]
