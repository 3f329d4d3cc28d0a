"""Scale: metres are believed only where they are plausible, and can be given."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from volec.capture import Capture, Frame, Intrinsics
from volec.errors import ScaleError
from volec.geometry import look_at_opencv
from volec.scale import (
    camera_distance,
    fixation_point,
    require_metric,
    scale_from_distance,
    with_scale,
)

INTR = Intrinsics(64, 48, 60.0, 60.0, 31.5, 23.5)


def _orbit(radius: float, metric: bool | None, target=(0.1, 0.0, -0.2)) -> Capture:
    frames = []
    for i in range(12):
        a = 2 * np.pi * i / 12
        eye = np.asarray(target) + radius * np.array([np.cos(a), np.sin(a), 0.6])
        T = look_at_opencv(eye, np.asarray(target), np.array([0.0, 0.0, 1.0]))
        frames.append(Frame(f"f{i}.jpg", Path(f"/nowhere/f{i}.jpg"), INTR, T))
    return Capture(Path("/nowhere"), tuple(frames), metric=metric)


def test_the_point_an_orbit_looks_at_and_its_distance():
    capture = _orbit(0.3, True)
    np.testing.assert_allclose(fixation_point(capture), [0.1, 0.0, -0.2], atol=1e-9)
    assert camera_distance(capture) == pytest.approx(0.3 * np.hypot(1.0, 0.6))


def test_plausible_metres_are_believed_and_said_so():
    assert require_metric(_orbit(0.3, True)).source == "file"
    check = require_metric(_orbit(0.3, None))
    assert check.source == "plausibility" and "does not say" in check.warning


@pytest.mark.parametrize("radius, words", [(30.0, "centimetres"), (300.0, "centimetres"),
                                           (0.003, "another unit")])
def test_implausible_distances_are_refused_with_how_to_give_scale(radius, words):
    for metric in (True, None):
        with pytest.raises(ScaleError, match=f"{words}.*--scale"):
            require_metric(_orbit(radius, metric))


def test_a_capture_that_is_not_metric_is_refused_until_a_scale_is_given():
    capture = _orbit(30.0, False)
    with pytest.raises(ScaleError, match="not in metres.*--scale-from-distance"):
        require_metric(capture)
    scaled = with_scale(capture, 0.01)
    assert scaled.metric and scaled.metres_per_unit == 0.01
    np.testing.assert_allclose(scaled.camera_centres, capture.camera_centres * 0.01)
    np.testing.assert_allclose(scaled.frames[3].T_world_from_cam[:3, :3],
                               capture.frames[3].T_world_from_cam[:3, :3])
    assert require_metric(scaled, user_scale=True).source == "user"


def test_scale_from_the_distance_between_two_cameras():
    capture = _orbit(30.0, False)
    gap = np.linalg.norm(capture.frames[0].camera_centre - capture.frames[6].camera_centre)
    factor = scale_from_distance(capture, "f0.jpg", "f6.jpg", 0.5)
    assert factor == pytest.approx(0.5 / gap)
    scaled = with_scale(capture, factor)
    assert np.linalg.norm(scaled.frames[0].camera_centre - scaled.frames[6].camera_centre) == \
        pytest.approx(0.5)
    with pytest.raises(ScaleError, match="no frame named 'f99.jpg'"):
        scale_from_distance(capture, "f0.jpg", "f99.jpg", 0.5)
    with pytest.raises(ScaleError, match="positive"):
        with_scale(capture, -1.0)
