"""Masking against silhouettes of a sphere, computed analytically."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from volec.capture import Capture, Frame, Intrinsics
from volec.geometry import look_at_opencv
from volec.masking import MaskingConfig, MaskingError, check_masks, mask_cloud
from volec.pointcloud import PointCloud
from volec.segment import given_masks

INTR = Intrinsics(96, 72, 90.0, 90.0, 47.5, 35.5)
RADIUS_M = 0.03


def _sphere_capture(root: Path, n_views: int = 8, intr: Intrinsics = INTR) -> Capture:
    """Cameras on a ring around a sphere of RADIUS_M at the origin, each with its exact
    silhouette as mask."""
    root.mkdir(parents=True, exist_ok=True)
    u, v = np.meshgrid(np.arange(intr.width), np.arange(intr.height))
    rays = np.stack([(u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, np.ones(u.shape)], -1)
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    frames = []
    for i in range(n_views):
        a = 2 * np.pi * i / n_views
        eye = np.array([0.25 * np.cos(a), 0.25 * np.sin(a), 0.12])
        T = look_at_opencv(eye, np.zeros(3), np.array([0.0, 0.0, 1.0]))
        centre_cam = T[:3, :3].T @ (np.zeros(3) - eye)
        # a ray is inside the silhouette when it passes within RADIUS_M of the centre
        along = rays @ centre_cam
        miss = np.linalg.norm(rays * along[..., None] - centre_cam, axis=-1)
        mask = (miss <= RADIUS_M) & (along > 0)
        path = root / f"mask_{i}.png"
        Image.fromarray((mask * 255).astype(np.uint8)).save(path)
        frames.append(Frame(f"f{i}.png", root / f"f{i}.png", intr, T, mask_path=path))
    return Capture(root, tuple(frames))


def test_points_inside_the_item_stay_and_the_table_goes(tmp_path):
    cap = _sphere_capture(tmp_path / "cap")
    masks = given_masks(cap)
    rng = np.random.default_rng(0)
    inside = rng.normal(size=(300, 3))
    radii = 0.9 * RADIUS_M * rng.random(300) ** (1 / 3)
    inside *= (radii / np.linalg.norm(inside, axis=1))[:, None]
    # a table ring at the sphere's foot, well outside its silhouettes
    angle = rng.uniform(0, 2 * np.pi, 200)
    radius = rng.uniform(2.0 * RADIUS_M, 3.0 * RADIUS_M, 200)
    table = np.c_[radius * np.cos(angle), radius * np.sin(angle), np.full(200, -RADIUS_M)]
    cloud = PointCloud(np.vstack([inside, table]))
    poses = np.stack([f.T_world_from_cam for f in cap.frames])
    result = mask_cloud(cloud, cap, masks, poses, np.ones(len(cap), bool), MaskingConfig())
    assert len(result.cloud) == 300
    np.testing.assert_array_equal(result.cloud.xyz, inside)
    r = result.report
    assert r["input_points"] == 500 and r["kept"] == 300 and r["removed_outside_mask"] == 200
    assert r["kept"] + r["removed_outside_mask"] + r["removed_too_few_views"] == 500


def test_stereo_noise_on_the_surface_is_not_pushed_inside(tmp_path):
    # a phone's view of the sphere (0.48 mm per pixel at the ring's 25 cm) and surface points
    # with symmetric radial noise, as dense stereo gives them (0.6 mm, smooth over a few mm
    # like the errors of windowed matching): masking drops the ones noise put outside a
    # silhouette near the rims and keeps those it put inside, unless the masks are grown
    # enough; the kept points' median must stay on the sphere
    cap = _sphere_capture(tmp_path / "cap", 48, Intrinsics(640, 480, 520.0, 520.0, 319.5,
                                                           239.5))
    rng = np.random.default_rng(2)
    direction = rng.normal(size=(40000, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    waves = rng.normal(size=(24, 3))
    waves *= (2 * np.pi / rng.uniform(0.003, 0.006, 24) / np.linalg.norm(waves, axis=1))[:, None]
    smooth = np.sin(RADIUS_M * direction @ waves.T + rng.uniform(0, 2 * np.pi, 24)).sum(axis=1)
    noise_m = 0.0006 * smooth / smooth.std()
    cloud = PointCloud(direction * (RADIUS_M + noise_m)[:, None])
    poses = np.stack([f.T_world_from_cam for f in cap.frames])

    def median_offset_mm(cfg: MaskingConfig) -> float:
        kept = mask_cloud(cloud, cap, given_masks(cap), poses, np.ones(len(cap), bool), cfg)
        return 1000 * float(np.median(np.linalg.norm(kept.cloud.xyz, axis=1) - RADIUS_M))

    assert abs(median_offset_mm(MaskingConfig())) < 0.03
    assert median_offset_mm(MaskingConfig(mask_dilation_px=1)) < -0.05  # the bias it removes


def test_the_inside_fraction_decides_points_missed_by_one_view(tmp_path):
    cap = _sphere_capture(tmp_path / "cap")
    masks = given_masks(cap)
    poses = np.stack([f.T_world_from_cam for f in cap.frames])
    # a point straight behind the sphere from view 0, off-axis: outside some silhouettes
    point = np.array([[-1.6 * RADIUS_M, 0.0, 0.0]])
    strict = mask_cloud(PointCloud(np.vstack([point, [[0, 0, 0]]])), cap, masks, poses,
                        np.ones(len(cap), bool), MaskingConfig(min_inside_fraction=1.0))
    assert len(strict.cloud) == 1  # only the centre
    from volec.masking import mask_votes

    seen, inside = mask_votes(PointCloud(point), cap, masks, poses, np.ones(len(cap), bool), 0)
    assert seen[0] == len(cap) and 0 < inside[0] < len(cap)
    fraction = inside[0] / seen[0]
    loose = mask_cloud(PointCloud(point), cap, masks, poses, np.ones(len(cap), bool),
                       MaskingConfig(min_inside_fraction=fraction, mask_dilation_px=0))
    assert len(loose.cloud) == 1


def test_unregistered_views_do_not_vote_and_too_few_views_remove(tmp_path):
    cap = _sphere_capture(tmp_path / "cap")
    masks = given_masks(cap)
    poses = np.stack([f.T_world_from_cam for f in cap.frames])
    use = np.zeros(len(cap), bool)
    use[:2] = True
    origin = PointCloud(np.zeros((1, 3)))
    with pytest.raises(MaskingError, match="no point"):
        mask_cloud(origin, cap, masks, poses, use, MaskingConfig(min_views=3))
    result = mask_cloud(origin, cap, masks, poses, use, MaskingConfig(min_views=2))
    assert result.report["views"] == 2 and len(result.cloud) == 1


def test_a_capture_without_masks_is_a_clear_error(tmp_path):
    cap = _sphere_capture(tmp_path / "cap")
    from dataclasses import replace

    bare = Capture(cap.root, tuple(replace(f, mask_path=None) for f in cap.frames))
    with pytest.raises(MaskingError, match="no food mask"):
        given_masks(bare)


def _edit_mask(frame: Frame, change) -> None:
    mask = np.asarray(Image.open(frame.mask_path)) > 127
    Image.fromarray((change(mask) * 255).astype(np.uint8)).save(frame.mask_path)


def _sphere_and_table(n_inside: int = 300) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(1)
    inside = rng.normal(size=(n_inside, 3))
    inside *= (0.9 * RADIUS_M * rng.random(n_inside) ** (1 / 3)
               / np.linalg.norm(inside, axis=1))[:, None]
    angle = rng.uniform(0, 2 * np.pi, 200)
    radius = rng.uniform(2.0 * RADIUS_M, 3.0 * RADIUS_M, 200)
    table = np.c_[radius * np.cos(angle), radius * np.sin(angle), np.full(200, -RADIUS_M)]
    return inside, table


def test_unusable_masks_are_named_and_take_no_part(tmp_path):
    cap = _sphere_capture(tmp_path / "cap", n_views=16)
    _edit_mask(cap.frames[2], lambda m: np.zeros_like(m))
    _edit_mask(cap.frames[5], lambda m: ~m)

    def frame_with_a_hole(m: np.ndarray) -> np.ndarray:
        out = np.ones_like(m)
        out[10:-10, 12:-12] = False  # half the image, all of its border
        return out

    _edit_mask(cap.frames[7], frame_with_a_hole)
    masks = given_masks(cap)
    bad = check_masks(masks)
    assert sorted(bad) == ["f2.png", "f5.png", "f7.png"]
    assert "empty" in bad["f2.png"] and "whole frame" in bad["f5.png"]
    assert "border" in bad["f7.png"]
    inside, table = _sphere_and_table()
    poses = np.stack([f.T_world_from_cam for f in cap.frames])
    result = mask_cloud(PointCloud(np.vstack([inside, table])), cap, masks, poses,
                        np.ones(len(cap), bool), MaskingConfig())
    # the empty mask would have removed the whole item, the inverted one the table's absence
    np.testing.assert_array_equal(result.cloud.xyz, inside)
    assert result.report["unusable_masks"] == bad and result.report["views"] == 13
    _edit_mask(cap.frames[8], lambda m: np.zeros_like(m))
    with pytest.raises(MaskingError, match=r"4 of 16 food masks are unusable \(.*mask_2\.png"):
        check_masks(given_masks(cap))


def test_one_frame_missing_part_of_the_food_does_not_remove_it(tmp_path):
    cap = _sphere_capture(tmp_path / "cap", n_views=10)
    # a segmenter missed the right half of the item in one frame
    _edit_mask(cap.frames[3], lambda m: m & (np.arange(m.shape[1]) < INTR.cx)[None, :])
    masks = given_masks(cap)
    inside, table = _sphere_and_table()
    cloud = PointCloud(np.vstack([inside, table]))
    poses = np.stack([f.T_world_from_cam for f in cap.frames])
    use = np.ones(len(cap), bool)
    tolerant = mask_cloud(cloud, cap, masks, poses, use, MaskingConfig())
    np.testing.assert_array_equal(tolerant.cloud.xyz, inside)  # all food, no table
    strict = mask_cloud(cloud, cap, masks, poses, use, MaskingConfig(max_outside_views=0))
    assert 0 < len(strict.cloud) < 0.8 * len(inside)  # the paper's rule loses the half
