"""Running the stages in a work folder, reusing the finished ones, and only those.

In: a :class:`~volec.capture.Capture`, a work folder and each stage's config. Out:
:class:`StageResults` (SfM, the food masks, dense and masking results), each loaded from the
work folder when
a finished stage there was made from exactly this (:mod:`volec.provenance`: the same capture,
the same upstream results, config and code, and its files unchanged), computed and saved
otherwise (files first, record last).

A work folder holding results made from anything else (another capture, other settings, other
code) is never overwritten silently: :func:`preflight` refuses it before any work starts,
naming what differs, unless ``overwrite``; with ``stale="recompute"`` (the experiments) such
results are recomputed instead. A stage that is recomputed makes every later stage recompute.
"""

from __future__ import annotations

import hashlib
import json
import logging
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np

from volec.capture import Capture
from volec.dense import DenseConfig, DenseResult, load_dense, run_dense, save_dense
from volec.errors import OutputExistsError, VolecError
from volec.masking import (
    MaskingConfig,
    MaskingResult,
    load_masking,
    mask_cloud,
    require_masks,
    save_masking,
)
from volec.progress import step
from volec.provenance import (
    capture_identity,
    differences,
    file_problems,
    json_data,
    record_digest,
    stage_provenance,
)
from volec.segment import (
    MaskSet,
    SegmentConfig,
    given_masks,
    load_masks,
    save_masks,
    segment,
)
from volec.sfm import SfmConfig, SfmResult, load_sfm, run_sfm

log = logging.getLogger(__name__)

Stale = Literal["refuse", "recompute"]
"""What to do with a finished stage made from something else: ``refuse`` (raise
:class:`OutputExistsError`; the command line) or ``recompute`` it (the experiments)."""


@dataclass(frozen=True)
class Stage:
    """Where a stage keeps its record, and the modules whose code computes it."""

    name: str
    record: str
    """The record's path in the work folder (its files are relative to its folder)."""
    modules: tuple[str, ...]


STAGES = {
    "sfm": Stage("sfm", "sfm/summary.json", ("volec.sfm",)),
    "segment": Stage("segment", "segment.json", ("volec.segment",)),
    "dense": Stage("dense", "dense.json", ("volec.dense",)),
    "masking": Stage("masking", "masking.json", ("volec.masking",)),
}


def config_record(cfg: Any) -> dict[str, Any]:
    """A config dataclass as the JSON-able dict stage records store (tuples become lists)."""
    return json_data(cfg)


def read_record(path: Path) -> dict[str, Any] | None:
    """The JSON record at ``path``; None when there is none. A record that is not valid JSON
    (an edited or damaged file) is an :class:`OutputExistsError` naming it."""
    path = Path(path)
    if not path.exists():
        return None
    try:
        record = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise OutputExistsError(f"{path} is not valid JSON ({e}): an edited or damaged result; "
                                "pass --overwrite to redo it, or choose another output "
                                "folder") from None
    if not isinstance(record, dict):
        raise OutputExistsError(f"{path} is not a volec record; pass --overwrite to redo it, "
                                "or choose another output folder")
    return record


def check_output_folder(capture: Capture, out_dir: Path) -> None:
    """Raise unless ``out_dir`` is a folder (or does not exist yet) outside the capture's
    folder: volec never writes into a capture."""
    if Path(out_dir).exists() and not Path(out_dir).is_dir():
        raise OutputExistsError(f"the output folder {out_dir} exists and is a file; choose "
                                "another folder")
    root, out = Path(capture.root).resolve(), Path(out_dir).resolve()
    if out == root or root in out.parents:
        raise VolecError(f"the output folder {out_dir} is inside the capture {capture.root}; "
                         "volec never writes into a capture: choose another folder")


def stale_reasons(record: dict[str, Any], wanted: dict[str, Any], folder: Path,
                  record_name: str, upstream: bool = True) -> list[str]:
    """Why a finished stage with ``record`` is not what ``wanted`` (a provenance) would make;
    empty when it can be reused. ``upstream=False`` ignores the upstream digests (whether an
    earlier stage will be recomputed is not known yet)."""
    recorded = record.get("provenance")
    if not upstream and recorded is not None:
        recorded = {**recorded, "upstream": wanted["upstream"]}
    return differences(recorded, wanted) + file_problems(record, folder, record_name)


def _refuse(path: Path, reasons: list[str]) -> None:
    raise OutputExistsError(f"{path} holds a result that is not from this run's inputs: "
                            f"{'; '.join(reasons)}. Pass --overwrite (overwrite=True) to redo "
                            "it, or choose another output folder")


def preflight(work_dir: Path, wanted: dict[str, dict[str, Any]], overwrite: bool,
              stale: Stale) -> None:
    """Before any work: refuse (:class:`OutputExistsError`) a work folder whose finished
    stages were made from another capture, config or code, or whose files were changed.
    ``wanted``: stage name -> the provenance this run would give it (upstream not compared)."""
    if overwrite or stale == "recompute":
        return
    for name, provenance in wanted.items():
        path = Path(work_dir) / (STAGES[name].record if name in STAGES else name)
        record = read_record(path)
        if record is None:
            continue
        reasons = stale_reasons(record, provenance, path.parent, path.name, upstream=False)
        if reasons:
            _refuse(path, reasons)


def _reusable(path: Path, wanted: dict[str, Any], overwrite: bool, stale: Stale) -> bool:
    record = None if overwrite else read_record(path)
    if record is None:
        return False
    reasons = stale_reasons(record, wanted, path.parent, path.name)
    if not reasons:
        return True
    only_upstream = not stale_reasons(record, wanted, path.parent, path.name, upstream=False)
    if stale == "refuse" and not only_upstream:
        _refuse(path, reasons)
    log.info("%s is stale (%s): recomputing", path, "; ".join(reasons))
    return False


MaskSource = Literal["default", "given", "auto"]
"""Which food masks the stages use: the capture's own (``given``), :mod:`volec.segment`'s
(``auto``), or the capture's when every frame has one and automatic ones otherwise
(``default``)."""


def masks_source(capture: Capture, wanted: MaskSource | MaskSet) -> str:
    """``given``, ``auto`` or (masks handed in as a :class:`MaskSet`) ``handed``: what
    ``wanted`` means for ``capture``."""
    if isinstance(wanted, MaskSet):
        if wanted.names != tuple(f.name for f in capture.frames):
            raise VolecError("the masks handed in are not for this capture's frames")
        return "handed"
    if wanted == "default":
        return "given" if capture.has_masks else "auto"
    if wanted == "given":
        require_masks(capture)
    return wanted


@dataclass(frozen=True, eq=False)
class StageResults:
    """The results of the stages before meshing, and how they were obtained."""

    sfm: SfmResult
    masks: MaskSet
    dense: DenseResult
    masked: MaskingResult
    identity: dict[str, Any]
    """The capture's identity (:func:`~volec.provenance.capture_identity`)."""
    reused: tuple[str, ...]
    """The stages loaded from the work folder instead of computed."""
    seconds: dict[str, float] = field(default_factory=dict)
    """Wall time of each stage in this run (``sfm_s``, ``segment_s``, ``dense_s``,
    ``masking_s``)."""

    def digests(self) -> dict[str, str]:
        """The digest of each stage's record, as downstream records name them."""
        return {"sfm": record_digest(self.sfm.summary), "masks": masks_digest(self.masks),
                "dense": record_digest(self.dense.summary),
                "masking": record_digest(self.masked.report)}


def masks_digest(masks: MaskSet) -> str:
    """How downstream records name the masks: ``given`` (the capture's identity holds their
    digests) or the digest of the segmentation's record."""
    if masks.source == "given":
        return "given"
    if "record" in masks.summary:
        return record_digest(masks.summary["record"])
    h = hashlib.sha256()
    for mask in masks.masks:  # masks handed in: their content
        h.update(np.packbits(mask).tobytes())
    return f"{masks.source}:{h.hexdigest()[:16]}"


def wanted_provenance(identity: dict[str, Any], sfm_cfg: SfmConfig, segment_cfg: SegmentConfig,
                      dense_cfg: DenseConfig, mask_cfg: MaskingConfig
                      ) -> dict[str, dict[str, Any]]:
    """The provenance of each stage of a run on the capture with ``identity`` (upstream
    digests left empty: they are known only once the earlier stage is done)."""
    return {"sfm": stage_provenance(identity, sfm_cfg, {}, STAGES["sfm"].modules),
            "segment": stage_provenance(identity, segment_cfg, {}, STAGES["segment"].modules),
            "dense": stage_provenance(identity, dense_cfg, {}, STAGES["dense"].modules),
            "masking": stage_provenance(identity, mask_cfg, {}, STAGES["masking"].modules)}


def run_segment_stage(capture: Capture, sfm: SfmResult, work_dir: Path,
                      cfg: SegmentConfig | None = None, overwrite: bool = False,
                      stale: Stale = "refuse", progress: bool = True) -> tuple[MaskSet, bool]:
    """(automatic food masks, whether they were computed now) for ``work_dir/segment.json``,
    reused when made from exactly this capture, SfM result, config and code."""
    cfg = cfg or SegmentConfig()
    wanted = stage_provenance(capture_identity(capture), cfg, {}, STAGES["segment"].modules)
    preflight(work_dir, {"segment": wanted}, overwrite, stale)
    masks, reused = _masks_stage(capture, sfm, Path(work_dir), "auto", cfg, wanted, True,
                                 overwrite, stale, progress)
    return masks, not reused


def _masks_stage(capture: Capture, sfm: SfmResult, work_dir: Path, source: str,
                 cfg: SegmentConfig, wanted: dict[str, Any], reuse: bool, overwrite: bool,
                 stale: Stale, progress: bool) -> tuple[MaskSet, bool]:
    """(the food masks, whether they were reused): the capture's, or the segmentation's,
    reused from ``work_dir`` when made from exactly this SfM result (masks handed in are
    dealt with by the caller)."""
    if source == "given":
        return given_masks(capture), True
    wanted = {**wanted, "upstream": {"sfm": record_digest(sfm.summary)}}
    path = work_dir / STAGES["segment"].record
    if reuse and _reusable(path, wanted, overwrite, stale):
        masks = load_masks(work_dir)
        return _with_record(masks, read_record(path)), True
    masks = segment(capture, sfm.T_world_from_cam, sfm.registered, sfm.points_xyz, cfg,
                    progress=progress)
    masks.summary["provenance"] = wanted
    save_masks(work_dir, masks)
    return _with_record(masks, read_record(path)), False


def _with_record(masks: MaskSet, record: dict[str, Any]) -> MaskSet:
    """``masks`` with the record its stage wrote in its summary (the digest downstream)."""
    return replace(masks, summary={**masks.summary, "record": record})


def run_stages(capture: Capture, work_dir: Path, sfm_cfg: SfmConfig | None = None,
               dense_cfg: DenseConfig | None = None, mask_cfg: MaskingConfig | None = None,
               overwrite: bool = False, stale: Stale = "refuse", progress: bool = True,
               identity: dict[str, Any] | None = None,
               masks: MaskSource | MaskSet = "default",
               segment_cfg: SegmentConfig | None = None) -> StageResults:
    """SfM, the food masks (given or automatic), dense stereo and masking of ``capture`` in
    ``work_dir``, each reused when finished from exactly these inputs (see the module
    docstring). A work folder of another capture is refused before any work is done."""
    sfm_cfg, dense_cfg = sfm_cfg or SfmConfig(), dense_cfg or DenseConfig()
    mask_cfg, segment_cfg = mask_cfg or MaskingConfig(), segment_cfg or SegmentConfig()
    source = masks_source(capture, masks)
    work_dir = Path(work_dir)
    identity = identity or capture_identity(capture)
    wanted = wanted_provenance(identity, sfm_cfg, segment_cfg, dense_cfg, mask_cfg)
    if source != "auto":
        wanted.pop("segment")
    preflight(work_dir, wanted, overwrite, stale)
    seconds: dict[str, float] = {}
    reused: list[str] = []

    step(progress, f"SfM on {len(capture)} frames")
    t = time.perf_counter()
    if _reusable(work_dir / STAGES["sfm"].record, wanted["sfm"], overwrite, stale):
        sfm = load_sfm(work_dir)
        reused.append("sfm")
    else:
        sfm = run_sfm(capture, work_dir, sfm_cfg, provenance=wanted["sfm"])
    seconds["sfm_s"] = round(time.perf_counter() - t, 2)

    step(progress, "food segmentation" if source == "auto" else "the food masks")
    t = time.perf_counter()
    if isinstance(masks, MaskSet):
        food_masks, was_reused = masks, True
    else:
        food_masks, was_reused = _masks_stage(capture, sfm, work_dir, source, segment_cfg,
                                              wanted.get("segment", {}), "sfm" in reused,
                                              overwrite, stale, progress)
    if was_reused and "sfm" in reused:
        reused.append("masks")
    seconds["segment_s"] = round(time.perf_counter() - t, 2)
    upstream = {"sfm": record_digest(sfm.summary), "masks": masks_digest(food_masks)}

    step(progress, "dense stereo")
    t = time.perf_counter()
    dense_wanted = {**wanted["dense"], "upstream": upstream}
    if "masks" in reused and _reusable(work_dir / "dense.json", dense_wanted, overwrite, stale):
        dense = load_dense(work_dir)
        reused.append("dense")
    else:
        dense = run_dense(capture, food_masks, sfm.T_world_from_cam, sfm.registered,
                          sfm.points_xyz, dense_cfg, progress=progress)
        dense.summary["provenance"] = dense_wanted
        save_dense(work_dir, dense)
    seconds["dense_s"] = round(time.perf_counter() - t, 2)

    step(progress, "masking")
    t = time.perf_counter()
    mask_wanted = {**wanted["masking"], "upstream": {**upstream,
                                                     "dense": record_digest(dense.summary)}}
    if "dense" in reused and _reusable(work_dir / "masking.json", mask_wanted, overwrite, stale):
        masked = load_masking(work_dir)
        reused.append("masking")
    else:
        masked = mask_cloud(dense.cloud, capture, food_masks, sfm.T_world_from_cam,
                            sfm.registered, mask_cfg)
        masked.report["provenance"] = mask_wanted
        save_masking(work_dir, masked)
    seconds["masking_s"] = round(time.perf_counter() - t, 2)
    return StageResults(sfm, food_masks, dense, masked, identity, tuple(reused), seconds)


def run_sfm_stage(capture: Capture, work_dir: Path, cfg: SfmConfig | None = None,
                  overwrite: bool = False, stale: Stale = "refuse") -> tuple[SfmResult, bool]:
    """(SfM result, whether it was computed now) for ``work_dir/sfm``, reused when finished
    from exactly this capture, config and code."""
    cfg = cfg or SfmConfig()
    wanted = stage_provenance(capture_identity(capture), cfg, {}, STAGES["sfm"].modules)
    preflight(work_dir, {"sfm": wanted}, overwrite, stale)
    if _reusable(Path(work_dir) / STAGES["sfm"].record, wanted, overwrite, stale):
        log.info("reusing the finished SfM stage in %s", Path(work_dir) / "sfm")
        return load_sfm(work_dir), False
    return run_sfm(capture, work_dir, cfg, provenance=wanted), True
