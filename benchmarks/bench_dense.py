"""Measure dense stereo and masking: accuracy and completeness against the true surface, time
and peak memory.

Usage: .venv/bin/python benchmarks/bench_dense.py [--items apple banana ...] [--quick]
                                                  [--cli-item banana]

1. The experiment table (SfM poses and exact poses) over the items' full-orbit captures, cached
   under data/bench-sfm (-quick) like notebook 02; written to figures/dense_benchmark.{csv,md}.
2. ``volec dense`` as a user runs it, in a child process on a copy of one item's SfM stage:
   wall time and peak resident memory of dense + masking (SfM reused), from
   ``resource.getrusage(RUSAGE_CHILDREN)``.
"""

from __future__ import annotations

import argparse
import logging
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

from volec.capture import read_transforms_json
from volec.experiments import dense_experiment, dense_table, ensure_capture, scenarios
from volec.paths import experiment_dir, figures_dir
from volec.pipeline import run_sfm_stage
from volec.tables import write_table


def cli_run(capture_root: Path) -> tuple[float, float]:
    """(wall seconds, peak RSS MiB) of ``volec dense`` with a finished SfM stage."""
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp) / "work"
        shutil.copytree(capture_root / "work" / "sfm", work / "sfm")
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "volec", "dense", str(capture_root / "capture"),
                        "--out", str(work), "--quiet"], check=True)
        wall = time.perf_counter() - start
    peak_mib = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    return wall, peak_mib


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--items", nargs="+", default=["apple", "banana", "chocolate_cake"])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--cli-item", default="banana")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    root = experiment_dir(args.quick)
    scenario = scenarios(args.quick)["quick" if args.quick else "full_orbit"]
    raw = pd.concat([dense_experiment(root, args.items, scenario, poses)
                     for poses in ("refined", "exact")], ignore_index=True)
    shown = dense_table(raw)
    write_table(shown, figures_dir() / "dense_benchmark", float_digits=2)
    print(shown.to_string(index=False, float_format=lambda x: f"{x:.2f}"))

    out = ensure_capture(root, args.cli_item, scenario)
    run_sfm_stage(read_transforms_json(out / "capture"), out / "work", stale="recompute")
    wall, peak = cli_run(out)
    print(f"\nvolec dense on {args.cli_item} ({scenario.name}, SfM reused): "
          f"{wall:.1f} s wall, {peak:.0f} MiB peak RSS")


if __name__ == "__main__":
    main()
