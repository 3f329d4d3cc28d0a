"""Measure the SfM stage against the exact poses of synthetic captures.

Usage: .venv/bin/python benchmarks/bench_sfm.py [--items apple banana ...] [--quick]
Captures and per-run results are cached under data/bench-sfm (or -quick), keyed on the config
and the code. Prints the table and writes figures/sfm_benchmark.{csv,md}.
"""

from __future__ import annotations

import argparse
import logging

from volec.experiments import scenarios, sfm_error_table, sfm_experiment
from volec.paths import experiment_dir, figures_dir
from volec.tables import write_table


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--items", nargs="+", default=["apple", "banana", "chocolate_cake"])
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    table = sfm_experiment(experiment_dir(args.quick), args.items,
                           list(scenarios(args.quick).values()))
    shown = sfm_error_table(table)
    write_table(shown, figures_dir() / "sfm_benchmark", float_digits=3)
    print(shown.to_string(index=False, float_format=lambda x: f"{x:.3f}"))


if __name__ == "__main__":
    main()
