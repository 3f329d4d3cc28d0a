"""Where single depth maps err, pixel by pixel, against the renderer's exact depth.

Usage: .venv/bin/python benchmarks/bench_depth_bias.py [--scenario smooth]
       [--items banana pear ...] [--set dense.coarse_factor=2 ...] [--workers 2]

Per item of the full-size benchmark's scenario, dense stereo's reference views are set up
with the **exact** camera poses (the ground truth's, so no pose error enters) and the given
masks, and their depth maps are estimated, before any fusion, once with the default settings
and, when given, once with the ``--set`` ones (``SECTION.FIELD=VALUE`` of
:class:`volec.estimate.EstimateConfig`). Each food pixel's estimated depth is compared with
the renderer's exact depth through the same pixel centre (read only to score). Pixels are
grouped by the reference image's texture (the intensity standard deviation in the 7x7 window,
0..1), by how obliquely the camera sees the surface (the cosine between the exact surface's
normal and the view ray) and by how far inside the food mask's outline they lie (pixels at
working resolution, the Euclidean distance transform). Per group: its share of the food
pixels, the share that got a depth, the median signed error (mm; positive: farther from the
camera than the surface, which on a convex item is inside it), and the share of the food
pixels whose depth is within 0.5 % of the truth (what fusion's consistency test asks of two
views). Written to figures/depth_bias_SCENARIO.{csv,md}.
"""

from __future__ import annotations

import argparse

import cv2
import numpy as np
import pandas as pd

from volec.dense import (
    _window_stats,
    depth_maps,
    inside_outline_px,
    plan_dense,
    surface_cosines,
)
from volec.estimate import EstimateConfig, with_settings
from volec.experiments import map_items, scenario_capture, scenarios
from volec.paths import experiment_dir, figures_dir
from volec.pipeline import run_sfm_stage
from volec.segment import given_masks
from volec.synth.generate import ExactDepth
from volec.tables import write_table

TEXTURE_BINS = (0.0, 0.01, 0.02, 0.04, 1.0)
COSINE_BINS = (0.0, 0.5, 0.75, 0.9, 1.01)
OUTLINE_BINS = (0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 1000.0)


def _window_std(gray: np.ndarray, k: int = 7) -> np.ndarray:
    """(H, W) intensity standard deviation of each pixel's k x k window, as dense stereo's
    texture test computes it."""
    import torch

    return _window_stats(torch.from_numpy(np.ascontiguousarray(gray)), k)[1].numpy()


def pixel_errors(item: str, scenario_name: str, settings: tuple[str, ...]) -> pd.DataFrame:
    """One row per food pixel of every reference view and config: the config, the texture,
    the cosine, whether a depth was estimated and its signed error (m)."""
    scenario = scenarios(False)[scenario_name]
    out = scenario.folder(experiment_dir(False), item)
    capture = scenario_capture(out, scenario)
    exact = scenario_capture(out, scenario, exact=True)
    base = EstimateConfig()
    sfm, _ = run_sfm_stage(capture, scenario.work(out), base.sfm, stale="recompute")
    masks = given_masks(capture)
    poses = np.stack([f.T_world_from_cam for f in exact.frames])
    # the sparse points only bound the depth range: moved by the SfM-to-exact frame offset
    # of the first frame, which is within millimetres
    shift = poses[0] @ np.linalg.inv(sfm.T_world_from_cam[0])
    sparse = sfm.points_xyz @ shift[:3, :3].T + shift[:3, 3]
    truth = ExactDepth(item, scenario.synth)
    configs = [("default", base)] + ([(" ".join(settings), with_settings(base, settings))]
                                     if settings else [])
    rows = []
    for name, cfg in configs:
        plan = plan_dense(capture, masks, poses, np.ones(len(capture), bool), sparse, cfg.dense)
        maps, _ = depth_maps(plan, sparse, cfg.dense, progress=False)
        for r, depth_map in maps.items():
            view = plan.views[r]
            h, w = view.gray.shape
            exact_depth = truth(view.K, w, h, np.linalg.inv(view.T_cam_from_world))
            food = cv2.resize(masks.mask(view.index).astype(np.float32), (w, h),
                              interpolation=cv2.INTER_AREA) >= 0.5
            food &= np.isfinite(exact_depth)
            cosine = surface_cosines(view, np.where(np.isfinite(exact_depth), exact_depth, 0))
            got = depth_map.depth_m
            outline_px = inside_outline_px(food)
            rows.append(pd.DataFrame({
                "item": item, "config": name, "texture": _window_std(view.gray)[food],
                "cosine": cosine[food], "outline_px": outline_px[food],
                "estimated": got[food] > 0,
                "error_m": np.where(got[food] > 0, got[food] - exact_depth[food], np.nan),
                "relative": np.where(got[food] > 0, (got[food] - exact_depth[food])
                                     / exact_depth[food], np.nan)}))
    return pd.concat(rows)


def _scores(group: pd.DataFrame, n: int) -> dict[str, float]:
    est = group[group["estimated"]]
    return {"pixels_pct": 100 * len(group) / n,
            "estimated_pct": 100 * group["estimated"].mean(),
            "median_error_mm": 1000 * est["error_m"].median() if len(est) else np.nan,
            "within_half_pct": 100 * (group["relative"].abs() < 0.005).mean()}


def summary(pixels: pd.DataFrame, by: str, bins: tuple[float, ...]) -> pd.DataFrame:
    """Per item, config and bin of ``by`` (and all pixels): the shares and the median signed
    error."""
    pixels = pixels.assign(bin=pd.cut(pixels[by], bins, right=False))  # ordered categories
    rows = []
    for (item, config), part in pixels.groupby(["item", "config"], sort=False):
        for b, group in part.groupby("bin", sort=True, observed=True):
            rows.append({"item": item, "config": config, "group": f"{by} {b}",
                         **_scores(group, len(part))})
        if by == "texture":
            rows.append({"item": item, "config": config, "group": "all",
                         **_scores(part, len(part))})
    return pd.DataFrame(rows)


def _item_pixels(item: str, scenario_name: str, settings: tuple[str, ...]
                 ) -> dict[str, pd.DataFrame]:
    return {"pixels": pixel_errors(item, scenario_name, settings)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="smooth")
    parser.add_argument("--items", nargs="+", default=["banana", "pear"])
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.FIELD=VALUE")
    parser.add_argument("--workers", type=int, default=1)
    args = parser.parse_args()
    jobs = [(item, args.scenario, tuple(args.set)) for item in args.items]
    frames = map_items(_item_pixels, jobs, args.items,
                       args.workers, progress=True)
    pixels = pd.concat([f["pixels"] for f in frames])
    table = pd.concat([summary(pixels, "texture", TEXTURE_BINS),
                       summary(pixels, "cosine", COSINE_BINS),
                       summary(pixels, "outline_px", OUTLINE_BINS)])
    write_table(table, figures_dir() / f"depth_bias_{args.scenario}", float_digits=3)
    print(table.to_string(index=False, float_format=lambda x: f"{x:.3f}"))


if __name__ == "__main__":
    main()
