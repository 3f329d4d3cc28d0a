"""The mirror baseline finds a known plane of symmetry."""

import numpy as np

from volec.completion.mirror import fit_mirror_plane, mirror_complete, reflect
from volec.geometry import rotvec_to_matrix


def _cut_shape(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Points on a bent, curled ellipsoid whose only plane of symmetry is x = 0 (the bend and
    the curl are even in x, and break the y and z symmetries), and the same with one end cut
    away obliquely (x + z / 2 > 2 cm), as a view from one side would miss it."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(20000, 3))
    p = d / np.linalg.norm(d, axis=1, keepdims=True) * [0.06, 0.025, 0.018]
    p[:, 1] += 12.0 * p[:, 0] ** 2
    p[:, 2] += 30.0 * p[:, 1] ** 2
    return p[p[:, 0] + p[:, 2] / 2 < 0.02], p


def test_finds_the_plane_of_a_partially_seen_symmetric_box():
    partial, _ = _cut_shape()
    R = rotvec_to_matrix(np.array([0.3, 0.5, -0.2]))
    moved = partial @ R.T + [0.1, 0.2, 0.3]
    normal, offset = fit_mirror_plane(moved)
    truth = R @ np.array([1.0, 0.0, 0.0])
    assert abs(abs(normal @ truth) - 1.0) < 1e-2
    # the plane passes through the shape's middle (x = 0, moved to [0.1, 0.2, 0.3])
    assert abs(normal @ np.array([0.1, 0.2, 0.3]) - offset) < 2e-3


def test_mirror_completion_fills_the_missing_end_and_respects_the_support_plane():
    partial, full = _cut_shape()
    done = mirror_complete(partial)
    assert done[:, 0].max() > 0.055  # the cut-away end came back
    np.testing.assert_allclose(reflect(reflect(partial, np.array([0, 0, 1.0]), 0.01),
                                       np.array([0, 0, 1.0]), 0.01), partial, atol=1e-12)
    clipped = mirror_complete(partial, up=np.array([0.0, 0.0, 1.0]))
    assert clipped[:, 2].min() >= partial[:, 2].min() - 1e-12


def test_the_pipeline_mirror_completion_adds_only_what_was_missing():
    from scipy.spatial import cKDTree

    from volec.completion.complete import CompletionConfig, mirror_completion
    from volec.pointcloud import PREDICTED_RGB, PointCloud

    partial, full = _cut_shape()
    cfg = CompletionConfig(missing_only_gap_m=0.004)
    done = mirror_completion(PointCloud(partial), np.array([0.0, 0.0, 1.0]), cfg)
    added = done.predicted_xyz
    assert len(done.cloud) == len(partial) + len(added)
    np.testing.assert_array_equal(done.cloud.xyz[:len(partial)], partial)
    # what it adds is the cut-away end, on the true surface, and none of it near the partial
    assert added[:, 0].min() > 0.0 and added[:, 0].max() > 0.055
    assert np.median(cKDTree(full).query(added)[0]) < 1e-3
    assert cKDTree(partial).query(added)[0].min() > 0.004
    assert done.cloud.rgb is None or (done.cloud.rgb[len(partial):] == PREDICTED_RGB).all()


def _egg_lying(n: int = 20000, seed: int = 0) -> np.ndarray:
    """Points on an egg lying along x (wider at +x), centred at (0.02, 0.03, 0.025): mirror
    symmetric about the vertical plane y = 0.03 only."""
    d = np.random.default_rng(seed).normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    radius = 0.025 * (1.0 + 0.25 * d[:, 0])
    return np.array([0.02, 0.03, 0.025]) + d * radius[:, None] * np.array([1.6, 1.0, 1.0])


def test_a_vertical_mirror_plane_is_found_and_an_asymmetric_cloud_is_told_apart():
    from volec.completion.mirror import MirrorViewsConfig, fit_vertical_mirror, reflection_matrix

    up = np.array([0.0, 0.0, 1.0])
    egg = _egg_lying()
    fit = fit_vertical_mirror(egg, up)
    assert fit.symmetric and fit.median_distance_m < 0.001
    assert abs(fit.normal @ [0.0, 1.0, 0.0]) > np.cos(np.radians(2.0))  # the plane y = 0.03
    assert abs(fit.offset_m / (fit.normal @ [0.0, 1.0, 0.0]) - 0.03) < 0.0005
    # the homogeneous reflection maps the egg onto itself
    S = reflection_matrix(fit.normal, fit.offset_m)
    moved = egg @ S[:3, :3].T + S[:3, 3]
    np.testing.assert_allclose(moved @ S[:3, :3].T + S[:3, 3], egg, atol=1e-12)
    # a twisted blob (its two lobes turn with height, like a screw): chiral, so no plane at all
    # maps it onto itself
    d = np.random.default_rng(1).normal(size=(20000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    phi, polar = np.arctan2(d[:, 1], d[:, 0]), np.arccos(d[:, 2])
    twisted = d * 0.03 * (1.0 + 0.35 * np.sin(2 * phi + 3 * np.cos(polar)))[:, None]
    fit = fit_vertical_mirror(twisted, up, cfg=MirrorViewsConfig())
    assert not fit.symmetric and fit.median_distance_m > 0.003
