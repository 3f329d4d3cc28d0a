"""SfM: unit tests against analytic answers, and one small end-to-end run."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from volec.capture import Capture, Frame, Intrinsics, read_transforms_json
from volec.geometry import look_at_opencv, make_transform, rotation_angle_deg, rotvec_to_matrix
from volec.sfm import (
    SfmConfig,
    SfmError,
    evaluate_sfm,
    fit_similarity,
    load_sfm,
    rotation_mean,
    run_sfm,
    select_pairs,
    short_baseline_scale,
)

INTR = Intrinsics(64, 48, 50.0, 50.0, 31.5, 23.5)


def orbit_capture(n: int, arc_deg: float = 360.0, root: Path = Path("/nonexistent")) -> Capture:
    frames = []
    for i in range(n):
        a = np.radians(arc_deg) * i / n
        eye = np.array([0.3 * np.cos(a), 0.3 * np.sin(a), 0.2])
        T = look_at_opencv(eye, np.zeros(3), np.array([0.0, 0.0, 1.0]))
        frames.append(Frame(f"f{i}.png", root / f"f{i}.png", INTR, T))
    return Capture(root, tuple(frames))


def test_pairing_counts_and_loop_closure():
    cap = orbit_capture(40)
    assert len(select_pairs(cap, SfmConfig(pairing="exhaustive"))) == 40 * 39 // 2
    seq = select_pairs(cap, SfmConfig(pairing="sequential", sequential_overlap=5))
    assert len(seq) == sum(min(5, 39 - i) for i in range(40))
    assert (0, 39) not in seq
    guided = select_pairs(cap, SfmConfig(pairing="ar_guided", pair_max_angle_deg=30))
    assert (0, 39) in guided  # last frame sees what the first saw: the loop closes
    assert (0, 20) not in guided  # opposite sides are not matched


def test_fit_similarity_recovers_a_known_similarity():
    rng = np.random.default_rng(0)
    src = rng.normal(size=(30, 3))
    truth = make_transform(2.5 * rotvec_to_matrix(np.array([0.3, -0.2, 1.0])), [1.0, 2, 3])
    dst = src @ truth[:3, :3].T + truth[:3, 3]
    np.testing.assert_allclose(fit_similarity(src, dst), truth, atol=1e-10)


def test_rotation_mean_of_small_perturbations():
    rng = np.random.default_rng(1)
    R0 = rotvec_to_matrix(np.array([0.5, 0.1, -0.4]))
    # 0.29 degrees of noise per axis; the mean of 400 has a standard error of about 0.025
    # degrees (0.29 * sqrt(3) / 20), while one sample is off by about 0.5 degrees.
    noisy = np.stack([rotvec_to_matrix(rng.normal(scale=0.005, size=3)) @ R0 for _ in range(400)])
    assert rotation_angle_deg(noisy[0], R0) > 0.2
    assert rotation_angle_deg(rotation_mean(noisy), R0) < 0.1


def test_short_baseline_scale_ignores_slow_drift():
    # A model trajectory, the AR one = 0.08 x model (rotated, shifted) + slow drift that
    # is large compared with the orbit. Short displacements keep the scale.
    t = np.linspace(0, 1, 100)
    model = np.stack([np.cos(2 * np.pi * t), np.sin(2 * np.pi * t), 0.3 * np.sin(6 * t)], 1) * 4
    R = rotvec_to_matrix(np.array([0.1, 0.2, 0.3]))
    drift = 0.01 * np.stack([t**2, np.sin(np.pi * t), t], 1)  # 1 cm over the capture
    ar = 0.08 * model @ R.T + [0.5, 0.1, -0.2] + drift
    s_short = short_baseline_scale(model, ar, R, max_sep=3)
    s_all = float(np.cbrt(np.linalg.det(fit_similarity(model, ar)[:3, :3])))
    assert abs(s_short / 0.08 - 1) < 0.002
    assert abs(s_short / 0.08 - 1) < abs(s_all / 0.08 - 1)


def test_drift_model_recovers_scale_and_the_drift_free_trajectory():
    # AR centres = 0.08 x model (rotated, shifted) + a random walk from zero + jitter: the
    # generalised least squares gets the scale, and the aligned model is closer to the truth
    # than the AR centres are.
    from volec.sfm import drift_model_alignment

    rng = np.random.default_rng(4)
    n = 120
    t = np.linspace(0, 1, n)
    model = np.stack([np.cos(2 * np.pi * t), np.sin(2 * np.pi * t), 0.3 * np.sin(9 * t)], 1) * 3
    R = rotvec_to_matrix(np.array([0.2, -0.1, 0.5]))
    truth = 0.08 * model @ R.T + [0.3, -0.2, 0.1]
    walk = np.cumsum(rng.normal(scale=0.0005, size=(n, 3)), axis=0)
    walk -= walk[0]
    ar = truth + walk + rng.normal(scale=0.0003, size=(n, 3))
    s, tr, drift = drift_model_alignment(model, ar, np.arange(n), R, 0.0003, 0.0005)
    assert abs(s / 0.08 - 1) < 0.003
    aligned = s * model @ R.T + tr
    err_aligned = np.median(np.linalg.norm(aligned - truth, axis=1))
    err_ar = np.median(np.linalg.norm(ar - truth, axis=1))
    assert err_aligned < err_ar / 2
    np.testing.assert_allclose(drift, walk, atol=0.004)


def test_rootsift_descriptors_have_unit_norm_in_colmap_units():
    from volec.sfm import rootsift_uint8

    rng = np.random.default_rng(5)
    raw = rng.integers(0, 200, size=(50, 128)).astype(np.float32)
    d = rootsift_uint8(raw).astype(float) / 512.0
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=0.02)
    # the square root of the L1-normalised descriptor, as COLMAP's L1_ROOT normalisation
    expected = np.sqrt(raw / raw.sum(axis=1, keepdims=True))
    np.testing.assert_allclose(d, expected, atol=1.0 / 512)


@pytest.mark.parametrize("max_size", [400, 200])
def test_opencv_sift_keypoints_are_in_full_image_pixels(max_size):
    # Dark Gaussian blobs with known centres on a 400x300 image: SIFT finds each blob at its
    # centre, also when the image is first halved, once mapped back to full-size pixels.
    # (Without enable_precise_upscale OpenCV put them 0.24 px off; halved, 0.7 px.)
    from volec.sfm import opencv_sift_features

    centres = np.array([[80.0, 70.0], [250.0, 90.0], [150.0, 200.0], [320.0, 230.0]])
    v, u = np.mgrid[0:300, 0:400].astype(float)
    img = np.full((300, 400), 220.0)
    for cx, cy in centres:
        img -= 150 * np.exp(-((u - cx) ** 2 + (v - cy) ** 2) / (2 * 6.0**2))
    xy, desc = opencv_sift_features(img.astype(np.uint8), SfmConfig(max_image_size_px=max_size))
    assert desc.shape == (len(xy), 128) and desc.dtype == np.uint8
    found = xy[:, :2] - 0.5  # COLMAP's 0.5 convention back to pixel centres at integers
    for c in centres:  # sub-pixel: a half-pixel convention slip or upsampling bias fails
        assert np.linalg.norm(found - c, axis=1).min() < 0.1


def test_sift_of_images_is_the_same_on_one_thread_or_several_and_keeps_the_order(tmp_path):
    import cv2

    from volec.sfm import opencv_sift_features, sift_of_images

    rng = np.random.default_rng(2)
    paths = []
    for k in range(5):  # textured images, each its own
        img = cv2.GaussianBlur(rng.uniform(0, 255, (120, 160)), (0, 0), 1.5 + 0.3 * k)
        paths.append(tmp_path / f"f{k}.png")
        cv2.imwrite(str(paths[-1]), img.astype(np.uint8))
    cfg = SfmConfig(max_num_features=300)
    before = cv2.getNumThreads()
    try:
        cv2.setNumThreads(1)
        serial = sift_of_images(paths, cfg)
        cv2.setNumThreads(3)
        pooled = sift_of_images(paths, cfg)
        assert cv2.getNumThreads() == 3  # OpenCV's setting is given back
    finally:
        cv2.setNumThreads(before)
    cv2.setNumThreads(1)
    try:  # each image's own features, in the given order
        alone = [opencv_sift_features(cv2.imread(str(p), cv2.IMREAD_GRAYSCALE), cfg)
                 for p in paths]
    finally:
        cv2.setNumThreads(before)
    for (xy_a, d_a), (xy_b, d_b), (xy_c, d_c) in zip(serial, pooled, alone, strict=True):
        assert len(xy_a) > 20
        np.testing.assert_array_equal(xy_a, xy_b)
        np.testing.assert_array_equal(d_a, d_b)
        np.testing.assert_array_equal(xy_a, xy_c)
        np.testing.assert_array_equal(d_a, d_c)
    with pytest.raises(SfmError, match="cannot be read"):
        sift_of_images([tmp_path / "absent.png"], cfg)


def test_too_few_frames_is_an_error(tmp_path):
    with pytest.raises(SfmError, match="at least 8"):
        run_sfm(orbit_capture(4), tmp_path)


def test_textureless_frames_are_an_error(tmp_path):
    cap = orbit_capture(10, arc_deg=60, root=tmp_path)
    for f in cap.frames:
        Image.new("RGB", (64, 48), (128, 128, 128)).save(f.image_path)
    with pytest.raises(SfmError, match="textureless"):
        run_sfm(cap, tmp_path / "work")
    assert not (tmp_path / "work" / "sfm").exists()  # nothing half-written is left


def test_colmap_sift_backend_also_recovers_the_poses(small_capture, tmp_path):
    reported = read_transforms_json(small_capture / "capture")
    exact = read_transforms_json(small_capture / "ground_truth" / "transforms_exact.json")
    # also the incremental mapping from scratch, which ignores the AR poses
    result = run_sfm(reported, tmp_path, SfmConfig(features="colmap_sift",
                                                   mapping="incremental"))
    assert result.summary["mapping"] == "incremental"
    errors = evaluate_sfm(result, exact, reported)
    assert errors["registered_fraction"] >= 0.9
    assert abs(errors["scale_err_pct"]) < 1.0


def test_sfm_recovers_metric_poses(small_capture, small_result):
    result, reported = small_result
    exact = read_transforms_json(small_capture / "ground_truth" / "transforms_exact.json")
    errors = evaluate_sfm(result, exact, reported)
    assert result.summary["mapping"] == "known_poses"
    assert errors["registered_fraction"] >= 0.9
    assert abs(errors["scale_err_pct"]) < 1.0
    # bundle adjustment removed most of the AR error, not only kept the AR poses
    assert errors["centre_err_median_m"] < 0.5 * errors["ar_centre_err_median_m"]
    assert errors["centre_err_median_m"] < 0.004
    assert errors["rot_err_median_deg"] < 0.5
    assert len(result.points_xyz) > 500
    # the sparse points lie near the scene: within 1 m of the cameras' mean
    assert np.median(np.linalg.norm(result.points_xyz - reported.camera_centres.mean(0),
                                    axis=1)) < 1.0


def test_sfm_writes_an_openable_model_and_reloads(small_capture, small_result):
    from volec.capture import read_colmap_model

    result, reported = small_result
    work = small_capture / "work"
    model = read_colmap_model(work / "sfm" / "model", reported.root)
    assert len(model) == result.registered.sum()
    again = load_sfm(work)
    np.testing.assert_allclose(again.T_world_from_cam, result.T_world_from_cam)
    # bit for bit: dense stereo's depth ranges come from these points, and a stage resumed
    # from disk must give the cloud the first run gave
    np.testing.assert_array_equal(again.points_xyz, result.points_xyz)
    np.testing.assert_array_equal(again.points_rgb, result.points_rgb)
    assert again.summary["registered"] == result.summary["registered"]
    # the written model is metric: its cameras are where the refined poses are
    names = {f.name: f for f in model.frames}
    i = int(np.flatnonzero(result.registered)[0])
    np.testing.assert_allclose(names[result.frame_names[i]].camera_centre,
                               result.T_world_from_cam[i, :3, 3], atol=1e-6)


def test_sfm_run_again_gives_the_same_poses_bit_for_bit(small_result, tmp_path):
    # one COLMAP thread (the default): with all cores the same capture registered other
    # points and poses in every run, and the volume moved by up to 0.8 %
    result, reported = small_result
    again = run_sfm(reported, tmp_path / "work")
    np.testing.assert_array_equal(again.T_world_from_cam, result.T_world_from_cam)
    np.testing.assert_array_equal(again.points_xyz, result.points_xyz)


def test_ar_poses_that_disagree_with_the_images_are_an_error(small_capture, small_result):
    import pycolmap

    from volec.sfm import align_to_ar

    _, reported = small_result
    rng = np.random.default_rng(0)
    order = rng.permutation(len(reported))
    shuffled = Capture(reported.root, tuple(
        replace(f, T_world_from_cam=reported.frames[j].T_world_from_cam)
        for f, j in zip(reported.frames, order, strict=True)))
    rec = pycolmap.Reconstruction(str(small_capture / "work" / "sfm" / "model"))
    with pytest.raises(SfmError, match="disagree|no similarity"):
        align_to_ar(shuffled, rec, SfmConfig())


def test_ar_poses_far_off_are_not_triangulated_from(small_capture, tmp_path, caplog):
    """Each frame given another frame's AR pose: known-pose triangulation keeps too few frames,
    mapping starts from scratch (recorded), and the alignment then refuses the AR poses."""
    reported = read_transforms_json(small_capture / "capture")
    order = np.random.default_rng(0).permutation(len(reported))
    shuffled = Capture(reported.root, tuple(
        replace(f, T_world_from_cam=reported.frames[j].T_world_from_cam)
        for f, j in zip(reported.frames, order, strict=True)))
    with pytest.raises(SfmError, match="disagree"):
        run_sfm(shuffled, tmp_path / "work")
    assert "agree with their AR poses; mapping from scratch" in caplog.text
    assert not (tmp_path / "work" / "sfm").exists()


def test_sampson_distance_is_zero_on_the_epipolar_geometry_and_grows_off_it():
    from volec.sfm import sampson_distance

    rng = np.random.default_rng(1)
    points = rng.uniform([-0.1, -0.1, 0.4], [0.1, 0.1, 0.6], size=(200, 3))
    R = rotvec_to_matrix(np.radians([2.0, -10.0, 1.0]))
    t = np.array([0.1, 0.0, 0.01])
    x1 = points[:, :2] / points[:, 2:]
    in_cam2 = points @ R.T + t
    x2 = in_cam2[:, :2] / in_cam2[:, 2:]
    tn = t / np.linalg.norm(t)
    E = np.array([[0, -tn[2], tn[1]], [tn[2], 0, -tn[0]], [-tn[1], tn[0], 0]]) @ R
    assert sampson_distance(E, x1, x2).max() < 1e-9
    # moving the second view's points 0.01 across (y: the epipolar lines run along x here)
    # puts them about 0.01 / sqrt(2) off in the Sampson sense (split over the two views)
    off = sampson_distance(E, x1, x2 + [0.0, 0.01])
    assert 0.004 < np.median(off) < 0.011


def test_matching_parts_give_the_same_poses_one_at_a_time_or_at_once(small_result, tmp_path):
    # the pairs are matched in parts, each on one thread; how many parts run at once (OpenCV's
    # thread count, which volec batch workers set to one) changes nothing
    import cv2

    result, reported = small_result
    before = cv2.getNumThreads()
    try:
        cv2.setNumThreads(1)
        one = run_sfm(reported, tmp_path / "one")
        cv2.setNumThreads(2)
        two = run_sfm(reported, tmp_path / "two")
    finally:
        cv2.setNumThreads(before)
    for again in (one, two):
        np.testing.assert_array_equal(again.T_world_from_cam, result.T_world_from_cam)
        np.testing.assert_array_equal(again.points_xyz, result.points_xyz)
    assert not list((tmp_path / "two").rglob("*.part*"))  # the parts' copies are gone


def test_a_subset_is_aligned_at_its_frames_times_in_the_recording(small_capture, small_result):
    # every other frame of the 16: the drift model runs on their shares of the recording
    # (0, 2/15, ...), which the summary records and the scale's deviation reads back
    import pycolmap

    from volec.scale_uncertainty import sfm_scale_std
    from volec.sfm import align_to_ar

    result, reported = small_result
    np.testing.assert_array_equal(result.elapsed_shares, np.arange(16) / 15)
    subset = replace(reported, frames=reported.frames[::2])
    rec = pycolmap.Reconstruction(str(small_capture / "work" / "sfm" / "model"))
    aligned = align_to_ar(subset, rec, SfmConfig())
    np.testing.assert_array_equal(aligned.elapsed_shares, np.arange(0, 16, 2) / 15)
    renumbered = align_to_ar(replace(subset, frames=tuple(
        replace(f, elapsed_share=None) for f in subset.frames)), rec, SfmConfig())
    assert sfm_scale_std(aligned, SfmConfig()) < sfm_scale_std(renumbered, SfmConfig())
