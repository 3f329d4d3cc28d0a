"""Running the stages in a work folder, reusing the finished ones.

In: a :class:`~volec.capture.Capture`, a work folder and each stage's config. Out: the stage
results, loaded from the work folder when a finished stage there was made with the same config,
computed (and saved atomically) otherwise. A finished stage made with *other* settings is never
replaced silently: that is an :class:`~volec.errors.OutputExistsError` unless ``overwrite``.
A stage that is recomputed makes every later stage recompute too.
"""

from __future__ import annotations

import json
import logging
from dataclasses import asdict
from pathlib import Path
from typing import Any

from volec.capture import Capture
from volec.dense import DenseConfig, DenseResult, load_dense, run_dense, save_dense
from volec.errors import OutputExistsError
from volec.masking import (
    MaskingConfig,
    MaskingResult,
    load_masking,
    mask_cloud,
    require_masks,
    save_masking,
)
from volec.sfm import SfmConfig, SfmResult, load_sfm, run_sfm

log = logging.getLogger(__name__)


def config_record(cfg: Any) -> dict[str, Any]:
    """A config dataclass as the JSON-able dict stage records store (tuples become lists)."""
    return json.loads(json.dumps(asdict(cfg)))


def reusable(record_path: Path, recorded_config: dict[str, Any] | None, cfg: Any,
             overwrite: bool) -> bool:
    """Whether the finished stage recorded at ``record_path`` can be reused for ``cfg``.

    False when there is none or ``overwrite`` is set; raises :class:`OutputExistsError` when
    it was made with other settings and ``overwrite`` is not set.
    """
    if overwrite or recorded_config is None:
        return False
    wanted = config_record(cfg)
    if recorded_config == wanted:
        return True
    changed = sorted(k for k in set(wanted) | set(recorded_config)
                     if wanted.get(k) != recorded_config.get(k))
    raise OutputExistsError(
        f"{record_path} was made with other settings ({', '.join(changed)} differ); pass "
        "--overwrite (overwrite=True) to redo it, or choose another work folder"
    )


def _recorded_config(path: Path) -> dict[str, Any] | None:
    return json.loads(path.read_text()).get("config") if path.exists() else None


def ensure_sfm(capture: Capture, work_dir: Path, cfg: SfmConfig | None = None,
               overwrite: bool = False) -> tuple[SfmResult, bool]:
    """(SfM result, whether it was computed now) for ``work_dir/sfm``."""
    cfg = cfg or SfmConfig()
    record = Path(work_dir) / "sfm" / "summary.json"
    if reusable(record, _recorded_config(record), cfg, overwrite):
        log.info("reusing the finished SfM stage in %s", record.parent)
        return load_sfm(work_dir), False
    return run_sfm(capture, work_dir, cfg), True


def ensure_dense(capture: Capture, sfm: SfmResult, work_dir: Path,
                 cfg: DenseConfig | None = None, overwrite: bool = False,
                 progress: bool = True) -> tuple[DenseResult, bool]:
    """(dense result, whether it was computed now) for ``work_dir/scene.ply``."""
    cfg = cfg or DenseConfig()
    record = Path(work_dir) / "dense.json"
    if reusable(record, _recorded_config(record), cfg, overwrite):
        log.info("reusing the finished dense stage %s", record)
        return load_dense(work_dir), False
    result = run_dense(capture, sfm.T_world_from_cam, sfm.registered, sfm.points_xyz, cfg,
                       progress=progress)
    save_dense(work_dir, result)
    return result, True


def ensure_masking(capture: Capture, sfm: SfmResult, dense: DenseResult, work_dir: Path,
                   cfg: MaskingConfig | None = None, overwrite: bool = False
                   ) -> tuple[MaskingResult, bool]:
    """(masking result, whether it was computed now) for ``work_dir/food_masked.ply``."""
    cfg = cfg or MaskingConfig()
    record = Path(work_dir) / "masking.json"
    if reusable(record, _recorded_config(record), cfg, overwrite):
        log.info("reusing the finished masking stage %s", record)
        return load_masking(work_dir), False
    result = mask_cloud(dense.cloud, capture, sfm.T_world_from_cam, sfm.registered, cfg)
    save_masking(work_dir, result)
    return result, True


def dense_and_mask(capture: Capture, work_dir: Path, sfm_cfg: SfmConfig | None = None,
                   dense_cfg: DenseConfig | None = None, mask_cfg: MaskingConfig | None = None,
                   overwrite: bool = False, progress: bool = True
                   ) -> tuple[SfmResult, DenseResult, MaskingResult]:
    """SfM (reused when finished), dense stereo and masking in ``work_dir``. A capture
    without a mask for every frame is refused before any work is done."""
    require_masks(capture)
    sfm, redone = ensure_sfm(capture, work_dir, sfm_cfg, overwrite)
    dense, redone = ensure_dense(capture, sfm, work_dir, dense_cfg, overwrite or redone,
                                 progress)
    masked, _ = ensure_masking(capture, sfm, dense, work_dir, mask_cfg, overwrite or redone)
    return sfm, dense, masked
