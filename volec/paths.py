"""Where volec keeps generated data and figures.

In: nothing (or an explicit start folder). Out: the repository's ``data/``, ``figures/`` and
``build/`` folders, found from the working directory upward, so notebooks run the same from
``make paper`` (repository root) and from Jupyter (``notebooks/``). The environment variables
``VOLEC_FIGURES_DIR`` and ``VOLEC_DATA_DIR`` send them elsewhere (the notebook tests do).
"""

from __future__ import annotations

import os
from pathlib import Path


def repo_root(start: Path | None = None) -> Path:
    """The nearest folder at or above ``start`` (default: cwd) holding volec's pyproject.toml."""
    here = Path(start or Path.cwd()).resolve()
    for folder in (here, *here.parents):
        marker = folder / "pyproject.toml"
        if marker.exists() and 'name = "volec"' in marker.read_text():
            return folder
    raise FileNotFoundError(
        f"no volec checkout at or above {here}; run from the repository or pass a folder"
    )


def figures_dir(start: Path | None = None) -> Path:
    """``figures/``: every table and figure the notebooks write (created if missing)."""
    override = os.environ.get("VOLEC_FIGURES_DIR")
    d = Path(override) if override else repo_root(start) / "figures"
    d.mkdir(parents=True, exist_ok=True)
    return d


def data_dir(start: Path | None = None) -> Path:
    """``data/``: generated data and small shipped artefacts (created if missing)."""
    override = os.environ.get("VOLEC_DATA_DIR")
    d = Path(override) if override else repo_root(start) / "data"
    d.mkdir(parents=True, exist_ok=True)
    return d


def experiment_dir(quick: bool, start: Path | None = None) -> Path:
    """Where the experiments keep their captures and work folders: ``data/bench-sfm`` or, in
    quick mode, ``data/bench-sfm-quick``, so CI-sized results never mix with full ones."""
    return data_dir(start) / ("bench-sfm-quick" if quick else "bench-sfm")


def benchmark_dir(quick: bool, start: Path | None = None) -> Path:
    """Where the synthetic benchmark captures live: ``data/benchmark`` or, in quick mode,
    ``data/benchmark-quick`` (small captures that never mix with full-size ones)."""
    return data_dir(start) / ("benchmark-quick" if quick else "benchmark")
