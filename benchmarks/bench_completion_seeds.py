"""How much the completed volume depends on the completion's resampling seed, on the same
finished stages: the network sees a random subset of the masked cloud (1024 of some 70,000
points for the ``cpu`` checkpoint), so another seed predicts other points.

Usage: .venv/bin/python benchmarks/bench_completion_seeds.py [--scenario full_orbit]
       [--seeds 3] [--resamplings 1] ITEM...

Uses the captures and stages of ``data/bench-sfm`` as ``bench_volume.py`` does (stages made by
other code or settings are recomputed, never reused), runs the estimate that ``volec
estimate`` runs (:func:`volec.estimate.estimate_from_stages`) without completion and with
the default completion once per seed (each pooling ``--resamplings`` draws,
:attr:`volec.completion.complete.CompletionConfig.resamplings`), and writes
figures/completion_seeds.{csv,md}: per item the volume error without completion and per seed,
and the spread (range and standard deviation) over the seeds.
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np
import pandas as pd

from volec.estimate import (
    EstimateConfig,
    estimate_from_stages,
    food_silhouettes,
    load_completion_model,
)
from volec.experiments import Scenario, ensure_capture, scenario_capture, scenarios
from volec.paths import experiment_dir, figures_dir
from volec.pipeline import run_stages
from volec.synth import load_truth
from volec.tables import write_table


def item_row(item: str, scenario: Scenario, seeds: int, resamplings: int = 1
             ) -> dict[str, float | str]:
    """Volume errors (%) of ``item`` without completion and with each seed."""
    out = ensure_capture(experiment_dir(False), item, scenario)
    capture = scenario_capture(out, scenario)
    cfg = EstimateConfig()
    stages = run_stages(capture, scenario.work(out), cfg.sfm, cfg.dense, cfg.masking,
                        stale="recompute", progress=False)
    views = food_silhouettes(capture, stages, cfg)
    truth_ml = load_truth(out)["volume_ml"]  # scoring only

    def error_pct(variant: EstimateConfig, model) -> float:
        est = estimate_from_stages(capture, stages, model, variant, views)
        return (est.food.volume_ml / truth_ml - 1) * 100

    row: dict[str, float | str] = {
        "item": item, "without_pct": error_pct(replace(cfg, use_completion=False), None)}
    model = load_completion_model(cfg)
    errors = [error_pct(replace(cfg, completion=replace(cfg.completion, seed=seed,
                                                        resamplings=resamplings)), model)
              for seed in range(seeds)]
    row.update({f"seed{seed}_pct": e for seed, e in enumerate(errors)})
    row["spread_pct"] = float(np.ptp(errors))
    row["std_pct"] = float(np.std(errors))
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("items", nargs="+")
    parser.add_argument("--scenario", default="full_orbit")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--resamplings", type=int, default=1)
    args = parser.parse_args()
    scenario = scenarios(False)[args.scenario]
    table = pd.DataFrame([item_row(item, scenario, args.seeds, args.resamplings)
                          for item in args.items])
    write_table(table, figures_dir() / "completion_seeds", float_digits=2)
    print(table.to_string(index=False, float_format=lambda x: f"{x:+.2f}"))
    print(f"mean spread over {args.seeds} seeds: {table['spread_pct'].mean():.2f} % "
          f"(largest {table['spread_pct'].max():.2f} %)")


if __name__ == "__main__":
    main()
