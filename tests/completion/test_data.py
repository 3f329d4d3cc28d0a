"""Simulated partial views: what a phone orbit's dense stereo reconstructs of a shape."""

from __future__ import annotations

import numpy as np
import trimesh

from volec.completion.data import ViewConfig, in_holes, partial_view

RADIUS_M = 0.03
# A sphere resting on the table (z = 0).
SPHERE = trimesh.creation.icosphere(subdivisions=4, radius=RADIUS_M)
SPHERE.apply_translation([0.0, 0.0, RADIUS_M])


def _lowest_heights(cfg: ViewConfig, views: int = 4) -> list[float]:
    rng = np.random.default_rng(3)
    return [float(partial_view(SPHERE, rng, cfg)[:, 2].min()) for _ in range(views)]


def test_partial_views_stop_where_every_camera_sees_the_sphere_too_obliquely():
    # Cameras are at least 15 degrees above the table. The sphere's normal tilts theta below
    # the horizontal at height R (1 - sin theta), and the direction to a camera is at least
    # theta + 15 degrees from it, so no camera sees it within 60 degrees (cosine 0.5) below
    # theta = 45 degrees: height 0.293 R. Less 1.5 mm for the noise (0.3 mm) and the mesh.
    cfg = ViewConfig(elevation_deg=(15.0, 60.0), min_view_cosine=0.5, noise_m=0.0003)
    bound_m = RADIUS_M * (1 - np.sin(np.radians(45.0))) - 0.0015
    assert min(_lowest_heights(cfg)) >= bound_m


def test_without_the_limit_partial_views_reach_below_it():
    # Seen edge-on, the sphere shows down to theta = 75 degrees (height 0.034 R = 1 mm), above
    # the contact's 2 mm: some views reach below the 45-degree bound of the test above.
    cfg = ViewConfig(elevation_deg=(15.0, 60.0), min_view_cosine=0.0, noise_m=0.0003)
    bound_m = RADIUS_M * (1 - np.sin(np.radians(45.0))) - 0.0015
    assert min(_lowest_heights(cfg)) < bound_m


def test_holes_are_balls_around_seen_points_of_the_drawn_size():
    # Three holes of radius 10 % of a 60 mm sphere (6 mm) around seen points: every removed
    # point lies within 6 mm of one of three centres, and each hole removes the sphere's
    # points within 6 mm of its centre (about 1 % of the surface each).
    rng = np.random.default_rng(0)
    points = np.asarray(trimesh.sample.sample_surface(SPHERE, 20000, seed=1)[0])
    seen = points[:, 2] > RADIUS_M
    cfg = ViewConfig(holes=(3, 3), hole_radius_share=(0.1, 0.1))
    holes = in_holes(points, seen, 2 * RADIUS_M, rng, cfg)
    assert 0.005 < holes.mean() < 0.04
    assert holes[seen].sum() > 0.5 * holes.sum()  # centred on seen points
    none = in_holes(points, seen, 2 * RADIUS_M, rng, ViewConfig(holes=(0, 0)))
    assert not none.any()


def test_an_upright_dataset_frames_each_pair_about_the_table_normal(tmp_path):
    from volec.completion.data import TABLE_UP, CompletionDataset
    from volec.completion.preprocess import fit_upright_normalization, resample

    rng = np.random.default_rng(3)
    complete = rng.normal(size=(400, 3)) * [0.01, 0.02, 0.04] + [0.0, 0.0, 0.05]
    partial = complete[complete[:, 0] > 0]
    path = tmp_path / "shape.npz"
    np.savez(path, complete=complete, partial_points=partial,
             partial_sizes=np.array([len(partial)]))
    got_partial, got_complete = CompletionDataset([path], 64, 128, "upright").pair(
        0, np.random.default_rng(0))
    draw = np.random.default_rng(0)  # the pair draws the complete cloud first, then the partial
    want_complete = resample(complete, 128, draw)
    want_partial = resample(partial, 64, draw)
    norm = fit_upright_normalization(partial, TABLE_UP)
    np.testing.assert_allclose(got_complete, norm.apply(want_complete), atol=1e-12)
    np.testing.assert_allclose(got_partial, norm.apply(want_partial), atol=1e-12)
    # the largest spread is vertical: framed by PCA it would lie along x instead
    pca_partial, _ = CompletionDataset([path], 64, 128).pair(0, np.random.default_rng(0))
    assert np.var(got_partial[:, 2]) > np.var(got_partial[:, 0])
    assert np.var(pca_partial[:, 0]) > np.var(pca_partial[:, 2])
