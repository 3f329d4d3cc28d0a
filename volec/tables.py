"""Tables the notebooks write: one pandas DataFrame -> CSV and Markdown, atomically.

In: a DataFrame and a path stem. Out: ``STEM.csv`` (full precision) and ``STEM.md``
(rounded for reading), both replaced atomically.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from volec.io import write_text_atomic


def write_table(table: pd.DataFrame, stem: Path, float_digits: int = 2) -> tuple[Path, Path]:
    """Write ``table`` to ``stem.csv`` and ``stem.md``; returns both paths."""
    stem = Path(stem)
    csv, md = stem.with_suffix(".csv"), stem.with_suffix(".md")
    write_text_atomic(csv, table.to_csv(index=False))
    write_text_atomic(md, table.to_markdown(index=False, floatfmt=f".{float_digits}f") + "\n")
    return csv, md
