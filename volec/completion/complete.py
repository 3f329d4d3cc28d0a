"""Completing a metric partial cloud with the trained network.

In: a :class:`~volec.pointcloud.PointCloud` of one food item (metres, any frame and
orientation), a trained model and a :class:`CompletionConfig`. Out: a :class:`Completion`:
the completed cloud in the input's frame (the partial's points plus the network's, which are
coloured magenta, :data:`volec.pointcloud.PREDICTED_RGB`), the network's points alone, and
the normalization used.

Steps (paper section III-C): normalize (centre, unit sphere, then the checkpoint's frame: the
paper's PCA axes, or upright about the support normal ``up``), resample to the network's
input size, predict, map back with the normalization's exact inverse, then drop
statistical outliers from the predicted points.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from volec.completion.model import SymmCompletion
from volec.completion.preprocess import (
    Normalization,
    fit_normalization,
    frame_normalization,
    remove_statistical_outliers,
    resample,
)
from volec.errors import ConfigError, VolecError
from volec.pointcloud import PREDICTED_RGB, PointCloud

if TYPE_CHECKING:
    from volec.space import SpaceGrid

#: The checkpoint shipped with volec (trained by ``make retrain``, preset ``cpu_upright``):
#: package data, found through importlib.resources wherever volec is installed.
SHIPPED_CHECKPOINT = Path(str(resources.files("volec.completion") / "weights"
                              / "symmcompletion_cpu.pt"))



@dataclass(frozen=True)
class CompletionConfig:
    """Options of the completion stage."""

    merge_partial: bool = True
    """The completed cloud is the partial plus the predicted points (else predicted only)."""
    missing_only_gap_m: float = 0.0
    """When merging, keep only predicted points farther than this (metres) from the partial:
    the network then only fills what was missing, and where the phone saw the surface the
    dense points (far more accurate than the network's) stand alone. 0 keeps every predicted
    point."""
    outlier_neighbours: int = 16
    """Statistical outlier removal on the predicted points: neighbours considered..."""
    outlier_std_ratio: float = 2.0
    """... and the standard deviations beyond which a point is dropped."""
    min_points: int = 64
    """Partial clouds with fewer points are refused."""
    seed: int = 0
    """Seeds the resampling of the partial to the network's input size."""
    resamplings: int = 1
    """How many times the partial is resampled to the network's input size and completed;
    the predictions are pooled and a random share of one prediction's size kept, so the
    meshing weighs them as it weighs one. Each resampling shows the network another subset
    of the partial, and its points under an item move with it: on the benchmark's full-orbit
    apple the network's volume was -0.58, -0.03, -1.78 and -0.23 % off with seeds 0-3, the
    orange's +0.44, -0.15, -0.18 and -0.53 %. With 4 the orange's spread went from 0.97 to
    0.11 points and the network alone gained a little on the benchmark (full orbits 1.41 ->
    1.32 %), but the default estimate did not (full 0.78 -> 0.80 %, sparse 1.07 -> 1.26 %;
    docs/measurements.md, Where the remaining error lies). 1: one prediction, the first of the
    seed's draws (the default)."""


@dataclass(eq=False)
class Completion:
    """A completed cloud and how it was made."""

    cloud: PointCloud
    """The completed cloud, metres, in the partial's frame."""
    predicted_xyz: np.ndarray
    """(M, 3) the network's points after outlier removal, metres, the partial's frame."""
    normalization: Normalization
    """The transform into the network's frame."""
    summary: dict[str, Any] = field(default_factory=dict)
    """Counts and timing."""


def complete_cloud(partial: PointCloud, model: SymmCompletion,
                   cfg: CompletionConfig | None = None, up: np.ndarray | None = None,
                   shown: PointCloud | None = None) -> Completion:
    """Complete ``partial`` with ``model`` (see the module docstring); ``up``, the support
    plane's normal, frames the input for a model trained upright (ignored otherwise). The
    network is shown the ``shown`` points beside ``partial`` (the rim points, say); its
    predictions are merged with ``partial`` alone."""
    cfg = cfg or CompletionConfig()
    seen = partial.xyz if shown is None else np.concatenate([partial.xyz, shown.xyz])
    _check_partial(PointCloud(seen), cfg)
    start = time.perf_counter()
    norm = frame_normalization(seen, model.cfg.input_frame, up)
    rng = np.random.default_rng(cfg.seed)
    runs = [_predict(model, norm.apply(resample(seen, model.cfg.n_input, rng)))
            for _ in range(cfg.resamplings)]
    out = np.concatenate(runs)
    if len(runs) > 1:  # pooled, then thinned to one prediction's size
        out = out[np.sort(rng.choice(len(out), len(runs[0]), replace=False))]
    predicted = remove_statistical_outliers(norm.invert(out), cfg.outlier_neighbours,
                                            cfg.outlier_std_ratio)
    return merged_completion(partial, predicted, norm, cfg, len(out), start)


def _predict(model: SymmCompletion, x: np.ndarray) -> np.ndarray:
    """The network's completion (M, 3) of one normalised partial ``x`` (n_input, 3)."""
    device = next(model.parameters()).device
    model.eval()
    with torch.no_grad():
        out = model(torch.from_numpy(x[None]).float().to(device))[-1][0].cpu().numpy()
    return out.astype(float)


def _check_partial(partial: PointCloud, cfg: CompletionConfig) -> None:
    if cfg.resamplings < 1:
        raise ConfigError(f"completion resamplings must be 1 or more, not {cfg.resamplings}")
    if len(partial) < cfg.min_points:
        raise VolecError(
            f"the partial cloud has {len(partial)} points; completion needs at least "
            f"{cfg.min_points} (is it the masked food cloud?)"
        )
    if not np.all(np.isfinite(partial.xyz)):
        raise VolecError("the partial cloud has non-finite coordinates")


def merged_completion(partial: PointCloud, predicted: np.ndarray, norm: Normalization,
                      cfg: CompletionConfig, predicted_points: int, start: float) -> Completion:
    """The :class:`Completion` of ``partial`` by the ``predicted`` points (metres), merged
    as ``cfg`` says (only those farther than ``missing_only_gap_m`` from the partial)."""
    if cfg.merge_partial and cfg.missing_only_gap_m > 0:
        from scipy.spatial import cKDTree

        gap = cKDTree(partial.xyz).query(predicted)[0]
        predicted = predicted[gap > cfg.missing_only_gap_m]
    magenta = np.tile(np.array(PREDICTED_RGB, np.uint8), (len(predicted), 1))
    if cfg.merge_partial:
        rgb = None if partial.rgb is None else np.concatenate([partial.rgb, magenta])
        # the partial's normals are kept; the predicted points' are unknown (NaN)
        normals = None if partial.normals is None else np.concatenate(
            [partial.normals, np.full((len(predicted), 3), np.nan)])
        cloud = PointCloud(np.concatenate([partial.xyz, predicted]), rgb, normals)
    else:
        cloud = PointCloud(predicted, magenta)
    summary = {"partial_points": len(partial), "predicted_points": int(predicted_points),
               "predicted_kept": int(len(predicted)), "points": len(cloud),
               "seconds": round(time.perf_counter() - start, 3)}
    return Completion(cloud, predicted, norm, summary)


def mirror_completion(partial: PointCloud, up: np.ndarray | None,
                      cfg: CompletionConfig | None = None, fit_points: int = 10000
                      ) -> Completion:
    """Complete ``partial`` by its reflection in its best mirror plane
    (:mod:`volec.completion.mirror`, fitted on at most ``fit_points`` of it), the reflected
    points merged as the network's are; with ``up``, reflected points below the partial's
    lowest point are dropped."""
    from volec.completion.mirror import mirrored_points

    cfg = cfg or CompletionConfig()
    _check_partial(partial, cfg)
    start = time.perf_counter()
    rng = np.random.default_rng(cfg.seed)
    sample = partial.xyz[rng.choice(len(partial), min(fit_points, len(partial)),
                                    replace=False)]
    mirrored = mirrored_points(partial.xyz, up=up, fit_xyz=sample)
    return merged_completion(partial, mirrored, fit_normalization(partial.xyz), cfg,
                             len(mirrored), start)


def rotation_completion(partial: PointCloud, up: np.ndarray, space: SpaceGrid | None,
                        cfg: CompletionConfig | None = None) -> Completion:
    """Complete ``partial`` by its half-turn about its best vertical axis
    (:mod:`volec.completion.rotation`): the turned points that land in ``space``'s unknown
    part, merged as the network's are; none when the cloud is not symmetric under the turn.
    The summary has the axis and how well the turn fits."""
    from volec.completion.rotation import rotated_points

    cfg = cfg or CompletionConfig()
    _check_partial(partial, cfg)
    start = time.perf_counter()
    moved, fit = rotated_points(partial.xyz, up, space)
    done = merged_completion(partial, moved, fit_normalization(partial.xyz), cfg, len(moved),
                             start)
    done.summary |= fit.record()
    return done
