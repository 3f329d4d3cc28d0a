"""Dense reconstruction on the CPU: plane-sweep stereo depth maps fused into one cloud.

In: a :class:`~volec.capture.Capture` (images, intrinsics, optional food masks), the
refined metric poses and sparse points of :class:`~volec.sfm.SfmResult`, and a
:class:`DenseConfig`. Out: a :class:`DenseResult` whose ``cloud`` is the fused scene cloud
(metres, the capture's world frame, with colours and normals) and a summary (counts,
timings). :func:`run_dense` is the pure core; :func:`save_dense` / :func:`load_dense` write
and read ``WORKDIR/scene.ply`` and ``WORKDIR/dense.json``.

Why volec has its own stereo: the paper densifies with OpenMVS on CUDA and pycolmap's wheel
has no CPU PatchMatch, so each view's depth is found here by a plane sweep written in torch
(the same code runs on a GPU when one is present):

1. every ``reference_stride``-th registered frame is a reference view, at most
   ``max_image_size_px`` on its long side; its work is restricted to the food mask's
   surroundings (the mask dilated by ``roi_margin_px``) when the capture has masks, and the
   depth range comes from the sparse SfM points seen there;
2. a few source views with a good triangulation angle are warped onto fronto-parallel
   planes, uniform in inverse depth; the cost is the zero-mean normalised cross-correlation
   (NCC) over a small window, averaged over the best ``top_k_sources`` sources (so a source
   in which the point is occluded does not veto it);
3. the best plane is refined per pixel by two finer local sweeps and a parabola through the
   last three costs (sub-plane depth);
4. depths with a low NCC, or at the ends of the range, are dropped; the rest must agree with
   the depth maps of ``geometric_min_views`` neighbour views (reprojection and relative
   depth), and each kept point is the mean of its agreeing estimates;
5. a depth its camera saw obliquely is dropped; with ``min_oblique_cosine`` under
   ``min_view_cosine`` it is kept where no view saw that surface more frontally (it fills a
   hole there: a wall seen only from high, the band under a round item's widest level);
   with ``contour_margin_px``, a depth just inside its view's food outline likewise gives
   way to depths from further inside some other view;
6. the points of all views, with normals from the depth maps' gradients and colours from
   the images, are merged on a voxel grid of ``fusion_voxel_m``.
"""

from __future__ import annotations

import logging
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image
from scipy import ndimage

from volec.capture import Capture, Frame, Intrinsics
from volec.errors import ConfigError, VolecError
from volec.geometry import invert_rigid
from volec.pointcloud import (
    PointCloud,
    from_open3d,
    read_cloud_record,
    to_open3d,
    write_cloud_record,
)
from volec.progress import progress_over
from volec.segment import MaskSet

log = logging.getLogger(__name__)


class DenseError(VolecError):
    """Dense reconstruction could not produce a trustworthy cloud for this capture."""


@dataclass(frozen=True)
class DenseConfig:
    """Options of the dense stage; the defaults suit a 100-frame 480x640 phone orbit."""

    max_image_size_px: int = 512
    """Images are downscaled to at most this many pixels on the long side (paper: OpenMVS
    ``max-resolution 512``)."""
    roi: str = "mask"
    """``mask``: estimate depth only around the food mask (dilated by ``roi_margin_px``), the
    part of the scene the volume needs; ``full``: the whole image. Without masks in the
    capture ``mask`` falls back to ``full``."""
    roi_margin_px: int = 12
    """Dilation of the food mask, in working-resolution pixels, that bounds the work."""
    reference_stride: int = 2
    """Every this-many-th registered frame is a reference view (gets a depth map); every
    registered frame can be a source, and the reference views' depth maps are checked against
    each other. On a 100-frame orbit, 2 instead of 1 halves the depth and fusion time
    (croissant: 46 s to 24 s) and kept the volume error of the benchmark banana, croissant
    and apple within 0.3 % of the truth or better (with completion: -2.7/+2.0/-1.8 % at 1,
    -1.6/+1.7/-0.7 % at 2; mesh Chamfer distances within 0.08 mm)."""
    n_sources: int = 3
    """Source views compared with each reference view. 3 (with 48 planes) since 2026-12-05:
    4 and 64 planes (the ``thorough`` preset) took 1.45 times as long (``run_dense`` alone,
    one thread: capsicum 14.7 against 10.1 s, apple 11.9 against 8.1 s) for the same volume
    accuracy (Table II default MAPE, 64/4 -> 48/3: full orbit 1.69 -> 1.66 %, half 3.20 ->
    3.19, sparse 2.61 -> 2.44, low 2.01 -> 1.72, smooth 2.02 -> 2.03) and a surface a few
    hundredths of a millimetre further off (docs/measurements.md, Reproducing)."""
    source_angle_deg: tuple[float, float, float] = (4.0, 14.0, 40.0)
    """Triangulation angle at the object between reference and source camera: (smallest,
    preferred, largest), degrees."""
    top_k_sources: int = 2
    """The cost of a depth is the mean NCC of the best this-many sources."""
    ncc_window_px: int = 7
    """Side of the square NCC window, pixels (odd)."""
    faint_window_px: int = 0
    """Side of a larger NCC window (odd) used instead where the reference image is faint: the
    intensity standard deviation in its ``ncc_window_px`` window is below
    ``faint_texture_std`` (a peach's or a plum's skin); 0: one window everywhere. The warped
    source is shared, so it costs only the larger window's box filters (1.11-1.22 times the
    dense time, measured on two items). Off by default: 11 raised the faint-skin coverage
    (exact poses: banana 77 -> 84 %, pear 66 -> 76 %) but moved the ``smooth`` scenario's
    volume MAPE from 2.02 to 2.39 % (docs/measurements.md, Completion): the fronto-parallel
    window is biased on curved faint skin."""
    faint_texture_std: float = 0.02
    """With ``faint_window_px``: a reference window with less intensity standard deviation
    (0..1 scale) than this is faint and matched over the larger window."""
    n_depth_planes: int = 48
    """Fronto-parallel planes of the first sweep, uniform in inverse depth (the refining
    sweeps that follow find the depth between them; see ``n_sources`` for 64)."""
    coarse_factor: int = 1
    """The first sweep (``n_depth_planes``) runs on the images shrunk by this factor on each
    side, and its depth, enlarged again, is what the refining sweeps start from at the
    working resolution (refined first at the coarse level too); 1: the first sweep at the
    working resolution. Off by default: at 2 the dense stage took 0.55-0.6 of its time and
    the masked cloud covered more of the faint skins (``smooth`` banana, pear, orange,
    capsicum: 59.0 -> 70.7 % of the surface two cameras saw), but the added depths lie
    inside the surface (faint banana: median -0.66 -> -0.86 mm) and the volumes followed them
    in (default MAPE on those four 1.37 -> 2.29 %, on the full orbits of the apple, banana,
    pear and orange 0.83 -> 1.84 %, the banana -0.6 -> -3.3 %; docs/measurements.md, Dense
    cloud): the refining sweeps at full resolution do not undo the large window's bias where
    the skin is too faint for their own windows."""
    coarse_min_cosine: float = 0.0
    """With ``coarse_factor`` above 1 and this above 0: the first sweep runs at both
    resolutions, and a pixel starts from the coarse one's depth only where the surface that
    depth implies faces the camera at least this much (the cosine between the plane fitted to
    the enlarged coarse depths and the view ray, :func:`depth_normals`), else from the
    full-resolution one's. Off: at 2 and 0.75 the ten faint skins' default MAPE went from
    1.61 to 1.40 % (p = 0.01) and their coverage up by 5 points, but the 21 full orbits'
    from 1.08 to 1.09 % with a slightly worse surface, and dense stereo took 1.2-1.3 times as
    long (docs/measurements.md, Dense cloud)."""
    n_refine_hypotheses: int = 7
    """Depths tried per pixel in each refining sweep."""
    refine_span_planes: float = 0.5
    """The first refining sweep tries depths within this many plane spacings either side of
    the first sweep's."""
    refine_sweeps: int = 2
    """Local sweeps, each finer, that refine the first sweep's depth (0: the plane sweep and
    its parabola alone)."""
    food_window_erode_px: int = 0
    """Above 0: a food pixel's NCC is taken over the food pixels of its window alone, the
    food mask shrunk by this many pixels (working resolution); the plate's pixels keep the
    whole window (0: off, the default; without masks it does nothing). A window that reaches
    the food's outline is pulled behind the surface by the silhouette's edge and the plate
    past it (docs/measurements.md, Dense cloud). At 2, with the exact poses, the depths 0-2,
    2-4 and 4-6 px inside the outline went from +3.9, +7.2 and +3.9 mm behind the surface along
    the ray to -0.9, +0.5 and +1.2 mm (full-orbit banana; apple +2.8, +5.6, +3.1 to -2.3, -0.3,
    +0.8 mm). But the default estimate lost volume with it (MAPE 0.78 -> 1.25 % on the 21 full
    orbits, p = 0.042, mean signed -0.26 -> -0.94 %; 1.40 -> 2.18 % on the ten faint skins)
    while without completion nothing changed (1.45 -> 1.47 %, 1.92 -> 1.95 %): the food-only
    windows lose the lowest band's depths, which each view sees near its outline (apple: no
    masked point below 15.8 mm above the plate instead of 1.8 mm), and the completion, which
    works from the cloud's lower edge, then places the underside further in
    (docs/measurements.md). Off: a food-only window must keep that band to help. Three more box
    filters per hypothesis: the dense stage took 7.1-8.5 s instead of 5.0-6.1 s (banana and
    apple full orbits, twice each, one capture at a time), more than issue 13's quarter. The
    texture test (``min_texture_std``) still takes the whole window's statistics."""
    refine_median_px: int = 0
    """Before each refining sweep, the inverse depths it starts from, and that its windows
    follow, are median-filtered over this many pixels square (3 or 5; 0: taken as they are).
    The windows follow the surface by warping each pixel at its own depth; where the first
    sweep's peak was wrong (a faint skin, an oblique view), a pixel's own depth and its
    window's are outliers that the local sweep cannot reach, and its neighbours' windows
    follow it too. Started from the median of its neighbours' instead, it is refined about
    the surface around it. With the exact poses on the benchmark's phone-look full orbits
    (``benchmarks/bench_depth_bias.py``), 5 took the share of food pixels whose depth lies
    within the 0.5 % fusion's consistency test asks from 41 to 56 % (banana), 41 to 59 %
    (apple) and 37 to 56 % (chocolate cake), on the faintest skin (window standard deviation
    under 0.01) from 46 to 72 %, 29 to 62 % and 33 to 58 %, the median errors within 0.05 mm
    of before; on the ten faint-skinned items it covered 79.7 % of the surface two cameras
    saw instead of 72.5 %. Off by default: the added depths lie a little inside, and the
    volumes did not gain (21 full orbits: the default estimate's MAPE 0.78 -> 0.83 %, p =
    0.61, without completion 1.45 -> 1.34 %; the ten faint skins: 1.40 -> 1.38 %, p = 0.92;
    docs/measurements.md, Dense cloud and masking). With ``fill_min_views=1`` too the faint
    skins' coverage reached 89.2 %, but the volumes went down with it (faint skins 1.40 ->
    1.65 %, full orbits 0.78 -> 0.87 %): the depths added on sides seen only at grazing angles
    lie behind the surface (docs/measurements.md)."""
    depth_range_margin: float = 0.08
    """The sparse points' depth range (2nd to 98th percentile) is widened by this fraction."""
    min_ncc: float = 0.45
    """Depths whose aggregated NCC is below this are dropped."""
    min_texture_std: float = 0.004
    """Pixels whose window's intensity standard deviation (0..1 scale) is below this are
    textureless: no depth is estimated there."""
    geometric_max_reprojection_px: float = 1.0
    """A neighbour agrees when its depth re-projects to within this many pixels..."""
    geometric_max_relative_depth: float = 0.005
    """... and within this fraction of the depth."""
    geometric_min_views: int = 2
    """Neighbour depth maps that must agree for a depth to be kept everywhere."""
    fill_min_views: int = 2
    """A depth that at least this many (but fewer than ``geometric_min_views``) neighbour depth
    maps agree with is kept where no point that ``geometric_min_views`` confirmed lies within
    ``fill_gap_m``: it fills a hole, as on a faint skin, whose noisier depths two neighbours
    rarely both confirm. Equal to ``geometric_min_views``: off, the default. With 1, on four
    faint-skin items (``smooth``, SfM poses, the given masks) dense stereo covered more of
    the surface two cameras saw: banana 71.5 -> 85.1 %, capsicum 42.6 -> 61.7, pear 59.7 ->
    75.4, orange 62.1 -> 80.1 (the masked cloud's median signed distance moved by at most
    0.03 mm; its 10th percentile by up to 0.2 mm inwards). But on the ten ``smooth`` items
    the default estimate's MAPE went from 1.93 to 2.33 % (banana -4.6 -> -6.1 %, capsicum
    -0.9 -> -2.8, pear -3.3 -> -4.0; lemon +1.8 -> 0.0) and without completion from 2.47 to
    2.58 %: the depths it adds on a faint, curved skin lie inside it, as a larger window's do
    (``faint_window_px``), and the volume follows them in (``benchmarks/bench_volume.py
    --scenario smooth --set dense.fill_min_views=1`` against the default, in copies of
    data/)."""
    fill_gap_m: float = 0.0015
    """With ``fill_min_views``: how far, metres, the nearest confirmed point must be for a
    depth fewer neighbours agree with to fill the gap."""
    min_view_cosine: float = 0.5
    """A depth whose surface the reference camera sees more obliquely than this (the cosine
    between the surface normal and the direction to the camera) is oblique: a window on a
    grazing, curving surface matches it too far (benchmark banana, exact poses, phone look:
    raw depths 1.2 mm too far, normal to the surface, under cos 0.5; 0.4 mm at 0.5-0.7; 0.04
    mm above 0.85), and on an orbit the same surface is seen face-on from other frames. On
    five phone-look items (SfM poses) 0.5 moved the mesh's aligned median signed distance
    towards zero on four (banana -0.25 to -0.15 mm, pear -0.19 to -0.09, capsicum -0.12 to
    -0.01) and the mean volume error from 2.5 to 2.2 %; on the croissant, whose grazing sides
    bound the gap under it, the overestimate grew (+2.1 to +3.7 %). Those measurements used
    normals from neighbouring depths, 25-40 degrees off the surface's, so the cosines they
    were binned by were blurred. With the fitted-plane normals (:func:`depth_normals`), exact
    poses and depths kept down to a cosine of 0.1, the fused depths' median signed distance to
    the true surface was within 0.05 mm down to a cosine of 0.3 on the apple, pear and orange,
    but -0.18 to -0.26 mm on the faintly textured banana between 0.2 and 0.4; with SfM poses
    and no completion, 0.4 and 0.3 instead of 0.5 moved the banana from -0.5 to -1.6 and
    -2.6 %, the pear from -0.6 to -1.0 and -1.1 %, the croissant from +5.0 to +4.7 and
    +3.9 %, the apple and orange by 0.3 % or less: 0.5 stays. Oblique depths are dropped
    unless ``min_oblique_cosine`` is lower (then they may fill holes); 0 keeps all."""
    min_oblique_cosine: float = 0.5
    """Depths seen more obliquely than this are dropped everywhere (the rims of the
    silhouette, where windows straddle surfaces at very different depths). Equal to
    ``min_view_cosine`` (the default) no depth counts as oblique, so the hole filling of
    ``oblique_gap_m`` is off. 0.2 turns it on: on ten full-orbit phone-look items (SfM poses,
    ``OMP_NUM_THREADS=1``, two at a time) it changed the mean absolute volume error without
    completion from 2.46 to 2.37 %, but with network completion from 2.24 to 2.34 % (capsicum
    -1.12 to -2.27 %, lemon +1.79 to +2.17; pear -1.38 to -1.10, yellow cane +2.94 to +2.76),
    at the same dense time (247 s against 242 s over the ten), so it is not the default. The
    differences were within the run-to-run spread of the time: the pear at 0.5, stages
    recomputed from the same SfM stage, gave 77,284 then 77,251 food points and a completion
    error of -1.38 then -0.88 % (``benchmarks/bench_oblique_fusion.py``). That spread came from
    the reloaded SfM points, rounded to float32 (fixed: ``sfm/points.npz``), so this is worth
    measuring again."""
    oblique_gap_m: float = 0.0015
    """An oblique depth is kept where no frontal point (``min_view_cosine`` or better, from any
    view) lies within this distance: there it fills a hole, where it would otherwise be
    dropped. On an orbit most surface is seen face-on from some frame, but not all: a vertical
    face towards the azimuths where the phone was held high, and the band under a round item's
    widest level, are seen only obliquely (the benchmark orbit's elevation swings between 20
    and 60 degrees)."""
    normal_window_px: int = 7
    """Side of the window, pixels, whose depths a plane is fitted to for each depth's normal
    (:func:`depth_normals`)."""
    normal_max_thickness: float = 0.005
    """A window whose points stand off their fitted plane by more than this share of the
    depth (root mean square) straddles two surfaces: its depth gets no normal and is
    dropped."""
    contour_margin_px: float = 0.0
    """Depths less than this many pixels (working resolution) inside their view's food-mask
    outline give way to the others: they are dropped where a depth from further inside some
    view lies within ``contour_gap_m``, and kept where none does (0: off, the default;
    without masks, or with ``roi="full"``, it does nothing). Near its outline a view sees the
    surface at a grazing angle, and those depths lie behind it: on the faint banana with the
    exact poses, the confirmed depths 2-4 px inside the outline at a median of 1.3 mm inside
    the surface, 4-6 px 2.1 mm, from 6 px on 0.0 mm. At 6 (``contour_gap_m`` 3 mm) the
    default estimate's MAPE went 1.40 -> 1.01 % on the ten faint skins (p = 0.10) and 0.78
    -> 0.73 % on the 21 full orbits (p = 0.55), but 1.20 -> 1.49 % on the half orbits (p =
    0.09), 1.07 -> 1.40 % on the sparse ones (p = 0.018) and 1.81 -> 1.95 % at low
    elevations, and without completion every scenario but the low one lost (full orbits
    1.45 -> 1.64 %, p = 0.046): the inward depths it removes were offsetting outward errors
    elsewhere (docs/measurements.md, Dense cloud). With the visual hull's silhouette margin at
    0.25 px as well, the losses without completion went, but not the default's on half orbits
    (1.64 %) and sparse ones (1.36 %). Off until those are found."""
    contour_gap_m: float = 0.003
    """With ``contour_margin_px``: how far, metres, the nearest depth from further inside an
    outline must be for a depth near one to be kept (it fills a hole). Larger than the depths'
    offset there, so that they do not count as a hole behind the surface."""
    fusion_voxel_m: float = 0.0005
    """Voxel size of the final merge, metres (0 keeps every point)."""
    planes_per_chunk: int = 16
    """Planes evaluated at once (bounds memory: about 20 floats per pixel and plane)."""
    device: str = "auto"
    """torch device: ``auto`` (CUDA when present, else CPU), ``cpu`` or ``cuda``."""


PRESETS: dict[str, DenseConfig] = {
    "default": DenseConfig(),
    # The default before 2026-12-05: 64 planes and 4 sources, 1.45 times the time.
    "thorough": DenseConfig(n_depth_planes=64, n_sources=4),
    # Kept for scripts that name it: the default has been as fast since it took these values.
    "fast": DenseConfig(n_depth_planes=48, n_sources=3),
    "full_image": DenseConfig(roi="full"),
}


@dataclass(frozen=True, eq=False)
class View:
    """A frame at working resolution, ready for stereo."""

    index: int
    """Index of the frame in the capture."""
    K: np.ndarray
    """3x3 calibration at working resolution (OpenCV pixel centres)."""
    T_cam_from_world: np.ndarray
    """4x4 world-to-camera transform (refined pose), metres."""
    gray: np.ndarray
    """(H, W) float32 intensity in 0..1."""
    rgb: np.ndarray
    """(H, W, 3) uint8 colour."""
    roi: np.ndarray
    """(H, W) bool: where depth is estimated."""
    food: np.ndarray | None = None
    """(H, W) bool food mask at working resolution (None without masks)."""

    @property
    def centre(self) -> np.ndarray:
        """Camera centre, world, metres."""
        return invert_rigid(self.T_cam_from_world)[:3, 3]


@dataclass(eq=False)
class DepthMap:
    """One view's estimated depth."""

    depth_m: np.ndarray
    """(H, W) float32 depth along the optical axis, metres; 0 where there is none."""
    ncc: np.ndarray
    """(H, W) float32 aggregated NCC of the chosen depth (-1 where there is none)."""
    sources: list[int]
    """Positions (in the view list) of the source views used."""


@dataclass(eq=False)
class DenseResult:
    """The fused scene cloud and how it was made."""

    cloud: PointCloud
    """Scene cloud, metres, world frame, with colours and normals."""
    summary: dict[str, Any] = field(default_factory=dict)
    """Counts per step, depth ranges, timings (JSON-able)."""


# ----------------------------------------------------------------------------- views


def _undistort(image: np.ndarray, intr: Intrinsics, nearest: bool) -> np.ndarray:
    """``image`` resampled to the pinhole camera ``intr.K`` (no-op without distortion)."""
    if intr.is_undistorted:
        return image
    import cv2

    K, dist = intr.K, np.asarray(intr.distortion, float)
    size = (intr.width, intr.height)
    if intr.model == "OPENCV_FISHEYE":
        maps = cv2.fisheye.initUndistortRectifyMap(K, dist, np.eye(3), K, size, cv2.CV_32FC1)
    else:
        maps = cv2.initUndistortRectifyMap(K, dist, np.eye(3), K, size, cv2.CV_32FC1)
    interp = cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR
    return cv2.remap(image, maps[0], maps[1], interp)


def working_size(intr: Intrinsics, max_image_size_px: int) -> tuple[int, int, float]:
    """(width, height, factor) of the working resolution: the long side at most
    ``max_image_size_px``, never enlarged."""
    factor = min(1.0, max_image_size_px / max(intr.width, intr.height))
    return int(round(intr.width * factor)), int(round(intr.height * factor)), factor


def prepare_view(index: int, frame: Frame, T_world_from_cam: np.ndarray,
                 cfg: DenseConfig, mask: np.ndarray | None) -> View:
    """Load, undistort and downscale one frame; its ROI from its food ``mask`` (or the whole
    image when None)."""
    intr = frame.intrinsics
    with Image.open(frame.image_path) as im:
        rgb = np.asarray(im.convert("RGB"))
    rgb = _undistort(rgb, intr, nearest=False)
    w, h, factor = working_size(intr, cfg.max_image_size_px)
    if factor < 1.0:
        rgb = np.asarray(Image.fromarray(rgb).resize((w, h), Image.Resampling.BOX))
    if mask is not None:
        mask = _undistort(mask.astype(np.uint8), intr, nearest=True)
        mask = np.asarray(Image.fromarray(mask * 255).resize((w, h), Image.Resampling.BOX)) > 0
        roi = ndimage.binary_dilation(mask, iterations=cfg.roi_margin_px) if mask.any() else mask
    else:
        roi = np.ones((h, w), bool)
    gray = (rgb.astype(np.float32) @ np.array([0.299, 0.587, 0.114], np.float32)) / 255.0
    return View(index, intr.scaled(factor).K if factor < 1.0 else intr.K,
                invert_rigid(T_world_from_cam), gray, rgb, roi, mask)


# ----------------------------------------------------------------------------- geometry


def project(K: np.ndarray, T_cam_from_world: np.ndarray, xyz: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates (N, 2) and depths (N,) of world points in a camera."""
    cam = xyz @ T_cam_from_world[:3, :3].T + T_cam_from_world[:3, 3]
    z = cam[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = (cam[:, :2] / z[:, None]) * np.diag(K)[:2] + K[:2, 2]
    return uv, z


def backproject(K: np.ndarray, T_cam_from_world: np.ndarray, uv: np.ndarray,
                depth: np.ndarray) -> np.ndarray:
    """World points (N, 3) of pixels ``uv`` (N, 2) at ``depth`` (N,) metres."""
    x = (uv[:, 0] - K[0, 2]) / K[0, 0]
    y = (uv[:, 1] - K[1, 2]) / K[1, 1]
    cam = np.stack([x * depth, y * depth, depth], axis=1)
    T = invert_rigid(T_cam_from_world)
    return cam @ T[:3, :3].T + T[:3, 3]


def depth_range(view: View, sparse_xyz: np.ndarray, margin: float) -> tuple[float, float] | None:
    """(near, far) metres from the sparse points seen inside the view's ROI, widened by
    ``margin``; None when fewer than 10 points fall there."""
    uv, z = project(view.K, view.T_cam_from_world, sparse_xyz)
    h, w = view.roi.shape
    ok = (z > 0) & np.all(np.isfinite(uv), axis=1)
    iu = np.round(uv[ok]).astype(int)
    inside = (iu[:, 0] >= 0) & (iu[:, 0] < w) & (iu[:, 1] >= 0) & (iu[:, 1] < h)
    zin = z[ok][inside]
    zin = zin[view.roi[iu[inside, 1], iu[inside, 0]]]
    if len(zin) < 10:
        return None
    near, far = np.percentile(zin, [2.0, 98.0])
    return float(near * (1 - margin)), float(far * (1 + margin))


def select_sources(centres: np.ndarray, targets: np.ndarray, ref: int, candidates: np.ndarray,
                   n: int, angles_deg: tuple[float, float, float]) -> list[int]:
    """Up to ``n`` positions from ``candidates`` whose triangulation angle with ``ref`` at
    its target point lies in the allowed range, closest to the preferred angle first."""
    lo, best, hi = angles_deg
    target = targets[ref]
    a = centres[ref] - target
    b = centres[candidates] - target
    cos = (b @ a) / (np.linalg.norm(b, axis=1) * np.linalg.norm(a) + 1e-12)
    angle = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    ok = (angle >= lo) & (angle <= hi) & (candidates != ref)
    order = np.argsort(np.abs(angle[ok] - best), kind="stable")
    return [int(c) for c in candidates[ok][order][:n]]


# ----------------------------------------------------------------------------- the sweep


def _torch_device(name: str):
    import torch

    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(name)


def _box_mean(x, k: int):
    """Mean over a k x k window (same size, edges replicated) of a (..., H, W) tensor.

    On the CPU this is OpenCV's box filter, plane by plane: torch's ``avg_pool2d`` measured
    10-20 times slower there and was most of the sweep's time. On a GPU, torch's pooling.
    """
    import torch

    shape = x.shape
    planes = x.reshape(-1, shape[-2], shape[-1])
    if x.device.type == "cpu":
        import cv2

        arr = planes.contiguous().numpy()
        out = np.empty_like(arr)
        for i in range(len(arr)):
            cv2.blur(arr[i], (k, k), dst=out[i], borderType=cv2.BORDER_REPLICATE)
        return torch.from_numpy(out).reshape(shape)
    import torch.nn.functional as F

    p = k // 2
    y = F.pad(planes[:, None], (p, p, p, p), mode="replicate")
    return F.avg_pool2d(y, k, stride=1).reshape(shape)


class _Reference:
    """A reference view's crop as torch tensors, with its window statistics."""

    def __init__(self, view: View, cfg: DenseConfig, device) -> None:
        import torch

        ys, xs = np.nonzero(view.roi)
        self.y0, self.y1 = int(ys.min()), int(ys.max()) + 1
        self.x0, self.x1 = int(xs.min()), int(xs.max()) + 1
        h, w = self.y1 - self.y0, self.x1 - self.x0
        self.shape = (h, w)
        ref = torch.from_numpy(view.gray[self.y0:self.y1, self.x0:self.x1].copy()).to(device)
        self.image = ref
        self.mean, self.std = _window_stats(ref, cfg.ncc_window_px)
        # Where the small window is faint, the larger one's statistics (and its NCC) are used.
        self.faint = None
        if cfg.faint_window_px:
            faint = self.std < cfg.faint_texture_std
            if bool(faint.any()):
                self.faint = faint
                self.faint_mean, self.faint_std = _window_stats(ref, cfg.faint_window_px)
        # Food pixels' windows over the food alone (the mask shrunk by food_window_erode_px):
        # a window reaching the outline is otherwise pulled behind the surface.
        self.weight = None
        if cfg.food_window_erode_px > 0 and view.food is not None:
            food = view.food[self.y0:self.y1, self.x0:self.x1]
            inner = ndimage.binary_erosion(food, iterations=cfg.food_window_erode_px)
            weight = torch.from_numpy(inner.astype(np.float32)).to(device)
            k = cfg.ncc_window_px
            self.weight = weight
            self.food_px = torch.from_numpy(food.copy()).to(device)
            self.weight_mean = _box_mean(weight, k)
            share = self.weight_mean.clamp_min(1e-6)
            self.food_mean = _box_mean(weight * ref, k) / share
            self.food_std = (_box_mean(weight * ref * ref, k) / share - self.food_mean ** 2
                             ).clamp_min(0).sqrt()
        u, v = np.meshgrid(np.arange(self.x0, self.x1), np.arange(self.y0, self.y1))
        pix = np.stack([u.ravel(), v.ravel(), np.ones(u.size)])  # (3, P)
        self.rays = np.linalg.inv(view.K) @ pix  # camera-frame rays with z = 1


def _window_stats(image, k: int):
    """The mean and standard deviation (both (h, w)) of ``image`` over k x k windows."""
    mean = _box_mean(image, k)
    return mean, (_box_mean(image * image, k) - mean**2).clamp_min(0).sqrt()


def _texture_std(ref: _Reference):
    """(h, w) intensity standard deviation of each pixel's matching window (the larger one
    where the reference is faint)."""
    import torch

    if ref.faint is None:
        return ref.std
    return torch.where(ref.faint, ref.faint_std, ref.std)


def _source_terms(ref_view: View, ref: _Reference, src: View, device):
    """Per pixel, the source's grid_sample coordinates are (x/z, y/z) of
    ``A + inv_depth * b``; A (P, 3) and b (3,) fold in the map from pixels to [-1, 1]."""
    import torch

    H, W = src.gray.shape
    to_grid = np.array([[2.0 / (W - 1), 0.0, -1.0], [0.0, 2.0 / (H - 1), -1.0], [0, 0, 1.0]])
    T = src.T_cam_from_world @ invert_rigid(ref_view.T_cam_from_world)
    A = (to_grid @ src.K @ T[:3, :3] @ ref.rays).T
    b = to_grid @ src.K @ T[:3, 3]
    image = torch.from_numpy(src.gray).to(device)[None, None]
    return (torch.from_numpy(np.ascontiguousarray(A)).float().to(device),
            torch.from_numpy(b).float().to(device), image)


def _ncc(ref: _Reference, term, inv_depth, cfg: DenseConfig):
    """NCC (D, h, w) between the reference and one source warped at per-pixel inverse depths
    ``inv_depth`` (D, P); -1 where the source does not see the pixel."""
    import torch
    import torch.nn.functional as F

    A, b, image = term
    h, w = ref.shape
    hom = torch.addcmul(A[None], inv_depth[..., None], b)  # (D, P, 3)
    z = hom[..., 2:3]
    grid = hom[..., :2] / z.clamp_min(1e-9)
    inside = grid.abs() <= 1.0  # two comparisons, not .all(dim=-1): 3 times faster on the CPU
    valid = (z[..., 0] > 1e-9) & inside[..., 0] & inside[..., 1]
    warped = F.grid_sample(image, grid[None], mode="bilinear", padding_mode="border",
                           align_corners=True)[0, 0].reshape(-1, h, w)
    squared, product = warped * warped, warped * ref.image
    ncc = _window_ncc(warped, squared, product, ref.mean, ref.std, cfg.ncc_window_px)
    if ref.faint is not None:
        faint = _window_ncc(warped, squared, product, ref.faint_mean, ref.faint_std,
                            cfg.faint_window_px)
        ncc = torch.where(ref.faint, faint, ncc)
    if ref.weight is not None:
        ncc = torch.where(ref.food_px, _food_window_ncc(ref, warped, cfg.ncc_window_px), ncc)
    return ncc.masked_fill_(~valid.reshape(-1, h, w), -1.0)


def _food_window_ncc(ref: _Reference, warped, k: int):
    """NCC (D, h, w) over the food pixels of each k x k window alone (the reference's
    ``weight``); -1 where under 30 % of the window is food."""
    import torch

    share = ref.weight_mean.clamp_min(1e-6)
    weighted = warped * ref.weight
    mean_s = _box_mean(weighted, k) / share
    var_s = (_box_mean(weighted * warped, k) / share - mean_s * mean_s).clamp_min(0)
    cov = _box_mean(weighted * ref.image, k) / share - ref.food_mean * mean_s
    ncc = cov / (var_s.sqrt() * ref.food_std + 1e-6)
    return torch.where(ref.weight_mean > 0.3, ncc, torch.full_like(ncc, -1.0))


def _window_ncc(warped, squared, product, ref_mean, ref_std, k: int):
    """NCC (D, h, w) over k x k windows from the warped source, its square, its product with
    the reference, and the reference's window mean and standard deviation."""
    # In place where a tensor is not needed again: the same operations in the same order
    # (the same bits) with fewer (D, h, w) temporaries.
    mean_s = _box_mean(warped, k)
    var_s = _box_mean(squared, k)
    var_s -= mean_s * mean_s
    cov = _box_mean(product, k)
    cov -= mean_s.mul_(ref_mean)
    return cov.div_(var_s.clamp_min_(0).sqrt_().mul_(ref_std).add_(1e-6))


def _aggregate(ref: _Reference, terms, inv_depth, cfg: DenseConfig):
    """Mean of the best ``top_k_sources`` NCCs, (D, h, w), evaluated in plane chunks."""
    import torch

    out = []
    for start in range(0, inv_depth.shape[0], cfg.planes_per_chunk):
        chunk = inv_depth[start:start + cfg.planes_per_chunk]
        per_source = [_ncc(ref, t, chunk, cfg) for t in terms]
        out.append(_mean_of_largest(per_source, min(cfg.top_k_sources, len(terms))))
    return torch.cat(out)


def _mean_of_largest(costs: list, k: int):
    """Element-wise mean of the ``k`` largest of ``costs`` (same-shape tensors): the same
    numbers as ``torch.stack(costs).topk(k, dim=0).values.mean(dim=0)``, kept as a running
    top-k instead, which measured 8 times faster on the CPU for 4 sources (topk along the
    first axis was a tenth of the sweep's time)."""
    import torch

    best = [torch.full_like(costs[0], float("-inf")) for _ in range(k)]
    for cost in costs:
        for j in range(k):  # insert into the sorted running top-k, largest first
            larger = torch.maximum(best[j], cost)
            cost = torch.minimum(best[j], cost)
            best[j] = larger
    return torch.stack(best).mean(dim=0)


def _parabola_peak(cost, index, value, spacing: float):
    """Sub-sample peak of ``cost`` (n, P) near ``index`` (P,): the vertex of the parabola
    through the best sample and its two neighbours, as ``value`` shifted by at most half a
    ``spacing``; unchanged at the ends or where the cost is not concave."""
    import torch

    n = cost.shape[0]
    jc = index.clamp(1, n - 2)
    c_minus = cost.gather(0, (jc - 1)[None])[0]
    c_zero = cost.gather(0, jc[None])[0]
    c_plus = cost.gather(0, (jc + 1)[None])[0]
    curvature = c_minus - 2 * c_zero + c_plus
    concave = (curvature < -1e-6) & (index > 0) & (index < n - 1)
    shift = torch.where(concave, 0.5 * (c_minus - c_plus) / curvature.clamp_max(-1e-6),
                        torch.zeros_like(curvature))
    return value + shift.clamp(-0.5, 0.5) * spacing


def estimate_depth(views: list[View], ref_pos: int, sources: list[int],
                   near_far: tuple[float, float], cfg: DenseConfig) -> DepthMap:
    """Plane-sweep depth of ``views[ref_pos]`` against ``views[s]`` for ``s`` in ``sources``
    (the first sweep at ``cfg.coarse_factor`` times coarser), refined by local sweeps."""
    import torch

    device = _torch_device(cfg.device)
    view = views[ref_pos]
    H, W = view.gray.shape
    depth = np.zeros((H, W), np.float32)
    score = np.full((H, W), -1.0, np.float32)
    if not sources or not view.roi.any():
        return DepthMap(depth, score, sources)
    with torch.no_grad():
        ref = _Reference(view, cfg, device)
        h, w = ref.shape
        terms = [_source_terms(view, ref, views[s], device) for s in sources]
        near, far = near_far
        planes = torch.linspace(1.0 / far, 1.0 / near, cfg.n_depth_planes, device=device)
        step = float(planes[1] - planes[0])
        if cfg.coarse_factor > 1:
            inv, best_cost, at_end = _coarse_sweep(views, ref_pos, sources, ref, planes, cfg,
                                                   device)
            if cfg.coarse_min_cosine > 0:
                face_on = _facing(view, ref, inv, cfg.coarse_min_cosine)
                full = _plane_sweep(ref, terms, planes, cfg)
                inv, best_cost, at_end = (torch.where(face_on, a, b) for a, b in
                                          zip((inv, best_cost, at_end), full, strict=True))
        else:
            inv, best_cost, at_end = _plane_sweep(ref, terms, planes, cfg)
        if cfg.refine_sweeps:
            inv, best_cost = _refine(ref, terms, inv, step, cfg)
        keep = ((best_cost >= cfg.min_ncc) & ~at_end
                & (_texture_std(ref).reshape(-1) >= cfg.min_texture_std) & (inv > 0))
        d = torch.where(keep, 1.0 / inv.clamp_min(1e-9), torch.zeros_like(inv))
        crop_depth = d.reshape(h, w).cpu().numpy()
        crop_score = torch.where(keep, best_cost, torch.full_like(inv, -1.0))
        crop_score = crop_score.reshape(h, w).cpu().numpy()
    roi = view.roi[ref.y0:ref.y1, ref.x0:ref.x1]
    depth[ref.y0:ref.y1, ref.x0:ref.x1] = np.where(roi, crop_depth, 0.0)
    score[ref.y0:ref.y1, ref.x0:ref.x1] = np.where(roi, crop_score, -1.0)
    return DepthMap(depth, score, sources)


def _plane_sweep(ref: _Reference, terms, planes, cfg: DenseConfig):
    """The first sweep over fronto-parallel ``planes`` (inverse depths): per pixel of the
    reference's crop (P,), the parabola-refined inverse depth, its cost and whether the best
    plane is the first or the last."""
    P = ref.shape[0] * ref.shape[1]
    cost = _aggregate(ref, terms, planes[:, None].expand(-1, P), cfg).reshape(-1, P)
    best_cost, best = cost.max(dim=0)
    at_end = (best == 0) | (best == len(planes) - 1)
    inv = _parabola_peak(cost, best, planes[best], float(planes[1] - planes[0]))
    return inv, best_cost, at_end


def _refine(ref: _Reference, terms, inv, step: float, cfg: DenseConfig):
    """Local sweeps around the (continuous) inverse depth ``inv`` (P,), each finer, the first
    over +- ``cfg.refine_span_planes`` plane spacings ``step``: the refined inverse depth and
    its cost.

    A pixel's window is warped with its neighbours' own depths plus the same offset, which
    follows the surface; starting from the quantised planes instead, it would follow their
    staircase and not refine (measured on the textured-plane test). Each sweep starts from
    the inverse depths median-filtered (:attr:`DenseConfig.refine_median_px`), so that an
    outlier neither stays one nor bends its neighbours' windows."""
    import torch

    n = cfg.n_refine_hypotheses
    offsets = torch.linspace(-1.0, 1.0, n, device=inv.device)
    span = step * cfg.refine_span_planes
    best_cost = None
    for _ in range(cfg.refine_sweeps):
        if cfg.refine_median_px:
            inv = _median_filtered(inv, ref.shape, cfg.refine_median_px)
        hyp = inv[None] + offsets[:, None] * span  # (n, P)
        cost = _aggregate(ref, terms, hyp, cfg).reshape(n, len(inv))
        best_cost, j = cost.max(dim=0)
        spacing = span * 2.0 / (n - 1)
        inv = _parabola_peak(cost, j, hyp.gather(0, j[None])[0], spacing)
        span = spacing
    return inv, best_cost


def _median_filtered(values, shape: tuple[int, int], k: int):
    """(P,) ``values`` over a crop of ``shape`` median-filtered over k x k pixels (OpenCV's
    median filter, which takes float32 for k of 3 or 5, :func:`plan_dense` checks; edges
    replicated)."""
    import cv2
    import torch

    image = values.reshape(shape).cpu().numpy().astype(np.float32)
    return torch.from_numpy(cv2.medianBlur(image, k).reshape(-1)).to(values.device)


def surface_cosines(view: View, depth_m: np.ndarray) -> np.ndarray:
    """(H, W) how directly ``view``'s camera sees the surface of the depth map ``depth_m``:
    the absolute cosine between each pixel's ray and the plane fitted around its depth
    (:func:`depth_normals`); 0 where no plane fits."""
    h, w = depth_m.shape
    u, v = np.meshgrid(np.arange(w), np.arange(h))
    rays = np.stack([u, v, np.ones((h, w))], -1) @ np.linalg.inv(view.K).T
    rays = rays @ invert_rigid(view.T_cam_from_world)[:3, :3].T
    normals = depth_normals(view, depth_m)
    return np.abs(np.sum(normals * rays, axis=-1)) / np.linalg.norm(rays, axis=-1)


def _facing(view: View, ref: _Reference, inv, min_cosine: float):
    """(P,) bool: where the surface of the inverse depths ``inv`` over the reference crop
    faces the camera with a cosine of at least ``min_cosine`` (:func:`surface_cosines`)."""
    import torch

    depth = np.zeros(view.gray.shape, np.float32)
    crop = inv.reshape(ref.shape).cpu().numpy()
    depth[ref.y0:ref.y1, ref.x0:ref.x1] = np.where(crop > 0, 1.0 / np.maximum(crop, 1e-9), 0)
    cosine = surface_cosines(view, depth)[ref.y0:ref.y1, ref.x0:ref.x1]
    return torch.from_numpy(cosine.reshape(-1) >= min_cosine).to(inv.device)


def coarse_view(view: View, factor: int) -> View:
    """``view`` shrunk by ``factor`` on each side (area averaging; the ROI wherever a coarse
    pixel covers any of it), its calibration to match (pixel centres kept)."""
    import cv2

    H, W = view.gray.shape
    w, h = max(1, W // factor), max(1, H // factor)
    gray = cv2.resize(view.gray, (w, h), interpolation=cv2.INTER_AREA)
    roi = cv2.resize(view.roi.astype(np.uint8), (w, h), interpolation=cv2.INTER_AREA) > 0
    sx, sy = w / W, h / H
    K = view.K.copy()
    K[0, 0] *= sx
    K[1, 1] *= sy
    K[0, 2] = (K[0, 2] + 0.5) * sx - 0.5
    K[1, 2] = (K[1, 2] + 0.5) * sy - 0.5
    food = None if view.food is None else cv2.resize(
        view.food.astype(np.uint8), (w, h), interpolation=cv2.INTER_AREA) > 0
    return View(view.index, K, view.T_cam_from_world, gray, view.rgb, roi, food)


def _coarse_sweep(views: list[View], ref_pos: int, sources: list[int], ref: _Reference,
                  planes, cfg: DenseConfig, device):
    """:func:`_plane_sweep` on the views shrunk by ``cfg.coarse_factor``, its inverse depth
    enlarged (bilinear) to the full reference crop ``ref``; the cost and the end-plane flag
    from the nearest coarse pixel."""
    import cv2
    import torch

    small = {i: coarse_view(views[i], cfg.coarse_factor) for i in [ref_pos, *sources]}
    coarse_ref = _Reference(small[ref_pos], cfg, device)
    terms = [_source_terms(small[ref_pos], coarse_ref, small[s], device) for s in sources]
    inv, cost, at_end = _plane_sweep(coarse_ref, terms, planes, cfg)
    if cfg.refine_sweeps:  # windows that follow the surface already at the coarse level
        inv, cost = _refine(coarse_ref, terms, inv, float(planes[1] - planes[0]), cfg)
    hc, wc = coarse_ref.shape
    H, W = views[ref_pos].gray.shape
    grids = []
    for values, interpolation in ((inv, cv2.INTER_LINEAR), (cost, cv2.INTER_NEAREST),
                                  (at_end.float(), cv2.INTER_NEAREST)):
        full = np.zeros(small[ref_pos].gray.shape, np.float32)
        full[coarse_ref.y0:coarse_ref.y0 + hc, coarse_ref.x0:coarse_ref.x0 + wc] = (
            values.reshape(hc, wc).cpu().numpy())
        if values is inv:  # outside the coarse crop: the crop's median, for the refinement
            outside = np.ones(full.shape, bool)
            outside[coarse_ref.y0:coarse_ref.y0 + hc, coarse_ref.x0:coarse_ref.x0 + wc] = False
            full[outside] = float(np.median(full[~outside]))
        up = cv2.resize(full, (W, H), interpolation=interpolation)
        grids.append(torch.from_numpy(
            np.ascontiguousarray(up[ref.y0:ref.y1, ref.x0:ref.x1])).reshape(-1).to(device))
    return grids[0], grids[1], grids[2] > 0.5


# ----------------------------------------------------------------------------- fusion


def depth_normals(view: View, depth_m: np.ndarray, window_px: int = 7,
                  max_thickness: float = 0.005) -> np.ndarray:
    """(H, W, 3) unit normals in world coordinates, facing the camera: per pixel, the normal
    of the plane fitted (least squares) to the camera-frame points of the depths in its
    ``window_px`` x ``window_px`` window; zero where fewer than half the window has a depth,
    or where the window's points stand off their plane by more than ``max_thickness`` times
    the depth (they lie on no one surface). A window that straddles a depth step (a
    silhouette against the plate) spreads along the view ray: its plane is steep, and the
    depth counts as seen too obliquely to keep.

    A normal from the differences of neighbouring depths alone follows the depth noise: on
    the benchmark's phone-look orange and apple (full orbits, SfM poses), the masked clouds'
    normals made that way were 31 and 38 degrees off the true surface's on average, and the
    meshing's normals, oriented by them, pointed into the item at 4 and 9 % of the points (at
    29-53 % of those in the 6 mm bands below the widest level). The plane fitted to a 7 x 7
    window (about 4 mm on the item at 512 px) gave 12 and 18 degrees, 1 and 3 % pointing in
    (3-21 % in those bands). The normals decide which depths were seen too obliquely to keep
    (:attr:`DenseConfig.min_view_cosine`) and orient the meshing's normals.

    The plane is the least-squares fit of depth as a linear function of the camera-frame
    x and y over the window (closed form, from box filters of the points and their products
    in OpenCV), so each pixel costs the same whatever the window: a 3 x 3 eigen-solve per
    pixel instead cost 80 ms a map."""
    import cv2

    H, W = depth_m.shape
    K = view.K
    depth = np.asarray(depth_m, np.float64)
    valid = depth > 0
    out = np.zeros((H, W, 3))
    if not valid.any():
        return out
    u, v = np.meshgrid(np.arange(W), np.arange(H))
    cam = np.stack([(u - K[0, 2]) / K[0, 0] * depth, (v - K[1, 2]) / K[1, 1] * depth, depth],
                   axis=-1)
    centre = cam[valid].mean(axis=0)  # products of small numbers: float64 keeps them exact
    rel = np.where(valid[..., None], cam - centre, 0.0)

    def window_sum(a: np.ndarray) -> np.ndarray:
        return cv2.boxFilter(a, -1, (window_px, window_px), normalize=False,
                             borderType=cv2.BORDER_CONSTANT)

    count = window_sum(valid.astype(np.float64))
    rows, cols = np.nonzero(valid & (count >= 0.5 * window_px * window_px))
    n = count[rows, cols]
    x, y, z = (window_sum(rel[..., i])[rows, cols] / n for i in range(3))

    def moment(i: int, j: int, mean_i: np.ndarray, mean_j: np.ndarray) -> np.ndarray:
        return window_sum(rel[..., i] * rel[..., j])[rows, cols] / n - mean_i * mean_j

    cxx, cxy, cyy = moment(0, 0, x, x), moment(0, 1, x, y), moment(1, 1, y, y)
    cxz, cyz, czz = moment(0, 2, x, z), moment(1, 2, y, z), moment(2, 2, z, z)
    det = np.maximum(cxx * cyy - cxy * cxy, 1e-30)
    a = (cyy * cxz - cxy * cyz) / det  # depth = a x + b y + c over the window
    b = (cxx * cyz - cxy * cxz) / det
    slope = np.sqrt(1.0 + a * a + b * b)
    normal = np.stack([a, b, -np.ones_like(a)], axis=1) / slope[:, None]
    off_plane = np.sqrt(np.maximum(czz - a * cxz - b * cyz, 0.0)) / slope
    normal[np.sum(normal * cam[rows, cols], axis=1) > 0] *= -1  # face the camera
    flat = off_plane <= max_thickness * depth[rows, cols]
    out[rows[flat], cols[flat]] = normal[flat]
    R_world_from_cam = view.T_cam_from_world[:3, :3].T
    return out @ R_world_from_cam.T


def _sample_depth(depth_m: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Nearest-pixel depth at ``uv`` (0 outside the image)."""
    H, W = depth_m.shape
    iu = np.round(uv).astype(int, copy=False) if np.all(np.isfinite(uv)) else np.full(
        uv.shape, -1)
    inside = (iu[:, 0] >= 0) & (iu[:, 0] < W) & (iu[:, 1] >= 0) & (iu[:, 1] < H)
    out = np.zeros(len(uv), np.float32)
    out[inside] = depth_m[iu[inside, 1], iu[inside, 0]]
    return out


def consistent_points(views: list[View], maps: dict[int, DepthMap], ref_pos: int,
                      neighbours: list[int], cfg: DenseConfig
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The reference's depths that ``geometric_min_views`` neighbour depth maps agree with, or
    ``fill_min_views`` where that is fewer (``maps`` by position in ``views``;
    ``neighbours`` must have one).

    Returns (pixel indices (N, 2) as (row, col), fused world points (N, 3) -- the mean of
    the reference's point and its agreeing neighbours' --, agreeing-view counts (N,)).
    """
    view, dm = views[ref_pos], maps[ref_pos]
    rows, cols = np.nonzero(dm.depth_m > 0)
    uv = np.stack([cols, rows], axis=1).astype(float)
    d = dm.depth_m[rows, cols].astype(float)
    X = backproject(view.K, view.T_cam_from_world, uv, d)
    total = X.copy()
    count = np.zeros(len(X), int)
    for nb in neighbours:
        other = views[nb]
        uv_n, _ = project(other.K, other.T_cam_from_world, X)
        uv_n = np.where(np.isfinite(uv_n), uv_n, -1.0)
        d_n = _sample_depth(maps[nb].depth_m, uv_n).astype(float)
        has = d_n > 0
        X_n = backproject(other.K, other.T_cam_from_world, np.round(uv_n), d_n)
        uv_back, d_back = project(view.K, view.T_cam_from_world, X_n)
        reproj = np.linalg.norm(uv_back - uv, axis=1)
        agree = (has & (reproj <= cfg.geometric_max_reprojection_px)
                 & (np.abs(d_back - d) <= cfg.geometric_max_relative_depth * d))
        total[agree] += X_n[agree]
        count += agree
    keep = count >= min(cfg.geometric_min_views, cfg.fill_min_views)
    fused = total[keep] / (count[keep] + 1)[:, None]
    return np.stack([rows[keep], cols[keep]], axis=1), fused, count[keep]


def voxel_merge(cloud: PointCloud, voxel_m: float) -> PointCloud:
    """Points averaged per voxel (colours and normals too; normals renormalised)."""
    if voxel_m <= 0 or len(cloud) == 0:
        return cloud
    merged = from_open3d(to_open3d(cloud).voxel_down_sample(voxel_m))
    if merged.normals is not None:
        norm = np.linalg.norm(merged.normals, axis=1, keepdims=True)
        merged = PointCloud(merged.xyz, merged.rgb, merged.normals / np.maximum(norm, 1e-12))
    return merged


# ----------------------------------------------------------------------------- the stage


def _object_targets(views: list[View], sparse_xyz: np.ndarray) -> np.ndarray:
    """Per view, the median sparse point inside its ROI (the point the triangulation angle is
    measured at); the view's centre plus 0.3 m along its axis when no point falls there."""
    targets = []
    for v in views:
        uv, z = project(v.K, v.T_cam_from_world, sparse_xyz)
        h, w = v.roi.shape
        ok = (z > 0) & np.all(np.isfinite(uv), axis=1)
        iu = np.round(uv[ok]).astype(int)
        inside = (iu[:, 0] >= 0) & (iu[:, 0] < w) & (iu[:, 1] >= 0) & (iu[:, 1] < h)
        pts = sparse_xyz[ok][inside][v.roi[iu[inside, 1], iu[inside, 0]]]
        if len(pts):
            targets.append(np.median(pts, axis=0))
        else:
            axis = invert_rigid(v.T_cam_from_world)[:3, 2]
            targets.append(v.centre + 0.3 * axis)
    return np.asarray(targets)


@dataclass(eq=False)
class DensePlan:
    """The views of a dense run and who is compared with whom."""

    views: list[View]
    """The registered frames at working resolution."""
    references: list[int]
    """Positions (in ``views``) of the reference views, which get a depth map."""
    sources: dict[int, list[int]]
    """Per reference, the stereo source views."""
    checks: dict[int, list[int]]
    """Per reference, the other references whose depth maps must confirm its depths."""
    use_mask: bool
    """Whether the work is limited to the food masks' surroundings."""


def plan_dense(capture: Capture, masks: MaskSet | None, T_world_from_cam: np.ndarray,
               registered: np.ndarray, sparse_xyz: np.ndarray, cfg: DenseConfig,
               progress: bool = False) -> DensePlan:
    """Load the registered frames (``T_world_from_cam`` (N, 4, 4) per capture frame) and
    choose the reference views, their sources and their consistency checks; ``masks`` bound
    the work (``roi="mask"``)."""
    if cfg.ncc_window_px % 2 == 0 or cfg.ncc_window_px < 3:
        raise ConfigError("ncc_window_px must be odd and at least 3")
    if cfg.faint_window_px and (cfg.faint_window_px % 2 == 0
                                or cfg.faint_window_px <= cfg.ncc_window_px):
        raise ConfigError("faint_window_px must be 0, or odd and larger than ncc_window_px")
    if cfg.coarse_factor < 1 or cfg.refine_span_planes <= 0:
        raise ConfigError("coarse_factor must be 1 or more and refine_span_planes positive")
    if cfg.food_window_erode_px and cfg.faint_window_px:
        raise ConfigError("food_window_erode_px and faint_window_px cannot be combined: the "
                          "food-only windows have the small window's size")
    if cfg.refine_median_px not in (0, 3, 5):
        raise ConfigError("refine_median_px must be 0, 3 or 5 (OpenCV's float median filter)")
    if len(T_world_from_cam) != len(capture) or len(registered) != len(capture):
        raise ValueError("one pose and one registered flag per capture frame are needed")
    use_mask = cfg.roi == "mask" and masks is not None
    if cfg.roi == "mask" and masks is None:
        log.warning("no food masks: dense stereo runs on the whole image (slower)")
    indices = np.flatnonzero(registered)
    if len(indices) < 3:
        raise DenseError(f"only {len(indices)} frames registered; dense stereo needs 3 or more")
    views = [prepare_view(int(i), capture.frames[i], T_world_from_cam[i], cfg,
                          masks.mask(int(i)) if use_mask else None)
             for i in progress_over(indices, "dense: loading frames", progress, "frames")]
    centres = np.stack([v.centre for v in views])
    targets = _object_targets(views, sparse_xyz)
    positions = np.arange(len(views))
    references = positions[::cfg.reference_stride]
    sources = {int(r): select_sources(centres, targets, r, positions, cfg.n_sources,
                                      cfg.source_angle_deg) for r in references}
    # Depth maps are checked against those of other reference views, chosen the same way
    # (with every frame a reference, they are the stereo sources themselves).
    checks = {int(r): select_sources(centres, targets, r, references, cfg.n_sources,
                                     cfg.source_angle_deg) for r in references}
    return DensePlan(views, [int(r) for r in references], sources, checks, use_mask)


def depth_maps(plan: DensePlan, sparse_xyz: np.ndarray, cfg: DenseConfig,
               progress: bool = False) -> tuple[dict[int, DepthMap], list]:
    """The plane-sweep depth map of every reference view of ``plan``, and each one's depth
    range (None where too few sparse points fall in its view: then its map is empty)."""
    maps: dict[int, DepthMap] = {}
    ranges = []
    for r in progress_over(plan.references, "dense: depth maps", progress, "views"):
        view = plan.views[r]
        near_far = depth_range(view, sparse_xyz, cfg.depth_range_margin)
        ranges.append(near_far)
        if near_far is None:
            log.warning("frame %d: too few sparse points in view; no depth map", view.index)
            maps[r] = DepthMap(np.zeros_like(view.gray), np.full_like(view.gray, -1), [])
            continue
        maps[r] = estimate_depth(plan.views, r, plan.sources[r], near_far, cfg)
    return maps, ranges


def inside_outline_px(mask: np.ndarray) -> np.ndarray:
    """(H, W) float32: how far each pixel of the bool ``mask`` lies inside its outline,
    pixels (OpenCV's Euclidean distance transform, 5x5 mask); 0 outside."""
    import cv2

    return cv2.distanceTransform(mask.astype(np.uint8), cv2.DIST_L2, 5)


def contour_band(view: View, margin_px: float) -> np.ndarray:
    """(H, W) bool: the pixels less than ``margin_px`` pixels inside ``view``'s food-mask
    outline (none without a mask or a margin)."""
    if view.food is None or margin_px <= 0:
        return np.zeros(view.gray.shape, bool)
    return view.food & (inside_outline_px(view.food) < margin_px)


def fuse_depth_maps(plan: DensePlan, maps: dict[int, DepthMap], cfg: DenseConfig
                    ) -> tuple[PointCloud, int, int]:
    """The consistent depths of all reference views as one cloud with colours and normals,
    merged on the fusion voxel grid; with the number of depths estimated and of those that
    neighbouring depth maps confirmed."""
    xyz, rgb, normals, cosines, agreeing, rims = [], [], [], [], [], []
    n_estimated = 0
    for r in maps:
        n_estimated += int((maps[r].depth_m > 0).sum())
        pix, X, count = consistent_points(plan.views, maps, r, plan.checks[r], cfg)
        if not len(X):
            continue
        view = plan.views[r]
        n = depth_normals(view, maps[r].depth_m, cfg.normal_window_px,
                          cfg.normal_max_thickness)[pix[:, 0], pix[:, 1]]
        to_camera = view.centre - X
        cosine = np.sum(n * to_camera, axis=1) / np.linalg.norm(to_camera, axis=1)
        seen = cosine >= cfg.min_oblique_cosine
        xyz.append(X[seen])
        rgb.append(view.rgb[pix[seen, 0], pix[seen, 1]])
        normals.append(n[seen])
        cosines.append(cosine[seen])
        agreeing.append(count[seen])
        rims.append(contour_band(view, cfg.contour_margin_px)[pix[seen, 0], pix[seen, 1]])
    if not xyz:
        raise DenseError(
            "no depth survived the multi-view consistency check: the frames may be blurred, "
            "the food textureless, or the poses wrong (check the SfM summary)"
        )
    fused = PointCloud(np.concatenate(xyz), np.concatenate(rgb), np.concatenate(normals))
    confirmed = np.concatenate(agreeing) >= cfg.geometric_min_views
    keep = strong_or_filling(fused.xyz, confirmed, cfg.fill_gap_m)
    fused, cosine = fused.subset(keep), np.concatenate(cosines)[keep]
    oblique_kept = strong_or_filling(fused.xyz, cosine >= cfg.min_view_cosine,
                                     cfg.oblique_gap_m)
    fused = fused.subset(oblique_kept)
    rim = np.concatenate(rims)[keep][oblique_kept]
    fused = fused.subset(strong_or_filling(fused.xyz, ~rim, cfg.contour_gap_m))
    fused = fused.subset(np.linalg.norm(fused.normals, axis=1) > 0.5)
    return voxel_merge(fused, cfg.fusion_voxel_m), n_estimated, len(fused)


def strong_or_filling(xyz: np.ndarray, strong: np.ndarray, gap_m: float) -> np.ndarray:
    """(N,) which of the points ``xyz`` (N, 3) to keep: the ``strong`` ones (N,) and the weak
    ones that no strong point lies within ``gap_m`` of (they fill a hole); all when none or
    all are strong. Used with frontal against oblique depths (``min_view_cosine``,
    ``oblique_gap_m``) and with fully against partly confirmed ones (``fill_min_views``)."""
    from scipy.spatial import cKDTree

    if strong.all() or not strong.any():
        return np.ones(len(xyz), bool)
    keep = strong.copy()
    weak = np.flatnonzero(~strong)
    gap = cKDTree(xyz[strong]).query(xyz[weak], distance_upper_bound=gap_m)[0]
    keep[weak[np.isinf(gap)]] = True
    return keep


def run_dense(capture: Capture, masks: MaskSet | None, T_world_from_cam: np.ndarray,
              registered: np.ndarray, sparse_xyz: np.ndarray, cfg: DenseConfig | None = None,
              progress: bool = True) -> DenseResult:
    """Depth maps of every registered frame, filtered and fused into the scene cloud.

    ``T_world_from_cam`` (N, 4, 4) and ``registered`` (N,) are per capture frame (the SfM
    stage's refined poses); ``sparse_xyz`` (M, 3) are the SfM points, which bound the depths.
    """
    cfg = cfg or DenseConfig()
    timings: dict[str, float] = {}
    t = time.perf_counter()
    plan = plan_dense(capture, masks, T_world_from_cam, registered, sparse_xyz, cfg, progress)
    timings["load_s"] = time.perf_counter() - t
    t = time.perf_counter()
    maps, ranges = depth_maps(plan, sparse_xyz, cfg, progress)
    timings["depth_s"] = time.perf_counter() - t
    t = time.perf_counter()
    cloud, n_estimated, n_consistent = fuse_depth_maps(plan, maps, cfg)
    timings["fuse_s"] = time.perf_counter() - t
    views = plan.views
    summary = {
        "frames": len(capture),
        "reference_views": len(maps),
        "depth_maps": int(sum(1 for m in maps.values() if m.sources)),
        "working_size_px": list(views[0].gray.shape[::-1]),
        "roi": "mask" if plan.use_mask else "full",
        "roi_pixels_median": int(np.median([v.roi.sum() for v in views])),
        "depths_estimated": n_estimated,
        "depths_consistent": n_consistent,
        "points": len(cloud),
        "depth_range_median_m": [float(np.median([r[i] for r in ranges if r]))
                                 for i in (0, 1)] if any(ranges) else None,
        "timings_s": {k: round(v, 3) for k, v in timings.items()},
        "config": asdict(cfg),
    }
    log.info("dense: %d views, %d consistent depths, %d points after a %.1f mm merge",
             len(views), n_consistent, len(cloud), cfg.fusion_voxel_m * 1000)
    return DenseResult(cloud, summary)


def save_dense(work_dir: Path, result: DenseResult) -> Path:
    """Write ``WORKDIR/scene.ply`` and ``WORKDIR/dense.json`` (each atomically)."""
    work_dir = Path(work_dir)
    return write_cloud_record(result.cloud, result.summary, work_dir / "scene.ply",
                              work_dir / "dense.json")


def load_dense(work_dir: Path) -> DenseResult:
    """Read a finished dense stage back from ``work_dir``."""
    work_dir = Path(work_dir)
    return DenseResult(*read_cloud_record(work_dir / "scene.ply", work_dir / "dense.json"))
