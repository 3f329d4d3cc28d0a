"""Shared fixtures: small synthetic data made in tmp_path."""

from __future__ import annotations

from pathlib import Path

import pytest

from volec.synth import PRESETS, write_synthetic_capture


@pytest.fixture(scope="session")
def quick_capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 12-frame 240x320 synthetic capture of the apple (rendered once per test session)."""
    out = tmp_path_factory.mktemp("synth") / "apple"
    return write_synthetic_capture("apple", out, PRESETS["quick"], progress=False)
