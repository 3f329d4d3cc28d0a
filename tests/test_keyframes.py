"""Keyframes: blurred frames, near-duplicates and an even spread, on known answers."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from volec.capture import Capture, Frame, Intrinsics, read_transforms_json
from volec.geometry import look_at_opencv
from volec.keyframes import (
    KeyframeConfig,
    choose_keyframes,
    keyframe_capture,
    select_keyframes,
    sharpness,
)
from volec.synth import PRESETS, write_synthetic_capture
from volec.synth.generate import motion_blur

INTR = Intrinsics(64, 48, 50.0, 50.0, 31.5, 23.5)


def _orbit(angles_deg: list[float]) -> Capture:
    """Cameras 0.35 m from the origin at the given azimuths, 30 degrees above it."""
    root = Path("/nonexistent")
    frames = []
    for i, a in enumerate(np.radians(angles_deg)):
        eye = 0.35 * np.array([np.cos(a) * np.cos(0.52), np.sin(a) * np.cos(0.52), np.sin(0.52)])
        T = look_at_opencv(eye, np.zeros(3), np.array([0.0, 0.0, 1.0]))
        frames.append(Frame(f"f{i}.jpg", root / f"f{i}.jpg", INTR, T))
    return Capture(root, tuple(frames))


def _largest_gap_deg(angles_deg: np.ndarray) -> float:
    a = np.sort(np.mod(angles_deg, 360.0))
    return float(np.max(np.diff(np.concatenate([a, [a[0] + 360.0]]))))


def test_an_even_spread_of_the_wanted_number_of_frames():
    angles = np.linspace(0.0, 360.0, 400, endpoint=False)
    capture = _orbit(list(angles))
    sharp = list(100.0 + 10.0 * np.sin(np.arange(400)))  # no frame is blurred
    selection = select_keyframes(capture, sharp, KeyframeConfig(max_frames=40))
    assert len(selection.kept) == 40
    assert set(selection.dropped.values()) == {"not needed for an even spread"}
    assert _largest_gap_deg(angles[selection.kept]) < 2 * 9.0  # 9 degrees apart when even
    for i in selection.kept:  # the sharpest frame of its ten
        arc = slice(10 * (i // 10), 10 * (i // 10) + 10)
        assert sharp[i] == max(sharp[arc])


def test_blurred_frames_and_a_phone_held_still_are_dropped():
    angles = list(np.linspace(0.0, 360.0, 60, endpoint=False)) + [30.0, 30.0, 30.1]
    capture = _orbit(angles)
    sharp = [100.0] * 60 + [101.0, 99.0, 98.0]  # three more frames where frame 5 was taken
    sharp[20] = sharp[41] = 40.0  # shaken
    selection = select_keyframes(capture, sharp)
    assert selection.dropped == {5: "near-duplicate", 20: "blurred", 41: "blurred",
                                 61: "near-duplicate", 62: "near-duplicate"}
    assert 60 in selection.kept  # the sharpest of the four at 30 degrees
    kept = keyframe_capture(capture, selection)
    assert [f.name for f in kept.frames] == [capture.frames[i].name for i in selection.kept]
    record = selection.record(capture)
    assert record["frames_in"] == 63 and record["frames_kept"] == 58
    assert record["dropped"]["f20.jpg"] == "blurred"
    assert record["dropped_counts"] == {"near-duplicate": 3, "blurred": 2}


def test_motion_blur_keeps_brightness_and_lowers_sharpness():
    rng = np.random.default_rng(0)
    texture = rng.random((120, 160, 3))
    flat = np.full((40, 50, 3), 0.4)
    np.testing.assert_allclose(motion_blur(flat, 9.0, 20.0), flat, atol=1e-6)
    smeared = motion_blur(texture, 9.0, 0.0)
    assert smeared.mean() == pytest.approx(texture.mean(), abs=1e-3)
    # a horizontal smear leaves columns of a horizontal-stripe image alone
    stripes = np.repeat((np.arange(120) % 2).astype(float)[:, None, None], 160, 1).repeat(3, 2)
    np.testing.assert_allclose(motion_blur(stripes, 9.0, 0.0)[:, 10:-10], stripes[:, 10:-10],
                               atol=1e-6)

    def sharp(img: np.ndarray) -> float:
        return sharpness(Image.fromarray((img * 255).astype(np.uint8)), 160)

    assert sharp(smeared) < 0.3 * sharp(texture)


def test_the_shaken_frames_of_a_rendered_video_are_the_ones_dropped(tmp_path):
    cfg = PRESETS["quick"].with_(n_frames=20, motion_blur_share=0.4)
    out = write_synthetic_capture("apple", tmp_path / "apple", cfg, progress=False)
    capture = read_transforms_json(out / "capture")
    shaken = json.loads((out / "ground_truth" / "truth.json").read_text())["motion_blur"]
    assert 3 <= len(shaken) <= 14
    selection = choose_keyframes(capture)
    dropped = {Path(capture.frames[i].name).stem for i, why in selection.dropped.items()
               if why == "blurred"}
    clearly = {name for name, smear in shaken.items() if smear["length_px"] >= 4.0}
    assert clearly <= dropped <= set(shaken)


def test_the_command_line_refuses_fewer_than_three_keyframes(capsys):
    from volec.cli import build_parser

    parser = build_parser()
    assert parser.parse_args(["estimate", "cap", "--out", "o", "--max-frames", "40"]
                             ).max_frames == 40
    with pytest.raises(SystemExit):
        parser.parse_args(["estimate", "cap", "--out", "o", "--max-frames", "2"])
    assert "need at least 3 frames" in capsys.readouterr().err
