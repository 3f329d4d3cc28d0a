"""Food segmentation: one binary food mask per frame, without any learned model.

In: a :class:`~volec.capture.Capture` (its images), the SfM stage's result (refined metric
poses, the sparse points) and a :class:`SegmentConfig`. Out: a :class:`MaskSet` (a mask per
frame at the capture's resolution, per-frame area and confidence, the frames where it failed
and why) and, on disk, ``WORKDIR/masks/*.png`` with ``WORKDIR/segment.json``.
:func:`given_masks` wraps a capture's own masks in the same :class:`MaskSet`, read once, which
dense stereo, masking and meshing then use.

A capture is an orbit around one item resting on a plate or a table, with metric poses, so
geometry finds the item before any colour is looked at (after Campbell et al., "Automatic 3D
object segmentation in multiple views using volumetric graph-cuts", IVC 2010):

1. the point the cameras fixate (the point nearest to all optical axes);
2. the support plane: RANSAC on the sparse SfM points around that point, facing the cameras;
3. the item: the cluster of sparse points standing above the plane nearest to the fixation
   point (another object beside it is another cluster, and is left out);
4. on a subset of evenly spread views, OpenCV's GrabCut (a colour graph cut) seeded from the
   projection of the item's points (probable food), of the plane's points around it (sure
   background: plate, table and shadows cast on them), the image border, and stereo against
   two neighbouring views: what stands above the plane is food, what lies on it is not.
   Where the plate is so plain that SfM found no point on it, the plane found is the table
   under it; stereo round the item finds the plate's top, and the plane is lifted to it;
5. the visual hull of those masks on a voxel grid (a voxel is food when nearly all views that
   see it agree, so one view's mistake is outvoted), cut at the support plane;
6. every frame's mask: the hull's silhouette in that frame, refined by GrabCut in a narrow
   band around its border (colour decides the last pixels, geometry everything else).

No weights are downloaded or shipped: it needs only OpenCV, SciPy and open3d.
"""

from __future__ import annotations

import logging
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image
from scipy import ndimage

from volec.capture import Capture, Intrinsics, read_mask
from volec.errors import VolecError
from volec.geometry import azimuth_span_deg, azimuths_deg, horizontal_axes, ransac_plane
from volec.progress import progress_over
from volec.scale import fixation_of_poses

log = logging.getLogger(__name__)


class SegmentationError(VolecError):
    """The food could not be found or segmented in this capture."""


@dataclass(frozen=True)
class SegmentConfig:
    """Options of the segmentation stage."""

    search_radius_factor: float = 0.6
    """Sparse points farther from the fixation point than this times the median camera
    distance are not considered (the room beyond the table)."""
    plane_inlier_m: float = 0.0015
    """RANSAC inlier distance of the support plane, metres."""
    max_plane_tilt_deg: float = 20.0
    """Where the capture states its up direction, the support plane's normal must point within
    this angle of it."""
    min_camera_elevation_deg: float = 5.0
    """Every camera looks down on the support plane from at least this elevation."""
    min_height_m: float = 0.004
    """Sparse points at least this far above the support plane may be food."""
    cluster_eps_m: float = 0.008
    """Neighbouring food points are at most this far apart (DBSCAN radius)."""
    min_cluster_points: int = 25
    """An item needs at least this many sparse points."""
    max_fixation_gap: float = 0.25
    """The item's nearest point lies at most this far from the fixation point, as a share of
    the median camera distance (people aim roughly at the food)."""
    merge_gap_m: float = 0.01
    """Clusters this close to the item are part of it (a sparsely textured item falls apart
    into several); a second object is farther. At 0.02 the chocolate croissant and the yellow
    cane chained into the raised plate rim (a 300 mm "item", masks with the plate in them,
    +260 % and +223 % in volume). At 0.01 the croissant is found at its own size (153 mm)
    and the 16-frame cake of the tests still holds together; the yellow cane is found at its
    own size since rings round the item are never merged (``enclosing_span_deg``)."""
    enclosing_span_deg: float = 270.0
    """A cluster that goes round the item by more than this angle, farther out than the
    item's own points (a plate's raised rim, a bowl's wall), is never merged into it: the
    yellow cane's end came within 1 cm of the rim and the whole rim (a ring 97-160 mm from
    it, 358 degrees round) joined it."""
    beside_span_deg: float = 90.0
    """A cluster smaller than the item's that goes round it by more than this angle, farther
    out than the item's own points, is never merged into it either: a fork lying beside the
    durum on a dark plate spans 126 degrees seen from its centre, and its end came within
    1 cm of the durum's. Clusters larger than the item's are held to ``enclosing_span_deg``
    (when the cameras aim at a small fragment, the rest of the item goes round it)."""
    ambiguous_gap_m: float = 0.01
    """A second object at most this much farther from the fixation point than the nearest,
    and at least half its size, makes the choice ambiguous: an error."""
    min_cluster_share: float = 0.1
    """Clusters with fewer points than this share of the largest are noise, not objects."""
    hull_views: int = 24
    """Views, evenly spread through the capture, whose GrabCut masks make the visual hull."""
    work_long_side_px: int = 480
    """GrabCut runs on images downscaled to at most this long side."""
    grabcut_iterations: int = 4
    """GrabCut iterations on the hull views."""
    stereo_scale: float = 0.5
    """Stereo runs at this fraction of GrabCut's working size (its seeds need no detail)."""
    stereo_window_px: int = 7
    """NCC window of that stereo, pixels at its size."""
    stereo_planes: int = 48
    """Planes of the plane sweep that finds the heights of the hull views' pixels."""
    stereo_min_ncc: float = 0.5
    """Depths whose NCC is below this are not used as seeds."""
    plane_height_m: float = 0.0015
    """Pixels that stereo puts within this of the support plane are background."""
    support_ring_m: tuple[float, float] = (0.005, 0.03)
    """Stereo points this far outside the item's footprint (from, to; metres) show the
    surface it rests on (:func:`support_height_m`)."""
    plane_match_ncc: float = 0.8
    """Textured pixels that match their neighbours through the support plane this well are
    background (see :func:`plane_consistency`)."""
    seed_splat_px: int = 3
    """Radius of the disc each projected item point paints as probable food, work pixels."""
    probable_margin_px: int = 25
    """How far beyond the item's projected points GrabCut may grow the food, work pixels."""
    voxel_m: float = 0.001
    """Edge of the visual hull's voxels, metres (grown for large items, see
    ``hull_max_voxels_across``)."""
    hull_max_voxels_across: int = 240
    """The hull's voxels grow beyond ``voxel_m`` for an item whose grid would span more than
    this many along its longest side: the hull's cost grows with the cube of that count (on
    the instant-ngp fox's real photos, a 26 cm item at a guessed scale, the 1 mm hull took
    5 minutes with two other jobs on the cores). Every benchmark item (at most 186 mm, 226
    with the margins) keeps 1 mm."""
    hull_max_outside_views: int = 1
    """A voxel is food when at most this many of the hull views put it outside their mask:
    one view's mistake is outvoted, but two views that see empty space are believed (with a
    share of the views instead, the hull swells where few views constrain it, above the top
    and around the foot)."""
    hull_margin_m: float = 0.02
    """The hull's grid reaches this far beyond the item's sparse points."""
    band_px: int = 4
    """Half-width of the band around the hull's silhouette that GrabCut refines, capture
    pixels."""
    band_iterations: int = 2
    """GrabCut iterations in the band."""
    min_confidence: float = 0.85
    """A frame whose refined mask overlaps the hull's silhouette less than this (IoU) keeps
    the silhouette, and is listed."""
    max_border_frames: float = 0.5
    """More frames than this share with the food touching the image border is an error."""


@dataclass(frozen=True, eq=False)
class MaskSet:
    """One food mask per frame of a capture, read or made once and handed to the stages."""

    names: tuple[str, ...]
    """The frames' names, in capture order."""
    masks: tuple[np.ndarray, ...]
    """(H, W) bool food masks at each frame's image size."""
    source: str
    """``given`` (the capture's own masks) or ``auto`` (:func:`segment`)."""
    confidence: tuple[float, ...] = ()
    """Per frame, 0..1: how far the mask is to be believed (1 for given masks)."""
    failed: dict[str, str] = field(default_factory=dict)
    """Frames where segmentation fell back or failed, with why."""
    summary: dict[str, Any] = field(default_factory=dict)
    """Counts, the scene geometry found, timings (JSON-able)."""
    files: tuple[str, ...] = ()
    """Where each mask was read from (given masks), for messages."""

    def __len__(self) -> int:
        return len(self.masks)

    def mask(self, index: int) -> np.ndarray:
        """The mask of the frame at ``index``."""
        return self.masks[index]

    def describe(self, name: str) -> str:
        """The mask of the frame called ``name``, for messages: its file where it has one."""
        if self.files:
            return self.files[self.names.index(name)]
        return f"the automatic mask of {name}"

    @property
    def area_fraction(self) -> list[float]:
        """Per frame, the share of the image the food covers."""
        return [float(m.mean()) for m in self.masks]


def given_masks(capture: Capture) -> MaskSet:
    """The capture's own food masks, read once (every frame must have one)."""
    from volec.masking import require_masks

    require_masks(capture)
    masks = tuple(read_mask(f) for f in capture.frames)
    return MaskSet(tuple(f.name for f in capture.frames), masks, "given",
                   tuple(1.0 for _ in masks), files=tuple(str(f.mask_path)
                                                          for f in capture.frames))


# ----------------------------------------------------------------------------- geometry


@dataclass(frozen=True)
class SceneGeometry:
    """Where the item is, from the sparse points."""

    fixation: np.ndarray
    """The point the cameras look at, metres."""
    normal: np.ndarray
    """Unit normal of the support plane, towards the cameras."""
    offset_m: float
    """The plane is ``normal . x + offset_m = 0``."""
    item_points: np.ndarray
    """(M, 3) the sparse points of the item."""
    plane_points: np.ndarray
    """(K, 3) the sparse points of the support plane around the item."""
    other_objects: tuple[np.ndarray, ...] = ()
    """(K, 3) the sparse points of each other object standing on the plane near the item (a
    cup, a utensil), left out."""
    standing_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    """(K, 3) every sparse point near the item that stands above the plane and is not the
    item's (other objects, a rim, a utensil, strays)."""

    @property
    def other_clusters(self) -> int:
        """How many other objects were left out."""
        return len(self.other_objects)

    def height_m(self, points: np.ndarray) -> np.ndarray:
        """Heights (N,) of ``points`` above the plane."""
        return np.asarray(points) @ self.normal + self.offset_m


def _support_plane(points: np.ndarray, centres: np.ndarray, up: np.ndarray | None,
                   cfg: SegmentConfig, seed: int) -> tuple[np.ndarray, float, np.ndarray]:
    """(normal towards the cameras, offset, inlier mask) of the dominant plane in ``points``
    that the cameras all look down on (each at least ``min_camera_elevation_deg`` above it)
    and, where the capture states its up direction, that is level; up to three tries."""
    remaining = np.arange(len(points))
    for attempt in range(3):
        if len(remaining) < 50:
            break
        normal, offset, inliers = ransac_plane(points[remaining], cfg.plane_inlier_m, 2000,
                                               seed + attempt)
        heights = centres @ normal + offset
        if np.median(heights) < 0:
            normal, offset, heights = -normal, -offset, -heights
        elevation = np.degrees(np.arcsin(np.clip(
            heights / np.linalg.norm(centres - points[remaining][inliers].mean(axis=0), axis=1),
            -1, 1)))
        level = up is None or np.degrees(np.arccos(np.clip(normal @ up, -1, 1))) \
            <= cfg.max_plane_tilt_deg
        if level and np.all(elevation >= cfg.min_camera_elevation_deg):
            mask = np.zeros(len(points), bool)
            mask[remaining[inliers]] = True
            return normal, offset, mask
        remaining = np.delete(remaining, inliers)
    raise SegmentationError(
        "no plate or table that the cameras look down on around the point they look at: "
        "segmentation needs the food resting on a surface the frames show around it (or give "
        "masks)")


def _item_cluster(local: np.ndarray, normal: np.ndarray, offset: float, fixation: np.ndarray,
                  distance: float, cfg: SegmentConfig) -> tuple[np.ndarray, list[np.ndarray]]:
    """(indices into ``local`` of the item's points, those of each other object there):
    the cluster of points above the plane (``normal``, ``offset``) nearest to the fixation
    point, with the clusters near it (:func:`_merge_near`) except those that enclose it (the
    raised rim of a plate, the wall of a bowl: :func:`_encloses`)."""
    import open3d as o3d

    height = local @ normal + offset

    above = np.flatnonzero(height > cfg.min_height_m)
    if len(above) < cfg.min_cluster_points:
        raise SegmentationError("nothing stands on the plate at the point the cameras look "
                                "at: aim the orbit at the food (or give masks)")
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(local[above]))
    labels = np.asarray(pcd.cluster_dbscan(cfg.cluster_eps_m, 4))
    sizes = np.bincount(labels[labels >= 0]) if (labels >= 0).any() else np.zeros(0, int)
    clusters = [above[labels == k] for k in range(len(sizes))
                if sizes[k] >= max(cfg.min_cluster_points, cfg.min_cluster_share * sizes.max())]
    if not clusters:
        raise SegmentationError("no object at the point the cameras look at: the points above "
                                "the plate are scattered (or give masks)")
    gaps = np.array([float(np.linalg.norm(local[c] - fixation, axis=1).min())
                     for c in clusters])
    order = np.argsort(gaps)
    best = int(order[0])
    if gaps[best] > cfg.max_fixation_gap * distance:
        raise SegmentationError(
            f"no object at the point the cameras look at (the nearest is {gaps[best] * 1000:.0f}"
            " mm away): aim the orbit at the food (or give masks)")
    others = [clusters[int(k)] for k in order[1:]]
    main = clusters[best]
    others = [c for c in others if not _encloses(
        local[c], local[main], normal,
        cfg.enclosing_span_deg if len(c) >= len(main) else cfg.beside_span_deg)]
    item, rest = _merge_near(local, clusters[best], others, cfg.merge_gap_m)
    if rest:
        second = min(rest, key=lambda c: float(np.linalg.norm(local[c] - fixation, axis=1)
                                               .min()))
        gap = float(np.linalg.norm(local[second] - fixation, axis=1).min())
        if gap <= cfg.ambiguous_gap_m + gaps[best] and len(second) >= 0.5 * len(item):
            raise SegmentationError(
                "several separate objects stand where the cameras look (clusters of "
                f"{len(item)} and {len(second)} points, {gaps[best] * 1000:.0f} and "
                f"{gap * 1000:.0f} mm from it): film one item at a time, or give masks")
    return item, rest


def _encloses(cluster: np.ndarray, item: np.ndarray, normal: np.ndarray, span_deg: float
              ) -> bool:
    """Whether the points ``cluster`` (K, 3) go round the centre of ``item`` (M, 3) by more
    than ``span_deg`` degrees, seen along the plane's ``normal``, farther out than the item's
    own points: a ring such as a plate's raised rim. A fragment of the item itself (what
    :func:`_merge_near` joins) lies to one side of it."""
    if (np.median(_footprint_distance(cluster, item, normal))
            <= np.median(_footprint_distance(item, item, normal))):
        return False
    return azimuth_span_deg(cluster, item.mean(axis=0), normal) > span_deg


def _merge_near(points: np.ndarray, item: np.ndarray, others: list[np.ndarray],
                gap_m: float) -> tuple[np.ndarray, list[np.ndarray]]:
    """``item`` (indices into ``points``) with every cluster of ``others`` that comes within
    ``gap_m`` of it (in turn, so a chain of fragments joins: an item with sparse texture falls
    apart into several clusters); and the clusters left apart."""
    from scipy.spatial import cKDTree

    rest = list(others)
    merged = True
    while merged and rest:
        merged = False
        tree = cKDTree(points[item])
        for k, cluster in enumerate(rest):
            if tree.query(points[cluster], distance_upper_bound=gap_m)[0].min() <= gap_m:
                item = np.concatenate([item, cluster])
                rest.pop(k)
                merged = True
                break
    return item, rest


def _footprint_distance(points: np.ndarray, item: np.ndarray, normal: np.ndarray
                        ) -> np.ndarray:
    """Horizontal distance (N,) of ``points`` from the item's centre (along the plane)."""
    rel = points - item.mean(axis=0)
    return np.linalg.norm(rel - np.outer(rel @ normal, normal), axis=1)


def _plane_under(local: np.ndarray, item_idx: np.ndarray, normal: np.ndarray, offset: float,
                 cfg: SegmentConfig) -> tuple[np.ndarray, float]:
    """The plane the item rests on: the dominant plane found first may be the table under a
    plate; the points around the item's footprint (mostly the plate, when there is one) are
    fitted again, and their plane kept when it is parallel to the first and below the item."""
    item = local[item_idx]
    others = np.setdiff1d(np.arange(len(local)), item_idx)
    reach = 1.3 * np.percentile(_footprint_distance(item, item, normal), 95) + 0.01
    height = local @ normal + offset
    lowest = np.percentile(height[item_idx], 2)
    ring = others[(_footprint_distance(local[others], item, normal) < reach)
                  & (height[others] < lowest + 0.002) & (height[others] > -0.02)]
    if len(ring) < 50:
        return normal, offset
    n, o, inliers = ransac_plane(local[ring], cfg.plane_inlier_m, 1000, seed=0)
    if n @ normal < 0:
        n, o = -n, -o
    if len(inliers) < 0.3 * len(ring) or np.degrees(np.arccos(min(1.0, n @ normal))) > 10:
        return normal, offset
    return n, o


def find_item(T_world_from_cam: np.ndarray, points: np.ndarray, up: np.ndarray | None,
              cfg: SegmentConfig) -> SceneGeometry:
    """The support plane and the item on it, from the registered cameras (N, 4, 4) and the
    sparse points (M, 3) (see the module docstring, steps 1-3)."""
    fixation = fixation_of_poses(T_world_from_cam)
    centres = T_world_from_cam[:, :3, 3]
    distance = float(np.median(np.linalg.norm(centres - fixation, axis=1)))
    if up is not None:
        up = np.asarray(up, float) / np.linalg.norm(up)
    near = np.linalg.norm(points - fixation, axis=1) < cfg.search_radius_factor * distance
    local = points[near]
    if len(local) < cfg.min_cluster_points + 50:
        raise SegmentationError(f"only {len(local)} sparse points around the point the "
                                "cameras look at: too little texture to find the food")
    normal, offset, _ = _support_plane(local, centres, up, cfg, 0)
    item_idx, _ = _item_cluster(local, normal, offset, fixation, distance, cfg)
    normal, offset = _plane_under(local, item_idx, normal, offset, cfg)
    item_idx, others = _item_cluster(local, normal, offset, fixation, distance, cfg)
    height = local @ normal + offset
    item = local[item_idx]
    extent = float(np.percentile(np.linalg.norm(item - item.mean(axis=0), axis=1), 95))
    on_plane = np.abs(height) < cfg.plane_inlier_m
    near_item = _footprint_distance(local, item, normal) < 3.0 * extent + 0.02
    standing = near_item & (height > cfg.min_height_m)
    standing[item_idx] = False
    return SceneGeometry(fixation, normal, offset, item, local[on_plane & near_item],
                         tuple(local[c] for c in others), local[standing])


# ----------------------------------------------------------------------------- one view


@dataclass(frozen=True)
class _View:
    """A frame at GrabCut's working resolution."""

    rgb: np.ndarray
    intrinsics: Intrinsics
    T_cam_from_world: np.ndarray
    factor: float


def _work_view(capture: Capture, index: int, T_world_from_cam: np.ndarray,
               cfg: SegmentConfig) -> _View:
    frame = capture.frames[index]
    intr = frame.intrinsics
    with Image.open(frame.image_path) as im:
        rgb = im.convert("RGB")
        factor = min(1.0, cfg.work_long_side_px / max(im.size))
        if factor < 1.0:
            rgb = rgb.resize((round(im.size[0] * factor), round(im.size[1] * factor)),
                             Image.Resampling.BOX)
        rgb = np.asarray(rgb)
    return _View(rgb, intr.scaled(factor) if factor < 1.0 else intr,
                 np.linalg.inv(T_world_from_cam), factor)


def _pixels(view: _View, points: np.ndarray) -> np.ndarray:
    """Integer pixel positions (N, 2) (x, y) of world points; -1 where not in the image."""
    cam = points @ view.T_cam_from_world[:3, :3].T + view.T_cam_from_world[:3, 3]
    uv = view.intrinsics.project(cam)
    h, w = view.rgb.shape[:2]
    out = np.full((len(points), 2), -1)
    ok = np.isfinite(uv).all(axis=1)
    iu = np.round(uv[ok]).astype(int)
    inside = (iu[:, 0] >= 0) & (iu[:, 0] < w) & (iu[:, 1] >= 0) & (iu[:, 1] < h)
    out[np.flatnonzero(ok)[inside]] = iu[inside]
    return out


def _splat(shape: tuple[int, int], pix: np.ndarray, radius: int) -> np.ndarray:
    image = np.zeros(shape, bool)
    ok = pix[:, 0] >= 0
    image[pix[ok, 1], pix[ok, 0]] = True
    return ndimage.binary_dilation(image, iterations=radius) if radius else image


def _convex_fill(shape: tuple[int, int], pix: np.ndarray) -> np.ndarray:
    """The filled convex hull (H, W) bool of the valid pixel positions ``pix`` (N, 2)."""
    import cv2

    out = np.zeros(shape, np.uint8)
    ok = pix[pix[:, 0] >= 0]
    if len(ok) >= 3:
        cv2.fillConvexPoly(out, cv2.convexHull(ok.astype(np.int32)), 1)
    return out.astype(bool)


def item_region(view: _View, geometry: SceneGeometry) -> np.ndarray:
    """Where the item can be in a view: the convex hull of its points and of their feet on
    the support plane (an item stands on the plate; its points often cover only its top)."""
    points = geometry.item_points
    feet = points - np.outer(geometry.height_m(points), geometry.normal)
    return _convex_fill(view.rgb.shape[:2], _pixels(view, np.vstack([points, feet])))


def plane_consistency(view: _View, neighbours: list[_View], geometry: SceneGeometry,
                      window_px: int = 7, min_texture: float = 2e-4) -> np.ndarray:
    """Per pixel of ``view`` (H, W) float: how well it matches the neighbours warped onto it
    through the support plane (the best normalised cross-correlation over the neighbours;
    NaN where the view has no texture in two directions: a shading gradient or wood grain
    matches shifted copies of itself, so only corners and speckles can tell). The plate, the
    table and the shadows on them match; the item, which stands above the plane, does not.
    The best over neighbours on both sides copes with plane regions that the item hides from
    one of them."""
    import cv2

    gray = cv2.cvtColor(view.rgb, cv2.COLOR_RGB2GRAY).astype(np.float32) / 255.0
    k = (window_px, window_px)
    mean = cv2.blur(gray, k)
    std = np.sqrt(np.maximum(cv2.blur(gray * gray, k) - mean * mean, 0))
    texture = cv2.cornerMinEigenVal(gray, window_px, 3)
    best = np.full(gray.shape, -1.0, np.float32)
    R_v, t_v = view.T_cam_from_world[:3, :3], view.T_cam_from_world[:3, 3]
    n_v = R_v @ geometry.normal  # the plane in view coordinates: n_v . X = d_v
    d_v = -(geometry.offset_m - geometry.normal @ (R_v.T @ t_v))
    for other in neighbours:
        T = other.T_cam_from_world @ np.linalg.inv(view.T_cam_from_world)
        H = other.intrinsics.K @ (T[:3, :3] + np.outer(T[:3, 3], n_v) / d_v) @ np.linalg.inv(
            view.intrinsics.K)
        other_gray = cv2.cvtColor(other.rgb, cv2.COLOR_RGB2GRAY).astype(np.float32) / 255.0
        warped = cv2.warpPerspective(other_gray, H, gray.shape[::-1],
                                     flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                     borderMode=cv2.BORDER_CONSTANT, borderValue=-1.0)
        valid = cv2.erode((warped >= 0).astype(np.uint8), np.ones(k, np.uint8)) > 0
        w_mean = cv2.blur(warped, k)
        w_std = np.sqrt(np.maximum(cv2.blur(warped * warped, k) - w_mean * w_mean, 0))
        ncc = (cv2.blur(gray * warped, k) - mean * w_mean) / (std * w_std + 1e-6)
        best = np.where(valid, np.maximum(best, ncc), best)
    return np.where(texture >= min_texture, best, np.nan)


def stereo_points(view: _View, neighbours: list[_View], roi: np.ndarray,
                  geometry: SceneGeometry, cfg: SegmentConfig) -> np.ndarray:
    """Per pixel of ``view`` inside ``roi`` (H, W, 3): the world point it sees, from a
    plane-sweep depth map against ``neighbours`` (:mod:`volec.dense`'s stereo, at the
    segmentation's working size); NaN where stereo found no depth. Where the item's sparse
    points cover only its top, its body still stands above the plane."""
    import cv2

    from volec.dense import DenseConfig, View, backproject, depth_range, estimate_depth

    def dense_view(v: _View, region: np.ndarray) -> View:
        h, w = v.rgb.shape[:2]
        size = (max(1, round(w * cfg.stereo_scale)), max(1, round(h * cfg.stereo_scale)))
        rgb = cv2.resize(v.rgb, size, interpolation=cv2.INTER_AREA)
        small = cv2.resize(region.astype(np.uint8), size, interpolation=cv2.INTER_NEAREST) > 0
        gray = (rgb.astype(np.float32) @ np.array([0.299, 0.587, 0.114], np.float32)) / 255
        K = v.intrinsics.scaled(cfg.stereo_scale).K
        return View(0, K, v.T_cam_from_world, gray, rgb, small)

    views = [dense_view(view, roi)] + [dense_view(n, np.ones_like(roi)) for n in neighbours]
    dcfg = DenseConfig(n_depth_planes=cfg.stereo_planes, min_ncc=cfg.stereo_min_ncc,
                       top_k_sources=1, ncc_window_px=cfg.stereo_window_px, refine_sweeps=0)
    near_far = depth_range(views[0], np.vstack([geometry.item_points, geometry.plane_points]),
                           0.15)
    if near_far is None or not neighbours or not roi.any():
        return np.full((*roi.shape, 3), np.nan)
    depth = estimate_depth(views, 0, list(range(1, len(views))), near_far, dcfg).depth_m
    rows, cols = np.nonzero(depth > 0)
    small = np.full((*depth.shape, 3), np.nan)
    small[rows, cols] = backproject(views[0].K, views[0].T_cam_from_world,
                                    np.stack([cols, rows], axis=1).astype(float),
                                    depth[rows, cols])
    return cv2.resize(small, roi.shape[::-1], interpolation=cv2.INTER_NEAREST)


def outside_footprint_m(points: np.ndarray, geometry: SceneGeometry) -> np.ndarray:
    """How far (...,) each of ``points`` (..., 3) lies outside the item's footprint along the
    plane (the convex hull of its sparse points seen from above; negative inside, NaN where
    a point is NaN). The distance to the farthest edge line of the hull: exact beside an edge,
    less beyond a corner."""
    from scipy.spatial import ConvexHull

    basis = np.stack(horizontal_axes(geometry.normal), axis=1)  # (3, 2) along the plane
    edges = ConvexHull(geometry.item_points @ basis).equations  # (E, 3): unit normal, offset
    flat = np.asarray(points) @ basis
    return (flat @ edges[:, :2].T + edges[:, 2]).max(axis=-1)


def _azimuth_cover(points: np.ndarray, geometry: SceneGeometry, bin_deg: float = 10.0
                   ) -> float:
    """The share of the directions round the item's centre (``bin_deg`` sectors, along the
    plane) in which some of ``points`` (N, 3) lie."""
    azimuth = azimuths_deg(points, geometry.item_points.mean(axis=0), geometry.normal)
    return len(np.unique(np.floor(azimuth / bin_deg))) * bin_deg / 360.0


def support_height_m(point_maps: list[np.ndarray], geometry: SceneGeometry,
                     cfg: SegmentConfig) -> float:
    """The height above the support plane of the surface the item rests on, from what stereo
    sees around its footprint in the hull views (``point_maps``, :func:`stereo_points`): 0
    where that is the plane the sparse points found, more where the food lies on a plate so
    plain that SfM found no point on it (the plane found is then the table under the plate).
    The most common height, in ``plane_height_m`` bins, of the stereo points between
    ``support_ring_m`` outside the footprint, below the item's lowest sparse points and away
    from the other sparse points standing above the plane (a fork's top); 0 where
    that is not above ``min_height_m`` (a plate that thin is the plane for the masks), and
    where the plane's own sparse points lie round the item in half the directions or more
    (its lower sides, which the sparse points may have missed, would otherwise pass for a
    plate; the table shows only where the item reaches past the plate's edge). Stereo at the
    segmentation's size measures heights to a few millimetres: the dark plate's top, 12.5 mm
    above the table, came out at 15.8 and 17.2 mm in two SfM runs."""
    from scipy.spatial import cKDTree

    plane_outside = outside_footprint_m(geometry.plane_points, geometry)
    around = geometry.plane_points[(plane_outside > cfg.support_ring_m[0])
                                   & (plane_outside < cfg.support_ring_m[1])]
    if _azimuth_cover(around, geometry) >= 0.5:
        return 0.0  # the sparse points found the surface round the item: it is the plane
    points = np.concatenate([m.reshape(-1, 3) for m in point_maps])
    points = points[np.isfinite(points).all(axis=1)]
    if not len(points):
        return 0.0
    outside = outside_footprint_m(points, geometry)
    points = points[(outside > cfg.support_ring_m[0]) & (outside < cfg.support_ring_m[1])]
    if len(geometry.standing_points):  # not a fork's top, nor a rim's
        gap, _ = cKDTree(geometry.standing_points).query(points)
        points = points[gap > 0.5 * cfg.cluster_eps_m]
    heights = geometry.height_m(points)
    top = float(np.percentile(geometry.height_m(geometry.item_points), 2))
    heights = heights[(heights > -cfg.plane_height_m) & (heights < top)]
    if len(heights) < 100:
        return 0.0
    bins = np.arange(-cfg.plane_height_m, top + cfg.plane_height_m, cfg.plane_height_m)
    counts, edges = np.histogram(heights, bins=bins)
    k = int(np.argmax(counts))
    lift = float(np.median(heights[(heights >= edges[k]) & (heights < edges[k + 1])]))
    return lift if lift > cfg.min_height_m else 0.0


def seed_labels(view: _View, geometry: SceneGeometry, cfg: SegmentConfig,
                consistency: np.ndarray | None = None,
                heights: np.ndarray | None = None) -> np.ndarray:
    """GrabCut's starting labels for one view: the item's projected points (closed and
    filled) probable food; the rest of the item's region (:func:`item_region`) and a margin
    around it probable background; the plane's projected points outside the item and the
    rest of the image sure background, and so is every other object standing on the plane
    (its projected points, closed) outside the item's region. With the plane ``consistency``
    map, textured pixels that match the plane are sure background (shadows, a table the colour of
    the food) and textured pixels of the item's region that do not are probable food."""
    import cv2

    shape = view.rgb.shape[:2]
    item = _splat(shape, _pixels(view, geometry.item_points), cfg.seed_splat_px)
    item = ndimage.binary_fill_holes(ndimage.binary_closing(item, iterations=4))
    region = item_region(view, geometry) | item
    reach = ndimage.binary_dilation(region, iterations=cfg.probable_margin_px)
    plane = _splat(shape, _pixels(view, geometry.plane_points), 1) & ~item
    labels = np.full(shape, cv2.GC_BGD, np.uint8)
    labels[reach] = cv2.GC_PR_BGD
    labels[item] = cv2.GC_PR_FGD
    labels[plane & ~ndimage.binary_dilation(item, iterations=2)] = cv2.GC_BGD
    if consistency is not None:  # evidence of background only: a smooth plate matches badly
        with np.errstate(invalid="ignore"):
            on_plane = consistency > cfg.plane_match_ncc
        labels[on_plane & ~item] = cv2.GC_BGD
    if heights is not None:
        with np.errstate(invalid="ignore"):
            standing = heights > cfg.min_height_m
            lying = np.abs(heights) < cfg.plane_height_m
        standing = ndimage.binary_opening(standing & reach, iterations=1)
        labels[standing] = cv2.GC_PR_FGD
        # a stereo window straddling the item's border gives the background beside it the
        # item's depth: only pixels a window's width inside are sure
        inset = int(np.ceil(cfg.stereo_window_px / 2 / cfg.stereo_scale)) + 2
        labels[ndimage.binary_erosion(standing, iterations=inset) & region] = cv2.GC_FGD
        labels[lying & ~item & (labels != cv2.GC_FGD)] = cv2.GC_BGD
    # a cup or a fork beside the food: its points, closed, are never food; not their convex
    # hull, which for an arc of a plate's rim round the item would cover the item itself
    others = np.zeros(shape, bool)
    for points in geometry.other_objects:
        others |= _splat(shape, _pixels(view, points), cfg.seed_splat_px)
    labels[ndimage.binary_closing(others, iterations=4) & ~region] = cv2.GC_BGD
    return labels


def grabcut(rgb: np.ndarray, labels: np.ndarray, iterations: int) -> np.ndarray:
    """GrabCut (OpenCV) from ``labels``, on the crop around the undecided pixels; the food
    mask (bool). Pixels labelled sure stay as they are."""
    import cv2

    undecided = (labels == cv2.GC_PR_FGD) | (labels == cv2.GC_PR_BGD)
    if not undecided.any():
        return labels == cv2.GC_FGD
    ys, xs = np.nonzero(undecided)
    pad = 8
    y0, y1 = max(ys.min() - pad, 0), min(ys.max() + pad + 1, labels.shape[0])
    x0, x1 = max(xs.min() - pad, 0), min(xs.max() + pad + 1, labels.shape[1])
    crop = labels[y0:y1, x0:x1].copy()
    has_both = ((crop == cv2.GC_FGD) | (crop == cv2.GC_PR_FGD)).any() and (
        (crop == cv2.GC_BGD) | (crop == cv2.GC_PR_BGD)).any()
    if has_both:
        bgd, fgd = np.zeros((1, 65)), np.zeros((1, 65))
        cv2.grabCut(np.ascontiguousarray(rgb[y0:y1, x0:x1]), crop, None, bgd, fgd, iterations,
                    cv2.GC_INIT_WITH_MASK)
    out = labels == cv2.GC_FGD
    out[y0:y1, x0:x1] = (crop == cv2.GC_FGD) | (crop == cv2.GC_PR_FGD)
    return out


# ----------------------------------------------------------------------------- the hull


def plane_neighbours(T_world_from_cam: np.ndarray, registered: np.ndarray, index: int,
                     geometry: SceneGeometry, angle_deg: float = 12.0) -> list[int]:
    """Two registered frames that see the item from about ``angle_deg`` to either side of
    frame ``index`` (the nearest on each side, around the plane's normal)."""
    centre = geometry.item_points.mean(axis=0)
    rel = T_world_from_cam[:, :3, 3] - centre
    flat = rel - np.outer(rel @ geometry.normal, geometry.normal)
    ref = flat[index]
    cross = np.cross(ref, flat) @ geometry.normal
    angle = np.degrees(np.arctan2(cross, flat @ ref))
    chosen = []
    for side in (1.0, -1.0):
        ok = registered & (side * angle > 0.3 * angle_deg)
        ok[index] = False
        if ok.any():
            candidates = np.flatnonzero(ok)
            chosen.append(int(candidates[np.argmin(np.abs(side * angle[ok] - angle_deg))]))
    return chosen


def hull_views(registered: np.ndarray, n: int) -> np.ndarray:
    """Up to ``n`` registered frame indices, evenly spread through the capture."""
    chosen = np.flatnonzero(registered)
    if 0 < n < len(chosen):
        chosen = chosen[np.round(np.linspace(0, len(chosen) - 1, n)).astype(int)]
    return chosen


def _hull_grid(geometry: SceneGeometry, cfg: SegmentConfig, voxel_m: float) -> np.ndarray:
    """(P, 3) centres of a ``voxel_m`` grid around the item, down to its plane."""
    lo = geometry.item_points.min(axis=0) - cfg.hull_margin_m
    hi = geometry.item_points.max(axis=0) + cfg.hull_margin_m
    foot = geometry.item_points - np.outer(geometry.height_m(geometry.item_points),
                                           geometry.normal)
    lo, hi = np.minimum(lo, foot.min(axis=0) - 0.005), np.maximum(hi, foot.max(axis=0) + 0.005)
    axes = [np.arange(lo[i], hi[i], voxel_m) for i in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    return grid[geometry.height_m(grid) > -0.5 * voxel_m]


def hull_voxel_m(geometry: SceneGeometry, cfg: SegmentConfig) -> float:
    """The hull's voxel edge for this item, metres: ``cfg.voxel_m``, or more where the item's
    grid (its sparse points and the margins) would span more than
    ``cfg.hull_max_voxels_across`` voxels."""
    span_m = float(np.ptp(geometry.item_points, axis=0).max()) + 2 * cfg.hull_margin_m
    return max(cfg.voxel_m, span_m / cfg.hull_max_voxels_across)


def _carve(grid: np.ndarray, views: list[_View], masks: list[np.ndarray],
           max_outside: int) -> np.ndarray:
    """The points of ``grid`` that at most ``max_outside`` views see outside their mask and
    at least three views see."""
    seen = np.zeros(len(grid), np.int32)
    outside = np.zeros(len(grid), np.int32)
    for view, mask in zip(views, masks, strict=True):
        pix = _pixels(view, grid)
        ok = pix[:, 0] >= 0
        seen += ok
        outside[ok] += ~mask[pix[ok, 1], pix[ok, 0]]
        keep = outside <= max_outside
        grid, seen, outside = grid[keep], seen[keep], outside[keep]
    return grid[seen >= 3]


def visual_hull(views: list[_View], masks: list[np.ndarray], geometry: SceneGeometry,
                cfg: SegmentConfig, voxel_m: float) -> np.ndarray:
    """(P, 3) centres of ``voxel_m`` voxels around the surface of the hull the masks agree on,
    above the plane (step 5): a voxel is food when at most ``hull_max_outside_views`` of the
    views that see it put it outside their (work-resolution) mask, and at least three views
    see it. Carved first on a grid four times coarser, with the masks grown by a coarse voxel,
    then at full resolution only in the coarse surface cells (the shell the silhouettes need;
    they are filled in the image)."""
    coarse_m = 4 * voxel_m
    reach = [int(np.ceil(coarse_m * v.intrinsics.fx
                         / np.median(np.linalg.norm(geometry.item_points - _centre(v), axis=1))))
             for v in views]
    grown = [ndimage.binary_dilation(m, iterations=r) for m, r in zip(masks, reach, strict=True)]
    coarse = _carve(_hull_grid(geometry, cfg, coarse_m), views, grown,
                    cfg.hull_max_outside_views)
    if not len(coarse):
        return coarse
    coarse = hull_surface(coarse, coarse_m)  # the inside needs no finer look
    offsets = (np.stack(np.meshgrid(*[np.arange(-4, 4)] * 3, indexing="ij"), axis=-1)
               .reshape(-1, 3) + 0.5) * voxel_m
    fine = (coarse[:, None, :] + offsets[None]).reshape(-1, 3)
    fine = fine[geometry.height_m(fine) > -0.5 * voxel_m]
    return _carve(fine, views, masks, cfg.hull_max_outside_views)


def _centre(view: _View) -> np.ndarray:
    return np.linalg.inv(view.T_cam_from_world)[:3, 3]


def hull_surface(voxels: np.ndarray, voxel_m: float) -> np.ndarray:
    """The voxels (P, 3) of the hull that have an empty neighbour: its surface, all that its
    silhouettes need (the inside is filled in the image)."""
    index = np.round((voxels - voxels.min(axis=0)) / voxel_m).astype(int)
    occupied = np.zeros(index.max(axis=0) + 3, bool)
    occupied[tuple((index + 1).T)] = True
    interior = ndimage.binary_erosion(occupied)
    return voxels[~interior[tuple((index + 1).T)]]


def hull_silhouette(surface: np.ndarray, intrinsics: Intrinsics, T_cam_from_world: np.ndarray,
                    voxel_m: float) -> np.ndarray:
    """The hull's silhouette (H, W) bool in a camera, from its surface voxels
    (:func:`hull_surface`): each painted as the square it covers in the image, then filled."""
    cam = surface @ T_cam_from_world[:3, :3].T + T_cam_from_world[:3, 3]
    uv = intrinsics.project(cam)
    h, w = intrinsics.height, intrinsics.width
    out = np.zeros((h, w), bool)
    ok = np.isfinite(uv).all(axis=1)
    if not ok.any():
        return out
    iu = np.round(uv[ok]).astype(int)
    inside = (iu[:, 0] >= 0) & (iu[:, 0] < w) & (iu[:, 1] >= 0) & (iu[:, 1] < h)
    out[iu[inside, 1], iu[inside, 0]] = True
    reach = int(np.ceil(0.5 * voxel_m * intrinsics.fx / np.median(cam[ok, 2])))
    out = ndimage.binary_dilation(out, np.ones((2 * reach + 1, 2 * reach + 1), bool))
    return ndimage.binary_fill_holes(ndimage.binary_closing(out, iterations=2))


HISTOGRAM_BINS = 16
"""Bins per colour channel of the colour models (a 16^3 histogram, smoothed)."""


def colour_model(samples: np.ndarray) -> np.ndarray:
    """A colour likelihood model of ``samples`` (N, 3) 0..255: the log of their smoothed,
    normalised 3D histogram (a non-parametric stand-in for GrabCut's mixtures: OpenCV's
    headless wheel has no EM, and a histogram is as good on a few thousand pixels)."""
    bins = HISTOGRAM_BINS
    index = np.clip(samples.astype(int) * bins // 256, 0, bins - 1)
    hist = np.zeros((bins, bins, bins))
    np.add.at(hist, (index[:, 0], index[:, 1], index[:, 2]), 1.0)
    hist = ndimage.gaussian_filter(hist, 1.0, mode="constant") + 1e-3
    return np.log(hist / hist.sum())


def log_likelihood(model: np.ndarray, colours: np.ndarray) -> np.ndarray:
    """Per colour (N, 3), its log-likelihood under a :func:`colour_model`."""
    bins = HISTOGRAM_BINS
    index = np.clip(colours.astype(int) * bins // 256, 0, bins - 1)
    return model[index[:, 0], index[:, 1], index[:, 2]]


def refine_in_band(rgb: np.ndarray, silhouette: np.ndarray, cfg: SegmentConfig,
                   ring_px: int = 12) -> np.ndarray:
    """The silhouette with its border decided by colour (step 6): in a band of ``band_px``
    around it, each pixel goes to food or background by a graph cut (PyMaxflow) whose data
    term is the likelihood of its colour under the frame's own food colours (the silhouette's
    inside) and background colours (a ring just outside the band), and whose smoothness term
    is cheaper across strong colour edges (as in GrabCut)."""
    import maxflow

    inner = ndimage.binary_erosion(silhouette, iterations=cfg.band_px)
    outer = ndimage.binary_dilation(silhouette, iterations=cfg.band_px)
    ring = ndimage.binary_dilation(outer, iterations=ring_px) & ~outer
    band = outer & ~inner
    if not inner.any() or not band.any() or not ring.any():
        return silhouette
    ys, xs = np.nonzero(outer | ring)
    y0, y1, x0, x1 = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1
    img = rgb[y0:y1, x0:x1].astype(np.float32)
    inner_c, band_c, ring_c = inner[y0:y1, x0:x1], band[y0:y1, x0:x1], ring[y0:y1, x0:x1]
    edge = ndimage.binary_dilation(band_c) & ~band_c
    food = colour_model(img[inner_c & ndimage.binary_dilation(edge, iterations=ring_px)])
    background = colour_model(img[ring_c])
    cost = np.zeros(band_c.shape + (2,), np.float64)
    colours = img[band_c]
    cost[band_c, 0] = -log_likelihood(food, colours)
    cost[band_c, 1] = -log_likelihood(background, colours)
    diff_x = np.sum((img[:, 1:] - img[:, :-1]) ** 2, axis=-1)
    diff_y = np.sum((img[1:] - img[:-1]) ** 2, axis=-1)
    beta = 1.0 / (2.0 * max(np.mean(np.concatenate([diff_x.ravel(), diff_y.ravel()])), 1e-6))
    gamma = 25.0
    graph = maxflow.Graph[float]()
    nodes = graph.add_grid_nodes(band_c.shape)
    right = np.zeros(band_c.shape)
    right[:, :-1] = gamma * np.exp(-beta * diff_x)
    down = np.zeros(band_c.shape)
    down[:-1] = gamma * np.exp(-beta * diff_y)
    graph.add_grid_edges(nodes, weights=right, structure=np.array([[0, 0, 0], [0, 0, 1],
                                                                    [0, 0, 0]]), symmetric=True)
    graph.add_grid_edges(nodes, weights=down, structure=np.array([[0, 0, 0], [0, 0, 0],
                                                                   [0, 1, 0]]), symmetric=True)
    sure = 1e9
    source = np.where(inner_c, sure, np.where(band_c, cost[..., 1], 0.0))  # food side
    sink = np.where(band_c, cost[..., 0], np.where(inner_c, 0.0, sure))
    graph.add_grid_tedges(nodes, source, sink)
    graph.maxflow()
    is_food = ~graph.get_grid_segments(nodes)
    out = silhouette.copy()
    out[y0:y1, x0:x1] = np.where(band_c, is_food, inner_c | (silhouette[y0:y1, x0:x1] & ~band_c))
    return ndimage.binary_fill_holes(out)


# ----------------------------------------------------------------------------- the stage


def check_in_view(masks: list[np.ndarray], max_share: float) -> None:
    """Raise :class:`SegmentationError` when the food touches the image border in more than
    ``max_share`` of the frames (it is cut off: its silhouettes, and the hull, are wrong)."""
    cut = sum(bool(m[0].any() or m[-1].any() or m[:, 0].any() or m[:, -1].any())
              for m in masks)
    if cut > max_share * len(masks):
        raise SegmentationError(
            f"the food touches the image border in {cut} of {len(masks)} frames: step back so "
            "that the whole item is in view, or give masks")


def hull_view_masks(capture: Capture, T_world_from_cam: np.ndarray, registered: np.ndarray,
                    chosen: np.ndarray, geometry: SceneGeometry, cfg: SegmentConfig,
                    progress: bool = False
                    ) -> tuple[list[_View], list[np.ndarray], SceneGeometry]:
    """(the hull views ``chosen`` at GrabCut's working size, their GrabCut masks, the scene
    with its plane lifted to the surface the item rests on): step 4 of the module docstring,
    with stereo against two neighbours of each view. The stereo points find that surface
    (:func:`support_height_m`), and those standing above it seed food. (Leaving out the stereo
    points outside the item's footprint, as a plain plate first suggested, cut CO3D's real
    apple, whose sparse points cover only its top, to that top in every frame.)"""
    views = [_work_view(capture, int(i), T_world_from_cam[i], cfg) for i in chosen]
    neighbours = [[_work_view(capture, int(j), T_world_from_cam[j], cfg)
                   for j in plane_neighbours(T_world_from_cam, registered, int(i), geometry)]
                  for i in chosen]
    point_maps = [stereo_points(view, others, ndimage.binary_dilation(
        item_region(view, geometry), iterations=cfg.probable_margin_px), geometry, cfg)
        for view, others in zip(progress_over(views, "segment: hull views", progress, "views"),
                                neighbours, strict=True)]
    geometry = replace(geometry, offset_m=geometry.offset_m
                       - support_height_m(point_maps, geometry, cfg))
    masks = []
    for view, others, points in zip(views, neighbours, point_maps, strict=True):
        labels = seed_labels(view, geometry, cfg, plane_consistency(view, others, geometry),
                             geometry.height_m(points))
        masks.append(grabcut(view.rgb, labels, cfg.grabcut_iterations))
    return views, masks, geometry


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    union = np.logical_or(a, b).sum()
    return float(np.logical_and(a, b).sum() / union) if union else 1.0


def segment(capture: Capture, T_world_from_cam: np.ndarray, registered: np.ndarray,
            sparse_xyz: np.ndarray, cfg: SegmentConfig | None = None,
            progress: bool = False) -> MaskSet:
    """Food masks for every frame of ``capture`` (see the module docstring): the poses
    (N, 4, 4) and ``registered`` (N,) are the SfM stage's, ``sparse_xyz`` its points."""
    cfg = cfg or SegmentConfig()
    start = time.perf_counter()
    registered = np.asarray(registered, bool)
    up = capture.metadata.get("world_up")
    geometry = find_item(T_world_from_cam[registered], sparse_xyz,
                         None if up is None else np.asarray(up, float), cfg)
    voxel_m = hull_voxel_m(geometry, cfg)
    chosen = hull_views(registered, cfg.hull_views)
    views, coarse, lifted = hull_view_masks(capture, T_world_from_cam, registered, chosen,
                                            geometry, cfg, progress)
    lift_m = geometry.offset_m - lifted.offset_m
    geometry = lifted
    voxels = visual_hull(views, coarse, geometry, cfg, voxel_m)
    if len(voxels) == 0:
        raise SegmentationError("the views do not agree on any food: the colours of food and "
                                "plate may be too close (give masks)")
    surface = hull_surface(voxels, voxel_m)
    t_hull = time.perf_counter() - start
    masks, confidence, failed = [], [], {}
    for i, frame in enumerate(progress_over(capture.frames, "segment: masks", progress,
                                            "frames")):
        sil = hull_silhouette(surface, frame.intrinsics, np.linalg.inv(T_world_from_cam[i]),
                              voxel_m)
        with Image.open(frame.image_path) as im:
            rgb = np.asarray(im.convert("RGB"))
        mask = refine_in_band(rgb, sil, cfg) if sil.any() else sil
        agreement = _iou(mask, sil)
        if not registered[i]:
            failed[frame.name] = "not registered by SfM: its pose is the phone's (less exact)"
        if agreement < cfg.min_confidence:
            failed[frame.name] = (f"the colour refinement disagreed with the geometry "
                                  f"(IoU {agreement:.2f}): the hull's silhouette is kept")
            mask = sil
        masks.append(mask)
        confidence.append(round(agreement, 4))
    check_in_view(masks, cfg.max_border_frames)
    summary = {
        "method": "geometry seeds + GrabCut + visual hull (weights-free)",
        "hull_views": [capture.frames[i].name for i in chosen],
        "hull_voxels": len(voxels),
        "hull_voxel_m": voxel_m,
        "item_points": len(geometry.item_points),
        "plane_points": len(geometry.plane_points),
        "other_objects_left_out": geometry.other_clusters,
        "plane": {"normal": geometry.normal.tolist(), "offset_m": geometry.offset_m,
                  "lifted_m": round(lift_m, 5)},
        "fixation": geometry.fixation.tolist(),
        "seconds": {"hull_s": round(t_hull, 2),
                    "total_s": round(time.perf_counter() - start, 2)},
        "config": asdict(cfg),
    }
    log.info("segmentation: %d masks, %d frames listed, %.1f s", len(masks), len(failed),
             summary["seconds"]["total_s"])
    return MaskSet(tuple(f.name for f in capture.frames), tuple(masks), "auto",
                   tuple(confidence), failed, summary)


def save_masks(work_dir: Path, masks: MaskSet) -> Path:
    """``WORKDIR/masks/<frame>.png`` for every frame and ``WORKDIR/segment.json`` (method,
    config, per-frame area and confidence, failures), the record written last."""
    import io

    from volec.io import write_bytes_atomic, write_json_atomic
    from volec.provenance import bytes_digest

    work_dir = Path(work_dir)
    record_path = work_dir / "segment.json"
    record_path.unlink(missing_ok=True)
    files = {}
    for name, mask in zip(masks.names, masks.masks, strict=True):
        relative = f"masks/{Path(name).with_suffix('.png').name}"
        buf = io.BytesIO()
        Image.fromarray((mask * 255).astype(np.uint8)).save(buf, format="PNG")
        write_bytes_atomic(work_dir / relative, buf.getvalue())
        files[relative] = bytes_digest(buf.getvalue())
    record = {**masks.summary, "source": masks.source, "frames": list(masks.names),
              "area_fraction": [round(a, 5) for a in masks.area_fraction],
              "confidence": list(masks.confidence), "failed": masks.failed, "files": files}
    write_json_atomic(record_path, record)
    return record_path


def load_masks(work_dir: Path) -> MaskSet:
    """The masks a finished segmentation stage left in ``work_dir``."""
    import json

    work_dir = Path(work_dir)
    record = json.loads((work_dir / "segment.json").read_text())
    masks = []
    for relative in record["files"]:
        with Image.open(work_dir / relative) as im:
            masks.append(np.asarray(im.convert("L")) > 127)
    summary = {k: v for k, v in record.items()
               if k not in ("source", "frames", "confidence", "failed", "files")}
    return MaskSet(tuple(record["frames"]), tuple(masks), record["source"],
                   tuple(record["confidence"]), dict(record["failed"]), summary)
