"""Measure `volec estimate` end to end, as a user runs it: wall time per stage and in all, peak
memory, and the volume against the truth.

Usage: .venv/bin/python benchmarks/bench_estimate.py [--items apple banana ...] [--quick]

Each item's benchmark capture (generated under data/bench-sfm, or -quick, like notebook 04, if
missing) is estimated from scratch into a fresh temporary folder (nothing reused), one item at
a time, by ``volec estimate`` in a child process. The wall time is the child's; the per-stage
times come from its ``result.json``; peak resident memory from
``resource.getrusage(RUSAGE_CHILDREN)`` (the largest child so far).
Written to figures/estimate_benchmark.{csv,md}.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

from volec.experiments import ensure_capture, scenarios
from volec.paths import experiment_dir, figures_dir
from volec.synth import load_ground_truth_mesh
from volec.tables import write_table


def estimate_run(capture_root: Path) -> dict[str, float]:
    """Wall time, stage times, peak memory and volume of one fresh ``volec estimate``."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "estimate"
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "volec", "estimate", str(capture_root / "capture"),
                        "--out", str(out), "--quiet"], check=True)
        wall = time.perf_counter() - start
        result = json.loads((out / "result.json").read_text())
    truth_ml = load_ground_truth_mesh(capture_root).volume * 1e6
    return {"frames": result["frames"]["registered"], "wall_s": wall,
            **{k: v for k, v in result["stage_seconds"].items() if k != "total_s"},
            "peak_rss_mib": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024,
            "volume_ml": result["volume_ml"], "truth_ml": truth_ml,
            "error_pct": 100 * (result["volume_ml"] - truth_ml) / truth_ml}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--items", nargs="+", default=["apple", "banana", "chocolate_cake"])
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    root = experiment_dir(args.quick)
    scenario = scenarios(args.quick)["quick" if args.quick else "full_orbit"]
    rows = []
    for item in args.items:
        capture_root = ensure_capture(root, item, scenario)
        rows.append({"item": item, **estimate_run(capture_root)})
        print(rows[-1], flush=True)
    table = pd.DataFrame(rows)
    write_table(table, figures_dir() / "estimate_benchmark", float_digits=1)
    print(table.to_string(index=False))


if __name__ == "__main__":
    main()
