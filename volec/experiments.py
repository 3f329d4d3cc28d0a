"""Experiments behind the paper's tables: run a stage over synthetic captures, score it.

In: a benchmark folder, item names, scenario names and stage configs. Out: one pandas row per
(item, scenario) with the stage's errors against the ground truth and its wall time. Each run
is cached as ``ROOT/ITEM-SCENARIO/work/<stage>_eval.json``, keyed by the config, the digest of
the code that computes the row (the stage's modules and everything they import, and this
module) and, for completion, the checkpoint's digest: a re-run only redoes what is missing or
what other code would compute differently. The stage results in the work folders are reused on
the same terms (:mod:`volec.pipeline`, ``stale="recompute"``). The captures themselves are
generated on first use, and again when the generator's code changes.

Quick (CI-sized) and full runs use separate folders (:func:`volec.paths.experiment_dir`), so
their rows never mix. The volume experiment runs the same core as ``volec estimate``
(:func:`volec.estimate.estimate_from_stages`) and only adds scoring.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from volec.capture import Capture, read_transforms_json
from volec.dense import DenseConfig, run_dense, save_dense
from volec.errors import ConfigError, UnknownNameError, VolecError
from volec.io import write_bytes_atomic, write_json_atomic
from volec.masking import MaskingConfig, mask_cloud, save_masking
from volec.metrics import (
    chamfer_distance,
    cloud_scores,
    mesh_offset_scores,
    sample_surface,
    signed_distances_to_surface,
    signed_summary,
)
from volec.paths import experiment_dir
from volec.pipeline import StageResults, config_record, run_sfm_stage, run_stages
from volec.progress import step
from volec.provenance import code_identity, file_digest, module_digest
from volec.segment import given_masks
from volec.sfm import SfmConfig, evaluate_sfm, load_sfm
from volec.synth import PRESETS as SYNTH_PRESETS
from volec.synth import SynthConfig, load_ground_truth_mesh, write_synthetic_capture
from volec.synth.generate import is_current

if TYPE_CHECKING:
    from volec.estimate import EstimateConfig


@dataclass(frozen=True)
class Scenario:
    """A capture condition of the benchmark."""

    name: str
    """Short identifier used in folder names and tables."""
    synth: SynthConfig
    """How the capture is generated."""
    frames: str = "all"
    """Which of the rendered frames the pipeline gets (:func:`frame_subset`): ``all``,
    ``half_orbit`` or ``evenly:N``."""
    rendered_as: str = ""
    """The scenario whose rendering (``ITEM-RENDERED_AS/``, the same ``synth``) this one takes
    its frames from, running the whole pipeline on them alone in ``work-NAME/``; empty: its
    own rendering and ``work/``. Subsets of one rendering cost no rendering and compare
    directly."""

    def folder(self, root: Path, item: str) -> Path:
        """The capture's folder (capture and ground truth)."""
        return Path(root) / f"{item}-{self.rendered_as or self.name}"

    def work(self, out: Path) -> Path:
        """The work folder of this scenario's stages in the capture folder ``out``."""
        return Path(out) / (f"work-{self.name}" if self.rendered_as else "work")


def frame_subset(capture: Capture, rule: str) -> np.ndarray:
    """Indices of the frames of ``capture`` a scenario keeps: ``all``; ``half_orbit``: those
    whose camera lies within the 180 degrees of azimuth (about the capture's up, around the
    point the cameras fixate) that the orbit covers first, from the first frame;
    ``evenly:N``: N evenly spaced. Only the capture's own (AR) poses decide, never the ground
    truth."""
    n = len(capture)
    if rule == "all":
        return np.arange(n)
    if rule.startswith("evenly:"):
        keep = int(rule.split(":")[1])
        return np.unique(np.round(np.linspace(0, n - 1, min(keep, n))).astype(int))
    if rule == "half_orbit":
        from volec.geometry import horizontal_axes
        from volec.scale import fixation_point

        up = np.asarray(capture.metadata.get("world_up", (0.0, 0.0, 1.0)), float)
        e1, e2 = horizontal_axes(up)
        rel = capture.camera_centres - fixation_point(capture)
        azimuth = np.degrees(np.arctan2(rel @ e2, rel @ e1))
        # measured the way the phone went round, so the arc is the first half it filmed
        turn = np.sign(np.sum(np.diff(np.unwrap(np.radians(azimuth))))) or 1.0
        return np.flatnonzero((turn * (azimuth - azimuth[0])) % 360.0 < 180.0)
    raise ConfigError(f"unknown frame rule {rule!r}: all, half_orbit or evenly:N")


def scenario_capture(out: Path, scenario: Scenario, exact: bool = False) -> Capture:
    """The capture a scenario's pipeline gets from the capture folder ``out`` (with
    ``exact``, the ground truth's exact poses of the same frames, for scoring only)."""
    reported = read_transforms_json(out / "capture")
    keep = frame_subset(reported, scenario.frames)
    chosen = reported
    if exact:
        chosen = read_transforms_json(out / "ground_truth" / "transforms_exact.json",
                                      check_image_sizes=False)
    if len(keep) == len(chosen):
        return chosen
    return replace(chosen, frames=tuple(chosen.frames[i] for i in keep))


@dataclass(frozen=True)
class BenchmarkStages:
    """One item of the full-size benchmark in a scenario, as the pipeline sees it."""

    capture: Capture
    stages: StageResults
    truth_ml: float
    """The true volume, mL: for scoring only."""
    folder: Path
    """The capture's benchmark folder (its ``ground_truth/`` is read only to score)."""


def benchmark_stages(item: str, scenario_name: str, cfg: EstimateConfig) -> BenchmarkStages:
    """The capture and stage results (reused when the current code made them, else
    recomputed) of ``item`` in the full-size benchmark's scenario ``scenario_name``, as the
    benchmark scripts compare estimates on them."""
    scenario = scenarios(False)[scenario_name]
    out = scenario.folder(experiment_dir(False), item)
    capture = scenario_capture(out, scenario)
    stages = run_stages(capture, scenario.work(out), cfg.sfm, cfg.dense, cfg.masking,
                        stale="recompute", progress=False)
    return BenchmarkStages(capture, stages, load_ground_truth_mesh(out).volume * 1e6, out)


def scenarios(quick: bool) -> dict[str, Scenario]:
    """The capture conditions: full orbit at the default 5 mm drift, its frames within a
    half orbit, 30 of its frames evenly spread, 1 cm drift (all with a phone's look), the
    full orbit with the first benchmark's sharp look, 60 frames from low elevations
    (``low``), the full orbit with faint skins (``smooth``), and the full orbit in a setup
    that makes segmentation hard (one per item, see :data:`volec.synth.scene.HARD_SETUPS`).
    ``quick`` gives small captures for CI (20 frames over 120 degrees)."""
    if quick:
        small = SYNTH_PRESETS["default"].with_(n_frames=20, arc_deg=120.0)
        return {"quick": Scenario("quick", small),
                "quick_hard": Scenario("quick_hard", small.with_(setup="hard"))}
    full = SYNTH_PRESETS["default"]
    return {
        "full_orbit": Scenario("full_orbit", full),
        "half_orbit": Scenario("half_orbit", full, frames="half_orbit",
                               rendered_as="full_orbit"),
        "sparse": Scenario("sparse", full, frames="evenly:30", rendered_as="full_orbit"),
        "drift_1cm": Scenario("drift_1cm", SYNTH_PRESETS["drift_1cm"]),
        "full_orbit_sharp": Scenario("full_orbit_sharp", SYNTH_PRESETS["sharp"]),
        "low": Scenario("low", SYNTH_PRESETS["low"]),
        "smooth": Scenario("smooth", SYNTH_PRESETS["smooth"]),
        "hard": Scenario("hard", SYNTH_PRESETS["default"].with_(setup="hard")),
    }


def ensure_capture(root: Path, item: str, scenario: Scenario) -> Path:
    """The synthetic capture folder for (item, scenario), generated if missing or made with
    another config or generator code. A finished capture made by other code is rendered again
    beside it (:func:`rerender`): where the new files are the same bytes, the folder and the
    stages in it are kept (the stages are keyed by the capture's bytes); otherwise it is
    replaced, its work folders with it.

    Rendered by at most as many processes as this process may use threads
    (:func:`volec.batch.thread_limit`; the same bytes whatever their number): in a worker of
    :func:`map_items`, one. Two items at once on 2 cores, each with two render processes,
    took 80.0 s for two 100-frame captures, against 71.3 s with one each (0.89)."""
    from volec.batch import thread_limit

    out = scenario.folder(root, item)
    if not is_current(out, scenario.synth):
        synth = replace(scenario.synth, workers=min(scenario.synth.workers, thread_limit()))
        if (out / TRUTH_FILE).exists():
            rerender(item, out, synth)
        else:
            write_synthetic_capture(item, out, synth, overwrite=True, progress=False)
    return out


TRUTH_FILE = Path("ground_truth") / "truth.json"
"""A finished synthetic capture's record (written last)."""


def rerender(item: str, out: Path, synth: SynthConfig) -> None:
    """Render ``item`` by ``synth`` again into a sibling of the finished capture ``out``. When
    every file of its capture and ground truth is the same bytes as in ``out`` (the truth
    record apart from the generator code's identity), ``out`` and its work folders are kept
    and only that record is replaced; otherwise the new rendering replaces ``out``. A change
    to code the renderer imports but that leaves its output alone (such as b9eba51's, in
    volec/capture.py) then costs the renders, not every stage made from them."""
    import os
    import shutil
    import tempfile

    scratch = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".render", dir=out.parent))
    try:
        fresh = write_synthetic_capture(item, scratch / out.name, synth, progress=False)
        if same_rendering(out, fresh):
            write_bytes_atomic(out / TRUTH_FILE, (fresh / TRUTH_FILE).read_bytes())
            return
        os.replace(out, scratch / "replaced")
        os.replace(fresh, out)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def same_rendering(a: Path, b: Path) -> bool:
    """Whether the synthetic captures ``a`` and ``b`` hold the same files with the same bytes
    in ``capture/`` and ``ground_truth/``, their truth records differing at most in the
    generator code's identity (``code``)."""
    def files(root: Path) -> list[Path]:
        return sorted(p.relative_to(root) for sub in ("capture", "ground_truth")
                      for p in (root / sub).rglob("*") if p.is_file())

    names = files(a)
    if names != files(b):
        return False
    for name in names:
        if name == TRUTH_FILE:
            first, second = (json.loads((root / name).read_text()) for root in (a, b))
            first.pop("code", None)
            second.pop("code", None)
            if first != second:
                return False
        elif (a / name).read_bytes() != (b / name).read_bytes():
            return False
    return True


def _rendered(root: Path, item: str, scenario: Scenario) -> dict[str, str]:
    """The (item, scenario) capture, rendered if needed: a job of :func:`render_captures`."""
    return {"folder": str(ensure_capture(root, item, scenario))}


def render_captures(root: Path, runs: list[tuple[str, Scenario]], workers: int = 1,
                    progress: bool = False) -> None:
    """Make every capture folder the (item, scenario) ``runs`` need, each once, before any of
    them runs: scenarios that share a rendering (``rendered_as``) would otherwise render it in
    two processes at once, each replacing the folder under the other's work."""
    first: dict[Path, tuple[str, Scenario]] = {}
    for item, scenario in runs:
        first.setdefault(scenario.folder(root, item), (item, scenario))
    jobs = [(root, item, scenario) for item, scenario in first.values()]
    map_items(_rendered, jobs, [f"{item} {sc.name}" for _, item, sc in jobs], workers, progress)


def row_key(config: dict[str, Any], *modules: str, **extra: Any) -> dict[str, Any]:
    """The cache key of an experiment row: its config, the code of ``modules`` (with all they
    import) and of this module, and ``extra`` (e.g. a checkpoint's digest)."""
    return {"config": config, "code": code_identity(*modules),
            "experiment_code": module_digest(__name__), **extra}


def _cached(cache: Path, key: dict[str, Any], key_field: str = "key") -> dict[str, Any] | None:
    """The row stored in ``cache`` with ``key``, or None."""
    if cache.exists():
        cached = json.loads(cache.read_text())
        if cached.pop(key_field, None) == key:
            return cached
    return None


def cached_row(cache: Path, key: dict[str, Any], compute: Callable[[], dict[str, Any]],
               key_field: str = "key") -> dict[str, Any]:
    """The result row stored in ``cache`` when it was made with ``key``; otherwise
    ``compute()``, stored with its key (atomically) and returned."""
    cached = _cached(cache, key, key_field)
    if cached is not None:
        return cached
    row = compute()
    write_json_atomic(cache, {**row, key_field: key})
    return row


SFM_CACHE = "sfm_eval.json"


def sfm_row(root: Path, item: str, scenario: Scenario, cfg: SfmConfig) -> dict[str, Any]:
    """One (item, scenario) of :func:`sfm_experiment`, computed and cached."""
    out = ensure_capture(root, item, scenario)

    def run() -> dict[str, Any]:
        reported = scenario_capture(out, scenario)
        exact = scenario_capture(out, scenario, exact=True)
        # the stage is reused when another experiment already ran it from the same inputs;
        # its steps' wall times are those recorded when it ran
        result, _ = run_sfm_stage(reported, scenario.work(out), cfg, stale="recompute")
        return {"item": item, "scenario": scenario.name, "frames": len(reported),
                "wall_s": float(sum(result.summary["timings_s"].values())),
                **evaluate_sfm(result, exact, reported),
                **{f"{k}_s": v for k, v in result.summary["timings_s"].items()}}

    return cached_row(scenario.work(out) / SFM_CACHE, sfm_key(cfg), run)


def sfm_key(cfg: SfmConfig) -> dict[str, Any]:
    """The cache key of an SfM row."""
    return row_key(config_record(cfg), "volec.sfm")


def sfm_experiment(
    root: Path, items: list[str], scenario_list: list[Scenario], cfg: SfmConfig | None = None,
    workers: int = 1, progress: bool = False,
) -> pd.DataFrame:
    """SfM errors and wall time per (item, scenario), cached per run and config; runs not
    cached go to ``workers`` processes (:func:`map_items`).

    The cache is keyed by the config and the code (:func:`row_key`).
    """
    cfg = cfg or SfmConfig()
    runs = [(item, scenario) for scenario in scenario_list for item in items]
    rows = [_cached(sc.work(sc.folder(root, item)) / SFM_CACHE, sfm_key(cfg))
            for item, sc in runs]
    todo = [n for n, row in enumerate(rows) if row is None]
    render_captures(root, [runs[n] for n in todo], workers, progress)
    computed = map_items(sfm_row, [(root, *runs[n], cfg) for n in todo],
                         [f"{runs[n][0]} {runs[n][1].name}" for n in todo], workers, progress)
    for n, row in zip(todo, computed, strict=True):
        rows[n] = row
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


def dense_experiment(
    root: Path, items: list[str], scenario: Scenario, poses: str = "refined",
    dense_cfg: DenseConfig | None = None, mask_cfg: MaskingConfig | None = None,
    sfm_cfg: SfmConfig | None = None,
) -> pd.DataFrame:
    """Dense stereo and masking per item, scored against the true food surface.

    ``poses="refined"`` uses the SfM stage's poses (run or reused in ``ITEM-SCENARIO/work``),
    as the pipeline does; ``poses="exact"`` uses the exact ones (in ``work-exact``), which
    separates the stereo's own error from the poses'. Cached per run in ``dense_eval.json`` of
    the work folder, keyed by the configs and the code (:func:`row_key`).
    """
    if poses not in ("refined", "exact"):
        raise ConfigError("poses must be 'refined' or 'exact'")
    dense_cfg, mask_cfg = dense_cfg or DenseConfig(), mask_cfg or MaskingConfig()
    key = row_key({"sfm": config_record(sfm_cfg or SfmConfig()), "dense": config_record(dense_cfg),
                   "masking": config_record(mask_cfg), "poses": poses},
                  "volec.sfm", "volec.dense", "volec.masking", "volec.metrics")
    rows = []
    for item in items:
        out = ensure_capture(root, item, scenario)
        work = out / ("work" if poses == "refined" else "work-exact")

        def run(out: Path = out, work: Path = work, item: str = item) -> dict[str, Any]:
            capture = read_transforms_json(out / "capture")
            exact = read_transforms_json(out / "ground_truth" / "transforms_exact.json",
                                         check_image_sizes=False)
            if poses == "refined":  # the pipeline's stages, reused by the volume experiment
                stages = run_stages(capture, work, sfm_cfg, dense_cfg, mask_cfg,
                                    stale="recompute", progress=False)
                dense, masked = stages.dense, stages.masked
            else:
                sfm, _ = run_sfm_stage(capture, out / "work", sfm_cfg, stale="recompute")
                T = np.stack([f.T_world_from_cam for f in exact.frames])
                registered = np.ones(len(capture), bool)
                masks = given_masks(capture)
                dense = run_dense(capture, masks, T, registered, sfm.points_xyz, dense_cfg,
                                  progress=False)
                masked = mask_cloud(dense.cloud, capture, masks, T, registered, mask_cfg)
                save_dense(work, dense)
                save_masking(work, masked)
            scores = cloud_scores(masked.cloud.xyz, load_ground_truth_mesh(out), exact)
            report = masked.report
            # wall times as the stages recorded them when they ran
            return {"item": item, "scenario": scenario.name, "poses": poses,
                    "frames": len(capture),
                    "dense_s": float(sum(dense.summary["timings_s"].values())),
                    "mask_s": report["seconds"],
                    **{f"{k}_s": v for k, v in dense.summary["timings_s"].items()},
                    "scene_points": len(dense.cloud), "food_points": len(masked.cloud),
                    "removed_outside_mask": report["removed_outside_mask"],
                    "removed_too_few_views": report["removed_too_few_views"], **scores}

        rows.append(cached_row(work / "dense_eval.json", key, run))
    return pd.DataFrame(rows)


#: Dense columns shown in tables, with the factor to their display unit.
DENSE_COLUMNS = {
    "accuracy_median_m": 1000.0,
    "accuracy_p95_m": 1000.0,
    "cloud_signed_median_m": 1000.0,
    "cloud_signed_p10_m": 1000.0,
    "cloud_signed_p90_m": 1000.0,
    "completeness_visible": 100.0,
    "completeness_unseen": 100.0,
    "visible_surface_fraction": 100.0,
    "scene_points": 1.0,
    "food_points": 1.0,
    "removed_outside_mask": 1.0,
    "dense_s": 1.0,
    "mask_s": 1.0,
}


def dense_table(raw: pd.DataFrame) -> pd.DataFrame:
    """The rows of :func:`dense_experiment` in display units (``_mm`` and ``_pct`` columns),
    followed by a mean row per scenario and pose source."""
    shown = raw[["item", "scenario", "poses", "frames", *DENSE_COLUMNS]].copy()
    for col, factor in DENSE_COLUMNS.items():
        shown[col] = shown[col] * factor
    renamed = {c: c[:-2] + "_mm" for c in DENSE_COLUMNS if c.endswith("_m")}
    renamed |= {c: c + "_pct" for c, f in DENSE_COLUMNS.items() if f == 100.0}
    shown = shown.rename(columns=renamed)
    numeric = shown.columns.drop(["item", "scenario", "poses"])
    means = shown.groupby(["scenario", "poses"], sort=False)[numeric].mean().reset_index()
    means.insert(0, "item", "mean")
    return pd.concat([shown, means], ignore_index=True)


# ----------------------------------------------------------------------------- completion


def completion_test_views(quick: bool, views: int = 2) -> list[dict[str, Any]]:
    """Partial views the network never trained on: held-out shapes of the training families
    (seeds from 2000) and the 21 benchmark items (kinds it never saw). Each entry has
    ``kind``, ``name``, ``view``, ``partial`` and ``complete`` (metres, z up)."""
    from volec.completion.data import ViewConfig, partial_view, shape_sample
    from volec.metrics import sample_surface
    from volec.synth import item_mesh, item_names
    from volec.synth.families import FAMILIES
    from volec.synth.shapes import stable_seed

    cfg = ViewConfig()
    families = list(FAMILIES)[:3] if quick else list(FAMILIES)
    items = item_names()[:2] if quick else item_names()
    views = 1 if quick else views
    out = []
    for family in families:
        sample = shape_sample(family, 2000, views, cfg)
        parts = np.split(sample["partial_points"].astype(float),
                         np.cumsum(sample["partial_sizes"])[:-1])
        out += [{"kind": "held-out shape", "name": f"{family}-2000", "view": v,
                 "partial": p, "complete": sample["complete"]} for v, p in enumerate(parts)]
    for item in items:
        mesh = item_mesh(item)
        rng = np.random.default_rng(stable_seed(f"completion-test-{item}"))
        complete = sample_surface(mesh, cfg.n_complete_points, seed=1)
        out += [{"kind": "benchmark item", "name": item, "view": v,
                 "partial": partial_view(mesh, rng, cfg), "complete": complete}
                for v in range(views)]
    return out


def pipeline_completion() -> Any:
    """The completion settings ``volec estimate`` uses (a CompletionConfig)."""
    from volec.estimate import EstimateConfig

    return EstimateConfig().completion


def completion_experiment(checkpoint: Path, root: Path, quick: bool) -> pd.DataFrame:
    """Chamfer distances (L1 in mm, L2 in mm^2) to the complete surface of: the partial view,
    the mirror baseline (with the support plane), the network's points alone, and the
    completed cloud as the pipeline makes it (partial + the network's points that fill what is
    missing, :func:`pipeline_completion`), per test view; with the network's and the mirror's
    time. Cached per view in ``root/quick`` or ``root/full``, keyed by the checkpoint's digest,
    the settings and the code."""

    from volec.completion.complete import complete_cloud
    from volec.completion.data import TABLE_UP
    from volec.completion.mirror import mirror_complete
    from volec.completion.train import load_checkpoint
    from volec.metrics import chamfer_distance
    from volec.pointcloud import PointCloud

    digest = file_digest(checkpoint)
    model, _ = load_checkpoint(checkpoint)
    pipeline_cfg = pipeline_completion()
    network_cfg = replace(pipeline_cfg, merge_partial=False)
    key = row_key(config_record(pipeline_cfg), "volec.completion.complete",
                  "volec.completion.mirror", "volec.completion.data", "volec.metrics",
                  "volec.synth.generate", checkpoint=digest)
    rows = []
    for view in completion_test_views(quick):

        def run(view: dict[str, Any] = view) -> dict[str, Any]:
            partial, complete = view["partial"], view["complete"]
            row: dict[str, Any] = {k: view[k] for k in ("kind", "name", "view")}
            row["partial_points"] = len(partial)
            start = time.perf_counter()
            mirrored = mirror_complete(partial, up=TABLE_UP)
            row["mirror_s"] = time.perf_counter() - start
            start = time.perf_counter()
            network = complete_cloud(PointCloud(partial), model, network_cfg, TABLE_UP)
            row["network_s"] = time.perf_counter() - start
            done = complete_cloud(PointCloud(partial), model, pipeline_cfg, TABLE_UP)
            clouds = {"partial": partial, "mirror": mirrored, "network": network.predicted_xyz,
                      "completed": done.cloud.xyz}
            for name, xyz in clouds.items():
                l1, l2 = chamfer_distance(xyz, complete)
                row[f"cd_l1_{name}_mm"] = l1 * 1e3
                row[f"cd_l2_{name}_mm2"] = l2 * 1e6
            return row

        cache = Path(root) / ("quick" if quick else "full") / f"{view['name']}-{view['view']}.json"
        rows.append(cached_row(cache, key, run))
    return pd.DataFrame(rows)


def completion_table(raw: pd.DataFrame) -> pd.DataFrame:
    """Mean Chamfer distances and times per test set, and each method's change against the
    partial input in percent (negative: closer to the complete shape)."""
    methods = ["partial", "mirror", "network", "completed"]
    rows = []
    for kind, group in raw.groupby("kind", sort=False):
        row: dict[str, Any] = {"test set": kind, "views": len(group)}
        for m in methods:
            row[f"CD-L1 {m} (mm)"] = group[f"cd_l1_{m}_mm"].mean()
        for m in methods:
            row[f"CD-L2 {m} (mm2)"] = group[f"cd_l2_{m}_mm2"].mean()
        for m in methods[1:]:
            row[f"CD-L1 {m} vs partial (%)"] = (row[f"CD-L1 {m} (mm)"]
                                                / row["CD-L1 partial (mm)"] - 1) * 100
        row["network s / cloud"] = group["network_s"].mean()
        row["mirror s / cloud"] = group["mirror_s"].mean()
        rows.append(row)
    return pd.DataFrame(rows)


def completion_examples(checkpoint: Path, names: list[str], quick: bool
                        ) -> dict[str, dict[str, np.ndarray]]:
    """For the first test view of each named shape or item: its partial cloud, the mirror
    baseline, the completed cloud as the pipeline makes it and the complete surface samples
    (metres)."""
    from volec.completion.complete import complete_cloud
    from volec.completion.data import TABLE_UP
    from volec.completion.mirror import mirror_complete
    from volec.completion.train import load_checkpoint
    from volec.pointcloud import PointCloud

    model, _ = load_checkpoint(checkpoint)
    chosen = {v["name"]: v for v in completion_test_views(quick) if v["view"] == 0}
    missing = [n for n in names if n not in chosen]
    if missing:
        raise UnknownNameError(f"not in the test views: {', '.join(missing)}")
    out = {}
    for name in names:
        partial = chosen[name]["partial"]
        done = complete_cloud(PointCloud(partial), model, pipeline_completion(), TABLE_UP)
        out[name] = {"partial": partial,
                     "mirror": mirror_complete(partial, up=TABLE_UP),
                     "network": done.cloud.xyz, "complete": chosen[name]["complete"]}
    return out


# ----------------------------------------------------------------------------- volume


def _limited(function: Callable[..., dict[str, Any]], job: tuple, threads: int
             ) -> dict[str, Any]:
    """``function(*job)`` in a worker whose libraries use at most ``threads`` threads."""
    from volec.batch import limit_threads

    limit_threads(threads)
    return function(*job)


def map_items(function: Callable[..., dict[str, Any]], jobs: list[tuple], labels: list[str],
              workers: int = 1, progress: bool = True) -> list[dict[str, Any]]:
    """``[function(*job) for job in jobs]``, on a local Dask cluster of ``workers`` processes
    when above 1 (the mechanism of ``volec batch``).

    Most stages use one or two cores for much of their time (rendering, OpenCV SIFT,
    bundle adjustment), so on a 2-core machine two items at once finish sooner than one
    after the other. ``function`` must be importable and ``jobs`` picklable; a script that
    calls this with ``workers > 1`` needs the ``if __name__ == "__main__":`` guard (notebooks
    do not). Results come back in the order of ``jobs``.
    """
    if workers <= 1 or len(jobs) <= 1:
        rows = []
        for n, (job, label) in enumerate(zip(jobs, labels, strict=True)):
            step(progress, f"[{n + 1}/{len(jobs)}] {label}")
            rows.append(function(*job))
        return rows
    import os

    from dask.distributed import as_completed

    from volec.batch import local_cluster

    threads = max(1, (os.cpu_count() or 1) // workers)
    client, cluster = local_cluster(workers)
    try:
        futures = {client.submit(_limited, function, job, threads, pure=False): n
                   for n, job in enumerate(jobs)}
        rows: list[dict[str, Any] | None] = [None] * len(jobs)
        for done, future in enumerate(as_completed(futures), start=1):
            n = futures[future]
            rows[n] = future.result()
            step(progress, f"[{done}/{len(jobs)}] {labels[n]} done")
    finally:
        client.close()
        cluster.close()
    return rows  # type: ignore[return-value]


VOLUME_CACHE = "volume_eval.json"


def on_off_arguments(description: str, example: str, default_scenarios: list[str]
                     ) -> argparse.Namespace:
    """The command line of a benchmark that makes the default with a part of it on and off on
    one basis per item: ``--scenarios``, ``--items``, ``--workers`` and ``--set`` (``example``
    shows one)."""
    from volec.synth import item_names

    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--scenarios", nargs="+", default=default_scenarios)
    parser.add_argument("--items", nargs="+", default=item_names())
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.FIELD=VALUE",
                        help=f"change a setting of the default, e.g. {example}")
    return parser.parse_args()


def on_off_table(row: Callable[..., dict[str, Any]], scenario_name: str,
                 args: argparse.Namespace, stem: str) -> pd.DataFrame:
    """``row(item, scenario_name, settings)`` for every item of ``args`` (on its workers), as
    one table, written to figures/STEM_SCENARIO.{csv,md}."""
    from volec.paths import figures_dir
    from volec.tables import write_table

    jobs = [(item, scenario_name, tuple(args.set)) for item in args.items]
    raw = pd.DataFrame(map_items(row, jobs, [f"{i} {scenario_name}" for i, _, _ in jobs],
                                 args.workers, progress=True))
    write_table(raw, figures_dir() / f"{stem}_{scenario_name}", float_digits=2)
    return raw


def paired_errors(without_pct: pd.Series, with_pct: pd.Series) -> dict[str, float | None]:
    """Both MAPEs, both mean signed errors (%) and the paired t-test's p of the absolute errors
    (None with one item or none changed) of the same items without and with a change."""
    from scipy.stats import ttest_rel

    before, after = without_pct.abs(), with_pct.abs()
    changed = len(before) > 1 and bool((after != before).any())
    return {"mape_without": float(before.mean()), "mape_with": float(after.mean()),
            "p": float(ttest_rel(after, before).pvalue) if changed else None,
            "mean_without": float(without_pct.mean()), "mean_with": float(with_pct.mean())}


def method_variants(cfg: EstimateConfig, model: Any) -> dict[str, tuple[EstimateConfig, Any]]:
    """Per method of :data:`METHODS`, its config (``cfg`` with that completion) and the network
    it needs (``model``, or None): no completion, mirror, rotation, network, and ``cfg``'s own
    completion, the default."""
    return {"no_completion": (replace(cfg, use_completion=False), None),
            "mirror": (replace(cfg, use_completion=True, completion_method="mirror"), None),
            "rotation": (replace(cfg, use_completion=True, completion_method="rotation"), None),
            "network": (replace(cfg, use_completion=True, completion_method="network"), model),
            "completion": (replace(cfg, use_completion=True), model)}


def volume_row(root: Path, item: str, scenario: Scenario, cfg: EstimateConfig,
               key: dict[str, Any], workers: int = 1) -> dict[str, Any]:
    """One item of :func:`volume_experiment`, computed and cached under ``key``; ``workers``
    (how many items ran at once, sharing the cores) is recorded with the times.

    The estimate is :func:`volec.estimate.estimate_from_stages`, exactly what ``volec estimate``
    runs (its basis made once, the rest per method), once per method of :data:`METHODS` on the
    same stage results (no completion, mirror,
    rotation and network completion, and ``cfg``'s own completion, the default; the visual
    hull from the AR poses beside them); the ground truth is read only to score it."""

    from volec.estimate import (
        estimate_basis,
        estimate_from_basis,
        food_silhouettes,
        load_completion_model,
    )
    from volec.meshing import with_normals
    from volec.pointcloud import write_ply
    from volec.scale import require_metric
    from volec.synth import load_truth

    out = ensure_capture(root, item, scenario)
    work = scenario.work(out)

    def run() -> dict[str, Any]:
        model = load_completion_model(cfg)
        capture = scenario_capture(out, scenario)
        scale = require_metric(capture, cfg.scale)
        try:
            stages = run_stages(capture, work, cfg.sfm, cfg.dense, cfg.masking,
                                stale="recompute", progress=False)
        except VolecError as e:  # recorded as the item's result, as `volec batch` does
            return {"item": item, "label": load_truth(out)["label"], "scenario": scenario.name,
                    "frames": len(capture),
                    "gt_ml": float(load_ground_truth_mesh(out).volume * 1e6),
                    "error": f"{type(e).__name__}: {e}"}
        sfm, dense, masked = stages.sfm, stages.dense, stages.masked
        start = time.perf_counter()
        silhouettes = food_silhouettes(capture, stages, cfg)
        silhouettes_s = time.perf_counter() - start
        truth_mesh = load_ground_truth_mesh(out)  # scoring only, after the estimate's inputs
        truth_points = sample_surface(truth_mesh, 20000, seed=0)
        masked_signed = signed_distances_to_surface(masked.cloud.xyz, truth_mesh)
        row: dict[str, Any] = {
            "item": item, "label": load_truth(out)["label"], "scenario": scenario.name,
            "frames": len(capture), "registered": int(sfm.registered.sum()),
            "gt_ml": float(truth_mesh.volume * 1e6), "workers": workers,
            "sfm_s": float(sum(sfm.summary["timings_s"].values())),
            "dense_s": float(sum(dense.summary["timings_s"].values())),
            "masking_s": masked.report.get("seconds", np.nan),
            "silhouettes_s": silhouettes_s,
            **signed_summary(masked_signed, "masked"),
        }
        variants = method_variants(cfg, model)
        # the methods differ only in completion: one basis (carving views, plane, space)
        basis = estimate_basis(capture, stages, cfg, silhouettes)
        for tag, (variant, net) in variants.items():
            est = estimate_from_basis(capture, stages, net, variant, basis, scale)
            made = est.food
            write_bytes_atomic(work / f"mesh_{tag}.ply", made.mesh.mesh.export(file_type="ply"))
            if tag == DEFAULT_METHOD:  # the cloud the default meshed
                write_ply(with_normals(made.cloud), work / "food_completed.ply")
            row |= {f"{tag}_ml": made.volume_ml,
                    **_mesh_scores(made.mesh.mesh, truth_points, tag),
                    f"{tag}_cloud_chamfer_mm":
                        1000 * chamfer_distance(made.cloud.xyz, truth_points)[0],
                    f"{tag}_support_found": made.support is not None,
                    f"{tag}_carved_fraction": made.mesh.report.get("carved_fraction", 0.0),
                    f"{tag}_trusted": est.trusted,
                    f"{tag}_reasons": ",".join(r.code for r in est.reasons),
                    f"{tag}_warnings": len(est.warnings),
                    f"{tag}_completion_share": made.completion_share,
                    f"{tag}_measured_surface_share": made.measured_surface_share,
                    f"{tag}_low_ml": est.bounds.low_ml, f"{tag}_high_ml": est.bounds.high_ml,
                    f"{tag}_interval_low_ml": est.volume_interval_ml[0],
                    f"{tag}_interval_high_ml": est.volume_interval_ml[1],
                    f"{tag}_unknown_share": est.bounds.unknown_share,
                    **mesh_offset_scores(made.mesh.mesh, truth_mesh, prefix=f"{tag}_mesh"),
                    **{f"{tag}_{k}": v for k, v in made.seconds.items()}}
        row["scale_std_pct"] = 100 * est.scale_std  # the same for every method
        row |= _ar_visual_hull_scores(capture, stages, cfg, basis.support[0], truth_points,
                                      silhouettes)
        return row

    return cached_row(work / VOLUME_CACHE, key, run)


def _mesh_scores(mesh: Any, truth_points: np.ndarray, tag: str) -> dict[str, float]:
    """The mesh's Chamfer-L1 distance to the true surface (mm), under ``TAG_chamfer_mm``."""
    mesh_points = sample_surface(mesh, 20000, seed=0)
    return {f"{tag}_chamfer_mm": 1000 * chamfer_distance(mesh_points, truth_points)[0]}


def _ar_visual_hull_scores(capture: Capture, stages: Any, cfg: EstimateConfig,
                           support: Any, truth_points: np.ndarray,
                           silhouettes: list[Any] | None) -> dict[str, Any]:
    """The visual hull of the food masks from the AR poses alone (no SfM, no depth), above
    the support plane the pipeline found: its volume and Chamfer distance (``visual_hull_*``).
    The estimate's ``silhouettes`` (the same masks, seen from the refined poses) lend their
    signed distances."""
    from volec.masking import usable_masks
    from volec.meshing import silhouette_views
    from volec.space import visual_hull_mesh
    from volec.volume import volume_ml

    start = time.perf_counter()
    use = usable_masks(stages.masks, stages.masked.report["unusable_masks"])
    ar_poses = np.stack([f.T_world_from_cam for f in capture.frames])
    views = silhouette_views(capture, stages.masks, ar_poses, use,
                             cfg.meshing.silhouette_max_views, known=silhouettes or ())
    hull = visual_hull_mesh(stages.masked.cloud, views, support, cfg.space)
    return {"visual_hull_ml": volume_ml(hull), **_mesh_scores(hull, truth_points, "visual_hull"),
            "visual_hull_s": time.perf_counter() - start}


def volume_experiment(root: Path, items: list[str], scenario: Scenario,
                      cfg: EstimateConfig | None = None, progress: bool = True,
                      workers: int = 1) -> pd.DataFrame:
    """The whole pipeline per item, with and without completion, scored against the truth.

    SfM, dense and masking run (or are reused) in ``ROOT/ITEM-SCENARIO/work``, as in
    :func:`dense_experiment`; both meshes are saved there (``mesh_completion.ply``,
    ``mesh_no_completion.ply``, ``food_completed.ply``). A row has the true and estimated
    volumes, whether each estimate is trusted (and the reasons' codes), the Chamfer distance of
    each mesh to the true surface, and each stage's wall time (SfM and dense from their stage
    records, measured when they ran). Cached per item in ``volume_eval.json``, keyed by the
    config, the checkpoint's digest and the code (:func:`row_key`); items not cached run on
    ``workers`` processes (:func:`map_items`).
    """
    from volec.estimate import EstimateConfig, checkpoint_path

    cfg = cfg or EstimateConfig()
    key = row_key(config_record(cfg), "volec.estimate", "volec.metrics",
                  checkpoint=file_digest(checkpoint_path(cfg)))
    rows = {item: _cached(scenario.work(scenario.folder(root, item)) / VOLUME_CACHE, key)
            for item in items}
    todo = [item for item in items if rows[item] is None]
    computed = map_items(volume_row, [(root, item, scenario, cfg, key, workers)
                                      for item in todo],
                         todo, workers, progress)
    rows.update(zip(todo, computed, strict=True))
    return pd.DataFrame([rows[item] for item in items])


# ----------------------------------------------------------------------------- segmentation

SEGMENT_CACHE = "segment_eval.json"


def boundary_f_score(predicted: np.ndarray, exact: np.ndarray, tolerance_px: float = 2.0
                     ) -> float:
    """The boundary F-score of a mask: the harmonic mean of the share of its boundary pixels
    within ``tolerance_px`` of the exact boundary (precision) and the share of the exact
    boundary within that of its own (recall)."""
    from scipy import ndimage

    def edge(m: np.ndarray) -> np.ndarray:
        return m & ~ndimage.binary_erosion(m)

    a, b = edge(predicted), edge(exact)
    if not a.any() or not b.any():
        return float(a.any() == b.any())
    near_b = ndimage.distance_transform_edt(~b) <= tolerance_px
    near_a = ndimage.distance_transform_edt(~a) <= tolerance_px
    precision, recall = (a & near_b).sum() / a.sum(), (b & near_a).sum() / b.sum()
    return float(2 * precision * recall / max(precision + recall, 1e-12))


def mask_iou(predicted: np.ndarray, exact: np.ndarray) -> float:
    """Intersection over union of two masks (1 when both are empty)."""
    union = np.logical_or(predicted, exact).sum()
    return float(np.logical_and(predicted, exact).sum() / union) if union else 1.0


def exact_masks(out: Path, capture: Any) -> list[np.ndarray]:
    """The exact food masks of a synthetic capture (ground truth; for scoring only)."""
    from PIL import Image

    return [np.asarray(Image.open(out / "ground_truth" / "masks" / (Path(f.name).stem + ".png"))
                       .convert("L")) > 127 for f in capture.frames]


def noisy_mask_set(out: Path, capture: Any) -> Any:
    """The masks a real segmenter might give for a synthetic capture (its
    ``ground_truth/masks_noisy``, :mod:`volec.synth.masknoise`), as a MaskSet."""
    from PIL import Image

    from volec.segment import MaskSet

    masks = tuple(np.asarray(Image.open(out / "ground_truth" / "masks_noisy"
                                        / (Path(f.name).stem + ".png")).convert("L")) > 127
                  for f in capture.frames)
    return MaskSet(tuple(f.name for f in capture.frames), masks, "noisy",
                   tuple(1.0 for _ in masks))


def _volume_with_masks(out: Path, capture: Any, masks: Any, folder: str, cfg: EstimateConfig,
                       model: Any) -> float:
    """The default estimate's volume (completion on) with ``masks`` handed in, its stages in
    ``ITEM/folder`` (the SfM stage copied from ``work``, where it is reused)."""
    import shutil

    from volec.estimate import estimate_from_stages, food_silhouettes

    work = out / folder
    if not (work / "sfm").exists() and (out / "work" / "sfm").exists():
        shutil.copytree(out / "work" / "sfm", work / "sfm")
    stages = run_stages(capture, work, cfg.sfm, cfg.dense, cfg.masking, stale="recompute",
                        progress=False, masks=masks)
    est = estimate_from_stages(capture, stages, model, cfg, food_silhouettes(capture, stages, cfg))
    return est.food.volume_ml


def segmentation_row(root: Path, item: str, scenario: Scenario, cfg: EstimateConfig,
                     volumes: bool, key: dict[str, Any]) -> dict[str, Any]:
    """One item of :func:`segmentation_experiment`, computed and cached under ``key``."""
    from volec.estimate import PRESETS, load_completion_model
    from volec.pipeline import run_segment_stage
    from volec.synth import load_truth

    out = ensure_capture(root, item, scenario)

    def run() -> dict[str, Any]:
        capture = read_transforms_json(out / "capture")
        sfm, _ = run_sfm_stage(capture, out / "work", cfg.sfm, stale="recompute")
        start = time.perf_counter()
        masks, _ = run_segment_stage(capture, sfm, out / "work", cfg.segment, stale="recompute",
                                     progress=False)
        # the time the segmentation took when it made these masks: a reused stage's own
        # record, not the seconds it took to load it
        seconds = masks.summary.get("seconds", {}).get("total_s", time.perf_counter() - start)
        exact = exact_masks(out, capture)
        iou = np.array([mask_iou(m, e) for m, e in zip(masks.masks, exact, strict=True)])
        bf = np.array([boundary_f_score(m, e) for m, e in zip(masks.masks, exact, strict=True)])
        noisy = noisy_mask_set(out, capture)
        noisy_iou = [mask_iou(m, e) for m, e in zip(noisy.masks, exact, strict=True)]
        worst = np.argsort(iou)[:3]
        truth = load_truth(out)
        row: dict[str, Any] = {
            "item": item, "scenario": scenario.name, "setup": _setup_name(item, scenario),
            "frames": len(capture), "gt_ml": float(truth["volume_ml"]),
            "iou_median": float(np.median(iou)), "iou_p10": float(np.percentile(iou, 10)),
            "iou_min": float(iou.min()), "bf_median": float(np.median(bf)),
            "bf_min": float(bf.min()), "noisy_iou_median": float(np.median(noisy_iou)),
            "segment_s": seconds, "frames_listed": len(masks.failed),
            "worst_frames": [capture.frames[i].name for i in worst],
            "worst_iou": [float(iou[i]) for i in worst]}
        if volumes:
            model = load_completion_model(cfg)
            row["auto_ml"] = _volume_with_masks(out, capture, masks, "work-auto", cfg, model)
            # imperfect masks get the settings volec documents for them (the tolerant_masks
            # preset's masking, carving and underside), the rest of the experiment's config
            # unchanged
            tolerant = PRESETS["tolerant_masks"]
            noisy_cfg = replace(
                cfg, masking=tolerant.masking, underside=tolerant.underside,
                meshing=replace(
                    cfg.meshing, silhouette_min_views=tolerant.meshing.silhouette_min_views,
                    silhouette_min_share=tolerant.meshing.silhouette_min_share,
                    silhouette_margin_px=tolerant.meshing.silhouette_margin_px))
            row["noisy_ml"] = _volume_with_masks(out, capture, noisy, "work-noisy", noisy_cfg,
                                                 model)
        return row

    return cached_row(out / "work" / SEGMENT_CACHE, key, run)


def _setup_name(item: str, scenario: Scenario) -> str:
    from volec.synth.scene import hard_setup

    return hard_setup(item)[0] if scenario.synth.setup == "hard" else scenario.synth.setup


def segmentation_experiment(root: Path, items: list[str], scenario: Scenario,
                            volumes: bool = True, cfg: EstimateConfig | None = None,
                            workers: int = 1, progress: bool = True) -> pd.DataFrame:
    """Automatic masks per item against the exact ones (IoU and boundary F-score per frame:
    median, 10th percentile, worst), their time, the worst frames; with ``volumes``, the
    default estimate's volume with the automatic masks, and with the noisy masks a real
    segmenter might give (:mod:`volec.synth.masknoise`) under the masking and carving of the
    ``tolerant_masks`` preset, which volec documents for imperfect masks. Cached per item in
    ``segment_eval.json``, keyed like :func:`volume_experiment`."""
    from volec.estimate import EstimateConfig, checkpoint_path

    cfg = cfg or EstimateConfig()
    key = row_key({**config_record(cfg), "volumes": volumes}, "volec.estimate",
                  "volec.metrics", "volec.synth.generate",
                  checkpoint=file_digest(checkpoint_path(cfg)))
    rows = {item: _cached(root / f"{item}-{scenario.name}" / "work" / SEGMENT_CACHE, key)
            for item in items}
    todo = [item for item in items if rows[item] is None]
    computed = map_items(segmentation_row, [(root, item, scenario, cfg, volumes, key)
                                            for item in todo], todo, workers, progress)
    rows.update(zip(todo, computed, strict=True))
    return pd.DataFrame([rows[item] for item in items])


def segmentation_table(raw: pd.DataFrame) -> pd.DataFrame:
    """Per item: the setup, IoU (median, 10th percentile, worst) and boundary F-score of the
    automatic masks, the noisy masks' median IoU, the segmentation's time; with volumes, the
    volume error with automatic and with noisy masks (percent); then the medians and means."""
    cols = ["item", "setup", "iou_median", "iou_p10", "iou_min", "bf_median",
            "noisy_iou_median", "segment_s"]
    table = raw[cols].copy()
    for tag in ("auto", "noisy"):
        if f"{tag}_ml" in raw:
            table[f"{tag}_error_pct"] = 100 * (raw[f"{tag}_ml"] / raw["gt_ml"] - 1)
    numeric = table.columns.drop(["item", "setup"])
    median = table[numeric].median().to_frame().T
    median.insert(0, "setup", "")
    median.insert(0, "item", "median")
    mean = table[numeric].abs().mean().to_frame().T
    mean.insert(0, "setup", "")
    mean.insert(0, "item", "mean abs")
    return pd.concat([table, median, mean], ignore_index=True)


def worst_frames(root: Path, raw: pd.DataFrame, scenario: Scenario, n: int = 6
                 ) -> tuple[list[np.ndarray], list[str]]:
    """The ``n`` frames with the lowest IoU over the items of ``raw``, as pictures (the
    image, the automatic mask's outline green, the exact one's red) with titles."""
    from scipy import ndimage

    from volec.segment import load_masks

    candidates = [(iou, item, name) for _, r in raw.iterrows()
                  for name, iou in zip(r["worst_frames"], r["worst_iou"], strict=True)
                  for item in [r["item"]]]
    images, titles = [], []
    for iou, item, name in sorted(candidates)[:n]:
        out = ensure_capture(root, item, scenario)
        capture = read_transforms_json(out / "capture")
        index = [f.name for f in capture.frames].index(name)
        masks = load_masks(out / "work")
        from PIL import Image

        rgb = np.asarray(Image.open(capture.frames[index].image_path).convert("RGB")).copy()
        auto, exact = masks.mask(index), exact_masks(out, capture)[index]
        rgb[exact & ~ndimage.binary_erosion(exact, iterations=2)] = (230, 30, 30)
        rgb[auto & ~ndimage.binary_erosion(auto, iterations=2)] = (40, 220, 40)
        images.append(rgb)
        titles.append(f"{item} {Path(name).stem}: IoU {iou:.3f}")
    return images, titles


ATTRIBUTION_CACHE = "attribution_eval.json"

#: The attribution experiment's variants, from the pipeline to exact depth.
ATTRIBUTION_VARIANTS = {
    "pipeline": "SfM poses, stereo at 512 px (what volec estimate does)",
    "exact_poses": "exact poses, stereo at 512 px",
    "exact_poses_full_res": "exact poses, stereo at the full 640 px",
    "exact_depth": "exact poses, the renderer's depth maps at 512 px, the same fusion",
}


def _with_exact_poses(stages: Any, exact: Any) -> Any:
    """The stage results with the SfM poses replaced by the exact ones, every frame
    registered (for the attribution experiment only)."""

    sfm = replace(stages.sfm, T_world_from_cam=np.stack([f.T_world_from_cam for f in exact.frames]),
                  registered=np.ones(len(exact), bool))
    return replace(stages, sfm=sfm)


def _exact_depth_cloud(capture: Any, masks: Any, sfm: Any, item: str, scenario: Scenario,
                       cfg: DenseConfig) -> Any:
    """The scene cloud that the dense stage's fusion makes from the renderer's exact depth
    maps (at the working resolution, inside the same regions of interest)."""
    from volec.dense import DenseResult, DepthMap, fuse_depth_maps, plan_dense
    from volec.synth.generate import ExactDepth

    plan = plan_dense(capture, masks, sfm.T_world_from_cam, sfm.registered, sfm.points_xyz, cfg)
    exact_depth = ExactDepth(item, scenario.synth)
    maps = {}
    for r in plan.references:
        view = plan.views[r]
        h, w = view.gray.shape
        depth = exact_depth(view.K, w, h, np.linalg.inv(view.T_cam_from_world))
        depth = np.where(np.isfinite(depth) & view.roi, depth, 0.0).astype(np.float32)
        maps[r] = DepthMap(depth, np.where(depth > 0, 1.0, -1.0).astype(np.float32),
                           plan.sources[r])
    cloud, estimated, consistent = fuse_depth_maps(plan, maps, cfg)
    return DenseResult(cloud, {"depths_estimated": estimated, "depths_consistent": consistent})


def attribution_row(root: Path, item: str, scenario: Scenario, cfg: EstimateConfig,
                    key: dict[str, Any]) -> dict[str, Any]:
    """One item of :func:`attribution_experiment`, computed and cached under ``key``."""

    from volec.estimate import (
        estimate_basis,
        estimate_from_basis,
        food_silhouettes,
        load_completion_model,
    )

    out = ensure_capture(root, item, scenario)

    def run() -> dict[str, Any]:
        capture = read_transforms_json(out / "capture")
        exact = read_transforms_json(out / "ground_truth" / "transforms_exact.json",
                                     check_image_sizes=False)
        truth = load_ground_truth_mesh(out)
        model = load_completion_model(cfg)
        stages = run_stages(capture, out / "work", cfg.sfm, cfg.dense, cfg.masking,
                            stale="recompute", progress=False)
        exact_stages = _with_exact_poses(stages, exact)
        sfm = exact_stages.sfm
        full_res = replace(cfg.dense, max_image_size_px=max(capture.frames[0].intrinsics.width,
                                                            capture.frames[0].intrinsics.height))
        masks = stages.masks
        scenes = {
            "exact_poses": lambda: run_dense(capture, masks, sfm.T_world_from_cam,
                                             sfm.registered, sfm.points_xyz, cfg.dense,
                                             progress=False),
            "exact_poses_full_res": lambda: run_dense(capture, masks, sfm.T_world_from_cam,
                                                      sfm.registered, sfm.points_xyz, full_res,
                                                      progress=False),
            "exact_depth": lambda: _exact_depth_cloud(capture, masks, sfm, item, scenario,
                                                      cfg.dense),
        }
        row: dict[str, Any] = {"item": item, "gt_ml": float(truth.volume * 1e6)}
        for variant in ATTRIBUTION_VARIANTS:
            if variant == "pipeline":
                these = stages
            else:
                dense = scenes[variant]()
                masked = mask_cloud(dense.cloud, capture, masks, sfm.T_world_from_cam,
                                    sfm.registered, cfg.masking)
                these = replace(exact_stages, dense=dense, masked=masked)
            basis = estimate_basis(capture, these, cfg, food_silhouettes(capture, these, cfg))
            est = estimate_from_basis(capture, these, model, cfg, basis)
            # the same without completion: the network's points are not part of the surface
            # offset that stereo, fusion and meshing make, and can hide or add to it
            bare = estimate_from_basis(capture, these, None, replace(cfg, use_completion=False),
                                       basis)
            signed = signed_distances_to_surface(these.masked.cloud.xyz, truth)
            row |= {f"{variant}_ml": est.food.volume_ml,
                    f"{variant}_error_pct": 100 * (est.food.volume_ml / row["gt_ml"] - 1),
                    f"{variant}_no_completion_error_pct":
                        100 * (bare.food.volume_ml / row["gt_ml"] - 1),
                    **signed_summary(signed, f"{variant}_cloud"),
                    **mesh_offset_scores(est.food.mesh.mesh, truth, prefix=f"{variant}_mesh"),
                    **mesh_offset_scores(bare.food.mesh.mesh, truth,
                                         prefix=f"{variant}_no_completion_mesh")}
        return row

    return cached_row(out / "work" / ATTRIBUTION_CACHE, key, run)


def attribution_experiment(root: Path, items: list[str], scenario: Scenario,
                           cfg: EstimateConfig | None = None, workers: int = 1,
                           progress: bool = True) -> pd.DataFrame:
    """Where the surface offset comes from: per item, the masked cloud's and the mesh's signed
    distances to the true surface and the volume error, for each of
    :data:`ATTRIBUTION_VARIANTS` (SfM poses; exact poses; exact poses at full resolution;
    exact depth through the same fusion, masking and meshing), each with the default
    completion and without completion (``*_no_completion_*``). The stages of the pipeline
    variant are reused from the volume experiment. Cached per item in
    ``attribution_eval.json``, keyed like :func:`volume_experiment`."""
    from volec.estimate import EstimateConfig, checkpoint_path

    cfg = cfg or EstimateConfig()
    key = row_key(config_record(cfg), "volec.estimate", "volec.metrics", "volec.synth.generate",
                  checkpoint=file_digest(checkpoint_path(cfg)))
    rows = {item: _cached(root / f"{item}-{scenario.name}" / "work" / ATTRIBUTION_CACHE, key)
            for item in items}
    todo = [item for item in items if rows[item] is None]
    computed = map_items(attribution_row, [(root, item, scenario, cfg, key) for item in todo],
                         todo, workers, progress)
    rows.update(zip(todo, computed, strict=True))
    return pd.DataFrame([rows[item] for item in items])


def attribution_table(raw: pd.DataFrame) -> pd.DataFrame:
    """One row per (item, variant): the cloud's and the mesh's median signed distance (mm),
    the mesh's p10-p90 band, the volume its offset implies and the volume error (percent);
    without completion, the mesh's p90 and the volume error; then the mean per variant."""
    rows = []
    for _, r in raw.iterrows():
        for variant, what in ATTRIBUTION_VARIANTS.items():
            rows.append({
                "item": r["item"], "variant": variant, "what": what,
                "cloud_signed_median_mm": 1000 * r[f"{variant}_cloud_signed_median_m"],
                "mesh_signed_median_mm": 1000 * r[f"{variant}_mesh_signed_median_m"],
                "mesh_signed_p10_mm": 1000 * r[f"{variant}_mesh_signed_p10_m"],
                "mesh_signed_p90_mm": 1000 * r[f"{variant}_mesh_signed_p90_m"],
                "aligned_mesh_signed_median_mm": 1000 * r[
                    f"{variant}_mesh_aligned_signed_median_m"],
                "mesh_offset_implies_pct": r[f"{variant}_mesh_offset_pct"],
                "volume_error_pct": r[f"{variant}_error_pct"],
                "no_completion_mesh_signed_p90_mm": 1000 * r[
                    f"{variant}_no_completion_mesh_signed_p90_m"],
                "no_completion_volume_error_pct": r[f"{variant}_no_completion_error_pct"]})
    table = pd.DataFrame(rows)
    numeric = table.columns.drop(["item", "variant", "what"])
    means = table.groupby(["variant", "what"], sort=False)[numeric].mean().reset_index()
    means.insert(0, "item", "mean")
    return pd.concat([table, means], ignore_index=True)


def _ape(raw: pd.DataFrame, tag: str) -> pd.Series:
    """Absolute percentage error of the ``TAG_ml`` volumes against ``gt_ml``."""
    return 100 * (raw[f"{tag}_ml"] - raw["gt_ml"]).abs() / raw["gt_ml"]


def _failed(raw: pd.DataFrame) -> pd.Series:
    """Which rows are items whose pipeline failed (an ``error`` recorded instead of volumes)."""
    return raw["error"].notna() if "error" in raw else pd.Series(False, index=raw.index)


def volume_table(raw: pd.DataFrame, masks: pd.DataFrame | None = None) -> pd.DataFrame:
    """The paper's Table I: per item the true volume, the estimate without completion (the
    VolE-style baseline) and with it, their absolute percentage errors and accuracy
    (100 - APE), and whether volec trusted the estimate with completion (the default); with
    ``masks`` (:func:`segmentation_experiment` on the same items), the default estimate with
    automatic masks and with noisy ones; then the means (MAPE, mean accuracy, and the share
    of estimates trusted). An item whose pipeline failed (an ``error`` in its row) has no
    volumes and ``failed`` 1; the means are over the others, and the mean of ``failed`` is
    the share that failed."""
    table = pd.DataFrame({"item": raw["label"], "gt_ml": raw["gt_ml"]})
    failed = _failed(raw)
    for tag, name in (("no_completion", "without"), ("completion", "with")):
        ape = _ape(raw, tag)
        table[f"{name}_ml"] = raw[f"{tag}_ml"]
        table[f"{name}_ape_pct"] = ape
        table[f"{name}_accuracy_pct"] = 100 - ape
    table["with_trusted"] = raw["completion_trusted"].astype(float)
    if failed.any():
        table["failed"] = failed.astype(float)
    if masks is not None:
        by_item = masks.set_index("item").reindex(raw["item"])
        for tag in ("auto", "noisy"):
            values = by_item[f"{tag}_ml"].to_numpy()
            table[f"{tag}_masks_ml"] = values
            table[f"{tag}_masks_ape_pct"] = 100 * np.abs(values - raw["gt_ml"]) / raw["gt_ml"]
    means = table.drop(columns="item").mean().to_frame().T
    means.insert(0, "item", "mean")
    return pd.concat([table, means], ignore_index=True)


def pose_scale_errors(root: Path, items: list[str], scenario: Scenario) -> pd.Series:
    """Per item of :func:`volume_experiment` (indexed by item name), the error of the metric
    scale its SfM stage took from the AR poses, percent: :func:`volec.sfm.evaluate_sfm`
    against the exact poses of the same frames (for scoring only). Every length of the
    estimate carries it, and its volume three times over."""
    errors = {}
    for item in items:
        folder = ensure_capture(root, item, scenario)
        try:
            sfm = load_sfm(scenario.work(folder))
        except FileNotFoundError:  # the item's SfM failed: its row says why
            errors[item] = float("nan")
            continue
        errors[item] = evaluate_sfm(sfm, scenario_capture(folder, scenario, exact=True),
                                    scenario_capture(folder, scenario))["scale_err_pct"]
    return pd.Series(errors, name="scale_err_pct", dtype=float)


def surface_offset_table(raw: pd.DataFrame, tag: str = "completion", *,
                         scale_err_pct: pd.Series | None = None) -> pd.DataFrame:
    """Per item, how far the masked cloud and the final mesh (of variant ``tag``) lie outside
    (+) or inside (-) the true surface, in mm (median, 10th and 90th percentile of signed
    distances), the volume the mesh's offset implies (mean signed distance times area, as a
    percentage of the true volume), how far the poses misplaced the mesh and its signed
    distances once rigidly aligned (the shape's own offset), beside the volume error; with
    the poses' scale errors (:func:`pose_scale_errors`, by item name), also those and the
    volume error the estimate would have at the exact scale (its volume divided by the cube
    of the scale's factor: what the shape alone gets wrong); then the means and the means of
    magnitudes."""
    table = pd.DataFrame({"item": raw["label"]})
    for source, prefix in (("cloud", "masked"), ("mesh", f"{tag}_mesh")):
        for stat in ("median", "p10", "p90"):
            table[f"{source}_signed_{stat}_mm"] = 1000 * raw[f"{prefix}_signed_{stat}_m"]
    table["mesh_offset_implies_pct"] = raw[f"{tag}_mesh_offset_pct"]
    table["mesh_misplacement_mm"] = 1000 * raw[f"{tag}_mesh_misplacement_m"]
    for stat in ("median", "p10", "p90"):
        table[f"aligned_mesh_signed_{stat}_mm"] = 1000 * raw[f"{tag}_mesh_aligned_signed_{stat}_m"]
    table["volume_error_pct"] = 100 * (raw[f"{tag}_ml"] / raw["gt_ml"] - 1)
    if scale_err_pct is not None:
        factor = 1 + raw["item"].map(scale_err_pct) / 100
        table["scale_err_pct"] = 100 * (factor - 1)
        table["volume_error_exact_scale_pct"] = 100 * (raw[f"{tag}_ml"] / raw["gt_ml"]
                                                       / factor ** 3 - 1)
    means = table.drop(columns="item").mean().to_frame().T
    means.insert(0, "item", "mean")
    abs_means = table.drop(columns="item").abs().mean().to_frame().T
    abs_means.insert(0, "item", "mean abs")
    return pd.concat([table, means, abs_means], ignore_index=True)


def bounds_summary(raw: pd.DataFrame, tag: str = "completion", *,
                   scale_err_pct: pd.Series | None = None) -> pd.DataFrame:
    """One row: how far the estimates of variant ``tag`` in ``raw`` (one scenario's
    :func:`volume_experiment`) can be trusted. The scenario; how many items ran, how many
    were trusted and how many of those were more than 2 % off; the mean share of the
    estimate in unknown space; on how many items the space's bounds (``volume_bounds_ml``)
    and the interval that adds the metric scale's uncertainty (``volume_interval_ml``) hold
    the true volume, and their mean widths (% of the truth); the scale's mean standard
    deviation (%); with the poses' scale errors (:func:`pose_scale_errors`, by item name),
    the root mean square of each error over its standard deviation (1 where the AR noise
    model is right) and on how many items it is within two of them."""
    ran = raw[~_failed(raw)]
    truth = ran["gt_ml"]
    trusted = ran[f"{tag}_trusted"].astype(bool)
    ape = 100 * (ran[f"{tag}_ml"] / truth - 1).abs()
    row: dict[str, Any] = {
        "scenario": raw["scenario"].iloc[0], "items": len(ran), "trusted": int(trusted.sum()),
        "trusted_over_2pct": int((trusted & (ape > 2)).sum()),
        "unknown_share_mean": ran[f"{tag}_unknown_share"].mean()}
    for name, (low, high) in {"bounds": ("low_ml", "high_ml"),
                              "interval": ("interval_low_ml", "interval_high_ml")}.items():
        lower, upper = ran[f"{tag}_{low}"], ran[f"{tag}_{high}"]
        row[f"{name}_hold"] = int(((lower <= truth) & (truth <= upper)).sum())
        row[f"{name}_width_pct"] = (100 * (upper - lower) / truth).mean()
    row["scale_std_pct_mean"] = ran["scale_std_pct"].mean()
    if scale_err_pct is not None:
        z = ran["item"].map(scale_err_pct) / ran["scale_std_pct"]
        row["scale_z_rms"] = float(np.sqrt((z**2).mean()))
        row["scale_within_2_std"] = int((z.abs() <= 2).sum())
    return pd.DataFrame([row])


def signed_surfaces(root: Path, items: list[str], scenario: Scenario, tag: str = "completion"
                    ) -> dict[str, tuple[Any, np.ndarray]]:
    """Per item of :func:`volume_experiment`, its final mesh (variant ``tag``) rigidly aligned
    to the truth (taking away the poses' misplacement, which moves the whole mesh and hides the
    shape's own pattern) and the signed distance of each of its vertices to the true surface
    (metres), for :func:`volec.viz.signed_distance_figure`."""
    import trimesh

    from volec.metrics import rigid_alignment

    out = {}
    for item in items:
        folder = ensure_capture(root, item, scenario)
        mesh = trimesh.load(folder / "work" / f"mesh_{tag}.ply")
        truth = load_ground_truth_mesh(folder)
        mesh.apply_transform(rigid_alignment(sample_surface(mesh, 20000, seed=0), truth))
        out[item] = (mesh, signed_distances_to_surface(np.asarray(mesh.vertices), truth))
    return out


def surface_bands(root: Path, items: list[str], scenario: Scenario, tag: str = "completion"
                  ) -> pd.DataFrame:
    """Per item of :func:`volume_experiment` and band of height above its lowest point
    (:func:`volec.metrics.height_band_offsets`): how much of the true surface the masked cloud
    covers there, and how far the final mesh (variant ``tag``) lies outside (+, mm) and what
    volume that implies (% of the truth); then each band's mean over the items."""
    import trimesh

    from volec.metrics import height_band_offsets
    from volec.pointcloud import read_ply
    from volec.synth import load_truth

    rows = []
    for item in items:
        folder = ensure_capture(root, item, scenario)
        work = scenario.work(folder)
        bands = height_band_offsets(trimesh.load(work / f"mesh_{tag}.ply"),
                                    load_ground_truth_mesh(folder),
                                    read_ply(work / "food_masked.ply").xyz,
                                    np.asarray(load_truth(folder)["world_up"], float))
        rows += [{"item": item, **band} for band in bands]
    table = pd.DataFrame(rows)
    table["mesh_signed_median_mm"] = 1000 * table.pop("mesh_signed_median_m")
    means = table.drop(columns="item").groupby(["band_low", "band_high"]).mean().reset_index()
    means.insert(0, "item", "mean")
    return pd.concat([table, means], ignore_index=True)


#: Table II's methods, as ``volume_row`` tags them, and how the table names them.
METHODS = {
    "visual_hull": "visual hull (AR poses)",
    "no_completion": "VolE-style (no completion)",
    "mirror": "mirror completion",
    "rotation": "rotation completion",
    "network": "network completion",
    "completion": "volec's default (rotation where symmetric, then network)",
}
DEFAULT_METHOD = "completion"


def method_table(raw: pd.DataFrame) -> pd.DataFrame:
    """The paper's Table II for one scenario: per item the true volume and, per method of
    :data:`METHODS`, the volume, its absolute percentage error and the mesh's Chamfer-L1
    distance to the true surface (mm); then the mean and the standard deviation over the items
    (items whose pipeline failed are left out of both)."""
    ok = raw[~_failed(raw)]
    table = pd.DataFrame({"item": ok["label"], "gt_ml": ok["gt_ml"]})
    for tag in METHODS:
        table[f"{tag}_ml"] = ok[f"{tag}_ml"]
        table[f"{tag}_ape_pct"] = _ape(ok, tag)
        table[f"{tag}_chamfer_mm"] = ok[f"{tag}_chamfer_mm"]
    numbers = table.drop(columns="item")
    summary = pd.DataFrame([numbers.mean(), numbers.std(ddof=1)])
    summary.insert(0, "item", ["mean", "std"])
    return pd.concat([table, summary], ignore_index=True)


def paired_tests(raw: pd.DataFrame, baseline: str = "no_completion",
                 method: str = DEFAULT_METHOD) -> pd.DataFrame:
    """The paper's Table III: paired t-tests of ``method`` against ``baseline`` (tags of
    :data:`METHODS`; by default with against without completion), of the absolute percentage
    volume errors and of the meshes' Chamfer distances to the truth. Items whose pipeline
    failed are left out."""
    from scipy.stats import ttest_rel

    ok = raw[~_failed(raw)]
    rows = []
    for measure, values in (("absolute volume error (%)", lambda t: _ape(ok, t)),
                            ("mesh Chamfer-L1 to the true surface (mm)",
                             lambda t: ok[f"{t}_chamfer_mm"])):
        a, b = values(baseline).to_numpy(float), values(method).to_numpy(float)
        test = ttest_rel(a, b) if len(a) > 1 else None
        rows.append({"measure": measure, "baseline": baseline, "method": method,
                     "items": len(a), "mean_without": a.mean(),
                     "mean_with": b.mean(), "mean_difference": (a - b).mean(),
                     "t": np.nan if test is None else float(test.statistic),
                     "p": np.nan if test is None else float(test.pvalue)})
    return pd.DataFrame(rows)


def method_tests(raws: dict[str, pd.DataFrame]) -> pd.DataFrame:
    """Table III over scenarios: per scenario (``raws``: name -> :func:`volume_experiment`
    rows), the default method against each other method of :data:`METHODS`, paired t-tests
    of volume error and Chamfer distance (``mean_without`` is the other method's mean,
    ``mean_with`` the default's; a positive ``mean_difference`` favours the default)."""
    tables = [paired_tests(raw, other, DEFAULT_METHOD).assign(scenario=name)
              for name, raw in raws.items() for other in METHODS if other != DEFAULT_METHOD]
    table = pd.concat(tables, ignore_index=True)
    return table[["scenario"] + [c for c in table.columns if c != "scenario"]]


def completion_clouds(root: Path, items: list[str], scenario: Scenario
                      ) -> dict[str, dict[str, np.ndarray]]:
    """Fig. 1: per item of :func:`volume_experiment` (run before), the observed (masked)
    cloud, the cloud the network completed, and the true surface, turned so that the
    capture's up is +z, for :func:`volec.viz.cloud_grid`."""
    from volec.geometry import horizontal_axes
    from volec.pointcloud import read_ply
    from volec.synth import load_truth

    out = {}
    for item in items:
        folder = ensure_capture(root, item, scenario)
        work = scenario.work(folder)
        side, other = horizontal_axes(np.asarray(load_truth(folder)["world_up"], float))
        up_to_z = np.stack([side, other, np.cross(side, other)])
        truth = sample_surface(load_ground_truth_mesh(folder), 20000, seed=0)
        out[item] = {"observed": read_ply(work / "food_masked.ply").xyz @ up_to_z.T,
                     "completed": read_ply(work / "food_completed.ply").xyz @ up_to_z.T,
                     "true surface": truth @ up_to_z.T}
    return out


def runtime_table(raw: pd.DataFrame) -> pd.DataFrame:
    """Wall time per stage (s) over the items (with completion): mean, median and max, and
    the end-to-end total. Items that ran two or more at once (``workers``) shared the cores,
    so their times are longer than a capture processed alone (``benchmarks/bench_estimate.py``
    measures that)."""
    stages = {"SfM": raw["sfm_s"], "dense stereo": raw["dense_s"],
              "masking": raw["masking_s"], "completion": raw["completion_completion_s"],
              "meshing + volume": raw["silhouettes_s"] + raw["completion_meshing_s"]}
    stages["total"] = sum(stages.values())
    return pd.DataFrame([{"stage": k, "mean_s": v.mean(), "median_s": v.median(),
                          "max_s": v.max()} for k, v in stages.items()])


def qualitative_panels(root: Path, item: str, scenario: Scenario) -> dict[str, Any]:
    """The paper's Fig. 3 for one item of :func:`volume_experiment`: masked cloud, completed
    cloud, mesh with completion, true surface (name -> cloud or mesh)."""
    import trimesh

    from volec.masking import load_masking
    from volec.pointcloud import PREDICTED_RGB, read_ply
    from volec.viz import Highlighted

    out = ensure_capture(root, item, scenario)
    work = scenario.work(out)
    masked = load_masking(work).cloud
    completed = read_ply(work / "food_completed.ply")  # masked, rim, then the prior's points
    predicted = (completed.xyz[len(masked):] if completed.rgb is None else
                 completed.xyz[np.all(completed.rgb == PREDICTED_RGB, axis=1)])
    return {"masked cloud": masked,
            "completed cloud": Highlighted(masked, predicted),
            "mesh (completion)": trimesh.load(work / "mesh_completion.ply"),
            "true surface": load_ground_truth_mesh(out)}
