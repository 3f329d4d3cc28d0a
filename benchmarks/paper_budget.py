"""Where the time of a `make paper` run went: each notebook's and long cell's wall time (from
the executed notebooks' papermill records) and the worker-seconds each stage recorded for the
stages it made (SfM steps, dense stereo, segmentation, the estimates' meshing and completion).

Usage: .venv/bin/python benchmarks/paper_budget.py [REPO_ROOT] [--cells-over SECONDS]

Reads `build/notebooks/*.ipynb` of the checkout at or above REPO_ROOT (default: the working
directory) and the full-size experiments' `*/work*/` under its data folder (`VOLEC_DATA_DIR`
where set, as `make paper` finds it); computes nothing. Stage times are those each stage
wrote when it ran (two workers at once in `make paper`, sharing the cores), each stage counted
once: a copy in another folder (the automatic- and noisy-mask runs reuse the SfM stage) is
not counted again. Renders record no time of their own; they are the rest of the notebooks' time.
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from datetime import datetime
from pathlib import Path

from volec.paths import experiment_dir, repo_root


def _seconds(stamp: str) -> float:
    return datetime.fromisoformat(stamp.replace("Z", "+00:00")).timestamp()


def notebook_times(build: Path, cells_over_s: float) -> None:
    """Print each executed notebook's wall time and its cells longer than ``cells_over_s``."""
    total = 0.0
    for path in sorted(build.glob("*.ipynb")):
        record = json.loads(path.read_text())
        run = record["metadata"].get("papermill", {})
        if not run.get("end_time"):
            print(f"{path.name:32s} unfinished")
            continue
        wall = _seconds(run["end_time"]) - _seconds(run["start_time"])
        total += wall
        print(f"{path.name:32s} {wall / 60:6.1f} min")
        for n, cell in enumerate(record["cells"]):
            duration = cell.get("metadata", {}).get("papermill", {}).get("duration") or 0
            if duration > cells_over_s:
                first = "".join(cell["source"]).strip().splitlines()[0][:60]
                print(f"    cell {n:2d} {duration / 60:6.1f} min  {first}")
    print(f"{'notebooks':32s} {total / 60:6.1f} min")


def stage_seconds(root: Path) -> tuple[Counter, Counter]:
    """Worker-seconds and counts per stage, from the stage records under ``root``."""
    seconds, counts = Counter(), Counter()
    made: set[str] = set()
    for summary in sorted(root.glob("*/work*/sfm/summary.json")):
        record = json.loads(summary.read_text())
        digest = json.dumps(record.get("files"), sort_keys=True)
        if digest in made:  # a copy of a stage made elsewhere
            continue
        made.add(digest)
        counts["sfm"] += 1
        for step, value in record.get("timings_s", {}).items():
            seconds[f"sfm {step.removesuffix('_s')}"] += value
    for dense in root.glob("*/work*/dense.json"):
        timings = json.loads(dense.read_text()).get("timings_s", {})
        seconds["dense stereo"] += sum(timings.values())
        counts["dense stereo"] += 1
    for segment in root.glob("*/work*/segment.json"):
        seconds["segmentation"] += json.loads(segment.read_text())["seconds"]["total_s"]
        counts["segmentation"] += 1
    for row in root.glob("*/work*/volume_eval.json"):
        record = json.loads(row.read_text())
        counts["Table II rows"] += 1
        for key, value in record.items():
            if key.endswith(("_meshing_s", "_completion_s")) and isinstance(value, float | int):
                seconds[f"estimates: {key.rsplit('_', 2)[-2]}"] += value
        seconds["estimates: silhouettes"] += record.get("silhouettes_s", 0.0)
    return seconds, counts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("root", nargs="?", type=Path, default=None)
    parser.add_argument("--cells-over", type=float, default=60.0,
                        help="list cells that ran longer than this (seconds)")
    args = parser.parse_args()
    root = repo_root(args.root)
    notebook_times(root / "build" / "notebooks", args.cells_over)
    seconds, counts = stage_seconds(experiment_dir(False, start=root))
    print()
    for stage, value in sorted(seconds.items()):
        print(f"{stage:32s} {value / 60:6.1f} worker-min")
    print(f"{'recorded':32s} {sum(seconds.values()) / 60:6.1f} worker-min")
    print("stages made:", ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))


if __name__ == "__main__":
    main()
