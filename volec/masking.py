"""Point cloud masking: keep the scene points that are food.

In: a scene :class:`~volec.pointcloud.PointCloud` (metres, world frame), the capture (each
frame's intrinsics and food mask), the camera poses to project with (SfM's refined ones) and a
:class:`MaskingConfig`. Out: a :class:`MaskingResult`, the food cloud plus a report of how many
points each rule removed. :func:`save_masking` writes ``WORKDIR/food_masked.ply`` and
``WORKDIR/masking.json``.

The rule is the paper's: a food point projects inside the food mask in every view that sees it
(P is the intersection of the mask hits). That holds whether or not the point is occluded in
the view, because a mask is the silhouette of the whole item, so no visibility test is needed.
``min_inside_fraction`` below 1 relaxes it for imperfect masks or poses; the masks can be
grown by a few pixels for the same reason.
"""

from __future__ import annotations

import logging
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy import ndimage

from volec.capture import Capture, read_mask
from volec.errors import VolecError
from volec.pointcloud import PointCloud, read_cloud_record, write_cloud_record

log = logging.getLogger(__name__)


class MaskingError(VolecError):
    """The masks could not select a food cloud."""


@dataclass(frozen=True)
class MaskingConfig:
    """Options of the masking stage."""

    min_inside_fraction: float = 1.0
    """A point is food when it projects inside the food mask in at least this fraction of the
    views that see it (1.0: the paper's intersection of mask hits)."""
    min_views: int = 3
    """Points inside fewer views' images than this are dropped (too little evidence)."""
    mask_dilation_px: int = 1
    """Masks are grown by this many pixels before the test, absorbing sub-pixel pose error at
    the silhouette."""


PRESETS: dict[str, MaskingConfig] = {
    "default": MaskingConfig(),
    # For masks from an automatic segmenter or poses with more error.
    "tolerant": MaskingConfig(min_inside_fraction=0.9, mask_dilation_px=3),
}


@dataclass(eq=False)
class MaskingResult:
    """The food cloud and what each rule removed."""

    cloud: PointCloud
    """Points judged food, metres, world frame."""
    report: dict[str, Any] = field(default_factory=dict)
    """Counts: ``input_points``, ``removed_too_few_views``, ``removed_outside_mask``,
    ``kept``; the config; per-view inside fractions."""


def mask_votes(cloud: PointCloud, capture: Capture, T_world_from_cam: np.ndarray,
               use: np.ndarray, dilation_px: int) -> tuple[np.ndarray, np.ndarray]:
    """Per point, the number of used views whose image it falls in, and of those the number
    whose (dilated) food mask it falls in."""
    seen = np.zeros(len(cloud), int)
    inside = np.zeros(len(cloud), int)
    for i in np.flatnonzero(use):
        frame = capture.frames[i]
        mask = read_mask(frame)
        if dilation_px > 0:
            mask = ndimage.binary_dilation(mask, iterations=dilation_px)
        T_cam_from_world = np.linalg.inv(T_world_from_cam[i])
        cam = cloud.xyz @ T_cam_from_world[:3, :3].T + T_cam_from_world[:3, 3]
        uv = frame.intrinsics.project(cam)
        ok = np.all(np.isfinite(uv), axis=1)
        iu = np.full((len(uv), 2), -1)
        iu[ok] = np.round(uv[ok]).astype(int)
        h, w = mask.shape
        in_image = ok & (iu[:, 0] >= 0) & (iu[:, 0] < w) & (iu[:, 1] >= 0) & (iu[:, 1] < h)
        seen += in_image
        idx = np.flatnonzero(in_image)
        inside[idx] += mask[iu[idx, 1], iu[idx, 0]]
    return seen, inside


def require_masks(capture: Capture) -> None:
    """Raise :class:`MaskingError` unless every frame of ``capture`` has a food mask."""
    if not capture.has_masks:
        missing = [f.name for f in capture.frames if f.mask_path is None]
        raise MaskingError(
            f"{len(missing)} of {len(capture)} frames have no food mask (first: {missing[0]}); "
            "masking needs a mask_path for every frame in transforms.json"
        )


def mask_cloud(cloud: PointCloud, capture: Capture, T_world_from_cam: np.ndarray,
               registered: np.ndarray, cfg: MaskingConfig | None = None) -> MaskingResult:
    """Keep the points of ``cloud`` that the food masks of the registered frames agree on."""
    cfg = cfg or MaskingConfig()
    if not 0.0 < cfg.min_inside_fraction <= 1.0:
        raise ValueError("min_inside_fraction must be in (0, 1]")
    require_masks(capture)
    start = time.perf_counter()
    use = np.asarray(registered, bool)
    seen, inside = mask_votes(cloud, capture, T_world_from_cam, use, cfg.mask_dilation_px)
    enough_views = seen >= cfg.min_views
    # The small tolerance keeps 1.0 an exact "every view" without float trouble.
    food = enough_views & (inside >= cfg.min_inside_fraction * seen - 1e-9)
    report = {
        "input_points": len(cloud),
        "views": int(use.sum()),
        "removed_too_few_views": int((~enough_views).sum()),
        "removed_outside_mask": int((enough_views & ~food).sum()),
        "kept": int(food.sum()),
        "seconds": round(time.perf_counter() - start, 2),
        "config": asdict(cfg),
    }
    if not food.any():
        raise MaskingError(
            f"no point of the {len(cloud)}-point scene cloud lies inside the food masks "
            f"(seen by >= {cfg.min_views} views: {int(enough_views.sum())}); check that the "
            "masks mark the food in white and belong to these frames"
        )
    log.info("masking: kept %d of %d points (%d seen by too few views, %d outside a mask)",
             report["kept"], len(cloud), report["removed_too_few_views"],
             report["removed_outside_mask"])
    return MaskingResult(cloud.subset(food), report)


def save_masking(work_dir: Path, result: MaskingResult) -> Path:
    """Write ``WORKDIR/food_masked.ply`` and ``WORKDIR/masking.json`` (each atomically)."""
    work_dir = Path(work_dir)
    return write_cloud_record(result.cloud, result.report, work_dir / "food_masked.ply",
                              work_dir / "masking.json")


def load_masking(work_dir: Path) -> MaskingResult:
    """Read a finished masking stage back from ``work_dir``."""
    work_dir = Path(work_dir)
    return MaskingResult(*read_cloud_record(work_dir / "food_masked.ply",
                                            work_dir / "masking.json"))
