"""Cloud scores against analytic surfaces."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from volec.capture import Capture, Frame, Intrinsics
from volec.geometry import look_at_opencv
from volec.metrics import (
    bottom_gap,
    chamfer_distance,
    cloud_scores,
    distances_to_surface,
    elevations_deg,
    height_band_offsets,
    hidden_columns,
    mesh_offset_scores,
    sample_surface,
    signed_distances_to_surface,
    views_seeing,
    volume_below_gap,
)

BOX = trimesh.creation.box(extents=(0.1, 0.1, 0.1))  # centred at the origin


def _cameras_above(n: int = 6) -> Capture:
    intr = Intrinsics(200, 150, 150.0, 150.0, 99.5, 74.5)
    frames = []
    for i in range(n):
        a = 2 * np.pi * i / n
        eye = np.array([0.4 * np.cos(a), 0.4 * np.sin(a), 0.35])
        T = look_at_opencv(eye, np.zeros(3), np.array([0.0, 0.0, 1.0]))
        frames.append(Frame(f"f{i}", Path(f"/none/f{i}"), intr, T))
    return Capture(Path("/none"), tuple(frames))


def test_distances_to_a_box():
    pts = np.array([[0.0, 0.0, 0.06], [0.07, 0.0, 0.0], [0.0, 0.0, 0.0], [0.06, 0.06, 0.0]])
    expected = [0.01, 0.02, 0.05, np.hypot(0.01, 0.01)]
    np.testing.assert_allclose(distances_to_surface(pts, BOX), expected, atol=1e-6)


def test_cameras_above_see_the_top_and_not_the_bottom():
    top = np.array([[0.0, 0.0, 0.05], [0.02, -0.03, 0.05]])
    bottom = np.array([[0.0, 0.0, -0.05]])
    counts = views_seeing(np.vstack([top, bottom]), BOX, _cameras_above())
    assert list(counts) == [6, 6, 0]


def test_cameras_count_only_where_they_see_the_surface_frontally_enough():
    # A point in the middle of the box's +x face (normal +x) and one on its top (normal +z).
    # Camera i sits at (0.4 cos a, 0.4 sin a, 0.35), a = 60 i degrees: the cosine between the
    # side normal and the direction to camera 0 is 0.35 / |(0.35, 0, 0.35)| = 0.707, to
    # cameras 1 and 5 it is 0.15 / |(0.15, 0.346, 0.35)| = 0.291, and the other three are
    # behind the face; for the top point every camera sees it at 0.3 / 0.5 = 0.6.
    points = np.array([[0.05, 0.0, 0.0], [0.0, 0.0, 0.05]])
    normals = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    cameras = _cameras_above()
    assert list(views_seeing(points, BOX, cameras)) == [3, 6]
    for cosine, expected in ((0.0, [3, 6]), (0.25, [3, 6]), (0.5, [1, 6]), (0.65, [1, 0]),
                             (0.75, [0, 0])):
        counts = views_seeing(points, BOX, cameras, normals=normals, min_cosine=cosine)
        assert list(counts) == expected, cosine


def test_chamfer_of_shifted_copies():
    a = sample_surface(BOX, 2000, seed=1)
    assert chamfer_distance(a, a) == (0.0, 0.0)
    far = np.array([[0.0, 0.0, 1.0]])
    l1, l2 = chamfer_distance(far, far + [0.0, 0.0, 0.003])
    assert l1 == pytest.approx(0.003) and l2 == pytest.approx(0.003**2)


def test_cloud_scores_of_the_visible_surface():
    samples = sample_surface(BOX, 80000, seed=2)
    top_half = samples[samples[:, 2] > -0.0499]  # everything but the bottom face
    scores = cloud_scores(top_half, BOX, _cameras_above(), n_samples=5000)
    assert scores["accuracy_median_m"] < 1e-6
    assert scores["completeness_visible"] > 0.99
    # only the bottom face's 2 mm rim lies within 2 mm of the seen faces: 1 - 0.096^2 / 0.1^2
    assert scores["completeness_unseen"] == pytest.approx(1 - 0.096**2 / 0.1**2, abs=0.015)
    # the bottom is one face of six; the cameras see the other five
    assert scores["visible_surface_fraction"] == pytest.approx(5 / 6, abs=0.03)


def test_signed_distances_are_positive_outside_a_sphere_and_exact():
    truth = trimesh.creation.icosphere(subdivisions=6, radius=0.04)
    truth.apply_translation([0.3, -0.1, 0.7])  # away from the origin, as in a capture
    rng = np.random.default_rng(0)
    d = rng.normal(size=(500, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    offset = rng.uniform(-0.002, 0.002, 500)
    points = truth.bounds.mean(axis=0) + d * (0.04 + offset)[:, None]
    signed = signed_distances_to_surface(points, truth)
    # the icosphere's facets lie up to 4 micrometres inside the sphere
    np.testing.assert_allclose(signed, offset, atol=6e-6)


def test_a_mesh_offset_gives_the_volume_it_implies():
    truth = trimesh.creation.icosphere(subdivisions=6, radius=0.04)
    grown = trimesh.creation.icosphere(subdivisions=5, radius=0.0405)
    scores = mesh_offset_scores(grown, truth)
    assert scores["mesh_signed_median_m"] == pytest.approx(0.0005, abs=1e-5)
    assert scores["mesh_signed_p10_m"] < scores["mesh_signed_median_m"] < scores[
        "mesh_signed_p90_m"]
    exact_ml = (grown.volume - truth.volume) * 1e6
    assert scores["mesh_offset_ml"] == pytest.approx(exact_ml, rel=0.03)
    assert scores["mesh_offset_pct"] == pytest.approx(100 * exact_ml / (truth.volume * 1e6),
                                                      rel=0.03)


def test_a_misplaced_mesh_is_aligned_before_its_shape_offset_is_measured():
    truth = trimesh.creation.icosphere(subdivisions=6, radius=0.04)
    grown = trimesh.creation.icosphere(subdivisions=5, radius=0.0403)
    grown.apply_translation([0.0015, -0.001, 0.0])  # the poses put it 1.8 mm off
    scores = mesh_offset_scores(grown, truth)
    assert scores["mesh_signed_p90_m"] - scores["mesh_signed_p10_m"] > 0.002  # one side out
    assert scores["mesh_misplacement_m"] == pytest.approx(np.hypot(0.0015, 0.001), abs=1e-4)
    assert scores["mesh_aligned_signed_median_m"] == pytest.approx(0.0003, abs=2e-5)
    assert scores["mesh_aligned_signed_p90_m"] - scores["mesh_aligned_signed_p10_m"] < 1e-4


def test_height_bands_find_an_offset_of_the_lower_half_and_where_the_cloud_is():
    radius, grown_by = 0.04, 0.0005
    truth = trimesh.creation.icosphere(subdivisions=6, radius=radius)
    mesh = trimesh.creation.icosphere(subdivisions=5, radius=radius)
    lower = mesh.vertices[:, 2] < 0
    mesh.vertices[lower] *= (radius + grown_by) / radius  # the lower half 0.5 mm outside
    top = sample_surface(truth, 20000, seed=1)
    cloud = top[top[:, 2] > 0.01]  # stereo saw only the upper part
    rows = height_band_offsets(mesh, truth, cloud, np.array([0.0, 0.0, 1.0]),
                               edges=(0.0, 0.25, 0.5, 0.75, 1.0))
    median_mm = [1000 * r["mesh_signed_median_m"] for r in rows]
    assert median_mm[0] == pytest.approx(0.5, abs=0.02)
    assert median_mm[1] == pytest.approx(0.5, abs=0.02)
    assert median_mm[2] == pytest.approx(0.0, abs=0.02)
    assert median_mm[3] == pytest.approx(0.0, abs=0.02)
    # a sphere's area is spread evenly over its height: a quarter in each band
    assert [r["true_area_share"] for r in rows] == pytest.approx([0.25] * 4, abs=0.02)
    assert [r["cloud_coverage"] for r in rows] == pytest.approx([0, 0, 0.5, 1], abs=0.06)
    exact_pct = 100 * (mesh.volume - truth.volume) / truth.volume
    assert sum(r["mesh_offset_pct"] for r in rows) == pytest.approx(exact_pct, rel=0.05)
    assert rows[2]["mesh_offset_pct"] + rows[3]["mesh_offset_pct"] == pytest.approx(
        0.0, abs=0.05 * exact_pct)


def _resting_sphere(radius_m: float) -> trimesh.Trimesh:
    sphere = trimesh.creation.icosphere(subdivisions=5, radius=radius_m)
    sphere.apply_translation([0.0, 0.0, radius_m])
    return sphere


def _sphere_gap_within(radius_m: float, rim_m: float) -> float:
    """The gap under a sphere resting on a plane, inside the radius ``rim_m``: the integral of
    2 pi rho (R - sqrt(R^2 - rho^2)) from 0 to ``rim_m``."""
    r = radius_m
    return np.pi * rim_m**2 * r - 2 * np.pi / 3 * (r**3 - (r * r - rim_m**2) ** 1.5)


def test_the_gap_under_a_resting_sphere_is_a_third_of_pi_r_cubed():
    radius = 0.03
    _, gap, edge = bottom_gap(_resting_sphere(radius), np.array([0.0, 0.0, 1.0]), 0.0005)
    assert gap.sum() * 0.0005**2 == pytest.approx(np.pi * radius**3 / 3, rel=0.01)
    assert edge.max() == pytest.approx(radius, abs=0.001)  # the footprint's centre


def test_hidden_columns_and_what_a_flat_bottom_fills_there():
    radius, elevation = 0.03, 30.0
    up = np.array([0.0, 0.0, 1.0])
    base, gap, edge = bottom_gap(_resting_sphere(radius), up, 0.0005)
    hidden = hidden_columns(gap, edge, elevation)
    # hidden where (R - rho) tan(e) > R - sqrt(R^2 - rho^2): inside the radius solved here
    rho = np.linspace(0, radius, 200001)
    seen = (radius - rho) * np.tan(np.radians(elevation)) <= radius - np.sqrt(radius**2 - rho**2)
    rim = rho[np.argmax(seen)]
    expected = _sphere_gap_within(radius, rim)
    assert gap[hidden].sum() * 0.0005**2 == pytest.approx(expected, rel=0.03)
    # a cylinder standing on the plane fills all of that gap; the sphere itself none of it
    cylinder = trimesh.creation.cylinder(radius=radius, height=2 * radius, sections=128)
    cylinder.apply_translation([0.0, 0.0, radius])
    filled = volume_below_gap(cylinder, base[hidden], gap[hidden], up, 0.0005)
    assert filled == pytest.approx(expected, rel=0.03)
    assert volume_below_gap(_resting_sphere(radius), base, gap, up, 0.0005) == 0.0


def test_elevations_of_points_around_a_centre():
    centre = np.array([1.0, 2.0, 3.0])
    points = centre + np.array([[1.0, 0.0, 1.0], [0.0, 2.0, 0.0], [0.0, -1.0, -np.sqrt(3.0)]])
    assert elevations_deg(points, centre, np.array([0.0, 0.0, 2.0])) == pytest.approx(
        [45.0, 0.0, -60.0])
