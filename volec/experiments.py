"""Experiments behind the paper's tables: run a stage over synthetic captures, score it.

In: a benchmark folder, item names, scenario names and stage configs. Out: one pandas row per
(item, scenario) with the stage's errors against the ground truth and its wall time. Each run
is cached as ``ROOT/ITEM-SCENARIO/work/<stage>_eval.json``, so a re-run only redoes what is
missing; the captures themselves are generated on first use.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import pandas as pd

from volec.capture import read_transforms_json
from volec.io import write_json_atomic
from volec.sfm import SfmConfig, evaluate_sfm, run_sfm
from volec.synth import PRESETS as SYNTH_PRESETS
from volec.synth import SynthConfig, write_synthetic_capture


@dataclass(frozen=True)
class Scenario:
    """A capture condition of the benchmark."""

    name: str
    """Short identifier used in folder names and tables."""
    synth: SynthConfig
    """How the capture is generated."""


def scenarios(quick: bool) -> dict[str, Scenario]:
    """The capture conditions: full orbit at the default 5 mm drift, a half orbit, and 1 cm
    drift. ``quick`` gives small captures for CI (20 frames over 120 degrees)."""
    if quick:
        small = SYNTH_PRESETS["default"].with_(n_frames=20, arc_deg=120.0)
        return {"quick": Scenario("quick", small)}
    return {
        "full_orbit": Scenario("full_orbit", SYNTH_PRESETS["default"]),
        "half_orbit": Scenario("half_orbit", SYNTH_PRESETS["half_orbit"]),
        "drift_1cm": Scenario("drift_1cm", SYNTH_PRESETS["drift_1cm"]),
    }


def ensure_capture(root: Path, item: str, scenario: Scenario) -> Path:
    """The synthetic capture folder for (item, scenario), generated if missing."""
    out = Path(root) / f"{item}-{scenario.name}"
    truth = out / "ground_truth" / "truth.json"
    if not truth.exists() or json.loads(truth.read_text())["config"] != scenario.synth.recorded():
        write_synthetic_capture(item, out, scenario.synth, overwrite=True, progress=False)
    return out


def sfm_experiment(
    root: Path, items: list[str], scenario_list: list[Scenario], cfg: SfmConfig | None = None
) -> pd.DataFrame:
    """SfM errors and wall time per (item, scenario), cached per run and config.

    The cache is keyed by the config, not by volec's code: after changing the SfM code,
    delete ``ROOT/*/work`` to measure it again.
    """
    cfg = cfg or SfmConfig()
    key = json.loads(json.dumps(asdict(cfg)))
    rows = []
    for scenario in scenario_list:
        for item in items:
            out = ensure_capture(root, item, scenario)
            cache = out / "work" / "sfm_eval.json"
            if cache.exists():
                cached = json.loads(cache.read_text())
                if cached.pop("sfm_config", None) == key:
                    rows.append(cached)
                    continue
            reported = read_transforms_json(out / "capture")
            exact = read_transforms_json(out / "ground_truth" / "transforms_exact.json",
                                         check_image_sizes=False)
            start = time.perf_counter()
            result = run_sfm(reported, out / "work", cfg)
            row = {"item": item, "scenario": scenario.name, "frames": len(reported),
                   "wall_s": time.perf_counter() - start,
                   **evaluate_sfm(result, exact, reported),
                   **{f"{k}_s": v for k, v in result.summary["timings_s"].items()}}
            write_json_atomic(cache, {**row, "sfm_config": key})
            rows.append(row)
    return pd.DataFrame(rows)


#: SfM columns shown in tables, with the factor to their display unit.
SFM_COLUMNS = {
    "registered_fraction": 1.0,
    "ar_centre_err_median_m": 1000.0,
    "centre_err_median_m": 1000.0,
    "centre_err_max_m": 1000.0,
    "ar_rot_err_median_deg": 1.0,
    "rot_err_median_deg": 1.0,
    "scale_err_sim3_all_pct": 1.0,
    "scale_err_short_baseline_pct": 1.0,
    "scale_err_drift_model_pct": 1.0,
    "wall_s": 1.0,
}


def sfm_error_table(raw: pd.DataFrame) -> pd.DataFrame:
    """The rows of :func:`sfm_experiment` in display units (metres -> ``_mm`` columns),
    followed by one mean row per scenario."""
    shown = raw[["item", "scenario", "frames", *SFM_COLUMNS]].copy()
    for col, factor in SFM_COLUMNS.items():
        shown[col] = shown[col] * factor
    shown = shown.rename(columns=lambda c: c[:-2] + "_mm" if c.endswith("_m") else c)
    numeric = shown.columns.drop(["item", "scenario"])
    # Signed errors would cancel in a mean: the mean rows average their magnitudes.
    magnitudes = shown.copy()
    magnitudes[numeric] = magnitudes[numeric].abs()
    means = magnitudes.groupby("scenario", sort=False)[numeric].mean().reset_index()
    means.insert(0, "item", "mean abs")
    return pd.concat([shown, means], ignore_index=True)
