import hashlib
import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from scipy.ndimage import binary_dilation

from volec.capture import read_transforms_json
from volec.errors import OutputExistsError
from volec.geometry import rotation_angle_deg, transform_points
from volec.synth import PRESETS, load_ground_truth_mesh, load_truth, write_synthetic_capture


def test_capture_reads_back_with_the_configured_camera(quick_capture):
    cfg = PRESETS["quick"]
    cap = read_transforms_json(quick_capture / "capture")
    assert len(cap) == cfg.trajectory.n_frames
    assert cap.has_masks
    intr = cap.frames[0].intrinsics
    assert (intr.width, intr.height) == (240, 320)
    np.testing.assert_allclose(intr.K, cfg.intrinsics.K, atol=1e-12)
    assert cap.metadata["world_up"] == [0.0, 1.0, 0.0]


def test_ground_truth_volume_is_table_one(quick_capture):
    truth = load_truth(quick_capture)
    assert truth["volume_ml"] == pytest.approx(175.0, rel=1e-6)
    mesh = load_ground_truth_mesh(quick_capture)
    assert mesh.is_watertight
    assert mesh.volume * 1e6 == pytest.approx(175.0, rel=1e-3)


def test_ground_truth_vertices_project_inside_the_masks(quick_capture):
    exact = read_transforms_json(quick_capture / "ground_truth" / "transforms_exact.json")
    verts = np.asarray(load_ground_truth_mesh(quick_capture).vertices)
    for frame in exact.frames:
        mask = np.array(Image.open(frame.mask_path)) > 0
        mask = binary_dilation(mask, iterations=1)
        q = transform_points(frame.T_cam_from_world, verts)
        assert (q[:, 2] > 0).all()
        uv = q[:, :2] / q[:, 2:] * [frame.intrinsics.fx, frame.intrinsics.fy] + [
            frame.intrinsics.cx, frame.intrinsics.cy]
        px = np.round(uv).astype(int)
        inside_image = (px[:, 0] >= 0) & (px[:, 0] < mask.shape[1]) & (px[:, 1] >= 0) & (
            px[:, 1] < mask.shape[0])
        assert inside_image.mean() > 0.99
        hits = mask[px[inside_image, 1], px[inside_image, 0]]
        assert hits.mean() > 0.995, frame.name


def test_world_frame_is_y_up_and_the_food_sits_on_the_plate(quick_capture):
    mesh = load_ground_truth_mesh(quick_capture)
    truth = load_truth(quick_capture)
    T = np.array(truth["T_world_from_scene"])
    np.testing.assert_allclose(T[:3, :3] @ [0, 0, 1], [0, 1, 0], atol=1e-12)
    heights = np.asarray(mesh.vertices) @ np.array(truth["world_up"])
    # plate top is scene z = 0; the PLY holds float32 vertices (sub-micrometre)
    assert heights.min() == pytest.approx(T[1, 3], abs=1e-6)


def test_ar_poses_drift_smoothly_within_the_configured_bounds(quick_capture):
    cfg = PRESETS["quick"].drift
    rep = read_transforms_json(quick_capture / "capture")
    exact = read_transforms_json(quick_capture / "ground_truth" / "transforms_exact.json")
    err = np.linalg.norm(rep.camera_centres - exact.camera_centres, axis=1)
    assert err.max() <= cfg.position_m + 5 * cfg.jitter_position_m
    assert err.max() > cfg.position_m / 2  # there is drift
    assert err[0] < 5 * cfg.jitter_position_m  # it starts at zero
    rot = [rotation_angle_deg(a.T_world_from_cam[:3, :3], b.T_world_from_cam[:3, :3])
           for a, b in zip(rep.frames, exact.frames, strict=True)]
    assert max(rot) <= cfg.rotation_deg + 5 * cfg.jitter_rotation_deg


def test_camera_elevations_follow_the_config(quick_capture):
    cfg = PRESETS["quick"].trajectory
    exact = read_transforms_json(quick_capture / "ground_truth" / "transforms_exact.json")
    mesh = load_ground_truth_mesh(quick_capture)
    up = np.array(load_truth(quick_capture)["world_up"])
    offsets = exact.camera_centres - mesh.bounds.mean(axis=0)
    elevation = np.degrees(np.arcsin(offsets @ up / np.linalg.norm(offsets, axis=1)))
    assert elevation.min() > cfg.elevation_min_deg - 5
    assert elevation.max() < cfg.elevation_max_deg + 5


def _digest(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def test_same_seed_same_bytes_other_seed_other_bytes(tmp_path):
    cfg = PRESETS["quick"].with_(n_frames=4, workers=2)
    a = write_synthetic_capture("falafel", tmp_path / "a", cfg, progress=False)
    b = write_synthetic_capture("falafel", tmp_path / "b", cfg.with_(workers=1), progress=False)
    c = write_synthetic_capture("falafel", tmp_path / "c", cfg.with_(seed=1), progress=False)
    assert _digest(a) == _digest(b)
    da, dc = _digest(a), _digest(c)
    assert da["capture/images/frame_00000.jpg"] != dc["capture/images/frame_00000.jpg"]


def test_existing_output_is_refused_before_rendering(tmp_path, monkeypatch):
    out = tmp_path / "x"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    import volec.synth.generate as gen

    monkeypatch.setattr(gen, "render_frames", lambda *a, **k: pytest.fail("rendered"))
    with pytest.raises(OutputExistsError):
        write_synthetic_capture("apple", out, PRESETS["quick"], progress=False)
    assert (out / "keep.txt").read_text() == "mine"


def test_half_orbit_covers_half_the_azimuths(tmp_path):
    from volec.synth.generate import plan_capture

    plan = plan_capture("lemon", PRESETS["half_orbit"].with_(n_frames=30))
    c = plan.exact_scene_poses[:, :2, 3]
    az = np.unwrap(np.arctan2(c[:, 1], c[:, 0]))
    assert abs(np.degrees(az[-1] - az[0])) == pytest.approx(180, abs=15)


def test_masks_can_be_left_out_of_the_capture(tmp_path):
    cfg = PRESETS["quick"].with_(n_frames=2, masks_in_capture=False)
    out = write_synthetic_capture("orange", tmp_path / "o", cfg, progress=False)
    content = json.loads((out / "capture" / "transforms.json").read_text())
    assert all("mask_path" not in f for f in content["frames"])
    assert not (out / "capture" / "masks").exists()
    assert len(list((out / "ground_truth" / "masks").iterdir())) == 2
