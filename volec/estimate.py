"""The whole pipeline: a capture in, millilitres, a mesh and a report out.

In: a metric :class:`~volec.capture.Capture` with a food mask per frame, an output folder and
an :class:`EstimateConfig`. Out, in the output folder (which is also the work folder, so a
re-run reuses the finished SfM, dense and masking stages, and a finished estimate):

- ``scene.ply``, ``food_masked.ply`` (and ``sfm/``, ``dense.json``, ``masking.json``);
- ``food_completed.ply``: the masked cloud, the rim points (cyan) and the shape priors'
  points (magenta: the network's or a symmetry's, and the underside's mirrored ones), with
  completion;
- ``mesh.ply`` and ``mesh.glb``: the closed food mesh (metres, the capture's world frame);
- ``report.html``: one self-contained page (:mod:`volec.report`): the volume, its trust flag
  and reasons, the frames with the masks' outlines, the clouds and the mesh in a 3D viewer, the
  stage times and warnings; opens offline in any browser;
- ``report.md`` with pictures in ``report/``;
- ``result.json``: ``volume_ml``, ``volume_bounds_ml`` and ``unknown_share`` (how far the volume
  may be off from what no camera constrained, :mod:`volec.space`), ``scale_std_pct`` and
  ``volume_interval_ml`` (the metric scale's uncertainty, and the bounds widened by it,
  :mod:`volec.scale_uncertainty`), ``measured_surface_share``
  (how much of the mesh's surface was measured), ``trusted`` and the
  ``reasons`` it is not (:mod:`volec.trust`),
  warnings, frames used, per-stage wall time, the support plane, the scale's source, the
  config and what the result was made from (:mod:`volec.provenance`). Written last, listing
  the digests of the other files: a folder with a current ``result.json`` holds a finished
  estimate.

:func:`estimate_from_stages` is the pure core (stage results in, a :class:`Estimate` out) that
both :func:`run_estimate` (the command line) and the experiments call; the experiments only add
scoring. Nothing here reads a capture's ground truth. The capture is only read; every file is
written atomically, and an earlier result made from other inputs is refused unless
``overwrite``.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field, fields, is_dataclass, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
import trimesh

from volec import __version__
from volec.capture import Capture
from volec.completion.complete import (
    SHIPPED_CHECKPOINT,
    Completion,
    CompletionConfig,
    complete_cloud,
    mirror_completion,
    rotation_completion,
)
from volec.completion.mirror import (
    MirrorViewsConfig,
    VerticalMirrorFit,
    fit_vertical_mirror,
    reflection_matrix,
)
from volec.completion.model import SymmCompletion
from volec.completion.preprocess import frame_needs_up
from volec.dense import PRESETS as DENSE_PRESETS
from volec.dense import DenseConfig
from volec.errors import ConfigError, VolecError
from volec.geometry import azimuth_span_deg
from volec.io import folder_lock, write_bytes_atomic, write_json_atomic, write_text_atomic
from volec.keyframes import KeyframeConfig, choose_keyframes, keyframe_capture
from volec.masking import MaskingConfig, check_masks, usable_masks
from volec.meshing import PRESETS as MESHING_PRESETS
from volec.meshing import (
    MeshingConfig,
    MeshingError,
    MeshResult,
    PriorViews,
    SilhouetteView,
    SupportConfig,
    SupportPlane,
    consistent_views,
    fit_support_plane,
    mesh_cloud,
    mirrored_views,
    silhouette_views,
    with_normals,
)
from volec.metrics import nearest_distances, sample_surface
from volec.pipeline import (
    MaskSource,
    StageResults,
    check_output_folder,
    masks_source,
    preflight,
    read_record,
    run_stages,
    stale_reasons,
)
from volec.pointcloud import PointCloud, write_ply
from volec.progress import step
from volec.provenance import capture_identity, file_digest, json_data, stage_provenance
from volec.report import ReportScene, bounds_sentence, write_report_html
from volec.rims import RimConfig, rim_points
from volec.scale import ScaleCheck, ScaleConfig, require_metric
from volec.scale_uncertainty import sfm_scale_std, volume_interval
from volec.segment import MaskSet, SegmentConfig, given_masks
from volec.sfm import SfmConfig
from volec.space import (
    FOOD,
    SpaceConfig,
    SpaceGrid,
    VolumeBounds,
    observed_space,
    through_hole,
    volume_bounds,
)
from volec.trust import Reason, TrustConfig, TrustFacts, assess
from volec.underside import UndersideConfig, underside_points
from volec.volume import volume_ml

RESULT_FILE = "result.json"
MODULES = ("volec.estimate",)
"""The code that makes an estimate (with everything it imports: all the stages)."""

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class EstimateConfig:
    """Settings of every stage of :func:`run_estimate`."""

    use_completion: bool = True
    """Complete the masked cloud before meshing (False: the VolE-style baseline, where only
    the support plane and Poisson close the unseen underside)."""
    completion_method: Literal["network", "mirror", "rotation", "auto"] = "auto"
    """``network``: the trained SymmCompletion network; ``mirror``: the cloud's reflection in
    its best mirror plane (the non-learned baseline, :mod:`volec.completion.mirror`), merged
    the same way; ``rotation``: its half-turn about its best vertical axis, kept only where
    no camera constrained the space (:mod:`volec.completion.rotation`); ``auto``: that
    half-turn where the masked cloud is symmetric under it, then the network for what is still
    missing (the network alone where it is not). ``auto`` is the default: on the benchmark's
    21 items (exact masks) its MAPE was 2.73 % on half orbits against 2.99 % for the network
    alone and 3.19 % without completion, and 1.47 % on full orbits against 1.51 % and
    1.55 % (``benchmarks/bench_volume.py``, 2026-12-03, carving margin 0.5 px)."""
    network_sees_rims: bool = False
    """Show the completion network the rim points (:mod:`volec.rims`) beside the masked
    cloud (completion methods ``network`` and ``auto``); its points are then merged with the
    masked cloud as before. Stereo keeps few depths in an item's lowest band, and the
    network's points under the item follow those few: shown the rims, the full-orbit apple's
    network volume stays +0.69 / +0.66 % with and without the masked points below 8 mm
    (-0.58 / -2.14 % without the rims). Off: on the benchmark the default gained nothing
    (full orbits 0.78 -> 0.80 %, half 1.20 -> 1.37 %, sparse 1.07 -> 1.17 %;
    docs/measurements.md, Where the remaining error lies). A completion setting, not the rims'
    own: the estimate's basis, rims included, is the same either way."""
    priors_clear_of_holes: bool = True
    """Drop the completion's points (the half-turn's and the network's) that lie under a hole
    through the food seen into from above but not down to the plate, inside the hole's
    cross-section at the lowest height the cameras saw through it
    (:func:`volec.space.through_hole`): a doughnut seen from low cameras. The network, which
    learnt food without holes, put a floor of points on the plate there and the mesh closed
    the hole's lower part over them. The underside's reflected wall
    (:attr:`volec.underside.UndersideConfig.through_holes`) is kept."""
    checkpoint: str = ""
    """Completion checkpoint; empty: the one shipped with volec."""
    keyframes: KeyframeConfig = field(default_factory=KeyframeConfig)
    """Which frames are reconstructed: blurred ones and near-duplicates are dropped, and at
    most ``max_frames`` evenly spread ones kept (:mod:`volec.keyframes`)."""
    sfm: SfmConfig = field(default_factory=SfmConfig)
    masks: MaskSource = "default"
    """The capture's own food masks (``given``), automatic ones (``auto``, :mod:`volec.segment`),
    or the capture's where every frame has one and automatic ones otherwise (``default``)."""
    segment: SegmentConfig = field(default_factory=SegmentConfig)
    dense: DenseConfig = field(default_factory=DenseConfig)
    masking: MaskingConfig = field(default_factory=MaskingConfig)
    completion: CompletionConfig = field(
        default_factory=lambda: CompletionConfig(missing_only_gap_m=0.008))
    """Predicted points within 8 mm of a masked point are not meshed. Measured with silhouette
    carving on apple, capsicum, falafel and durum: keeping those farther than 4 mm
    under-estimates by 2.9 % on average, 8 mm by 2.0 %, 16 mm by 1.0 % (then the network
    adds almost nothing: 1.0 % without completion); the mesh's Chamfer distance to the truth
    is lowest at 8 mm (0.79 mm against 0.83 mm without completion)."""
    support: SupportConfig = field(default_factory=SupportConfig)
    meshing: MeshingConfig = field(default_factory=MeshingConfig)
    carve_silhouettes: bool = True
    """Intersect the mesh with the visual hull of the food masks (see :mod:`volec.meshing`)."""
    mirror_views: MirrorViewsConfig = field(default_factory=MirrorViewsConfig)
    """Where the food is symmetric about a vertical plane, carve also with the views reflected
    in it (completion methods ``auto`` and ``mirror``; :mod:`volec.completion.mirror`)."""
    trust: TrustConfig = field(default_factory=TrustConfig)
    """When the estimate is flagged ``trusted: false`` (see :mod:`volec.trust`)."""
    scale: ScaleConfig = field(default_factory=ScaleConfig)
    """Which camera distances are plausible as metres (see :mod:`volec.scale`)."""
    completion_share_pitch_m: float = 0.002
    """Grid spacing of the interior samples that measure the share of the volume decided by
    the network's points."""
    measured_reach_m: float = 0.001
    """The mesh's surface counts as measured where a measured point (the masked cloud or a
    rim point) lies within this of it (:func:`measured_surface_share`)."""
    space: SpaceConfig = field(default_factory=SpaceConfig)
    """How the space around the food is sorted into empty, food and unknown for the volume
    bounds (:mod:`volec.space`)."""
    scale_sigmas: float = 2.0
    """How many standard deviations of the metric scale (:mod:`volec.scale_uncertainty`)
    ``volume_interval_ml`` adds on each side of the bounds: 2 holds the scale's error about
    95 % of the time if the AR noise is what ``sfm.ar_jitter_m`` and
    ``sfm.ar_drift_m`` say."""
    rims: RimConfig = field(default_factory=RimConfig)
    """Where the food masks' outlines place the surface under the item's widest level, mesh
    with those points too (:mod:`volec.rims`; only with carving silhouettes)."""
    underside: UndersideConfig = field(default_factory=UndersideConfig)
    """Where the food is symmetric about a horizontal plane, its upper part reflected below it
    bounds the wedge under the lowest measured surface (the ``auto`` completion only, with a
    support plane and the sorted space; :mod:`volec.underside`)."""


PRESETS: dict[str, EstimateConfig] = {
    "default": EstimateConfig(),
    "fast": EstimateConfig(dense=DENSE_PRESETS["fast"], meshing=MESHING_PRESETS["fast"]),
    # Masks from an automatic segmenter, or poses with more error (see volec.masking): a point
    # stays food when inside the masks of 90 % of the views that see it, and carving needs
    # three views, not two (a mask whose boundary is 2-3 px inside the food's cannot carve
    # it with one other); masks that leave out part of the food cloud never carve, in any
    # preset (MeshingConfig.silhouette_max_contradiction). With the benchmark's noisy masks
    # (boundaries 1-3 px off, shadow leaks, missed chunks, false blobs, two empty) on the 21
    # full orbits, network completion: MAPE 1.64 % (exact masks 1.55 %), where carving that
    # needed 10 % of the views gave 2.08 % on the same stage results: a share of all the views
    # that see a point is more than the few that see it edge-on, so the unseen gap under the
    # food stayed. Notebook 02's run of this code, captures made anew: 1.72 %. Carving keeps
    # the 1 px silhouette margin of those measurements (the default carves with 0.5 px).
    # The underside's mirror is off: on those noisy masks it made the default's MAPE 1.36 ->
    # 1.76 % (mean signed +0.08 -> -0.70 %; apple -1.6 -> -4.2 %, orange 0.0 -> -2.4 %), while
    # on volec's automatic masks it helps (1.61 -> 1.41 %), so the default keeps it.
    "tolerant_masks": EstimateConfig(
        masking=replace(MaskingConfig(), min_inside_fraction=0.9),
        meshing=replace(MeshingConfig(), silhouette_min_views=3, silhouette_margin_px=1.0),
        underside=replace(UndersideConfig(), enabled=False)),
}


@dataclass(frozen=True)
class FoodMesh:
    """The food's closed mesh and what went into it."""

    cloud: PointCloud
    """The cloud that was meshed: the masked cloud, the rim points (:mod:`volec.rims`), then
    a prior's points with completion."""
    mesh: MeshResult
    volume_ml: float
    support: SupportPlane | None
    support_problem: str | None
    """Why no support plane was found (None when one was)."""
    completion_summary: dict[str, Any] | None
    completion_share: float | None
    """Share of the mesh's volume nearer to the shape priors' points (the network's or a
    symmetry's, the underside's) than to observed ones (None without completion)."""
    seconds: dict[str, float]
    """Wall time of ``completion_s`` (0 without) and ``meshing_s`` (support plane included)."""
    completion_problem: str | None = None
    """Why completion was asked for but skipped (None when it ran or was off)."""
    observed_points: int = 0
    """How many of ``cloud``'s first points were measured (the masked cloud and the rim
    points); the rest are a prior's."""
    measured_surface_share: float | None = None
    """Share of the mesh's surface area with a measured point within
    :attr:`EstimateConfig.measured_reach_m` (:func:`measured_surface_share`)."""


@dataclass(frozen=True)
class Estimate:
    """One volume estimate from the stage results, and how far it can be trusted."""

    food: FoodMesh
    reasons: list[Reason]
    """Why the volume is not to be trusted (empty: trusted)."""
    warnings: list[str]
    """Everything a person should read: the reasons' messages first, then notes."""
    orbit_coverage_deg: float
    view_up: np.ndarray
    """The support plane's normal, else the capture's up direction, else +z."""
    bounds: VolumeBounds
    """How far the volume may be off from what nobody saw (:mod:`volec.space`)."""
    bounds_s: float = 0.0
    """Wall time of the bounds, seconds."""
    silhouettes_left_out: tuple[str, ...] = ()
    """Frames whose masks left out part of the food cloud, so that they did not carve
    (:func:`volec.meshing.consistent_views`)."""
    mirror_views: dict[str, Any] | None = None
    """The mirror plane the carving's reflected views came from and how many carved (None:
    no reflected views were asked for)."""
    rims: dict[str, Any] | None = None
    """How the rim points were found (:func:`volec.rims.rim_points`; None: none were)."""
    scale_std: float = math.nan
    """Standard deviation of the metric scale, a fraction of it (NaN: not known, the poses'
    metres were not the AR tracking's; :func:`volec.scale_uncertainty.sfm_scale_std`)."""
    volume_interval_ml: tuple[float, float] = (math.nan, math.nan)
    """``bounds`` widened by the scale's uncertainty
    (:func:`volec.scale_uncertainty.volume_interval`): how far the volume may be off from
    what nobody saw and from the metric scale together."""

    @property
    def trusted(self) -> bool:
        """True when there is no reason to distrust the volume."""
        return not self.reasons


def with_setting(cfg: EstimateConfig, setting: str) -> EstimateConfig:
    """``cfg`` with one field changed by ``setting``, ``SECTION.FIELD=VALUE`` (e.g.
    ``dense.ncc_window_px=9``) or ``FIELD=VALUE`` for a top-level one; the value is read as the
    type the field holds now (int, float, bool, str). For benchmarks that compare a setting."""
    path, sep, text = setting.partition("=")
    names = path.strip().split(".")
    if not sep or not all(names):
        raise ConfigError(f"setting {setting!r}: use SECTION.FIELD=VALUE")
    return _with_field(cfg, names, text.strip(), setting)


def with_settings(cfg: EstimateConfig, settings: tuple[str, ...] | list[str]) -> EstimateConfig:
    """``cfg`` with each of ``settings`` applied in turn (:func:`with_setting`)."""
    for setting in settings:
        cfg = with_setting(cfg, setting)
    return cfg


def _with_field(obj: Any, names: list[str], text: str, setting: str) -> Any:
    """``obj`` (a frozen dataclass) with the field at ``names`` set to ``text``, typed."""
    names_here = {f.name for f in fields(obj)}
    if names[0] not in names_here:
        raise ConfigError(f"setting {setting!r}: {type(obj).__name__} has no field "
                          f"{names[0]!r} (fields: {', '.join(sorted(names_here))})")
    current = getattr(obj, names[0])
    if len(names) > 1:
        if not is_dataclass(current):
            raise ConfigError(f"setting {setting!r}: {names[0]!r} is not a section")
        value = _with_field(current, names[1:], text, setting)
    else:
        value = _typed(current, text, setting)
    return replace(obj, **{names[0]: value})


def _typed(current: Any, text: str, setting: str) -> Any:
    """``text`` as the type of ``current`` (bool from true/false)."""
    if isinstance(current, bool):
        if text.lower() not in ("true", "false"):
            raise ConfigError(f"setting {setting!r}: true or false")
        return text.lower() == "true"
    if isinstance(current, int | float | str):
        try:
            return type(current)(text)
        except ValueError as e:
            raise ConfigError(f"setting {setting!r}: {text!r} is not a valid "
                              f"{type(current).__name__}") from e
    raise ConfigError(f"setting {setting!r}: a {type(current).__name__} field cannot be set")


def checkpoint_path(cfg: EstimateConfig) -> Path:
    """The completion checkpoint ``cfg`` names."""
    return Path(cfg.checkpoint) if cfg.checkpoint else SHIPPED_CHECKPOINT


def load_completion_model(cfg: EstimateConfig) -> SymmCompletion:
    """The completion network of ``cfg``; a clear error when its checkpoint is missing."""
    from volec.completion.train import load_checkpoint

    try:
        return load_checkpoint(checkpoint_path(cfg))[0]
    except FileNotFoundError as e:
        raise VolecError(f"completion checkpoint not found: {e}") from e


def completion_share(mesh: trimesh.Trimesh, cloud: PointCloud, observed_points: int,
                     pitch_m: float) -> float:
    """Share of the volume inside ``mesh`` whose nearest point of ``cloud`` is one of the
    shape priors' (those after the first ``observed_points``), on a grid of ``pitch_m``."""
    from scipy.spatial import cKDTree

    lo, hi = mesh.bounds
    axes = [np.arange(lo[i] + pitch_m / 2, hi[i], pitch_m) for i in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    inside = grid[mesh.contains(grid)] if len(grid) else grid
    if not len(inside):
        return 0.0
    nearest = cKDTree(cloud.xyz).query(inside)[1]
    return float(np.mean(nearest >= observed_points))


def measured_surface_share(mesh: trimesh.Trimesh, measured_xyz: np.ndarray, reach_m: float,
                           samples: int = 20000, seed: int = 0) -> float:
    """Share of ``mesh``'s surface area (``samples`` area-uniform points, seeded) within
    ``reach_m`` of a point of ``measured_xyz`` (N, 3): how much of the surface stereo (or the
    outlines) measured, the rest being what the visual hull, the plate and the shape priors
    made of the gaps. Measured with the masked cloud alone (no rim points) at f682981: 0.59
    on the benchmark's full orbits on average, 0.46-0.54 on its other scenarios
    (docs/measurements.md, Trusted, yet more than 2 % off)."""
    if not len(mesh.faces):
        return 0.0
    points = sample_surface(mesh, samples, seed)
    return float(np.mean(nearest_distances(points, np.asarray(measured_xyz)) <= reach_m))


def support_scene(stages: StageResults, cfg: SupportConfig) -> PointCloud:
    """The points the support plane is sought in: the dense scene cloud, and the SfM points
    too with ``cfg.use_sparse_points``."""
    if not cfg.use_sparse_points or not len(stages.sfm.points_xyz):
        return stages.dense.cloud
    return PointCloud(np.vstack([stages.dense.cloud.xyz, stages.sfm.points_xyz]))


def find_support(masked: PointCloud, scene: PointCloud, up: np.ndarray | None,
                 cfg: SupportConfig) -> tuple[SupportPlane | None, str | None]:
    """(the support plane under the ``masked`` food in ``scene``, None) or, where none is
    found, (None, why): not an error, the mesh is then closed by Poisson alone and
    :func:`estimate_from_stages` flags it."""
    try:
        return fit_support_plane(scene, masked, up, cfg), None
    except MeshingError as e:
        return None, str(e)


def uses_network(cfg: EstimateConfig) -> bool:
    """True when ``cfg``'s completion may call the network (so its model is loaded)."""
    return cfg.use_completion and cfg.completion_method in ("network", "auto")


def network_lacks_up(model: SymmCompletion | None, support: SupportPlane | None,
                     up: np.ndarray | None, cfg: EstimateConfig) -> str | None:
    """Why the network cannot complete this capture (None when it can or is not used): a
    checkpoint that frames its input upright needs the support plane's normal or the
    capture's up, and a capture with neither is completed by nothing (it is already
    flagged ``no_support_plane``)."""
    if (uses_network(cfg) and model is not None and frame_needs_up(model.cfg.input_frame)
            and support is None and up is None):
        return ("the completion network frames its input upright, and neither a support "
                "plane nor the capture's up direction (world_up) is known")
    return None


def completed_cloud(masked: PointCloud, support: SupportPlane | None, up: np.ndarray | None,
                    model: SymmCompletion | None, space: SpaceGrid | None, cfg: EstimateConfig,
                    shown: PointCloud | None = None) -> Completion | None:
    """The masked cloud completed as ``cfg.completion_method`` says, or None without
    completion (also when the network is asked for and ``model`` is None). Mirror and rotation
    work about the support normal, else ``up``; rotation keeps what lands in ``space``'s
    unknown part. ``auto`` turns the cloud where it is symmetric under the half-turn, then
    lets the network complete what is still missing (:func:`symmetry_then_network`). The
    network is also shown the ``shown`` points (:func:`complete_cloud`)."""
    method = cfg.completion_method
    if not cfg.use_completion:
        return None
    plane_up = None if support is None and up is None else np.asarray(
        support.normal if support is not None else up, float)
    if method == "mirror":
        return mirror_completion(masked, plane_up, cfg.completion)
    if method == "rotation":
        if plane_up is None:
            raise VolecError("rotation completion needs a support plane or the capture's up "
                             "direction (world_up)")
        return rotation_completion(masked, plane_up, space, cfg.completion)
    if method == "auto" and plane_up is not None:
        return symmetry_then_network(masked, plane_up, model, space, cfg.completion, shown)
    return None if model is None else complete_cloud(masked, model, cfg.completion, plane_up,
                                                      shown)


def symmetry_then_network(masked: PointCloud, up: np.ndarray, model: SymmCompletion | None,
                          space: SpaceGrid | None, cfg: CompletionConfig,
                          shown: PointCloud | None = None) -> Completion | None:
    """The masked cloud plus its half-turn about the vertical ``up`` where the turn maps it
    onto itself (:func:`volec.completion.complete.rotation_completion`), then the network's
    points farther than ``cfg.missing_only_gap_m`` from all of that (none without ``model``).
    The summary's ``rotation`` holds the turn's (its ``symmetric`` says whether it was used);
    ``predicted_kept`` counts both priors' points."""
    turned = rotation_completion(masked, up, space, cfg)
    if model is None:
        return turned if turned.summary["symmetric"] else None
    start = turned.cloud if turned.summary["symmetric"] else masked
    network = complete_cloud(start, model, cfg, up, shown)
    added = len(start) - len(masked)
    summary = {**network.summary, "partial_points": len(masked),
               "predicted_kept": added + network.summary["predicted_kept"],
               "network_kept": network.summary["predicted_kept"], "rotation": turned.summary}
    return Completion(network.cloud, np.concatenate([turned.predicted_xyz[:added],
                                                     network.predicted_xyz]),
                      network.normalization, summary)


def completion_method_used(completion: Completion, cfg: EstimateConfig) -> str:
    """Which prior made ``completion`` under ``cfg``: ``network``, ``mirror``, ``rotation``
    or (``auto`` on a symmetric cloud) ``rotation+network``."""
    if cfg.completion_method in ("mirror", "rotation"):
        return cfg.completion_method
    turn = completion.summary.get("rotation")
    if turn is None:
        return "rotation" if completion.summary.get("symmetric") else "network"
    return "rotation+network" if turn["symmetric"] else "network"


def food_mesh(masked: PointCloud, support: tuple[SupportPlane | None, str | None],
              up: np.ndarray | None, model: SymmCompletion | None, cfg: EstimateConfig,
              silhouettes: list[SilhouetteView] | None = None,
              space: SpaceGrid | None = None,
              meshes: dict[str, MeshResult] | None = None,
              prior: PriorViews | None = None, rims: PointCloud | None = None) -> FoodMesh:
    """Completion (see :func:`completed_cloud`) and a closed mesh of the food on the
    ``support`` plane (:func:`find_support`), carved by ``silhouettes`` when given, with its
    volume. With ``meshes`` (those already made with the same masked cloud, plane,
    silhouettes and meshing settings, by :func:`cloud_digest`), a cloud meshed before is not
    meshed again: two completion methods often give the same cloud (the default is the
    network alone where the half-turn does not apply, mirror or rotation may add nothing).
    ``prior`` views (:func:`mirror_prior`) carve too, where they may. ``rims``
    (:func:`volec.rims.rim_points`) are meshed as measured surface, after the masked points
    (completion does not see them). The default completion adds the underside's reflected
    points last, as a prior's (:func:`volec.underside.underside_points`, with the plane and
    ``space``)."""
    start = time.perf_counter()
    plane, problem = support
    cloud, summary = masked, None
    skipped = network_lacks_up(model, plane, up, cfg)
    if skipped is not None:
        log.warning("completion skipped: %s", skipped)
    shown = rims if cfg.network_sees_rims else None
    completion = None if skipped else completed_cloud(masked, plane, up, model, space, cfg,
                                                      shown)
    completion_s = time.perf_counter() - start
    if completion is not None:
        cloud = completion.cloud
        summary = {"method": completion_method_used(completion, cfg), **completion.summary}
    observed = masked
    if rims is not None and len(rims):
        observed, cloud = with_rims(masked, cloud, rims)
    if completion is not None and cfg.priors_clear_of_holes and plane is not None \
            and space is not None:
        cloud, cleared = clear_of_hole(cloud, len(observed), observed.xyz.mean(axis=0), plane,
                                       space)
        if cleared:
            summary = {**(summary or {}), "dropped_under_hole": cleared}
    if (completion is not None and uses_underside(cfg) and plane is not None
            and space is not None and observed.normals is not None):
        below, record = underside_points(observed, plane, space, cfg.underside)
        cloud = cloud.joined(below)
        summary = {**(summary or {}), "underside": record}

    def meshed() -> MeshResult:
        enclosed = None  # the space the seen surface encloses, for the meshing's check
        if space is not None and cfg.meshing.food_cover.rounds:
            enclosed = space.points_in(FOOD)
        return mesh_cloud(cloud, plane, cfg.meshing, silhouettes, observed, prior, enclosed)

    if meshes is None:
        mesh = meshed()
    else:  # the same cloud carved by the same views (and the same space: one basis)
        key = cloud_digest(cloud) + views_digest([*(silhouettes or []),
                                                  *(prior.views if prior else ())])
        if key not in meshes:
            meshes[key] = meshed()
        mesh = meshes[key]
    if len(mesh.dropped):  # the prior's points that the meshing's checks dropped
        cloud = cloud.subset(~np.isin(np.arange(len(cloud)), mesh.dropped))
        summary = {**(summary or {}), **{
            f"dropped_for_{name}": mesh.report[check]["prior_points_dropped"]
            for check, name in (("mask_cover", "masks"), ("food_cover", "enclosed_space"))
            if mesh.report.get(check, {}).get("prior_points_dropped")}}
    volume = volume_ml(mesh.mesh)
    share = None
    if completion is not None:
        share = completion_share(mesh.mesh, cloud, len(observed), cfg.completion_share_pitch_m)
    measured = measured_surface_share(mesh.mesh, observed.xyz, cfg.measured_reach_m)
    meshing_s = time.perf_counter() - start - completion_s
    return FoodMesh(cloud, mesh, volume, plane, problem, summary, share,
                    {"completion_s": round(completion_s, 2), "meshing_s": round(meshing_s, 2)},
                    skipped, len(observed), measured)


def clear_of_hole(cloud: PointCloud, n_observed: int, centre: np.ndarray,
                  support: SupportPlane, space: SpaceGrid) -> tuple[PointCloud, int]:
    """``cloud`` without its prior's points (those after the first ``n_observed``) under the
    hole through the food around the vertical axis through ``centre``
    (:func:`volec.space.through_hole`; the whole cloud where there is none), and how many were
    dropped."""
    hole = through_hole(space, centre, support)
    if hole is None:
        return cloud, 0
    drop = np.zeros(len(cloud), bool)
    drop[n_observed:] = hole.below(cloud.xyz[n_observed:], support)
    return cloud.subset(~drop), int(drop.sum())


def uses_underside(cfg: EstimateConfig) -> bool:
    """True when ``cfg``'s estimate reflects the food's upper part below its horizontal mirror
    (:mod:`volec.underside`): the default (``auto``) completion with it enabled."""
    return cfg.use_completion and cfg.underside.enabled and cfg.completion_method == "auto"


def with_rims(masked: PointCloud, cloud: PointCloud, rims: PointCloud
              ) -> tuple[PointCloud, PointCloud]:
    """The observed points (``masked``, then the ``rims``) and the cloud to mesh: ``cloud``
    (``masked``, or ``masked`` then a prior's points) with the rims after the masked points,
    so that the meshing counts them as measured, not as a prior's to drop."""
    observed = masked.joined(rims)
    if len(cloud) < len(masked) or not np.array_equal(cloud.xyz[:len(masked)], masked.xyz):
        return observed, cloud.joined(rims)  # a completion that dropped the partial
    return observed, observed.joined(cloud.subset(np.arange(len(masked), len(cloud))))


def views_digest(views: list[SilhouetteView] | None) -> str:
    """A digest of which views carve (by name: reflected views are named apart)."""
    import hashlib

    return hashlib.sha256("\0".join(v.name for v in views or []).encode()).hexdigest()[:16]


def cloud_digest(cloud: PointCloud) -> str:
    """A digest of what meshing reads of ``cloud``: its points and normals, bit for bit."""
    import hashlib

    digest = hashlib.sha256(np.ascontiguousarray(cloud.xyz, float).tobytes())
    if cloud.normals is not None:
        digest.update(np.ascontiguousarray(cloud.normals, float).tobytes())
    return digest.hexdigest()


def food_silhouettes(capture: Capture, stages: StageResults, cfg: EstimateConfig
                     ) -> list[SilhouetteView] | None:
    """The food silhouettes of the registered frames with a usable mask, for the meshing's
    carving; None when ``cfg`` turns carving off."""
    if not cfg.carve_silhouettes:
        return None
    use = stages.sfm.registered & usable_masks(stages.masks,
                                               stages.masked.report["unusable_masks"])
    return silhouette_views(capture, stages.masks, stages.sfm.T_world_from_cam, use,
                            cfg.meshing.silhouette_max_views)


def capture_up(capture: Capture) -> np.ndarray | None:
    """The capture's up direction where it states one (``world_up`` in transforms.json)."""
    up = capture.metadata.get("world_up")
    return None if up is None else np.asarray(up, float)


def _notes(capture: Capture, stages: StageResults, food: FoodMesh, scale: ScaleCheck | None,
           use_completion: bool) -> list[str]:
    """Warnings that are not trust reasons: things a person should know."""
    notes = []
    if food.support_problem is not None:
        notes.append(f"no support plane: {food.support_problem}")
    if scale is not None and scale.warning:
        notes.append(scale.warning)
    for name, why in stages.masked.report.get("unusable_masks", {}).items():
        notes.append(f"the mask of {name} was left out: {why}")
    if food.completion_problem is not None:
        notes.append(f"completion was skipped: {food.completion_problem}")
    cover = food.mesh.report.get("mask_cover", {})
    if cover.get("prior_points_dropped"):
        notes.append(f"{cover['prior_points_dropped']} completion points were dropped: with "
                     "them the mesh left parts of the food masks uncovered (food the cameras "
                     "saw)")
    elif cover.get("uncovered_p90", 0.0) > cover.get("max_uncovered", 1.0):
        notes.append(f"the mesh leaves {100 * cover['uncovered_p90']:.1f} % of the food masks "
                     "uncovered in one view in ten (mask or pose errors, or food lost)")
    enclosed = food.mesh.report.get("food_cover", {})
    if enclosed.get("prior_points_dropped"):
        notes.append(f"{enclosed['prior_points_dropped']} completion points were dropped: with "
                     "them the mesh cut into space the seen surface encloses")
    if not use_completion:
        notes.append("completion was off: the unseen underside is closed by the support plane "
                     "and Poisson alone (the VolE-style baseline)")
    return notes


def stage_space(stages: StageResults, silhouettes: list[SilhouetteView] | None,
                support: SupportPlane | None, cfg: SpaceConfig) -> SpaceGrid:
    """The space around the masked food of ``stages``: what the cameras saw empty (through
    the scene cloud's depth and the silhouettes), what lies behind what they saw, and what
    nobody constrained (:func:`volec.space.observed_space`)."""
    return observed_space(stages.masked.cloud, silhouettes or [], support, cfg,
                          scene=stages.dense.cloud)


def estimate_bounds(food: FoodMesh, space: SpaceGrid) -> VolumeBounds:
    """The bounds of ``food``'s volume from the ``space`` around it."""
    inside = food.mesh.mesh.contains(space.points())
    return volume_bounds(space, inside, food.volume_ml)


@dataclass(frozen=True, eq=False)
class EstimateBasis:
    """What every completion method of one estimate shares, computed once from the stage
    results (:func:`estimate_basis`): the views that carve, the support plane and the sorted
    space. The experiments estimate five methods on one basis; volec estimate one."""

    silhouettes: list[SilhouetteView] | None
    """The views whose masks may carve (None: no carving)."""
    left_out: tuple[SilhouetteView, ...]
    """Views whose masks left out part of the food (:func:`volec.meshing.consistent_views`)."""
    support: tuple[SupportPlane | None, str | None]
    """The support plane, or None and why not (:func:`find_support`)."""
    space: SpaceGrid
    """The space around the food (:func:`stage_space`)."""
    space_s: float
    """Wall time of the space, seconds."""
    settings: tuple[MeshingConfig, SupportConfig, SpaceConfig, MirrorViewsConfig, RimConfig]
    """The settings it was made with; an estimate with other ones is refused."""
    mirrored: tuple[SilhouetteView, ...] = ()
    """The views reflected in the food's vertical mirror plane that may carve
    (:func:`mirror_carving_views`; none when the food is not symmetric or they are off)."""
    mirror_fit: VerticalMirrorFit | None = None
    """That plane's fit (None when reflected views are off or there is no up direction)."""
    rims: PointCloud | None = None
    """The points the masks' outlines place (:func:`volec.rims.rim_points`; None when off or
    without silhouettes or an up direction)."""
    rims_record: dict[str, Any] | None = None
    """How they were found (rays, points placed and kept, seconds)."""
    meshes: dict[str, MeshResult] = field(default_factory=dict)
    """The meshes made on it so far, by the digest of the cloud each was made from
    (:func:`food_mesh`): a method whose completed cloud another method already meshed takes
    that mesh."""


def estimate_basis(capture: Capture, stages: StageResults, cfg: EstimateConfig,
                   silhouettes: list[SilhouetteView] | None = None) -> EstimateBasis:
    """The :class:`EstimateBasis` of ``stages``: the ``silhouettes`` that may carve, the
    support plane and the space around the food, by ``cfg``'s meshing, support and space
    settings (the completion settings play no part)."""
    left_out: list[SilhouetteView] = []
    if silhouettes is not None:
        silhouettes, left_out = consistent_views(silhouettes, stages.masked.cloud.xyz,
                                                 cfg.meshing)
    support = find_support(stages.masked.cloud, support_scene(stages, cfg.support),
                           capture_up(capture), cfg.support)
    start = time.perf_counter()
    space = stage_space(stages, silhouettes, support[0], cfg.space)
    space_s = time.perf_counter() - start
    up = support[0].normal if support[0] is not None else capture_up(capture)
    mirrored, fit = mirror_carving_views(stages.masked.cloud, silhouettes, up, space, cfg)
    rims, rims_record = None, None
    if cfg.rims.enabled and silhouettes and up is not None:
        rims, rims_record = rim_points(silhouettes, stages.masked.cloud, space, up, cfg.rims,
                                       (cfg.meshing.silhouette_margin_px,
                                        cfg.meshing.silhouette_min_views), support[0])
    return EstimateBasis(silhouettes, tuple(left_out), support, space, space_s,
                         (cfg.meshing, cfg.support, cfg.space, cfg.mirror_views, cfg.rims),
                         mirrored=tuple(mirrored), mirror_fit=fit, rims=rims,
                         rims_record=rims_record)


def mirror_carving_views(masked: PointCloud, silhouettes: list[SilhouetteView] | None,
                         up: np.ndarray | None, space: SpaceGrid, cfg: EstimateConfig
                         ) -> tuple[list[SilhouetteView], VerticalMirrorFit | None]:
    """(the ``silhouettes`` reflected in the masked cloud's vertical mirror plane that agree
    with the cloud, its fit): none when ``cfg.mirror_views`` is off, ``cfg`` completes nothing
    (the plane's search is then skipped), there are no silhouettes or no ``up``, or the cloud
    is not symmetric about the plane. A reflected view whose
    silhouette leaves out more than ``cfg.mirror_views.max_contradiction`` of the cloud
    (:func:`volec.meshing.consistent_views`) says the food is not symmetric as seen from
    there, and does not carve."""
    if not (cfg.mirror_views.enabled and cfg.use_completion) or not silhouettes or up is None:
        return [], None
    fit = fit_vertical_mirror(masked.xyz, np.asarray(up, float), space, cfg.mirror_views)
    if not fit.symmetric:
        return [], fit
    reflected = mirrored_views(silhouettes, reflection_matrix(fit.normal, fit.offset_m),
                               cfg.mirror_views.margin_m, masked.xyz.mean(axis=0))
    strict = replace(cfg.meshing, silhouette_max_contradiction=min(
        cfg.meshing.silhouette_max_contradiction, cfg.mirror_views.max_contradiction))
    return consistent_views(reflected, masked.xyz, strict)[0], fit


def mirror_prior(basis: EstimateBasis, cfg: EstimateConfig) -> PriorViews | None:
    """The basis's reflected views as carving views of their own (None when there are none):
    with ``cfg.mirror_views.spare_seen_food``, they do not carve where the basis's space is
    food (what the cameras showed)."""
    if not basis.mirrored:
        return None
    if not cfg.mirror_views.spare_seen_food:
        return PriorViews(basis.mirrored, lambda points: np.ones(len(points), bool))
    space = basis.space
    return PriorViews(basis.mirrored, lambda points: space.states_at(points) != FOOD)


def uses_mirror_views(cfg: EstimateConfig) -> bool:
    """True when ``cfg``'s estimate carves with the reflected views too."""
    return (cfg.use_completion and cfg.mirror_views.enabled
            and cfg.completion_method in ("auto", "mirror"))


def estimate_from_stages(capture: Capture, stages: StageResults, model: SymmCompletion | None,
                         cfg: EstimateConfig, silhouettes: list[SilhouetteView] | None = None,
                         scale: ScaleCheck | None = None) -> Estimate:
    """The volume estimate from finished stage results: support plane, completion (when
    ``model`` is given), a closed mesh carved by ``silhouettes``, its volume, and the reasons
    it is not to be trusted (:mod:`volec.trust`). The pure core of :func:`run_estimate` and of
    the experiments: :func:`estimate_basis`, then :func:`estimate_from_basis`."""
    return estimate_from_basis(capture, stages, model, cfg,
                               estimate_basis(capture, stages, cfg, silhouettes), scale)


def estimate_from_basis(capture: Capture, stages: StageResults, model: SymmCompletion | None,
                        cfg: EstimateConfig, basis: EstimateBasis,
                        scale: ScaleCheck | None = None) -> Estimate:
    """:func:`estimate_from_stages` on a ``basis`` already made from the same stage results
    with the same meshing, support and space settings as ``cfg``'s (another is a
    :class:`ConfigError`): completion, the mesh, its volume, bounds and trust."""
    if basis.settings != (cfg.meshing, cfg.support, cfg.space, cfg.mirror_views, cfg.rims):
        raise ConfigError("the estimate's meshing, support, space or rim settings differ from "
                          "those its basis was made with")
    up = capture_up(capture)
    silhouettes, left_out, support, space = (basis.silhouettes, basis.left_out, basis.support,
                                             basis.space)
    mirror_record = None
    if uses_mirror_views(cfg) and silhouettes:
        mirror_record = {"fit": None if basis.mirror_fit is None else basis.mirror_fit.record(),
                         "views_carving": len(basis.mirrored),
                         "spare_seen_food": cfg.mirror_views.spare_seen_food}
    prior = mirror_prior(basis, cfg) if mirror_record is not None else None
    food = food_mesh(stages.masked.cloud, support, up, model, cfg, silhouettes, space,
                     basis.meshes, prior, basis.rims)
    view_up = (np.asarray(food.support.normal) if food.support is not None
               else up if up is not None else np.array([0.0, 0.0, 1.0]))
    sfm = stages.sfm
    centres = sfm.T_world_from_cam[sfm.registered][:, :3, 3]
    coverage = azimuth_span_deg(centres, food.mesh.mesh.centroid, view_up)
    start = time.perf_counter()
    bounds = estimate_bounds(food, space)
    bounds_s = round(basis.space_s + time.perf_counter() - start, 2)
    report = food.mesh.report
    facts = TrustFacts(
        frames=len(capture), registered=int(sfm.registered.sum()),
        orbit_coverage_deg=coverage, support_found=food.support is not None,
        carved_fraction=float(report.get("carved_fraction", 0.0)),
        dropped_volume_ml=float(report.get("dropped_volume_ml", 0.0)),
        volume_ml=food.volume_ml, completion_share=food.completion_share,
        scale_estimates=tuple(float(sfm.summary.get(k, 0.0)) for k in
                              ("scale_drift_model", "scale_short_baseline", "scale_sim3_all")),
        unusable_masks=len(stages.masked.report.get("unusable_masks", {})),
        far_point_fraction=report.get("far_points_dropped", 0) / max(report["points_in"], 1),
        unknown_share=bounds.unknown_share,
    )
    scale_std = (sfm_scale_std(sfm, cfg.sfm) if scale is None or scale.source == "file"
                 else math.nan)
    reasons = assess(facts, cfg.trust)
    warnings = [r.message for r in reasons] + _notes(capture, stages, food, scale,
                                                     food.completion_summary is not None)
    if left_out:
        warnings.append(f"{len(left_out)} masks left out part of the food and did not carve "
                        f"the mesh: {', '.join(v.name for v in left_out)}")
    return Estimate(food, reasons, warnings, coverage, view_up, bounds, bounds_s,
                    tuple(v.name for v in left_out), mirror_record, basis.rims_record,
                    scale_std, volume_interval(bounds, scale_std, cfg.scale_sigmas))


def report_pictures(result: FoodMesh, up: np.ndarray, folder: Path, masked: PointCloud
                    ) -> dict[str, Path]:
    """PNG pictures of the masked cloud, the meshed cloud and the mesh, from above and from
    below the table's level (where only completion puts points)."""
    from volec.viz import Geometry, Highlighted, panels_around, save_figure

    panels: dict[str, Geometry] = {"masked cloud": masked}
    if result.completion_summary is not None:
        panels["completed cloud"] = Highlighted(masked, result.cloud.xyz[len(masked):])
    panels["mesh"] = result.mesh.mesh
    paths = {}
    for name, elevation in (("above", 35.0), ("below", -25.0)):
        fig = panels_around(panels, up, elevation)
        paths[name] = save_figure(fig, folder / f"stages_{name}.png")
    return paths


def masks_picture(capture: Capture, masks: MaskSet, folder: Path, frames: int = 6) -> Path:
    """A strip of ``frames`` frames, evenly spread, with their food masks' outlines."""
    from PIL import Image

    from volec.viz import mask_outline_strip, save_figure

    chosen = np.round(np.linspace(0, len(capture) - 1, min(frames, len(capture)))).astype(int)
    images = []
    for i in chosen:
        with Image.open(capture.frames[i].image_path) as im:
            images.append(np.asarray(im.convert("RGB")))
    titles = [f"{Path(capture.frames[i].name).stem} ({masks.source})" for i in chosen]
    fig = mask_outline_strip(images, [masks.mask(int(i)) for i in chosen], titles)
    return save_figure(fig, folder / "masks.png")


def report_scene(est: Estimate) -> ReportScene:
    """What the report's 3D view shows: the mesh, the measured points (the masked cloud in
    its colours and the rim points) and the shape priors' points (those the completion and
    the underside's mirror added after them)."""
    observed = est.food.observed_points
    return ReportScene(est.food.mesh.mesh, est.food.cloud.subset(np.arange(observed)),
                       est.food.cloud.xyz[observed:], est.view_up)


def report_markdown(result: dict[str, Any], pictures: dict[str, Path], out_dir: Path) -> str:
    """The human-readable report of an estimate."""
    trust = ("**trusted**" if result["trusted"] else
             "**not trusted**: " + "; ".join(r["message"] for r in result["reasons"]))
    lines = [
        "# volec estimate",
        "",
        f"**Volume: {result['volume_ml']:.1f} mL** "
        f"({'with' if result['completion_used'] else 'without'} completion), {trust}",
        "",
        bounds_sentence(result),
        "",
        f"- capture: `{result['capture']}`",
        f"- frames used: {result['frames']['registered']} of {result['frames']['total']}",
        f"- scale: {result['scale']['source']}",
        f"- food masks: {result['masks']['source']}",
        f"- mesh: {result['mesh']['faces']} faces, watertight, `mesh.ply` / `mesh.glb`",
        f"- support plane: {'found' if result['support_plane'] else 'not found'}",
        f"- volec {result['volec_version']}",
        "",
        "## Warnings",
        "",
        *([f"- {w}" for w in result["warnings"]] or ["none"]),
        "",
        "## Wall time per stage (s)",
        "",
        "| stage | seconds |",
        "|---|---|",
        *[f"| {k.removesuffix('_s')} | {v:.1f} |" for k, v in result["stage_seconds"].items()],
        "",
        "## Pictures",
        "",
    ]
    for name, path in pictures.items():
        caption = {"masks": "The frames, with the food masks' outlines"}.get(
            name, f"Seen from {name}")
        lines += [f"{caption}:", "", f"![{name}]({path.relative_to(out_dir)})", ""]
    return "\n".join(lines)


def estimate_record(capture: Capture, stages: StageResults, est: Estimate, cfg: EstimateConfig,
                    scale: ScaleCheck, seconds: dict[str, float]) -> dict[str, Any]:
    """What ``result.json`` says of an estimate (its ``files`` and ``provenance`` are added
    when it is written)."""
    food = est.food
    return {
        "volume_ml": food.volume_ml,
        **est.bounds.record(),
        # JSON has no NaN or infinity: a scale no model bounds is written as null
        "volume_interval_ml": [round(v, 2) if math.isfinite(v) else None
                               for v in est.volume_interval_ml],
        "scale_std_pct": (round(100 * est.scale_std, 4) if math.isfinite(est.scale_std)
                          else None),
        "trusted": est.trusted,
        "reasons": [r.record() for r in est.reasons],
        "warnings": est.warnings,
        "completion_used": food.completion_summary is not None,
        "frames": {"total": len(capture), "registered": int(stages.sfm.registered.sum())},
        "orbit_coverage_deg": round(est.orbit_coverage_deg, 1),
        "scale": scale.record(),
        "masks": {"source": stages.masks.source,
                  "unusable": stages.masked.report.get("unusable_masks", {}),
                  "segmentation_listed": stages.masks.failed,
                  "left_out_of_carving": list(est.silhouettes_left_out),
                  "confidence_median": float(np.median(stages.masks.confidence))
                  if stages.masks.confidence else None},
        "stage_seconds": seconds,
        "stages_reused": list(stages.reused),
        "support_plane": None if food.support is None else food.support.record(),
        "mesh": {k: food.mesh.report.get(k) for k in (
            "faces", "vertices", "watertight", "grid_voxel_m", "cut_at_support",
            "silhouette_views", "prior_views", "carved_fraction", "pieces_dropped",
            "dropped_volume_ml", "far_points_dropped", "mask_cover", "food_cover")},
        "completion": food.completion_summary,
        "completion_share": food.completion_share,
        "measured_surface_share": food.measured_surface_share,
        "mirror_views": est.mirror_views,
        "rims": est.rims,
        "capture": str(capture.root),
        "checkpoint": (str(checkpoint_path(cfg)) if food.completion_summary is not None
                       and "network" in food.completion_summary["method"] else None),
        "volec_version": __version__,
        "config": json_data(cfg),
    }


def result_provenance(identity: dict[str, Any], cfg: EstimateConfig,
                      stages: StageResults | None) -> dict[str, Any]:
    """The provenance of an estimate: the capture, the stages' records (unknown, and left
    empty, before they ran), the completion checkpoint, the config and the code."""
    upstream = {} if stages is None else stages.digests()
    if cfg.use_completion and stages is not None:
        upstream["checkpoint"] = file_digest(checkpoint_path(cfg))
    return stage_provenance(identity, cfg, upstream, MODULES)


def write_outputs(out_dir: Path, est: Estimate, capture: Capture, stages: StageResults
                  ) -> dict[str, str]:
    """The clouds, meshes and report pictures of an estimate in ``out_dir``; returns the file
    names that ``result.json`` lists."""
    food = est.food
    files = {"scene": "scene.ply", "food_masked": "food_masked.ply", "mesh_ply": "mesh.ply",
             "mesh_glb": "mesh.glb", "report": "report.md", "report_html": "report.html"}
    if food.completion_summary is not None:
        write_ply(with_normals(food.cloud), out_dir / "food_completed.ply")
        files["food_completed"] = "food_completed.ply"
    write_bytes_atomic(out_dir / "mesh.ply", food.mesh.mesh.export(file_type="ply"))
    write_bytes_atomic(out_dir / "mesh.glb", food.mesh.mesh.export(file_type="glb"))
    pictures = report_pictures(food, est.view_up, out_dir / "report", stages.masked.cloud)
    pictures["masks"] = masks_picture(capture, stages.masks, out_dir / "report")
    files.update({f"picture_{k}": str(p.relative_to(out_dir)) for k, p in pictures.items()})
    return files


def _finished_result(out_dir: Path, wanted: dict[str, Any]) -> dict[str, Any] | None:
    """The result in ``out_dir`` when it is exactly what this run would compute."""
    record = read_record(out_dir / RESULT_FILE)
    if record is None or stale_reasons(record, wanted, out_dir, RESULT_FILE):
        return None
    return record


def run_estimate(capture: Capture, out_dir: Path, cfg: EstimateConfig | None = None,
                 overwrite: bool = False, progress: bool = True,
                 scale: ScaleCheck | None = None) -> dict[str, Any]:
    """Run every stage on ``capture`` into ``out_dir`` (see the module docstring) and return
    the record written to ``result.json``. ``scale``: why the capture is metric, when the
    caller already checked (:func:`volec.scale.require_metric`; checked here otherwise).

    Refused before any work: an output folder inside the capture, a capture that is not metric
    (:class:`~volec.errors.ScaleError`), unusable masks, a folder holding results made from
    other inputs (unless ``overwrite``), a folder another run is writing into. A finished
    estimate made from exactly these inputs is returned as it is."""
    cfg = cfg or EstimateConfig()
    out_dir = Path(out_dir)
    check_output_folder(capture, out_dir)
    scale = scale or require_metric(capture, cfg.scale)
    selection = choose_keyframes(capture, cfg.keyframes)
    keyframes = selection.record(capture)
    capture = keyframe_capture(capture, selection)
    if masks_source(capture, cfg.masks) == "given":  # checked before any work
        check_masks(given_masks(capture), cfg.masking.checks)
    model = load_completion_model(cfg) if uses_network(cfg) else None
    identity = capture_identity(capture)
    with folder_lock(out_dir):
        preflight(out_dir, {RESULT_FILE: result_provenance(identity, cfg, None)}, overwrite,
                  "refuse")
        start = time.perf_counter()
        stages = run_stages(capture, out_dir, cfg.sfm, cfg.dense, cfg.masking, overwrite,
                            progress=progress, identity=identity, masks=cfg.masks,
                            segment_cfg=cfg.segment)
        wanted = result_provenance(identity, cfg, stages)
        finished = None if overwrite else _finished_result(out_dir, wanted)
        if finished is not None:
            step(progress, f"{out_dir / RESULT_FILE} is already finished: "
                f"{finished['volume_ml']:.1f} mL")
            return finished
        (out_dir / RESULT_FILE).unlink(missing_ok=True)  # gone until the new one is complete
        seconds = dict(stages.seconds)
        step(progress, "support plane" + (", completion" if model else "") + " and meshing")
        t = time.perf_counter()
        silhouettes = food_silhouettes(capture, stages, cfg)
        seconds["silhouettes_s"] = round(time.perf_counter() - t, 2)
        est = estimate_from_stages(capture, stages, model, cfg, silhouettes, scale)
        seconds.update(est.food.seconds)
        seconds["bounds_s"] = est.bounds_s
        step(progress, "writing the clouds, the mesh and the report")
        t = time.perf_counter()
        files = write_outputs(out_dir, est, capture, stages)
        seconds["report_s"] = round(time.perf_counter() - t, 2)
        seconds["total_s"] = round(time.perf_counter() - start, 2)
        record = estimate_record(capture, stages, est, cfg, scale, seconds)
        record["keyframes"] = keyframes
        pictures = {k.removeprefix("picture_"): out_dir / v for k, v in files.items()
                    if k.startswith("picture_")}
        write_text_atomic(out_dir / "report.md", report_markdown(record, pictures, out_dir))
        write_report_html(out_dir / "report.html", record, report_scene(est),
                          {name: path.read_bytes() for name, path in pictures.items()})
        record["provenance"] = wanted
        record["files"] = {name: file_digest(out_dir / name) for name in files.values()}
        write_json_atomic(out_dir / RESULT_FILE, record)
    step(progress, f"done: {est.food.volume_ml:.1f} mL in {seconds['total_s']:.0f} s"
        + ("" if est.trusted else " (not trusted)"))
    return record
