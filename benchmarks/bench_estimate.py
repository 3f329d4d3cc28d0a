"""Measure `volec estimate` end to end, as a user runs it: wall time per stage and in all, peak
memory, and the volume against the truth.

Usage: .venv/bin/python benchmarks/bench_estimate.py [--items apple banana ...] [--quick]
       [--before DIR]

Each item's benchmark capture (generated under data/bench-sfm, or -quick, like notebook 04, if
missing) is estimated from scratch into a fresh temporary folder (nothing reused), one item at
a time, by ``volec estimate`` in a child process. The wall time is the child's; the per-stage
times come from its ``result.json``; peak resident memory from the child's own resource
usage (``os.wait4``).
With ``--before DIR`` (a checkout of older code, e.g. ``git worktree add /tmp/before REV``),
each item is also estimated by that code (``PYTHONPATH=DIR``), before and after alternating on
the same capture, and the table ends with the after/before ratio of each stage's time.
Written to figures/estimate_benchmark.{csv,md}.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import pandas as pd

from volec.experiments import ensure_capture, scenarios
from volec.paths import experiment_dir, figures_dir
from volec.synth import load_ground_truth_mesh
from volec.tables import write_table


def estimate_run(capture_root: Path, code: Path | None = None,
                 keep_result: bool = False) -> dict[str, Any]:
    """Wall time, stage times, peak memory and volume of one fresh ``volec estimate`` (by the
    volec in ``code`` when given; with ``keep_result``, its ``result.json`` under
    ``"result"``)."""
    env = dict(os.environ)
    if code is not None:  # `python -m` puts the working folder first on the path
        env["PYTHONPATH"] = str(code)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "estimate"
        start = time.perf_counter()
        child = subprocess.Popen([sys.executable, "-m", "volec", "estimate",
                                  str(capture_root / "capture"), "--out", str(out), "--quiet"],
                                 env=env, cwd=code)
        _, status, usage = os.wait4(child.pid, 0)  # this child's own peak memory
        wall = time.perf_counter() - start
        if status != 0:
            raise RuntimeError(f"volec estimate failed on {capture_root} (status {status})")
        result = json.loads((out / "result.json").read_text())
    truth_ml = load_ground_truth_mesh(capture_root).volume * 1e6
    return {"frames": result["frames"]["registered"], "wall_s": wall,
            **{k: v for k, v in result["stage_seconds"].items() if k != "total_s"},
            "peak_rss_mib": usage.ru_maxrss / 1024,
            "volume_ml": result["volume_ml"], "truth_ml": truth_ml,
            "error_pct": 100 * (result["volume_ml"] - truth_ml) / truth_ml,
            **({"result": result} if keep_result else {})}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--items", nargs="+", default=["apple", "banana", "chocolate_cake"])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--before", type=Path, help="a checkout of the code to compare with")
    args = parser.parse_args()
    root = experiment_dir(args.quick)
    scenario = scenarios(args.quick)["quick" if args.quick else "full_orbit"]
    codes = {"before": args.before.resolve(), "after": None} if args.before else {"now": None}
    rows = []
    for item in args.items:
        capture_root = ensure_capture(root, item, scenario)
        for label, code in codes.items():
            rows.append({"item": item, "code": label, **estimate_run(capture_root, code)})
            print(rows[-1], flush=True)
    table = pd.DataFrame(rows)
    if args.before:
        table = pd.concat([table, ratio_rows(table)], ignore_index=True)
    write_table(table, figures_dir() / "estimate_benchmark", float_digits=2)
    print(table.to_string(index=False, float_format=lambda x: f"{x:.2f}"))


def ratio_rows(table: pd.DataFrame) -> pd.DataFrame:
    """Per item and over all items, after/before of every time and of peak memory."""
    timed = [c for c in table.columns if c.endswith("_s") or c == "peak_rss_mib"]
    by_code = table.groupby(["code", "item"])[timed].mean()
    per_item = (by_code.loc["after"] / by_code.loc["before"]).reset_index()
    overall = (table[table.code == "after"][timed].sum()
               / table[table.code == "before"][timed].sum()).to_frame().T
    overall["item"] = "all"
    return pd.concat([per_item, overall], ignore_index=True).assign(code="after/before")


if __name__ == "__main__":
    main()
