"""Helpers shared by tests that check what a command wrote or left alone."""

from __future__ import annotations

from pathlib import Path

from volec.io import LOCK_FILE


def snapshot(folder: Path) -> dict[Path, tuple[int, int]]:
    """Size and modification time of every file under ``folder`` but the run lock (which
    every run takes): equal snapshots mean no result was written there."""
    return {p: (p.stat().st_size, p.stat().st_mtime_ns) for p in sorted(Path(folder).rglob("*"))
            if p.is_file() and p.name != LOCK_FILE}
