"""Tables the notebooks write: one pandas DataFrame -> CSV and Markdown, atomically.

In: a DataFrame and a path stem. Out: ``STEM.csv`` (full precision), ``STEM.md`` (rounded for
reading, with a last line naming the volec version and source digest that made it) and
``STEM.provenance.json`` (the same, for programs), all replaced atomically. The experiments'
caches are keyed on the code that computed each row, so the code named is the code that
computed every number in the table.
"""

from __future__ import annotations

import datetime
from pathlib import Path

import pandas as pd

from volec.io import write_json_atomic, write_text_atomic


def made_by() -> dict[str, str]:
    """The volec version and digest of its whole source, and the time, for written results."""
    from volec import __version__
    from volec.provenance import package_digest

    return {"volec_version": __version__, "source_digest": package_digest(),
            "written_utc": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")}


def write_table(table: pd.DataFrame, stem: Path, float_digits: int = 2) -> tuple[Path, Path]:
    """Write ``table`` to ``stem.csv`` and ``stem.md`` (and its provenance); returns the CSV
    and Markdown paths."""
    stem = Path(stem)
    csv, md = stem.with_suffix(".csv"), stem.with_suffix(".md")
    origin = made_by()
    footer = (f"\n_Made by volec {origin['volec_version']} (source "
              f"{origin['source_digest']}) at {origin['written_utc']}._\n")
    write_text_atomic(csv, table.to_csv(index=False))
    write_text_atomic(md, table.to_markdown(index=False, floatfmt=f".{float_digits}f") + "\n"
                      + footer)
    write_json_atomic(stem.with_name(stem.name + ".provenance.json"),
                      {**origin, "table": csv.name, "rows": len(table)})
    return csv, md
