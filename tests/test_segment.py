"""Segmentation: masks against the exact ones on a synthetic scene, and every error."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest
from PIL import Image
from scipy import ndimage

from volec.capture import Intrinsics, read_transforms_json
from volec.geometry import look_at_opencv
from volec.metrics import sample_surface
from volec.segment import (
    SceneGeometry,
    SegmentationError,
    SegmentConfig,
    _pixels,
    _View,
    check_in_view,
    find_item,
    hull_voxel_m,
    item_region,
    load_masks,
    outside_footprint_m,
    save_masks,
    seed_labels,
    segment,
    support_height_m,
)
from volec.synth import load_ground_truth_mesh, load_truth

UP = np.array([0.0, 0.0, 1.0])


def _ring_cameras(n: int = 12, radius: float = 0.3, height: float = 0.2,
                  target=(0.0, 0.0, 0.02)) -> np.ndarray:
    poses = []
    for k in range(n):
        a = 2 * np.pi * k / n
        eye = np.array([radius * np.cos(a), radius * np.sin(a), height])
        poses.append(look_at_opencv(eye, np.asarray(target, float), UP))
    return np.stack(poses)


def _scene_points(rng: np.random.Generator, objects: list[tuple[tuple, float]]) -> np.ndarray:
    """A textured table (z = 0, 40 cm across) and spheres (centre, radius) standing on it."""
    table = np.c_[rng.uniform(-0.2, 0.2, (3000, 2)), np.zeros(3000)]
    parts = [table]
    for centre, r in objects:
        d = rng.normal(size=(400, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        sphere = np.asarray(centre) + r * d
        parts.append(sphere[sphere[:, 2] > 0.004])
    return np.vstack(parts)


def test_the_item_on_the_table_is_found_and_a_second_object_left_out():
    rng = np.random.default_rng(0)
    points = _scene_points(rng, [((0.0, 0.0, 0.03), 0.03), ((0.12, 0.05, 0.02), 0.02)])
    geometry = find_item(_ring_cameras(), points, UP, SegmentConfig())
    np.testing.assert_allclose(geometry.normal, UP, atol=1e-3)
    assert abs(geometry.offset_m) < 1e-3
    assert np.linalg.norm(geometry.item_points.mean(axis=0)[:2]) < 0.01  # the centre one
    assert geometry.other_clusters == 1
    second = geometry.other_objects[0]
    assert np.linalg.norm(second.mean(axis=0)[:2] - (0.12, 0.05)) < 0.01
    assert np.all(geometry.height_m(geometry.plane_points) < 2e-3)


def test_another_object_beside_the_food_is_sure_background():
    # the scene above seen by one of the ring's cameras: the second ball's pixels start as
    # sure background (GrabCut may not grow the food into them), the item's as probable food
    rng = np.random.default_rng(0)
    points = _scene_points(rng, [((0.0, 0.0, 0.03), 0.03), ((0.12, 0.05, 0.02), 0.02)])
    poses = _ring_cameras()
    cfg = SegmentConfig()
    geometry = find_item(poses, points, UP, cfg)
    intr = Intrinsics(width=320, height=240, fx=300.0, fy=300.0, cx=160.0, cy=120.0)
    # camera 7 sees the second ball just beyond the item, within GrabCut's reach of it
    view = _View(np.zeros((240, 320, 3), np.uint8), intr, np.linalg.inv(poses[7]), 1.0)
    top = _pixels(view, np.array([[0.12, 0.05, 0.04], [0.0, 0.0, 0.06]]))
    labels = seed_labels(view, geometry, cfg)
    assert labels[top[0, 1], top[0, 0]] == cv2.GC_BGD
    assert labels[top[1, 1], top[1, 0]] == cv2.GC_PR_FGD
    unaware = seed_labels(view, replace(geometry, other_objects=()), cfg)
    assert unaware[top[0, 1], top[0, 0]] == cv2.GC_PR_BGD  # what it was before


def test_a_raised_plate_rim_near_the_item_is_not_part_of_it():
    # a 6 cm ball off the centre of a plate whose rim (a ring 75-80 mm out, 5-25 mm high)
    # comes within 2 cm of it: DBSCAN finds the rim as a cluster of its own (more than 8 mm
    # away), near enough to merge at a 2 cm merge gap
    rng = np.random.default_rng(3)
    angle = rng.uniform(0, 2 * np.pi, 3000)
    radius = rng.uniform(0.075, 0.08, 3000)
    rim = np.c_[radius * np.cos(angle), radius * np.sin(angle), rng.uniform(0.005, 0.025, 3000)]
    table_and_ball = _scene_points(rng, [((0.03, 0.0, 0.03), 0.03)])
    ball = table_and_ball[table_and_ball[:, 2] > 0]  # the table lies at z = 0
    points = np.vstack([table_and_ball, rim])
    assert 0.008 < np.min(np.linalg.norm(rim[:, None] - ball[None], axis=2)) < 0.02
    geometry = find_item(_ring_cameras(target=(0.03, 0.0, 0.02)), points, UP,
                         SegmentConfig(merge_gap_m=0.02))
    off_ball = np.abs(np.linalg.norm(geometry.item_points - (0.03, 0.0, 0.03), axis=1) - 0.03)
    assert np.all(off_ball < 1e-9)  # the ball's points only (a few at its foot lie on the
    assert len(geometry.item_points) > 0.95 * len(ball)  # plane's inlier band)
    assert geometry.other_clusters == 0  # a rim is not a second object either


def test_a_fork_beside_the_item_is_not_part_of_it():
    # a bar 14 mm wide and 17 cm long (a fork resting on something) beside a 6 cm ball at
    # its equator's height, with fewer points than the ball: a cluster of its own, near
    # enough to merge, and it goes round the ball's centre by about 120 degrees
    rng = np.random.default_rng(4)
    fork = np.c_[rng.uniform(-0.085, 0.085, 250), rng.uniform(0.0385, 0.0525, 250),
                 rng.uniform(0.028, 0.032, 250)]
    table_and_ball = _scene_points(rng, [((0.0, 0.0, 0.03), 0.03)])
    ball = table_and_ball[table_and_ball[:, 2] > 0]
    assert 0.008 < np.min(np.linalg.norm(fork[:, None] - ball[None], axis=2)) < 0.01
    geometry = find_item(_ring_cameras(), np.vstack([table_and_ball, fork]), UP,
                         SegmentConfig())
    off_ball = np.abs(np.linalg.norm(geometry.item_points - (0.0, 0.0, 0.03), axis=1) - 0.03)
    assert np.all(off_ball < 1e-9)
    assert geometry.other_clusters == 0  # left out, like a rim
    merged = find_item(_ring_cameras(), np.vstack([table_and_ball, fork]), UP,
                       SegmentConfig(beside_span_deg=360.0))
    assert len(merged.item_points) == len(geometry.item_points) + 250  # the rule matters


def _square_geometry(side_m: float, height_m: float) -> SceneGeometry:
    """An item whose sparse points fill a box ``side_m`` square, from 2 cm above the plane
    z = 0 (what SfM sees of its sides) to ``height_m``."""
    rng = np.random.default_rng(5)
    item = rng.uniform([-side_m / 2, -side_m / 2, 0.02], [side_m / 2, side_m / 2, height_m],
                       (2000, 3))
    item[:4, :2] = np.array([[-1, -1], [-1, 1], [1, -1], [1, 1]]) * side_m / 2  # its corners
    return SceneGeometry(np.zeros(3), UP, 0.0, item, np.zeros((0, 3)))


def test_the_distance_outside_the_footprint_is_measured_along_the_plane():
    geometry = _square_geometry(0.04, 0.03)
    points = np.array([[0.03, 0.0, 0.5], [0.0, -0.025, 0.0], [0.0, 0.0, 0.01],
                       [np.nan, 0.0, 0.0]])
    distance = outside_footprint_m(points, geometry)
    np.testing.assert_allclose(distance[:3], [0.01, 0.005, -0.02], atol=1e-9)
    assert np.isnan(distance[3])


@pytest.mark.parametrize("plate_top_m", [0.0, 0.012])
def test_the_surface_under_the_item_is_found_from_stereo_around_it(plate_top_m):
    # stereo points on a plain plate around the item (its top 12 mm above the table the
    # sparse points found, or on that table), some on the item, some NaN
    geometry = _square_geometry(0.04, 0.05)
    rng = np.random.default_rng(6)
    ring = np.c_[rng.uniform(-0.05, 0.05, (4000, 2)),
                 plate_top_m + rng.normal(0, 0.0005, 4000)]
    ring = ring[np.abs(ring[:, :2]).max(axis=1) > 0.027]
    on_item = rng.uniform([-0.02, -0.02, 0.02], [0.02, 0.02, 0.05], (3000, 3))
    maps = [np.vstack([ring, on_item, np.full((50, 3), np.nan)]).reshape(-1, 1, 3)]
    assert support_height_m(maps, geometry, SegmentConfig()) == pytest.approx(plate_top_m,
                                                                              abs=0.001)
    # where the sparse points found the plane round the item, it is the surface under it
    # (what stereo sees there may be the item's own lower sides)
    plane = np.c_[rng.uniform(-0.05, 0.05, (400, 2)), np.zeros(400)]
    plane = plane[np.abs(plane[:, :2]).max(axis=1) > 0.027]
    found = replace(geometry, plane_points=plane)
    assert support_height_m(maps, found, SegmentConfig()) == 0.0


@pytest.mark.parametrize("objects, words", [
    ([], "nothing stands on the plate"),
    ([((0.15, 0.1, 0.03), 0.03)], "no object at the point the cameras look at"),
    # two balls 3.6 cm apart, as near as each other to where the cameras look
    ([((-0.03, 0.0, 0.012), 0.012), ((0.03, 0.0, 0.012), 0.012)], "several separate objects"),
])
def test_what_cannot_be_the_food_is_a_clear_error(objects, words):
    points = _scene_points(np.random.default_rng(1), objects)
    with pytest.raises(SegmentationError, match=words):
        find_item(_ring_cameras(), points, UP, SegmentConfig())


def test_cameras_that_do_not_look_down_on_a_plane_are_an_error():
    points = _scene_points(np.random.default_rng(2), [((0.0, 0.0, 0.03), 0.03)])
    below = _ring_cameras(height=-0.2, target=(0.0, 0.0, 0.0))
    with pytest.raises(SegmentationError, match="look down on"):
        find_item(below, points, UP, SegmentConfig())


def test_food_cut_by_the_image_border_in_most_frames_is_an_error():
    inside = np.zeros((40, 40), bool)
    inside[10:30, 10:30] = True
    cut = np.zeros((40, 40), bool)
    cut[0:20, 10:30] = True
    check_in_view([inside] * 6 + [cut] * 4, 0.5)
    with pytest.raises(SegmentationError, match="touches the image border in 6 of 10"):
        check_in_view([inside] * 4 + [cut] * 6, 0.5)


def _quick_scene(quick_capture, table_below_m: float = 0.0):
    """The quick apple capture (12 frames around it, 240x320): its exact poses and sparse
    points sampled from what SfM would see: the food's top and the plate around it or, with
    ``table_below_m``, no point on the plate (a plain one) but a table that far under it."""
    capture = read_transforms_json(quick_capture / "capture")
    exact = read_transforms_json(quick_capture / "ground_truth" / "transforms_exact.json",
                                 check_image_sizes=False)
    poses = np.stack([f.T_world_from_cam for f in exact.frames])
    food = load_ground_truth_mesh(quick_capture)
    up = np.asarray(load_truth(quick_capture)["world_up"], float)
    food_points = sample_surface(food, 1500, seed=0)
    food_points = food_points[(food_points - food.bounds[0]) @ up > 0.01]  # the top SfM sees
    rng = np.random.default_rng(3)
    side, other = np.cross(up, [1.0, 0, 0]), np.cross(up, np.cross(up, [1.0, 0, 0]))
    lo, hi = (0.0, 0.08) if not table_below_m else (0.11, 0.2)  # the plate's radius: 0.09
    radius = np.sqrt(rng.uniform(lo**2, hi**2, 3000))
    angle = rng.uniform(0, 2 * np.pi, 3000)
    centre = food.bounds.mean(axis=0)
    base = centre - up * ((centre - food.bounds[0]) @ up + table_below_m)
    plane = base + np.outer(radius * np.cos(angle), side) + np.outer(radius * np.sin(angle),
                                                                     other)
    plane = plane[np.linalg.norm(plane - base, axis=1) > 0.5 * np.ptp(food.bounds, axis=0).max()]
    return capture, poses, np.vstack([food_points, plane])


def _ious(capture, masks) -> np.ndarray:
    ious = []
    for frame, mask in zip(capture.frames, masks.masks, strict=True):
        exact_mask = np.asarray(Image.open(frame.mask_path).convert("L")) > 127
        ious.append((mask & exact_mask).sum() / (mask | exact_mask).sum())
    return np.array(ious)


def test_masks_match_the_exact_ones_on_a_synthetic_capture(quick_capture, tmp_path):
    capture, poses, points = _quick_scene(quick_capture)
    masks = segment(capture, poses, np.ones(len(capture), bool), points,
                    SegmentConfig(hull_views=12, work_long_side_px=320))
    assert masks.source == "auto" and len(masks) == len(capture)
    ious = _ious(capture, masks)
    assert np.median(ious) > 0.95 and min(ious) > 0.85
    assert masks.summary["plane"]["lifted_m"] == 0.0
    # written as PNGs with a record; read back the same
    save_masks(tmp_path, masks)
    back = load_masks(tmp_path)
    assert back.names == masks.names and all(
        np.array_equal(a, b) for a, b in zip(back.masks, masks.masks, strict=True))
    assert (tmp_path / "masks" / "frame_00000.png").exists()


def test_a_plate_without_sparse_points_is_found_by_stereo(quick_capture):
    # SfM found the table 12 mm under the plate and nothing on the plate: the plane is lifted
    # to the plate's top (found at 11.3 mm), and the masks are as good as with the plate found
    # (median IoU 0.976; not lifted, 0.888)
    capture, poses, points = _quick_scene(quick_capture, table_below_m=0.012)
    cfg = SegmentConfig(hull_views=12, work_long_side_px=320)
    masks = segment(capture, poses, np.ones(len(capture), bool), points, cfg)
    assert masks.summary["plane"]["lifted_m"] == pytest.approx(0.012, abs=0.004)
    assert np.median(_ious(capture, masks)) > 0.95


def test_hull_voxel_grows_only_for_items_too_large_for_the_grid():
    def geometry(side_m: float) -> SceneGeometry:
        corners = np.array([[0.0, 0.0, 0.0], [side_m, side_m / 2, side_m / 3]])
        return SceneGeometry(np.zeros(3), UP, 0.0, corners, np.zeros((0, 3)))

    cfg = SegmentConfig(voxel_m=0.001, hull_margin_m=0.02, hull_max_voxels_across=240)
    assert hull_voxel_m(geometry(0.1), cfg) == 0.001  # 140 voxels across: as configured
    # 0.5 m and two 2 cm margins across 240 voxels
    assert hull_voxel_m(geometry(0.5), cfg) == pytest.approx(0.54 / 240)


def test_stereo_makes_sure_food_only_within_the_items_footprint():
    # stereo that puts the plate around the item above it (a plain plate's noise): those
    # pixels may become food only by their colour, never start as sure food
    points = _scene_points(np.random.default_rng(0), [((0.0, 0.0, 0.03), 0.03)])
    poses = _ring_cameras()
    cfg = SegmentConfig()
    geometry = find_item(poses, points, UP, cfg)
    intr = Intrinsics(width=320, height=240, fx=300.0, fy=300.0, cx=160.0, cy=120.0)
    view = _View(np.zeros((240, 320, 3), np.uint8), intr, np.linalg.inv(poses[0]), 1.0)
    region = item_region(view, geometry)
    around = ndimage.binary_dilation(region, iterations=cfg.probable_margin_px)
    heights = np.where(around, 0.02, np.nan)  # 2 cm up, the item and the plate around it
    # beyond the item's projected points, which reach a few pixels past that convex hull
    ring = around & ~ndimage.binary_dilation(region, iterations=8)
    labels = seed_labels(view, geometry, cfg, heights=heights)
    assert not (labels[ring] == cv2.GC_FGD).any()
    assert (labels[ring] == cv2.GC_PR_FGD).mean() > 0.5
    assert (labels[region] == cv2.GC_FGD).any()
