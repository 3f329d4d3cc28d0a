"""A two-step checkpoint shared by the completion tests."""

from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def smoke_checkpoint(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The ``smoke`` training preset's checkpoint (two CPU steps on one shape)."""
    from volec.completion.train import PRESETS, train

    folder = tmp_path_factory.mktemp("smoke")
    ckpt = folder / "smoke.pt"
    train(PRESETS["smoke"], ckpt, folder / "data", progress=False)
    return ckpt
