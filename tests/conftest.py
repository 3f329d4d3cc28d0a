"""Shared fixtures: small synthetic data made in tmp_path."""

from __future__ import annotations

from pathlib import Path

import pytest

from volec.capture import Capture, read_transforms_json
from volec.pipeline import run_sfm_stage
from volec.sfm import SfmResult
from volec.synth import PRESETS, write_synthetic_capture


@pytest.fixture(scope="session")
def quick_capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 12-frame 240x320 synthetic capture of the apple (rendered once per test session)."""
    out = tmp_path_factory.mktemp("synth") / "apple"
    return write_synthetic_capture("apple", out, PRESETS["quick"], progress=False)


@pytest.fixture(scope="session")
def small_capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """16 full-size frames of the cake over a 100-degree arc: enough for SfM, fast to render."""
    cfg = PRESETS["default"].with_(n_frames=16, arc_deg=100.0)
    return write_synthetic_capture("chocolate_cake", tmp_path_factory.mktemp("sfm") / "cake",
                                   cfg, progress=False)


@pytest.fixture(scope="session")
def small_result(small_capture: Path) -> tuple[SfmResult, Capture]:
    """SfM of ``small_capture`` in ``small_capture/work`` (run once per test session), with
    the provenance the pipeline records, so copies of it are reused for this capture."""
    cap = read_transforms_json(small_capture / "capture")
    return run_sfm_stage(cap, small_capture / "work")[0], cap
