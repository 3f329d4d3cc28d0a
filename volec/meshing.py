"""Meshing: a closed, consistently oriented surface from the metric food cloud.

In: the food cloud (masked, or completed: partial points with normals plus predicted points
without), and optionally the support plane the food rests on. Out: a :class:`MeshResult` whose
``mesh`` (a ``trimesh.Trimesh`` in metres, in the cloud's frame) is watertight with outward
faces, and a report of what each step did.

The steps:

1. Normals. Points that come with normals (dense stereo orients them towards the cameras) keep
   their direction; the others (completion's predictions) get PCA normals from their
   neighbours, turned away from the cloud's centroid.
2. Screened Poisson reconstruction (open3d) of the cloud thinned to a voxel grid. Poisson's
   indicator surface is closed by construction but open3d's triangulation of it can carry a few
   non-manifold edges or stray sheets where the cloud has holes, so its mesh is not used as is.
3. A signed distance field of the Poisson mesh on a regular grid (open3d ray casting; inside or
   outside by a majority of rays, robust to those defects), intersected with the half-space
   above the support plane (food rests on a table: nothing lies below it), then marching cubes
   (scikit-image) on the padded grid: the level set of a field sampled on a closed grid is a
   closed surface, so the result is watertight whatever the cloud looked like.
   With the food masks and camera poses (:func:`silhouette_views`), the field is also
   intersected with the visual hull: a grid point that projects outside the food mask in at
   least two views is not food. This carves what Poisson extrapolates where no camera saw the
   surface but the silhouettes rule it out, above all the gap under an item that curves in
   towards the plate (on the benchmark croissant: +7.1 % volume without carving, +1.0 % with).
   A shape prior's views (:class:`PriorViews`: the real ones reflected in the food's mirror
   plane) carve with a hull of their own, only where the prior may decide.
4. The largest connected piece is kept, and a few Taubin smoothing steps (volume-preserving,
   unlike plain Laplacian smoothing) remove the grid's staircase, as the paper smooths its mesh.
5. With the food masks, the mesh must hold them: every ray through a mask met food, so where
   the mesh leaves many of them uncovered (:func:`uncovered_mask_rays`), a shape prior's
   points (completion's, after the observed ones in the cloud) pulled the surface inside what
   the cameras saw; those near the missed rays are dropped and the cloud meshed again
   (:class:`MaskCoverConfig`).

The paper's Delaunay + graph cut (OpenMVS) is replaced by steps 2-3 because they need no
compiled code beyond open3d and scikit-image and give a closed surface by construction.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import trimesh

from volec.capture import Capture, Intrinsics
from volec.errors import VolecError
from volec.geometry import ransac_plane
from volec.pointcloud import PointCloud
from volec.segment import MaskSet


class MeshingError(VolecError):
    """No closed surface could be made (too few points, no support plane where one was asked)."""


@dataclass(frozen=True)
class SupportConfig:
    """How the plane the food rests on is found in the scene cloud."""

    search_radius_factor: float = 2.0
    """Scene points farther from the food's centre than this times the food's radius are not
    plate or table near the food, and are ignored. 1.6 left too little plate beside a round
    item (the 100-frame phone-look lemon: no plane, 54 % of its volume unknown); 2.0 finds it,
    and moved the volumes of apple, banana, pear, croissant and empanadilla by at most 0.5 %."""
    max_search_radius_factor: float = 4.0
    """Where fewer than ``min_inliers`` scene points that are not food lie within
    ``search_radius_factor``, the search widens in steps of 0.5 up to this factor. From few
    frames dense stereo keeps almost no plate and SIFT's plate points lie farther out: on the
    30-frame sparse orbits of the apple, orange, pear and falafel, 110-150 such points lay
    within 2 radii and about 1,200 within 3, so no plane was found and 47-66 % of the volume
    was unknown space (36 %, 12 % with the plane)."""
    min_gap_m: float = 0.003
    """Scene points nearer than this to a food point are food, not support."""
    inlier_m: float = 0.001
    """RANSAC inlier distance, metres."""
    ransac_iterations: int = 2000
    """RANSAC iterations (:func:`volec.geometry.ransac_plane`)."""
    min_inliers: int = 200
    """Fewer inliers than this: no support plane found."""
    max_tilt_deg: float = 10.0
    """Where the capture states its up direction, a plane tilted more than this from it is
    rejected (it is not a table)."""
    max_food_below_m: float = 0.004
    """A plane with more than 1 % of the food points further below it than this is rejected
    (the food cannot rest on it)."""
    seed: int = 0
    """Seed of the RANSAC sampling."""
    use_sparse_points: bool = True
    """Seek the plane in the SfM points too, not only in the dense scene cloud: dense stereo
    works near the food masks only, so beside a round item, or from few frames, it holds too
    little plate (a 40-frame apple: 173 points, no plane), and what it holds near the food
    tilts the plane (0.7-1.5 degrees on a banana and an apple, against 0.1 with the SfM
    points); SIFT finds the plate's print and the table's grain wherever they are."""


@dataclass(frozen=True)
class SupportPlane:
    """The plane ``normal . x + offset_m = 0`` (metres), ``normal`` a unit vector pointing
    from the support towards the food."""

    normal: tuple[float, float, float]
    offset_m: float
    inliers: int
    """Scene points within the inlier distance."""
    tilt_deg: float | None
    """Angle between the normal and the capture's up direction, if that is known."""

    def height_m(self, points: np.ndarray) -> np.ndarray:
        """Signed heights (N,) of ``points`` (N, 3) above the plane, metres."""
        return np.asarray(points, float) @ np.asarray(self.normal) + self.offset_m

    def record(self) -> dict[str, Any]:
        """JSON-able description."""
        return {"normal": list(self.normal), "offset_m": self.offset_m,
                "inliers": self.inliers, "tilt_deg": self.tilt_deg}


@dataclass(frozen=True)
class MaskCoverConfig:
    """How :func:`mesh_cloud` makes sure the mesh holds the food masks where a shape prior
    (completion) put its surface: the camera saw food along every ray through a mask, so the
    food's surface meets each of them, and a mesh that misses many has lost food the cameras
    saw (:func:`uncovered_mask_rays`). Where it does, the prior's points near the missed
    rays are dropped and the cloud meshed again; the new mesh is kept when it misses at most
    half as many. On the benchmark (phone look, SfM poses, default completion;
    ``benchmarks/bench_mask_cover.py`` at b9eba51) the network had pulled the far or lower
    side of some items inwards: the 30-frame sparse apple -4.59 -> +1.11 %, pear -6.57 ->
    -0.35 %, the half-orbit pear -8.35 -> +0.97 % (MAPE sparse 2.59 -> 2.13 %, half orbit
    2.42 -> 2.07 %); no full orbit, low or faint-skin capture came near the threshold (at most
    0.44 %, the full-orbit capsicum) and none changed."""

    max_uncovered: float = 0.01
    """The mesh is repaired when, in its 90th-percentile view, more than this share of the
    mask's inner pixels see no mesh (0.00-0.44 % on the 21 full orbits, up to 0.24 % for the
    true surface placed with the SfM poses; 2.8-5.4 % where the network pulled the side in)."""
    inset_px: float = 2.0
    """Only mask pixels more than this inside the mask's border count (the border is the
    segmenter's and the poses' error)."""
    stride_px: int = 3
    """Every this-many-th row and column of a mask is tested."""
    reach_m: float = 0.008
    """Prior points within this distance of a missed ray are dropped (4 mm left the sparse
    pear's side pulled in: the points that held it there lay farther from the rays)."""
    rounds: int = 2
    """At most this many repairs (0: no check)."""


@dataclass(frozen=True)
class FoodCoverConfig:
    """How :func:`mesh_cloud` makes sure the mesh holds the space the seen surface encloses
    (:data:`volec.space.FOOD`, given as ``food_points``), where a shape prior put its surface:
    enclosed space well behind the observed surface is food, so a mesh that leaves much of it
    out has cut into the item. Where it does, the prior's points near the missed space are
    dropped and the cloud meshed again; the new mesh is kept when it misses at most half as
    much. On by default since d96342d's measurement (phone look, SfM poses, default
    completion; ``benchmarks/bench_mask_cover.py --set meshing.food_cover.rounds=2``, after
    the masks' check, before -> after this one): the network had pulled the 30-frame sparse
    donut's lower inner side in, 1.4 % of its enclosed space missed and 0.5 % after, volume
    -5.73 -> -0.37 % (sparse MAPE 2.13 -> 1.87 %); the half-orbit orange -0.85 -> +0.63 %
    (2.07 -> 2.06 %); nothing else changed on the sparse, half and full orbits (1.51 %), the
    low cameras (1.84 %) or the faint skins (1.93 %). Counting the space within
    ``above_support_m`` of the plate too, the low-elevation donut had been "repaired" from
    +8.74 to +12.02 %: its mesh missed enclosed points 1.6 mm above the plate (median), and
    without the prior's points there Poisson closed the gap under the torus's rounded
    bottom, inside the ring and out. Some meshes miss 1.4-4.5 % with no repair that halves
    it (the capsicum in every scenario, the sparse and faint-skin banana, the chocolate bomb
    and cake, the faint-skin pear): theirs stay as they were."""

    max_missed: float = 0.01
    """The mesh is repaired when more than this share of the enclosed space deeper than
    ``depth_m`` behind the observed surface lies outside it."""
    depth_m: float = 0.003
    """Only enclosed grid points farther than this from every observed point count (nearer
    ones straddle the surface's own noise)."""
    above_support_m: float = 0.002
    """Only enclosed grid points higher than this above the support plane count: the plate
    closes the space under a rounded bottom, so the thin wedge at the contact is enclosed
    only by the plate's fit, and a mesh that leaves it out has not cut into the item."""
    reach_m: float = 0.008
    """Prior points within this distance of a missed grid point are dropped."""
    rounds: int = 2
    """At most this many repairs (0: no check)."""


@dataclass(frozen=True)
class MeshingConfig:
    """Settings of :func:`mesh_cloud`."""

    normal_neighbours: int = 24
    """Neighbours used to estimate the normal of a point that has none."""
    thinning_voxel_m: float = 0.001
    """The cloud is averaged on a grid of this size before Poisson (speed; the dense cloud is
    far denser than the surface detail Poisson keeps)."""
    poisson_depth: int = 9
    """Octree depth of the screened Poisson reconstruction."""
    grid_voxel_m: float = 0.001
    """Spacing of the signed distance grid that marching cubes meshes, metres."""
    inside_rays: int = 3
    """Rays cast per grid point to decide inside/outside (majority vote)."""
    below_support_m: float = 0.001
    """Points further than this below the support plane are dropped before Poisson."""
    silhouette_margin_px: float = 0.5
    """Tolerance of the silhouette carving, pixels: a grid point is outside a view's mask
    when it projects more than this outside it. The mask's signed distance field crosses zero
    halfway between its inside and outside pixels, where an exact mask's edge lies on
    average; but a point is carved by its ``silhouette_min_views``-th largest distance over
    the views, and on the seen surface those distances scatter by the pixels' quantization,
    so with no margin the carving bites into the food. Measured on the benchmark apple with
    exact poses and the renderer's exact depth (nothing else wrong): between 10 % and 100 %
    of its height the mesh lay 0.01-0.02 mm inside the true surface without carving and with
    0.5 px, 0.05-0.08 mm inside with 0 px; with 1 px (the earlier default) the visual hull,
    which binds wherever no depth reached (the gap under the item), lay a further pixel
    (about 0.5 mm) out, and the volume was +1.36 % against +0.91 % at 0.5 px. On the 21
    full orbits (SfM poses, phone look, exact masks, default completion) the MAPE was 1.67 %
    at 1 px, 1.47 % at 0.5 px and 1.44 % at 0 px; with volec's automatic masks (the
    benchmark's ordinary setup) 1.98 % at 1 px and 1.84 % at 0.5 px. Masks known to be a few
    pixels off take the ``tolerant_masks`` preset (1 px, three views)."""
    silhouette_max_views: int = 0
    """At most this many registered views, evenly spaced through the capture, make the
    visual hull (0: all). The carving's cost grows with the views; but under the item only
    the few lowest cameras at each azimuth carve, and a point is carved only where
    ``silhouette_min_views`` of them agree, so every view counts there: on eight phone-look
    full orbits (SfM poses, no completion, with ``spare_observed_m``) all 100 views instead
    of 50 took 0.1-0.9 % of the truth's volume off the unseen underside."""
    spare_observed_m: float = 0.001
    """Grid points behind the observed surface (the dense cloud, on the inner side of its
    normals) and within this distance of it are never carved: where the cameras measured
    the surface, depth stands, and the silhouettes decide only the space nobody measured
    (the gap under the item, grazing rims stereo dropped). The silhouettes are placed with
    the SfM poses, which err by a fraction of a pixel from frame to frame, and a point is
    carved by its ``silhouette_min_views``-th largest distance outside them over tens of
    views: an order statistic that sits in the tail of that error. Without sparing, on the
    benchmark's phone-look full orbits the carving cut 0.06-0.14 mm into the seen sides of
    apple, avocado, donut and orange (median; the same stages meshed without carving lay at
    0.00 to -0.06 mm) and 0.35 mm into the faintly textured banana's."""
    silhouette_min_views: int = 2
    """A grid point is carved when this many views see it outside their mask (one bad mask
    or pose cannot carve the food)."""
    silhouette_min_share: float = 0.0
    """... and at least this share of the views whose image it falls in (0: the count alone):
    with masks that miss a chunk here and there, a few views cannot carve the food."""
    silhouette_max_contradiction: float = 0.05
    """A view whose mask leaves out more than this share of the food cloud's points (by more
    than ``silhouette_contradiction_px``) missed part of the food, and does not carve
    (:func:`consistent_views`). On the benchmark's noisy masks (21 full orbits) the three
    frames per capture that miss a chunk leave out 6.8-29 % of the points, every other frame
    at most 2.6 %."""
    silhouette_contradiction_px: float = 4.0
    """How far outside a mask a food point must project to count against it, pixels (beyond
    a segmenter's boundary error)."""
    smoothing_iterations: int = 5
    """Taubin smoothing steps on the final mesh (the paper smooths 5 times)."""
    min_points: int = 500
    """Fewer points than this is refused."""
    far_point_factor: float = 3.0
    """Points farther from the cloud's median point than this times the 90th percentile of
    that distance are strays (a mismatched depth, a crumb), not the item: they are dropped
    before meshing and counted, so one of them cannot stretch the grid across the room."""
    max_grid_points: int = 20_000_000
    """A signed distance grid with more points than this is refused (at 1 mm, a 27 cm cube):
    the cloud is not one food item at this resolution."""
    mask_cover: MaskCoverConfig = field(default_factory=MaskCoverConfig)
    """The check that a shape prior's surface does not leave the food masks uncovered."""
    food_cover: FoodCoverConfig = field(default_factory=FoodCoverConfig)
    """The check that a shape prior's surface does not cut into the enclosed space."""


PRESETS: dict[str, MeshingConfig] = {
    "default": MeshingConfig(),
    "fast": MeshingConfig(poisson_depth=8, grid_voxel_m=0.002, inside_rays=1,
                          thinning_voxel_m=0.0015),
}


@dataclass(frozen=True)
class SilhouetteView:
    """One registered view's food silhouette, as the meshing's visual-hull constraint."""

    intrinsics: Intrinsics
    T_cam_from_world: np.ndarray
    """(4, 4) OpenCV camera-from-world, metres."""
    signed_distance_px: np.ndarray
    """(H, W) float32 distance to the food mask's border, pixels: positive outside the mask,
    negative inside."""
    name: str = ""
    """The frame's name in its capture."""


@dataclass(frozen=True)
class PriorViews:
    """Silhouettes a shape prior made (the real views reflected in the food's mirror plane,
    :func:`mirrored_views`) and where they may carve: they carve with their own visual hull
    (``MeshingConfig.silhouette_min_views`` of them agreeing), only at the points where
    ``may_carve`` (points (N, 3) -> (N,) bool) is True, e.g. not where the cameras showed
    food (:mod:`volec.space`)."""

    views: tuple[SilhouetteView, ...]
    may_carve: Callable[[np.ndarray], np.ndarray]


def signed_mask_distance(mask: np.ndarray) -> np.ndarray:
    """(H, W) float32: each pixel's Euclidean distance (pixels) to the nearest pixel on the
    other side of the boolean ``mask``'s border, positive outside the mask, negative inside.

    OpenCV's precise transform (Felzenszwalb's) in place of SciPy's exact one
    (``distance_transform_edt``): a 100-frame capture's silhouettes in a third to two fifths
    of the time (``benchmarks/bench_silhouettes.py``). OpenCV works in float32, and on one
    thread (a ``make paper`` or batch worker) its square root is approximate, up to 3e-5 px
    off. The squared distances are whole numbers, so rounding the square of its result
    recovers them, and their float64 square root is what SciPy returns: the same bits for
    every pixel within 4,096 px of the border (where float32 holds the squares exactly;
    farther, up to 5e-4 px off). A mask with no pixel on one side has no border, and goes to
    SciPy."""
    import cv2

    mask = np.asarray(mask, bool)
    if mask.all() or not mask.any():
        from scipy import ndimage

        signed = ndimage.distance_transform_edt(~mask) - ndimage.distance_transform_edt(mask)
        return signed.astype(np.float32)
    inside = mask.astype(np.uint8)
    signed = cv2.distanceTransform(1 - inside, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    signed -= cv2.distanceTransform(inside, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return np.copysign(np.sqrt(np.rint(np.square(signed, dtype=np.float64))),
                       signed).astype(np.float32)


def silhouette_view(mask: np.ndarray, intrinsics: Intrinsics, T_world_from_cam: np.ndarray,
                    name: str = "") -> SilhouetteView:
    """The :class:`SilhouetteView` of a boolean food ``mask`` (H, W) seen by a camera."""
    return SilhouetteView(intrinsics, np.linalg.inv(np.asarray(T_world_from_cam, float)),
                          signed_mask_distance(mask), name)


def silhouette_views(capture: Capture, masks: MaskSet, T_world_from_cam: np.ndarray,
                     registered: np.ndarray, max_views: int = 0,
                     known: Sequence[SilhouetteView] = ()) -> list[SilhouetteView]:
    """The silhouettes (``masks``) of the registered frames of ``capture`` (refined poses,
    metres); at most ``max_views`` of them, evenly spaced through the capture (0: all). A
    frame with a view in ``known`` (the same masks seen with other poses) takes its signed
    distances from there instead of transforming its mask again."""
    chosen = np.flatnonzero(np.asarray(registered, bool))
    if 0 < max_views < len(chosen):
        chosen = chosen[np.round(np.linspace(0, len(chosen) - 1, max_views)).astype(int)]
    by_name = {view.name: view for view in known}
    views = []
    for i in chosen:
        frame = capture.frames[i]
        if frame.name in by_name:
            views.append(replace(by_name[frame.name], intrinsics=frame.intrinsics,
                                 T_cam_from_world=np.linalg.inv(
                                     np.asarray(T_world_from_cam[i], float))))
        else:
            views.append(silhouette_view(masks.mask(int(i)), frame.intrinsics,
                                         T_world_from_cam[i], frame.name))
    return views


def _project(view: SilhouetteView, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``points`` (N, 3, metres) in ``view``: (N, 3) pixel column, row and depth (metres), and
    which of them fall in its image (N,) bool."""
    cam = points @ view.T_cam_from_world[:3, :3].T
    cam += view.T_cam_from_world[:3, 3]
    uv = view.intrinsics.project(cam)  # NaN behind the camera: every test below is False
    h, w = view.signed_distance_px.shape
    with np.errstate(invalid="ignore"):
        ok = uv[:, 0] >= 0
        ok &= uv[:, 0] <= w - 1
        ok &= uv[:, 1] >= 0
        ok &= uv[:, 1] <= h - 1
    return np.column_stack([uv, cam[:, 2]]), ok


def mask_contradiction(view: SilhouetteView, food_xyz: np.ndarray, margin_px: float) -> float:
    """Share of the food points ``food_xyz`` (N, 3) in ``view``'s image that project more than
    ``margin_px`` outside its mask: about 0 for a mask that holds the whole food (every food
    point projects inside the silhouette, seen or hidden), the missed part's share for one
    that left a chunk out, 1 for an empty one."""
    uvz, ok = _project(view, np.asarray(food_xyz, float))
    if not ok.any():
        return 1.0
    pix = np.round(uvz[ok, :2]).astype(int)
    return float(np.mean(view.signed_distance_px[pix[:, 1], pix[:, 0]] > margin_px))


def mask_contradictions(views: list[SilhouetteView], food_xyz: np.ndarray, margin_px: float
                        ) -> np.ndarray:
    """:func:`mask_contradiction` of each of ``views`` (V,), :func:`batched` views together."""
    food_xyz = np.asarray(food_xyz, float)
    if not views or not batched(views):
        return np.array([mask_contradiction(v, food_xyz, margin_px) for v in views])
    seen = np.zeros(len(views))
    outside = np.zeros(len(views))
    for _, px, _, ok in _view_samples(food_xyz, views, "nearest"):
        seen += ok.sum(dim=1).numpy()
        outside += ((px > margin_px) & ok).sum(dim=1).numpy()
    return np.where(seen > 0, outside / np.maximum(seen, 1), 1.0)


def mirrored_views(views: list[SilhouetteView], reflection: np.ndarray, margin_m: float,
                   centre: np.ndarray) -> list[SilhouetteView]:
    """``views`` composed with ``reflection`` (4, 4), a mirror plane of the food: a point lies
    inside a mirrored view's silhouette when its mirror image lies inside the view's. Each
    silhouette is shrunk by ``margin_m`` (in pixels at the depth of ``centre``, the food's), so
    that it carves only what lies that far outside."""
    out = []
    for view in views:
        T = view.T_cam_from_world @ reflection
        depth = float((T[:3, :3] @ np.asarray(centre, float) + T[:3, 3])[2])
        margin_px = margin_m * view.intrinsics.fx / max(depth, 1e-6)
        out.append(replace(view, T_cam_from_world=T, name=f"{view.name} (mirrored)",
                           signed_distance_px=(view.signed_distance_px
                                               - np.float32(margin_px)).astype(np.float32)))
    return out


def consistent_views(views: list[SilhouetteView], food_xyz: np.ndarray, cfg: MeshingConfig
                     ) -> tuple[list[SilhouetteView], list[SilhouetteView]]:
    """``views`` split into those that may carve and those whose mask leaves out more than
    ``cfg.silhouette_max_contradiction`` of the food cloud ``food_xyz``
    (:func:`mask_contradiction`): a mask that missed part of the food would carve it away,
    however many views agree."""
    share = mask_contradictions(views, food_xyz, cfg.silhouette_contradiction_px)
    keep = [s <= cfg.silhouette_max_contradiction for s in share]
    return ([v for v, k in zip(views, keep, strict=True) if k],
            [v for v, k in zip(views, keep, strict=True) if not k])


def batched(views: list[SilhouetteView]) -> bool:
    """True when ``views`` can be sampled together (:func:`_view_samples`): one image size,
    no lens distortion."""
    return (len({v.signed_distance_px.shape for v in views}) == 1
            and all(v.intrinsics.is_undistorted for v in views))


def _view_samples(points: np.ndarray, views: list[SilhouetteView], mode: str
                  ) -> Iterator[tuple[slice, Any, Any, Any]]:
    """The masks' signed distances (pixels) at ``points`` (N, 3) in every view at once, in
    chunks of points: per chunk its slice of the points and (V, n) torch tensors of the
    sampled distance (``mode`` "bilinear" or "nearest"), the depth (metres) and whether the
    point falls in the image. On the CPU's threads, float32 about the points' centre
    (coordinates of centimetres: sub-micrometre rounding). For :func:`batched` views."""
    import torch
    import torch.nn.functional as F

    h, w = views[0].signed_distance_px.shape
    images = torch.from_numpy(np.stack([v.signed_distance_px for v in views])[:, None])
    origin = points.mean(axis=0) if len(points) else np.zeros(3)
    T64 = np.stack([v.T_cam_from_world[:3] for v in views]).astype(float)
    T64[:, :, 3] += T64[:, :, :3] @ origin
    T = torch.from_numpy(T64.astype(np.float32))
    f_c = torch.tensor([[v.intrinsics.fx, v.intrinsics.fy, v.intrinsics.cx, v.intrinsics.cy]
                        for v in views], dtype=torch.float32)[:, None, :]
    fx, fy, cx, cy = f_c.unbind(-1)  # each (V, 1)
    # 4 million view-points a chunk: volec estimate's peak memory 1.5-1.6 GB instead of
    # 1.2-1.3 GB view by view. A quarter of that took as long, but matmul's float32 rounding
    # depends on the chunk's shape, and through the space sorting and completion it moved the
    # benchmark banana's volume by 0.17 % (147.76 -> 147.50 mL): chaotic, not wrong, yet
    # every table was measured with this chunk.
    chunk = max(1, 4_000_000 // len(views))
    with torch.no_grad():
        for start in range(0, len(points), chunk):
            xyz = torch.from_numpy((points[start:start + chunk] - origin).astype(np.float32))
            # (V, 3, n): each camera coordinate a contiguous row, R @ x + t in one batched
            # product, in about half the time of the (V, n, 3) layout's strided arithmetic.
            # Its sums came out the same bits as that layout's (x @ R^T + t) on every value
            # of the benchmark rows tried (benchmarks/bench_silhouettes.py and
            # bench_volume_row.py); another CPU's kernels may round them otherwise.
            x, y, z = torch.baddbmm(T[:, :, 3:], T[:, :, :3],
                                    xyz.T.expand(len(views), 3, len(xyz))).unbind(1)
            # In place where a temporary would be made: the same operations in the same
            # order, so the same bits.
            u = (x / z).mul_(fx).add_(cx)
            v = (y / z).mul_(fy).add_(cy)
            ok = z > 1e-9
            ok &= u >= 0
            ok &= u <= w - 1
            ok &= v >= 0
            ok &= v <= h - 1
            outside = ~ok
            grid = torch.stack([u.div_(w - 1).mul_(2).sub_(1).masked_fill_(outside, 0.0),
                                v.div_(h - 1).mul_(2).sub_(1).masked_fill_(outside, 0.0)],
                               dim=-1)
            sampled = F.grid_sample(images, grid[:, None], mode=mode,
                                    align_corners=True)[:, 0, 0]
            yield slice(start, start + len(xyz)), sampled, z / fx, ok


def outside_distances(points: np.ndarray, views: list[SilhouetteView], margin_px: float
                      ) -> np.ndarray:
    """(V, N) float32: how far (metres, at the point's depth) each point of ``points`` (N, 3)
    lies outside each view's mask widened by ``margin_px``; -inf where it is not in the view's
    image. Bilinear in the masks' signed distances. :func:`batched` views go through torch
    together (:func:`_view_samples`: 1.8 times faster than view by view in numpy on 2 cores,
    the same values within 1e-7 m), the others one by one (:func:`_outside_distances_numpy`).
    """
    if not batched(views):
        return _outside_distances_numpy(points, views, margin_px)
    import torch

    out = np.empty((len(views), len(points)), np.float32)
    for rows, outside_px, metres_per_px, ok in _view_samples(points, views, "bilinear"):
        metres = (outside_px - margin_px) * metres_per_px
        out[:, rows] = torch.where(ok, metres, torch.full_like(metres, -np.inf)).numpy()
    return out


def _outside_distances_numpy(points: np.ndarray, views: list[SilhouetteView],
                             margin_px: float) -> np.ndarray:
    """:func:`outside_distances` view by view (any image sizes, distorted lenses)."""
    from scipy import ndimage

    out = np.full((len(views), len(points)), -np.inf, np.float32)
    for j, view in enumerate(views):
        uvz, ok = _project(view, points)
        outside_px = ndimage.map_coordinates(view.signed_distance_px, [uvz[ok, 1], uvz[ok, 0]],
                                             order=1)
        out[j, ok] = (outside_px - margin_px) * uvz[ok, 2] / view.intrinsics.fx
    return out


def silhouette_field(points: np.ndarray, views: list[SilhouetteView], margin_px: float,
                     min_views: int, min_share: float = 0.0) -> np.ndarray:
    """Per point (N, 3), metres: how far outside the visual hull it is (negative inside).

    Each view gives the point's distance outside its (margin-widened) mask, turned from pixels
    into metres at the point's depth; the point's value is the ``min_views``-th largest of
    these over the views whose image it falls in, so that many views must agree before a point
    is carved; with ``min_share``, at least that share of those views too. Points that fewer
    views see are never carved (-inf)."""
    points = np.asarray(points, float)
    per_view = outside_distances(points, views, margin_px)
    if len(views) < min_views:  # too few views to carve anything
        per_view = np.vstack([per_view, np.full((min_views - len(views), len(points)),
                                                -np.inf, np.float32)])
    if min_share <= 0:
        return -np.partition(-per_view, min_views - 1, axis=0)[min_views - 1]
    seen = np.isfinite(per_view).sum(axis=0)
    needed = np.clip(np.maximum(min_views, np.ceil(min_share * seen)), 1,
                     len(per_view)).astype(int)
    out = np.empty(len(points), np.float32)
    for k in np.unique(needed):  # a few values: one partition each
        these = np.flatnonzero(needed == k)
        out[these] = -np.partition(-per_view[:, these], k - 1, axis=0)[k - 1]
    return out


@dataclass(frozen=True)
class MeshResult:
    """A closed mesh (metres, outward faces) and what making it did."""

    mesh: trimesh.Trimesh
    report: dict[str, Any] = field(default_factory=dict)
    dropped: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    """Indices into the cloud given to :func:`mesh_cloud` of the shape prior's points that
    were not meshed because they left the food masks uncovered (:class:`MaskCoverConfig`) or
    cut into the enclosed space (:class:`FoodCoverConfig`)."""


def support_candidates(scene: PointCloud, food: PointCloud, cfg: SupportConfig) -> np.ndarray:
    """(N, 3) the ``scene`` points that may be the support: not food (farther than
    ``cfg.min_gap_m`` from every ``food`` point) and near it, within the smallest multiple of
    the food's radius, from ``cfg.search_radius_factor`` up to
    ``cfg.max_search_radius_factor`` in steps of 0.5, that holds ``cfg.min_inliers`` of them.
    Raises :class:`MeshingError` when even the widest holds fewer."""
    from scipy.spatial import cKDTree

    centre = food.xyz.mean(axis=0)
    radius = float(np.percentile(np.linalg.norm(food.xyz - centre, axis=1), 99))
    gap = cKDTree(food.xyz).query(scene.xyz, distance_upper_bound=cfg.min_gap_m)[0]
    apart = np.linalg.norm(scene.xyz - centre, axis=1)[np.isinf(gap)] / radius
    not_food = scene.xyz[np.isinf(gap)]
    factor = cfg.search_radius_factor
    while True:
        candidates = not_food[apart < factor]
        if len(candidates) >= cfg.min_inliers:
            return candidates
        if factor + 0.5 > cfg.max_search_radius_factor + 1e-9:
            raise MeshingError(
                f"only {len(candidates)} scene points within {factor:g} food radii are not "
                f"food; a support plane needs at least {cfg.min_inliers} (is the table or "
                "plate in the scene cloud?)")
        factor += 0.5


def fit_support_plane(scene: PointCloud, food: PointCloud, up: np.ndarray | None = None,
                      cfg: SupportConfig | None = None) -> SupportPlane:
    """The plane under ``food`` in ``scene`` (plate or table top), by RANSAC on the scene
    points around the food that are not food. ``up`` (the capture's up direction, if it states
    one) rejects planes that are not level. Raises :class:`MeshingError` when none is found."""
    cfg = cfg or SupportConfig()
    centre = food.xyz.mean(axis=0)
    candidates = support_candidates(scene, food, cfg)
    normal, offset, inliers = ransac_plane(candidates, cfg.inlier_m, cfg.ransac_iterations,
                                           cfg.seed)
    if normal @ centre + offset < 0:
        normal, offset = -normal, -offset
    tilt = None
    if up is not None:
        up_unit = np.asarray(up, float) / np.linalg.norm(up)
        tilt = float(np.degrees(np.arccos(np.clip(normal @ up_unit, -1.0, 1.0))))
        if tilt > cfg.max_tilt_deg:
            raise MeshingError(f"the best plane near the food is tilted {tilt:.0f} degrees from "
                               "the capture's up direction: no level support found")
    if len(inliers) < cfg.min_inliers:
        raise MeshingError(f"the best plane near the food has {len(inliers)} points; at least "
                           f"{cfg.min_inliers} are needed")
    below = np.mean(food.xyz @ normal + offset < -cfg.max_food_below_m)
    if below > 0.01:
        raise MeshingError(f"{100 * below:.0f} % of the food lies below the best plane found; "
                           "it is not what the food rests on")
    return SupportPlane(tuple(float(v) for v in normal), offset, len(inliers), tilt)


def oriented_normals(cloud: PointCloud, neighbours: int = 24) -> np.ndarray:
    """Unit normals (N, 3) for every point of ``cloud``. Where ``cloud.normals`` has a finite,
    non-zero row it sets the direction; other rows get PCA normals pointing away from the
    centroid (right for the convex-ish underside that completion predicts)."""
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(cloud.xyz))
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(neighbours))
    normals = np.asarray(pcd.normals).copy()
    outward = cloud.xyz - cloud.xyz.mean(axis=0)
    if cloud.normals is not None:
        given = np.asarray(cloud.normals, float)
        known = np.isfinite(given).all(axis=1) & (np.linalg.norm(given, axis=1) > 0.5)
        outward = np.where(known[:, None], given, outward)
    flip = np.sum(normals * outward, axis=1) < 0
    normals[flip] *= -1.0
    return normals


def with_normals(cloud: PointCloud, neighbours: int = 24) -> PointCloud:
    """``cloud`` with a unit normal on every point (:func:`oriented_normals`): what a file
    for other tools should carry, where completion left the predicted points' normals NaN."""
    return PointCloud(cloud.xyz, cloud.rgb, oriented_normals(cloud, neighbours))


def _poisson(xyz: np.ndarray, normals: np.ndarray, cfg: MeshingConfig):  # -> o3d TriangleMesh
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz))
    pcd.normals = o3d.utility.Vector3dVector(normals)
    if cfg.thinning_voxel_m > 0:
        pcd = pcd.voxel_down_sample(cfg.thinning_voxel_m)
        # Opposite normals in one voxel (the two sides of a thin part) average to nearly
        # nothing: such points have no direction, and Poisson would reject them as bad data.
        length = np.linalg.norm(np.asarray(pcd.normals), axis=1)
        pcd = pcd.select_by_index(np.flatnonzero(length > 0.1).tolist())
        pcd.normalize_normals()
    # One thread: open3d's multi-threaded Poisson segfaults now and then (isl-org/Open3D#6828;
    # it killed a notebook's kernel in CI) and differs in the last digits from run to run. On
    # four benchmark clouds one thread took as long as two (2-6 s either way) and gave the
    # same mesh every time.
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        mesh, _ = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(
            pcd, depth=cfg.poisson_depth, scale=1.1, linear_fit=False, n_threads=1)
    return mesh, len(pcd.points)


def _grid_axes(lower: np.ndarray, shape: tuple[int, int, int], voxel_m: float
               ) -> list[np.ndarray]:
    """The coordinates (metres) of the grid points along each axis."""
    return [lower[i] + voxel_m * np.arange(shape[i]) for i in range(3)]


def ray_scene(mesh: trimesh.Trimesh):  # -> open3d.t.geometry.RaycastingScene
    """An open3d ray-casting scene holding ``mesh`` (float32 coordinates)."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(np.asarray(mesh.vertices, np.float32)),
                        o3d.core.Tensor(np.asarray(mesh.faces, np.uint32)))
    return scene


def uncovered_mask_rays(mesh: trimesh.Trimesh, views: list[SilhouetteView],
                        inset_px: float = 2.0, stride_px: int = 3
                        ) -> tuple[np.ndarray, list[tuple[np.ndarray, np.ndarray]]]:
    """(shares (V,), rays): per view, the share of its food mask whose viewing rays miss
    ``mesh``, over the mask's pixels more than ``inset_px`` inside its border, every
    ``stride_px``-th row and column; and per view the missed rays, as (camera centre (3,),
    unit directions (M, 3)) in the world frame.

    The camera saw food along each of those rays, so the food's own surface meets every one
    of them; a closed mesh carved by the visual hull leaves none uncovered (0, up to the
    poses' error), and a mesh that does has lost food the cameras saw, whatever the shape
    prior that put its surface there said."""
    import open3d as o3d

    scene = ray_scene(mesh)
    shares, missed = np.zeros(len(views)), []
    for i, view in enumerate(views):
        rows, cols = np.nonzero(view.signed_distance_px[::stride_px, ::stride_px] < -inset_px)
        rotation, translation = view.T_cam_from_world[:3, :3], view.T_cam_from_world[:3, 3]
        centre = -rotation.T @ translation
        if not len(rows):
            missed.append((centre, np.zeros((0, 3))))
            continue
        pixels = np.column_stack([cols, rows]).astype(float) * stride_px
        directions = view.intrinsics.unproject(pixels) @ rotation  # to the world: R^T d
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        rays = np.hstack([np.broadcast_to(centre, directions.shape), directions])
        hit = scene.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))["t_hit"].numpy()
        miss = ~np.isfinite(hit)
        shares[i] = float(miss.mean())
        missed.append((centre, directions[miss]))
    return shares, missed


def near_rays(points: np.ndarray, rays: list[tuple[np.ndarray, np.ndarray]], reach_m: float
              ) -> np.ndarray:
    """(N,) which of ``points`` (N, 3) lie within ``reach_m`` of one of the ``rays`` (per
    camera centre, its unit directions; :func:`uncovered_mask_rays`), in front of its
    camera."""
    near = np.zeros(len(points), bool)
    for centre, directions in rays:
        if not len(directions) or near.all():
            continue
        offsets = points - centre
        along = offsets @ directions.T  # (N, M)
        across_sq = (offsets ** 2).sum(axis=1)[:, None] - along ** 2
        near |= ((along > 0) & (across_sq <= reach_m ** 2)).any(axis=1)
    return near


def signed_distance_grid(mesh: trimesh.Trimesh, lower: np.ndarray, shape: tuple[int, int, int],
                         voxel_m: float, rays: int = 3, band_voxels: int = 3) -> np.ndarray:
    """Signed distance (negative inside) of ``mesh`` at the grid points
    ``lower + voxel_m * (i, j, k)``, as a float32 array of ``shape``. Inside/outside is a
    majority of ``rays`` ray casts, so a few defects of the mesh do not flip it.

    The distance is exact only within ``band_voxels`` grid steps of the surface, which is all
    that marching cubes and the intersections with other fields need; farther away it is the
    distance to the nearest grid point where inside/outside changes (a Euclidean distance
    transform, within a grid step of the truth). The closest-point query costs 20 times the
    ray casts, and open3d has no narrow-band version of it."""
    import open3d as o3d
    from scipy import ndimage

    scene = ray_scene(mesh)
    points = np.stack(np.meshgrid(*_grid_axes(lower, shape, voxel_m), indexing="ij"),
                      axis=-1).reshape(-1, 3).astype(np.float32)
    inside = scene.compute_occupancy(o3d.core.Tensor(points), nsamples=rays).numpy()
    inside = inside.reshape(shape).astype(bool)
    # Inside points with an outside neighbour: the surface passes within a step of them.
    border = inside & ~ndimage.binary_erosion(inside, border_value=1)
    if not border.any():
        return np.where(inside, -1.0, 1.0).astype(np.float32) * voxel_m * max(shape)
    steps = ndimage.distance_transform_edt(~border).reshape(-1)
    sign = np.where(inside.reshape(-1), -1.0, 1.0)
    # The surface lies within a step outside the border points: half a step on average.
    field_m = ((sign * steps - 0.5) * voxel_m).astype(np.float32)
    band = steps <= band_voxels + 1
    distance = scene.compute_distance(o3d.core.Tensor(points[band])).numpy()
    field_m[band] = sign[band] * distance
    return field_m.reshape(shape)


def closed_surface(field_m: np.ndarray, lower: np.ndarray, voxel_m: float) -> trimesh.Trimesh:
    """The zero level set of a signed field (negative inside, metres) sampled on a grid, as a
    watertight mesh with outward faces. The grid's border is forced outside first, so the
    surface cannot run off the grid and stay open."""
    from skimage.measure import marching_cubes

    padded = np.pad(field_m.astype(np.float32), 1, constant_values=voxel_m)
    # Samples exactly on the level (a cut plane through grid points) make degenerate,
    # non-manifold triangles: move them a hair outside.
    padded[padded == 0] = 1e-6 * voxel_m
    if not (padded < 0).any():
        raise MeshingError("the signed distance field has no inside: nothing to mesh")
    verts, faces, _, _ = marching_cubes(padded, 0.0, spacing=(voxel_m,) * 3,
                                        gradient_direction="ascent")
    mesh = trimesh.Trimesh(verts + np.asarray(lower) - voxel_m, faces, process=True)
    if not mesh.is_watertight:
        # Merging the vertices that lie at one point makes an edge non-manifold where two
        # sheets of the surface touch (a carved croissant's body: 5 such faces, and the
        # watertight pieces left were crumbs); marching cubes' own vertices are shared already.
        mesh = trimesh.Trimesh(verts + np.asarray(lower) - voxel_m, faces, process=False)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def offsets_along_normals(points: np.ndarray, observed: PointCloud, index: np.ndarray
                          ) -> np.ndarray:
    """(N, k) how far each of the ``points`` (N, 3) lies in front of (positive) or behind
    (negative) each of its observed neighbours ``index`` (N, k), along that neighbour's
    normal."""
    offsets = points[:, None, :] - observed.xyz[index]
    return np.einsum("nkj,nkj->nk", offsets, observed.normals[index])


def behind_observed(points: np.ndarray, observed: PointCloud, reach_m: float,
                    neighbours: int = 8) -> np.ndarray:
    """(N,) a field that is negative for the ``points`` (N, 3) behind the ``observed``
    surface within ``reach_m`` of it, positive elsewhere: the larger of the points' mean
    offset along the normals of their nearest observed points (negative behind) and their
    distance to the nearest one less ``reach_m``. ``observed`` needs normals."""
    from scipy.spatial import cKDTree

    out = np.full(len(points), float(reach_m))
    if observed.normals is None or not len(observed) or not len(points):
        return out
    k = min(neighbours, len(observed))
    distance, index = cKDTree(observed.xyz).query(points, k=k, distance_upper_bound=reach_m)
    distance, index = distance.reshape(len(points), k), index.reshape(len(points), k)
    near = np.isfinite(distance[:, 0])
    found = np.isfinite(distance[near])
    index = np.where(found, index[near], 0)
    along = offsets_along_normals(points[near], observed, index)
    along = np.where(found, along, 0.0).sum(axis=1) / found.sum(axis=1)
    out[near] = np.maximum(along, distance[near, 0] - reach_m)
    return out


def _carve(field_m: np.ndarray, lower: np.ndarray, shape: tuple[int, int, int],
           views: list[SilhouetteView], cfg: MeshingConfig, report: dict[str, Any],
           observed: PointCloud | None = None, prior: PriorViews | None = None) -> np.ndarray:
    """``field_m`` intersected with the visual hull of ``views`` (and, where they may carve,
    of the ``prior`` views), only evaluated near or inside the solid (elsewhere the result is
    outside anyway), except just behind the ``observed`` surface
    (:attr:`MeshingConfig.spare_observed_m`)."""
    flat = field_m.reshape(-1).copy()
    near = np.flatnonzero(flat < 2 * cfg.grid_voxel_m)
    axes = _grid_axes(lower, shape, cfg.grid_voxel_m)
    index = np.unravel_index(near, shape)
    points = np.stack([axes[i][index[i]] for i in range(3)], axis=1)
    hull = silhouette_field(points, views, cfg.silhouette_margin_px, cfg.silhouette_min_views,
                            cfg.silhouette_min_share)
    if prior is not None and prior.views:
        hull = np.maximum(hull, prior_field(points, prior, cfg))
        report["prior_views"] = len(prior.views)
    if observed is not None and cfg.spare_observed_m > 0:
        hull = np.minimum(hull, behind_observed(points, observed, cfg.spare_observed_m))
    inside_before = int((flat < 0).sum())
    flat[near] = np.maximum(flat[near], hull)
    carved = 1.0 - (flat < 0).sum() / max(inside_before, 1)
    report.update({"silhouette_views": len(views), "carved_fraction": round(float(carved), 4),
                   "silhouette_margin_px": cfg.silhouette_margin_px,
                   "spare_observed_m": cfg.spare_observed_m if observed is not None else 0.0})
    return flat.reshape(shape)


def prior_field(points: np.ndarray, prior: PriorViews, cfg: MeshingConfig) -> np.ndarray:
    """(N,) metres outside the ``prior`` views' hull (:func:`silhouette_field`), -inf where
    they may not carve."""
    out = silhouette_field(points, list(prior.views), cfg.silhouette_margin_px,
                           cfg.silhouette_min_views, cfg.silhouette_min_share)
    out[~np.asarray(prior.may_carve(points), bool)] = -np.inf
    return out


def within_reach(xyz: np.ndarray, factor: float) -> np.ndarray:
    """(N,) True for the points no farther from the median point than ``factor`` times the
    90th percentile of that distance (all of them when ``factor`` is 0)."""
    if factor <= 0 or len(xyz) == 0:
        return np.ones(len(xyz), bool)
    distance = np.linalg.norm(xyz - np.median(xyz, axis=0), axis=1)
    return distance <= factor * np.percentile(distance, 90)


def mesh_cloud(cloud: PointCloud, support: SupportPlane | None = None,
               cfg: MeshingConfig | None = None,
               silhouettes: list[SilhouetteView] | None = None,
               observed: PointCloud | None = None, prior: PriorViews | None = None,
               food_points: np.ndarray | None = None) -> MeshResult:
    """A closed mesh of the food cloud (see the module docstring). With ``support``, the
    surface is cut flat at that plane and points below it are dropped first; with
    ``silhouettes``, it is intersected with their visual hull (and the ``prior`` views' where
    those may carve), except just behind the ``observed`` cloud (the part of ``cloud`` the
    cameras measured, with normals, its first points), and the points after the observed
    ones (a shape prior's) that leave the masks uncovered are dropped
    (:class:`MaskCoverConfig`); with ``food_points`` (M, 3), space the seen surface encloses,
    so are those that cut into it (:class:`FoodCoverConfig`)."""
    cfg = cfg or MeshingConfig()
    result = _mesh_once(cloud, support, cfg, silhouettes, observed, prior)
    if (observed is None or len(cloud) <= len(observed)
            or not np.array_equal(cloud.xyz[:len(observed)], observed.xyz)):
        return result  # no points of a prior's to drop
    n_observed, kept, checks = len(observed), np.arange(len(cloud)), {}

    def remesh(subset: PointCloud) -> MeshResult:
        return _mesh_once(subset, support, cfg, silhouettes, observed, prior)

    masks = cfg.mask_cover
    if silhouettes and masks.rounds:
        result, kept, checks["mask_cover"] = _repaired(
            result, cloud, kept, n_observed, remesh,
            lambda mesh: _uncovered_p90(mesh, silhouettes, masks),
            lambda xyz, rays: near_rays(xyz, rays, masks.reach_m),
            masks.max_uncovered, masks.rounds, "uncovered_p90")
        checks["mask_cover"]["max_uncovered"] = masks.max_uncovered
    enclosed = cfg.food_cover
    if food_points is not None and enclosed.rounds:
        # enclosed points nearer the observed surface straddle its own noise
        deep = food_points[~near_points(food_points, observed.xyz, enclosed.depth_m)]
        if support is not None:
            deep = deep[support.height_m(deep) > enclosed.above_support_m]
        if len(deep):
            result, kept, checks["food_cover"] = _repaired(
                result, cloud, kept, n_observed, remesh,
                lambda mesh: missed_points(mesh, deep),
                lambda xyz, missed: near_points(xyz, missed, enclosed.reach_m),
                enclosed.max_missed, enclosed.rounds, "missed_share")
    dropped = np.setdiff1d(np.arange(len(cloud)), kept)
    return MeshResult(result.mesh, {**result.report, **checks}, dropped)


def _uncovered_p90(mesh: trimesh.Trimesh, views: list[SilhouetteView], cfg: MaskCoverConfig
                   ) -> tuple[float, list[tuple[np.ndarray, np.ndarray]]]:
    """The 90th-percentile view's share of uncovered mask rays, and those rays."""
    shares, rays = uncovered_mask_rays(mesh, views, cfg.inset_px, cfg.stride_px)
    return float(np.percentile(shares, 90)), rays


def missed_points(mesh: trimesh.Trimesh, points: np.ndarray) -> tuple[float, np.ndarray]:
    """The share of ``points`` (M, 3) outside the closed ``mesh``, and those points."""
    import open3d as o3d

    inside = ray_scene(mesh).compute_occupancy(
        o3d.core.Tensor(np.asarray(points, np.float32))).numpy() > 0.5
    return float(1.0 - inside.mean()), points[~inside]


def near_points(xyz: np.ndarray, targets: np.ndarray, reach_m: float) -> np.ndarray:
    """(N,) which of ``xyz`` (N, 3) lie within ``reach_m`` of one of ``targets`` (M, 3)."""
    from scipy.spatial import cKDTree

    if not len(targets) or not len(xyz):
        return np.zeros(len(xyz), bool)
    return np.isfinite(cKDTree(targets).query(xyz, distance_upper_bound=reach_m)[0])


def _repaired(result: MeshResult, cloud: PointCloud, kept: np.ndarray, n_observed: int,
              remesh: Callable[[PointCloud], MeshResult],
              missed: Callable[[trimesh.Trimesh], tuple[float, Any]],
              near: Callable[[np.ndarray, Any], np.ndarray], limit: float, rounds: int,
              key: str) -> tuple[MeshResult, np.ndarray, dict[str, Any]]:
    """``result`` (the mesh of ``cloud``'s ``kept`` points), or where ``missed`` (of a mesh:
    a share, and the evidence of what it misses) is above ``limit``, the mesh (by ``remesh``)
    without the prior's points (those after the first ``n_observed``) that ``near`` puts near
    the evidence, for as long as that halves the share, at most ``rounds`` times. Returns
    the mesh, the indices of the points it was made from and a record (``key``: the share)."""
    score, evidence = missed(result.mesh)
    record: dict[str, Any] = {key: round(score, 5), "repairs": 0, "prior_points_dropped": 0,
                              f"first_{key}": round(score, 5),
                              "first_volume_ml": round(float(result.mesh.volume) * 1e6, 3)}
    start = len(kept)
    for _ in range(rounds):
        if score <= limit:
            break
        drop = np.zeros(len(kept), bool)
        drop[n_observed:] = near(cloud.xyz[kept[n_observed:]], evidence)
        if not drop.any():
            break
        trial = remesh(cloud.subset(np.isin(np.arange(len(cloud)), kept[~drop])))
        trial_score, trial_evidence = missed(trial.mesh)
        record[f"tried_{key}"] = round(trial_score, 5)
        if trial_score > score / 2:  # the dropped points were not what missed it
            break
        result, evidence, score, kept = trial, trial_evidence, trial_score, kept[~drop]
        record.update({key: round(score, 5), "repairs": record["repairs"] + 1,
                       "prior_points_dropped": start - len(kept)})
    return result, kept, record


def _mesh_once(cloud: PointCloud, support: SupportPlane | None, cfg: MeshingConfig,
               silhouettes: list[SilhouetteView] | None, observed: PointCloud | None,
               prior: PriorViews | None) -> MeshResult:
    """:func:`mesh_cloud` without the masks' check."""
    start = time.perf_counter()
    if len(cloud) < cfg.min_points:
        raise MeshingError(f"the food cloud has {len(cloud)} points; meshing needs at least "
                           f"{cfg.min_points}")
    if not np.isfinite(cloud.xyz).all():
        raise MeshingError("the food cloud has non-finite coordinates")
    report: dict[str, Any] = {"points_in": len(cloud)}
    near = within_reach(cloud.xyz, cfg.far_point_factor)
    report["far_points_dropped"] = int((~near).sum())
    cloud = cloud.subset(near)
    if support is not None:
        keep = support.height_m(cloud.xyz) > -cfg.below_support_m
        report["points_below_support"] = int((~keep).sum())
        cloud = cloud.subset(keep)
    normals = oriented_normals(cloud, cfg.normal_neighbours)
    poisson, used = _poisson(cloud.xyz, normals, cfg)
    report["poisson_points"] = used
    surface = trimesh.Trimesh(np.asarray(poisson.vertices), np.asarray(poisson.triangles),
                              process=True)
    report["poisson_faces"] = len(surface.faces)
    report["poisson_watertight"] = bool(surface.is_watertight)

    # The grid spans the cloud (not Poisson's surface, which can bulge far where the cloud
    # has a hole): a bulge beyond the points is cut by the grid's border. With a support
    # plane it reaches down to the plane under the cloud, where the food rests.
    span = cloud.xyz
    if support is not None:
        span = np.vstack([span, span - np.outer(support.height_m(span), support.normal)])
    margin = 3 * cfg.grid_voxel_m
    lower = span.min(axis=0) - margin
    shape = tuple(int(n) for n in np.ceil((span.max(axis=0) + margin - lower)
                                          / cfg.grid_voxel_m) + 1)
    if np.prod(shape, dtype=float) > cfg.max_grid_points:
        size_mm = (np.asarray(shape) - 1) * cfg.grid_voxel_m * 1000
        raise MeshingError(
            f"the food cloud spans {size_mm[0]:.0f} x {size_mm[1]:.0f} x {size_mm[2]:.0f} mm, "
            f"a grid of {np.prod(shape, dtype=float):.3g} points at "
            f"{cfg.grid_voxel_m * 1000:g} mm (the limit is {cfg.max_grid_points:.3g}): it is "
            "not one food item; check the masks and the capture's scale")
    field_m = signed_distance_grid(surface, lower, shape, cfg.grid_voxel_m, cfg.inside_rays)
    if support is not None:
        axes = _grid_axes(lower, shape, cfg.grid_voxel_m)
        n = np.asarray(support.normal)
        height = (axes[0][:, None, None] * n[0] + axes[1][None, :, None] * n[1]
                  + axes[2][None, None, :] * n[2] + support.offset_m)
        field_m = np.maximum(field_m, -height)
    if silhouettes:
        field_m = _carve(field_m, lower, shape, silhouettes, cfg, report, observed, prior)
    mesh = closed_surface(field_m, lower, cfg.grid_voxel_m)
    pieces = mesh.split(only_watertight=False)
    if pieces and not max(pieces, key=lambda m: len(m.faces)).is_watertight:
        raise MeshingError("the food's surface is not closed (its largest piece has "
                           "non-manifold edges): no volume can be computed from it")
    pieces = [m for m in pieces if m.is_watertight]
    report["pieces_dropped"] = max(0, len(pieces) - 1)
    if pieces:
        largest = max(pieces, key=lambda m: m.volume)
        # a dropped inward piece is a cavity that the kept mesh now fills: count its size too
        report["dropped_volume_ml"] = round(float(sum(abs(m.volume) for m in pieces)
                                                  - largest.volume) * 1e6, 3)
        mesh = largest
    if cfg.smoothing_iterations:
        trimesh.smoothing.filter_taubin(mesh, iterations=cfg.smoothing_iterations)
    report.update({"grid_shape": list(shape), "grid_voxel_m": cfg.grid_voxel_m,
                   "cut_at_support": support is not None, "faces": len(mesh.faces),
                   "vertices": len(mesh.vertices), "watertight": bool(mesh.is_watertight),
                   "seconds": round(time.perf_counter() - start, 2)})
    return MeshResult(mesh, report)

