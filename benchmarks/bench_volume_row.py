"""Time one row of the volume experiment (what notebooks 05 and 07 compute per capture: the
five completion methods on one basis, each mesh scored, the visual hull from the AR poses),
before and after a code change, and check that the rows agree.

Usage: .venv/bin/python benchmarks/bench_volume_row.py --before DIR [--after DIR]
       [--items apple banana] [--scenario full_orbit] [--rounds 2]

Each item's finished stages (data/bench-sfm/ITEM-full_orbit: capture, ground truth and the
scenario's work folder, made here as the benchmark scripts make them if missing) are copied to
a temporary folder, so that the experiments' cache there is neither read nor overwritten. The
row is then computed there from scratch by the code in ``--before`` and in ``--after`` (this
checkout unless given; ``PYTHONPATH=DIR``, e.g. ``git worktree add /tmp/before REV``),
alternating (before first in odd rounds, after first in even ones), each in a child process
on one thread as a ``make paper`` worker runs it.
Prints the wall times and the meshing's share of them (the five methods' ``*_meshing_s``),
their after/before ratios per item, and every result column (not a time) in which the two
rows differ beyond 1e-9 relative; written to
figures/volume_row_benchmark.{csv,md}.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import pandas as pd

from volec.estimate import EstimateConfig
from volec.experiments import benchmark_stages, scenarios
from volec.paths import experiment_dir, figures_dir
from volec.tables import write_table

CHILD = """
import json, sys, time, uuid
from pathlib import Path
from volec.batch import limit_threads
limit_threads(1)
from volec.estimate import EstimateConfig
from volec.experiments import scenarios, volume_row
root, item, scenario, out = Path(sys.argv[1]), sys.argv[2], sys.argv[3], sys.argv[4]
start = time.perf_counter()
row = volume_row(root, item, scenarios(False)[scenario], EstimateConfig(),
                 {"benchmark": uuid.uuid4().hex})
row["row_wall_s"] = time.perf_counter() - start
Path(out).write_text(json.dumps(row, default=str))
"""


def copy_item(root: Path, item: str, scenario: str, to: Path) -> None:
    """The item's capture, ground truth and the scenario's work folder, copied under ``to``
    (the layout of ``root``)."""
    sc = scenarios(False)[scenario]
    source = sc.folder(root, item)
    target = sc.folder(to, item)
    for part in ("capture", "ground_truth"):
        shutil.copytree(source / part, target / part)
    # the stages, not what the rows write (meshes, the completed cloud, cached rows)
    shutil.copytree(sc.work(source), sc.work(target), ignore=shutil.ignore_patterns(
        "mesh_*.ply", "food_completed.ply", "*_eval.json"))


def timed_row(code: Path, root: Path, item: str, scenario: str) -> dict[str, Any]:
    """The row computed by the code at ``code`` in a child process."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "row.json"
        env = {**os.environ, "PYTHONPATH": str(code)}
        subprocess.run([sys.executable, "-c", CHILD, str(root), item, scenario, str(out)],
                       env=env, check=True, stdout=subprocess.DEVNULL)
        return json.loads(out.read_text())


def differing(before: dict[str, Any], after: dict[str, Any]) -> list[str]:
    """The result columns (not times) whose values differ beyond 1e-9 relative."""
    out = []
    for key in sorted(set(before) | set(after)):
        if key.endswith("_s") or key in ("key", "workers"):
            continue
        a, b = before.get(key), after.get(key)
        if isinstance(a, float) and isinstance(b, float):
            if abs(a - b) > 1e-9 * max(abs(a), abs(b), 1e-300):
                out.append(key)
        elif a != b:
            out.append(key)
    return out


def meshing_seconds(row: dict[str, Any]) -> float:
    """The seconds the row's five methods spent meshing (their ``*_meshing_s``), the part
    of a row that changes to the meshing speed up or slow down."""
    return sum(v for k, v in row.items() if k.endswith("_meshing_s"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", type=Path, required=True)
    parser.add_argument("--after", type=Path, default=Path(__file__).resolve().parents[1])
    parser.add_argument("--items", nargs="+", default=["apple", "banana"])
    parser.add_argument("--scenario", default="full_orbit")
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    root = experiment_dir(False)
    for item in args.items:  # the stages made (or reused) in data/
        benchmark_stages(item, args.scenario, EstimateConfig())
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for item in args.items:
            copy_item(root, item, args.scenario, Path(tmp))
        for rnd in range(args.rounds):
            for item in args.items:
                made = {}
                order = [(args.before, "before"), (args.after, "after")]
                for code, name in order if rnd % 2 == 0 else order[::-1]:  # alternating
                    made[name] = timed_row(code, Path(tmp), item, args.scenario)
                    print(f"round {rnd + 1} {item} {name}: {made[name]['row_wall_s']:.1f} s",
                          flush=True)
                rows.append({"item": item, "round": rnd + 1,
                             "before_s": made["before"]["row_wall_s"],
                             "after_s": made["after"]["row_wall_s"],
                             "before_meshing_s": meshing_seconds(made["before"]),
                             "after_meshing_s": meshing_seconds(made["after"]),
                             "differing": ",".join(differing(made["before"], made["after"]))})
    table = pd.DataFrame(rows)
    summary = table.groupby("item")[["before_s", "after_s", "before_meshing_s",
                                     "after_meshing_s"]].sum()
    summary["ratio"] = summary["after_s"] / summary["before_s"]
    summary["meshing_ratio"] = summary["after_meshing_s"] / summary["before_meshing_s"]
    write_table(table, figures_dir() / "volume_row_benchmark", float_digits=2)
    print(table.to_string(index=False, float_format=lambda x: f"{x:.1f}"))
    print(summary.to_string(float_format=lambda x: f"{x:.3f}"))


if __name__ == "__main__":
    main()
