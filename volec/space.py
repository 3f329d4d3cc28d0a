"""Space: what the cameras saw empty around the food, what is food, what nobody saw.

In: the observed food cloud (masked, with normals facing the cameras), the food silhouettes
(:func:`volec.meshing.silhouette_views`), optionally the support plane, and a
:class:`SpaceConfig`. Out: a :class:`SpaceGrid`: a regular grid over the food's surroundings
whose points are :data:`EMPTY`, :data:`FOOD` or :data:`UNKNOWN`; :func:`volume_bounds` turns it
into the bounds every estimate reports beside its volume: the estimate with its unknown part
taken as empty, and with all unknown space taken as food.

- **Empty**: space a camera saw through. A grid point outside the food masks of at least
  ``min_views`` views (the visual hull), or nearer to at least ``min_views`` cameras than the
  surface they saw there (the observed cloud drawn into each view as a depth map, only the
  points facing that camera, so the far side does not show through gaps), or just in front of
  the observed surface (within ``surface_reach_m`` of observed points, on their outer side).
  Where a view's food mask holds a pixel but no observed point fell there (a patch dense
  stereo missed, a grazing rim), the camera saw food at a depth nobody measured: nothing
  along that ray counts as seen through. The depth drawn is the whole scene's (the plate
  beside the food is seen through to) outside the food masks and the food cloud's alone
  inside them (``food_depth_in_masks``: else the plate hidden behind the item shows through
  the food cloud's holes), and ``depth_min_views`` views must agree (a few food points with
  wrong normals show through the same holes).
  Below the support plane is empty too; a point on or above it never reads the empty grid
  point below it (:attr:`SpaceGrid.floor`).
- **Food**: space enclosed by what was seen: just behind the observed surface, or a point
  from which a ray in each grid direction (26, or with a support plane those not pointing
  down: see ``SpaceConfig.max_ray_down``) meets observed surface or the support plane before
  it meets empty space. Inside a fully seen item every point is food.
- **Unknown**: the rest: not seen through, but open to empty space across a part of the
  surface nobody reconstructed: the far side of a half orbit, the gap under an overhang, a
  faint patch dense stereo missed.

When unknown space reaches the grid's border the upper bound is not closed (``high_open``).

Along the food's vertical axis the states tell a hole through it from a hollow under it
(:func:`through_hole`): a doughnut's axis is unknown low down and seen empty above, an apple's
runs into food.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import product
from typing import Any

import numpy as np
import trimesh

from volec.capture import Intrinsics
from volec.meshing import SilhouetteView, SupportPlane, offsets_along_normals, silhouette_field
from volec.pointcloud import PointCloud

EMPTY, FOOD, UNKNOWN = 0, 1, 2
"""The states of a grid point."""


@dataclass(frozen=True)
class SpaceConfig:
    """How space is sorted into empty, food and unknown."""

    pitch_m: float = 0.002
    """Grid spacing, metres."""
    margin_share: float = 0.25
    """The grid spans the food cloud grown by this share of its extent on every side (at
    least ``min_margin_m``)."""
    min_margin_m: float = 0.01
    min_views: int = 2
    """Views that must agree before a point is empty (one bad mask or pose cannot empty food)."""
    silhouette_margin_px: float = 1.0
    """A point is outside a view's mask when it projects more than this outside it."""
    depth_scale: float = 0.25
    """The observed cloud is drawn into each view at this share of its resolution."""
    depth_thinning: float = 0.75
    """The cloud drawn into the views is thinned to one point per voxel of this share of
    ``pitch_m`` (enough for a depth map at ``depth_scale``, at a fraction of the cost)."""
    food_depth_in_masks: bool = True
    """Inside a view's food mask, the depth the camera saw is that of the food cloud alone,
    not of the whole scene (:func:`observed_depth`). Off, the scene's plate points hidden
    behind the item in a view show through the holes in its food cloud, and the space in
    front of them, inside the item, counts as seen through: 19.6 of the full-orbit orange's
    200 mL, 7.1 with this on. Alone (``depth_min_views`` 2) it made the default estimate's
    MAPE 0.78 -> 0.82 % on the full orbits, 1.20 -> 1.25 % on the half and 1.07 -> 1.20 % on
    the sparse ones (docs/measurements.md, Volume from a capture); with six views it is the
    default."""
    depth_min_views: int = 6
    """Views whose observed depth must lie beyond a point for it to be seen through (the
    visual hull's test keeps ``min_views``). A view whose food cloud has a hole shows the
    points behind it, and where their normals are wrong (near the outlines, under the widest
    level) some face the camera: the space in front of them, inside the item, would count as
    seen through. With ``food_depth_in_masks``, 4 took the full-orbit orange's wrongly empty
    space from 7.1 to 3.0 mL; both on, the default estimate's MAPE moved 0.784 -> 0.782 %
    (full orbits), 1.20 -> 1.15 % (half), 1.07 -> 1.17 % (sparse), 1.40 -> 1.35 % (faint
    skins); at 6, 0.784 -> 0.766 % (full), 1.20 -> 1.21 % (half), 1.07 -> 1.10 % (sparse),
    1.40 -> 1.37 % (faint skins), 1.81 -> 1.84 % (low), none beyond the noise, while the
    true volume sorted empty over 20 full orbits fell 141 -> 70 mL (at 4 views) and the
    bounds narrowed 15.4 -> 11.8 % of the truth (docs/measurements.md, Volume from a
    capture): the default since 2026-12-07."""
    depth_tolerance_m: float = 0.004
    """A point is in front of the surface a camera saw when nearer to it by more than this."""
    surface_reach_m: float = 0.003
    """Points this near to the observed cloud take their side from its normals: in front is
    empty, behind is food."""
    surface_neighbours: int = 8
    """Observed points whose normals decide that side."""
    front_margin_m: float = 0.001
    """Only points farther than this in front of the observed surface are empty by its side
    (the cloud is noisy and a mesh through it is smoothed: nearer ones are left open)."""
    plug_m: float = 0.004
    """For the enclosure test the observed surface is thickened by this much, so that the
    gaps dense stereo leaves between its patches (smaller than about twice this) do not let
    the rays out; a larger unreconstructed patch stays open."""
    max_ray_down: float = 0.2
    """With a support plane, enclosure is tested along the grid directions that point up,
    across or down by less than this sine of the angle below the horizontal: no camera sees
    the underside, so a ray going down leaves through it into space nobody saw (the gap
    between a round item and the plate) however well the rest was seen, and the plane itself
    closes the food from below."""


@dataclass(frozen=True)
class SpaceGrid:
    """The states of the grid points ``lower + pitch_m * (i, j, k)``."""

    lower: np.ndarray
    """(3,) the first grid point, metres."""
    pitch_m: float
    state: np.ndarray
    """(I, J, K) int8: :data:`EMPTY`, :data:`FOOD` or :data:`UNKNOWN`."""
    floor: SupportPlane | None = None
    """The support plane below which every grid point is empty (None: none). A point above it
    is not given the state of a grid point below it (:meth:`states_at`)."""

    @property
    def cell_ml(self) -> float:
        """The volume each grid point stands for, mL."""
        return self.pitch_m ** 3 * 1e6

    @property
    def upper_open(self) -> bool:
        """True when unknown space reaches the grid's border (the upper bound is then only
        what the grid holds)."""
        s = self.state
        faces = (s[0], s[-1], s[:, 0], s[:, -1], s[:, :, 0], s[:, :, -1])
        return any(bool((f == UNKNOWN).any()) for f in faces)

    def points(self) -> np.ndarray:
        """(N, 3) every grid point, metres, in the order of ``state.ravel()``."""
        axes = [self.lower[i] + self.pitch_m * np.arange(n) for i, n in enumerate(self.state.shape)]
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)

    def points_in(self, state: int) -> np.ndarray:
        """(M, 3) the grid points of ``state``, metres (without making the whole grid's)."""
        return self.lower + self.pitch_m * np.argwhere(self.state == state)

    def states_at(self, points: np.ndarray) -> np.ndarray:
        """(N,) the state of the grid point nearest to each of ``points`` (EMPTY beyond the
        grid); for a point above the ``floor``, of the nearest one above it."""
        points = np.asarray(points, float)
        index = np.round((points - self.lower) / self.pitch_m).astype(int)
        if self.floor is not None:
            index = self._above_floor(points, index)
        shape = np.asarray(self.state.shape)
        inside = ((index >= 0) & (index < shape)).all(axis=1)
        out = np.full(len(index), EMPTY, np.int8)
        out[inside] = self.state[tuple(index[inside].T)]
        return out

    def _above_floor(self, points: np.ndarray, index: np.ndarray) -> np.ndarray:
        """``index`` (N, 3) of the grid points nearest ``points``, those of points on or above
        the floor whose grid point lies below it moved up along the grid axis nearest the
        floor's normal (at most two steps). The plate's plane falls anywhere between two
        layers of the grid, and below it all is empty: a point half a step above the plate,
        under the food where no camera looked, took that empty state as if seen through."""
        normal = np.asarray(self.floor.normal, float)
        axis = int(np.argmax(np.abs(normal)))
        step = 1 if normal[axis] > 0 else -1
        above = self.floor.height_m(points) >= 0
        for _ in range(2):
            low = above & (self.floor.height_m(self.lower + self.pitch_m * index) < 0)
            if not low.any():
                break
            index[low, axis] += step
        return index


def axis_foot(centre: np.ndarray, support: SupportPlane) -> np.ndarray:
    """(3,) where the vertical axis through ``centre`` meets the ``support`` plane."""
    centre = np.asarray(centre, float)
    return centre - support.height_m(centre[None])[0] * np.asarray(support.normal, float)


def axis_states(space: SpaceGrid, centre: np.ndarray, support: SupportPlane
                ) -> tuple[np.ndarray, np.ndarray]:
    """The vertical axis through ``centre``, sampled every half grid step from the plate up
    past the grid's top: the samples' heights above the plate (K,) and their states (K,)."""
    up = np.asarray(support.normal, float)
    foot = axis_foot(centre, support)
    reach_m = float(np.linalg.norm(np.asarray(space.state.shape) * space.pitch_m))
    corners = space.lower + np.array(list(product(*[(0.0, reach_m)] * 3)))
    top_m = float(support.height_m(corners).max()) + space.pitch_m
    heights_m = np.arange(0.0, max(top_m, space.pitch_m), space.pitch_m / 2)
    return heights_m, space.states_at(foot + np.outer(heights_m, up))


def first_known_above(states: np.ndarray) -> np.ndarray:
    """(K,) for each of ``states`` (along a line), the first state at or after it that is
    not :data:`UNKNOWN` (UNKNOWN where none is)."""
    known = np.flatnonzero(states != UNKNOWN)
    out = np.full(len(states), UNKNOWN, np.int8)
    if len(known):
        nxt = np.searchsorted(known, np.arange(len(states)))
        has = nxt < len(known)
        out[has] = states[known[nxt[has]]]
    return out


@dataclass(frozen=True)
class HoleFootprint:
    """Where a hole through the food lies, seen into from above but not down to the plate
    (a doughnut's from low cameras): the open cross-section around the vertical axis at the
    lowest height the axis was seen empty with unknown space below (:func:`through_hole`)."""

    foot_m: np.ndarray
    """The axis's foot on the plate (3,), metres."""
    axes: np.ndarray
    """Two horizontal unit vectors (2, 3) spanning the cross-section."""
    pitch_m: float
    inside: np.ndarray
    """(n, n) the cross-section's cells that are the hole, the axis at the centre cell."""
    level_m: float
    """The height above the plate of the cross-section, metres."""

    def below(self, points: np.ndarray, support: SupportPlane) -> np.ndarray:
        """(N,) which ``points`` lie in the hole's footprint, lower than its level."""
        rel = np.asarray(points, float) - self.foot_m
        half = self.inside.shape[0] // 2
        cells = np.round(rel @ self.axes.T / self.pitch_m).astype(int) + half
        ok = ((cells >= 0) & (cells < self.inside.shape[0])).all(axis=1)
        out = np.zeros(len(rel), bool)
        out[ok] = self.inside[cells[ok, 0], cells[ok, 1]]
        return out & (support.height_m(points) < self.level_m)


def through_hole(space: SpaceGrid, centre: np.ndarray, support: SupportPlane
                 ) -> HoleFootprint | None:
    """The hole through the food around the vertical axis through ``centre``, where the
    axis is unknown space below a height and seen empty just above it (no camera saw down
    into the hole's lower part), and the cross-section there that is not food, connected to
    the axis, is closed by food on every side (a crescent's open side is no hole). None
    otherwise."""
    from scipy import ndimage

    from volec.geometry import horizontal_axes

    heights_m, states = axis_states(space, centre, support)
    above = first_known_above(states)
    under_seen = np.flatnonzero((states == UNKNOWN) & (above == EMPTY))
    if not len(under_seen):
        return None
    level = under_seen[0] + int(np.argmax(states[under_seen[0]:] != UNKNOWN))
    up = np.asarray(support.normal, float)
    axes = np.array(horizontal_axes(up))
    foot = axis_foot(centre, support)
    half = int(np.ceil(max(space.state.shape) * np.sqrt(2)))
    offsets = space.pitch_m * np.arange(-half, half + 1)
    grid = np.stack(np.meshgrid(offsets, offsets, indexing="ij"), axis=-1)
    cross = foot + heights_m[level] * up + grid.reshape(-1, 2) @ axes
    open_ = (space.states_at(cross) != FOOD).reshape(grid.shape[:2])
    labels, _ = ndimage.label(open_)  # four-connected: a diagonal gap does not leak
    hole = labels == labels[half, half]
    if hole[0].any() or hole[-1].any() or hole[:, 0].any() or hole[:, -1].any():
        return None
    return HoleFootprint(foot, axes, space.pitch_m, hole, float(heights_m[level]))


def grid_frame(cloud: PointCloud, support: SupportPlane | None, cfg: SpaceConfig
               ) -> tuple[np.ndarray, tuple[int, int, int]]:
    """(lower corner, shape) of the grid around ``cloud``, reaching down to the support."""
    span = cloud.xyz
    if support is not None:
        span = np.vstack([span, span - np.outer(support.height_m(span), support.normal)])
    extent = span.max(axis=0) - span.min(axis=0)
    margin = np.maximum(cfg.margin_share * extent, cfg.min_margin_m)
    lower = span.min(axis=0) - margin
    shape = np.ceil((span.max(axis=0) + margin - lower) / cfg.pitch_m).astype(int) + 1
    return lower, (int(shape[0]), int(shape[1]), int(shape[2]))


def observed_depth(cloud: PointCloud, view: SilhouetteView, scale: float,
                   mask_margin_px: float = 1.0, food: PointCloud | None = None) -> np.ndarray:
    """(h, w) the depth of the observed surface in ``view`` at ``scale`` of its resolution:
    the nearest of the points facing the camera, widened by a 3x3 minimum so that the gaps
    between points do not let the far side through. Inside the view's food mask (grown by
    ``mask_margin_px``) only the ``food`` cloud's points count when it is given: the camera
    saw food there, so a point of the rest of the scene drawn there (the plate beside the
    item, facing the camera but hidden behind the item in this view) lies behind what it saw.
    Where no point fell the depth is inf (nothing stops the view there) outside the food mask,
    and -inf inside it: the camera saw food there at a depth nobody measured (a patch dense
    stereo missed, a grazing rim), so nothing along that ray was seen through."""
    small = view.intrinsics.scaled(scale)
    food_pixels = _food_pixels(view, small, mask_margin_px)
    depth = _drawn_depth(cloud, view, small)
    if food is not None:
        depth = np.where(food_pixels, _drawn_depth(food, view, small), depth)
    depth[np.isinf(depth) & food_pixels] = -np.inf
    return depth


def _drawn_depth(cloud: PointCloud, view: SilhouetteView, small: Intrinsics) -> np.ndarray:
    """(h, w) at the resolution of ``small`` (a scaled copy of ``view``'s intrinsics): the
    nearest depth of ``cloud``'s points that face the camera, widened by a 3x3 minimum; inf
    where none fell."""
    from scipy import ndimage

    T = view.T_cam_from_world
    cam = cloud.xyz @ T[:3, :3].T + T[:3, 3]
    facing = np.ones(len(cam), bool)
    if cloud.normals is not None:
        normals_cam = cloud.normals @ T[:3, :3].T
        facing = np.einsum("ij,ij->i", normals_cam, -cam) > 0
    dh, dw = small.height, small.width
    uv = small.project(cam)
    with np.errstate(invalid="ignore"):
        ok = facing & (cam[:, 2] > 0) & np.isfinite(uv).all(axis=1)
        u, v = np.round(uv[ok, 0]).astype(int), np.round(uv[ok, 1]).astype(int)
    z = cam[ok, 2]
    inside = (u >= 0) & (u < dw) & (v >= 0) & (v < dh)
    depth = np.full((dh, dw), np.inf)
    np.minimum.at(depth, (v[inside], u[inside]), z[inside])
    return ndimage.minimum_filter(depth, size=3, mode="nearest")


def _food_pixels(view: SilhouetteView, small: Intrinsics, margin_px: float) -> np.ndarray:
    """(h, w) True where the pixel centres of ``small`` (a scaled copy of ``view``'s
    intrinsics) fall inside the view's food mask grown by ``margin_px``."""
    h, w = view.signed_distance_px.shape
    factor = view.intrinsics.width / small.width
    rows = np.clip(np.round((np.arange(small.height) + 0.5) * factor - 0.5), 0, h - 1)
    cols = np.clip(np.round((np.arange(small.width) + 0.5) * factor - 0.5), 0, w - 1)
    return view.signed_distance_px[np.ix_(rows.astype(int), cols.astype(int))] <= margin_px


def seen_through(points: np.ndarray, cloud: PointCloud, views: list[SilhouetteView],
                 cfg: SpaceConfig, food: PointCloud | None = None) -> np.ndarray:
    """(N,) how many views saw the observed surface beyond each point (it is empty); inside
    the food masks only ``food``'s points count, when given (:func:`observed_depth`)."""
    count = np.zeros(len(points), np.int32)
    for view in views:
        depth = observed_depth(cloud, view, cfg.depth_scale, cfg.silhouette_margin_px, food)
        small = view.intrinsics.scaled(cfg.depth_scale)
        T = view.T_cam_from_world
        cam = points @ T[:3, :3].T + T[:3, 3]
        uv = small.project(cam)
        with np.errstate(invalid="ignore"):
            ok = (cam[:, 2] > 0) & np.isfinite(uv).all(axis=1)
            u = np.round(np.where(ok, uv[:, 0], -1)).astype(int)
            v = np.round(np.where(ok, uv[:, 1], -1)).astype(int)
        ok &= (u >= 0) & (u < small.width) & (v >= 0) & (v < small.height)
        surface = np.full(len(points), np.inf)
        surface[ok] = depth[v[ok], u[ok]]
        count += (cam[:, 2] < surface - cfg.depth_tolerance_m).astype(np.int32)
    return count


def surface_side(points: np.ndarray, cloud: PointCloud, cfg: SpaceConfig) -> np.ndarray:
    """(N,) +1 for points just in front of the observed surface (by more than
    ``front_margin_m``), -1 just behind it, 0 for the others (farther than ``surface_reach_m``
    from it, or a cloud without normals)."""
    from scipy.spatial import cKDTree

    side = np.zeros(len(points), np.int8)
    if cloud.normals is None or not len(cloud):
        return side
    tree = cKDTree(cloud.xyz)
    distance, _ = tree.query(points, distance_upper_bound=cfg.surface_reach_m)
    near = np.flatnonzero(np.isfinite(distance))
    if not len(near):
        return side
    k = min(cfg.surface_neighbours, len(cloud))
    _, idx = tree.query(points[near], k=k)
    idx = idx.reshape(len(near), k)
    along = offsets_along_normals(points[near], cloud, idx).sum(axis=1) / k
    side[near] = np.where(along > cfg.front_margin_m, 1, np.where(along < 0, -1, 0))
    return side


def ray_directions(up: np.ndarray | None, max_down: float) -> list[tuple[int, int, int]]:
    """The 26 grid directions, less those pointing down more steeply than ``max_down`` (the
    sine of the angle below the horizontal) when ``up`` is known."""
    out = []
    for d in product((-1, 0, 1), repeat=3):
        if d == (0, 0, 0):
            continue
        if up is not None and np.dot(d, up) / np.linalg.norm(d) < -max_down:
            continue
        out.append(d)
    return out


def _enclosed(stop: np.ndarray, open_: np.ndarray, directions: list[tuple[int, int, int]]
              ) -> np.ndarray:
    """True where a ray in each of ``directions`` meets a ``stop`` point before it leaves the
    ``open_`` points (or the grid)."""
    enclosed = np.ones(stop.shape, bool)
    for d in directions:
        enclosed &= _reaches_stop(stop, open_, d)
    return enclosed


def _reaches_stop(stop: np.ndarray, open_: np.ndarray, d: tuple[int, int, int]) -> np.ndarray:
    """``hit[p] = stop[p] or (open_[p] and hit[p + d])``, beyond the grid False: swept layer
    by layer along an axis that ``d`` moves on, from the far end."""
    axis = next(i for i in range(3) if d[i] != 0)
    order = range(stop.shape[axis] - 1, -1, -1) if d[axis] > 0 else range(stop.shape[axis])
    hit = np.zeros(stop.shape, bool)
    rest = [i for i in range(3) if i != axis]
    for layer in order:
        following = layer + d[axis]
        ahead = np.zeros([stop.shape[i] for i in rest], bool)
        if 0 <= following < stop.shape[axis]:
            ahead = _shifted(np.take(hit, following, axis=axis), d[rest[0]], d[rest[1]])
        here = [slice(None)] * 3
        here[axis] = layer
        hit[tuple(here)] = stop[tuple(here)] | (open_[tuple(here)] & ahead)
    return hit


def _shifted(layer: np.ndarray, da: int, db: int) -> np.ndarray:
    """``out[i, j] = layer[i + da, j + db]``, False beyond the layer."""
    out = np.zeros_like(layer)
    na, nb = layer.shape
    out[max(0, -da):na - max(0, da), max(0, -db):nb - max(0, db)] = \
        layer[max(0, da):na - max(0, -da), max(0, db):nb - max(0, -db)]
    return out


def outside_hull(points: np.ndarray, views: list[SilhouetteView], cfg: SpaceConfig
                 ) -> np.ndarray:
    """(N,) True for points outside the food masks of ``min_views`` views. A dozen of the
    views first: what they carve, all of them carve too, and most of the grid goes there."""
    few = views[::max(1, len(views) // 12)]
    out = silhouette_field(points, few, cfg.silhouette_margin_px, cfg.min_views) > 0
    rest = np.flatnonzero(~out)
    out[rest] = silhouette_field(points[rest], views, cfg.silhouette_margin_px,
                                 cfg.min_views) > 0
    return out


def thinned(cloud: PointCloud, voxel_m: float) -> PointCloud:
    """One point of ``cloud`` per occupied voxel of ``voxel_m``: enough to draw its depth
    at a coarse resolution, at a fraction of the cost."""
    keys = np.floor(cloud.xyz / voxel_m).astype(np.int64)
    _, first = np.unique(keys, axis=0, return_index=True)
    return cloud.subset(np.sort(first))


def _thickened(mask: np.ndarray, radius_steps: float) -> np.ndarray:
    """``mask`` grown by a ball of ``radius_steps`` grid steps."""
    from scipy import ndimage

    r = int(np.floor(radius_steps))
    if r < 1:
        return mask
    offsets = np.arange(-r, r + 1)
    ball = (offsets[:, None, None] ** 2 + offsets[None, :, None] ** 2
            + offsets[None, None, :] ** 2) <= radius_steps ** 2
    return ndimage.binary_dilation(mask, structure=ball)


def observed_space(cloud: PointCloud, views: list[SilhouetteView],
                   support: SupportPlane | None = None, cfg: SpaceConfig | None = None,
                   scene: PointCloud | None = None) -> SpaceGrid:
    """Sort the space around the observed food ``cloud`` into empty, food and unknown (see the
    module docstring). The depth the cameras saw is that of ``scene`` (the whole dense
    cloud: the plate seen beside the food empties the space in front of it) when given, else
    of the food cloud."""
    cfg = cfg or SpaceConfig()
    lower, shape = grid_frame(cloud, support, cfg)
    grid = SpaceGrid(lower, cfg.pitch_m, np.zeros(shape, np.int8))
    points = grid.points()
    below = (support.height_m(points) < 0) if support is not None else np.zeros(len(points), bool)
    empty = np.zeros(len(points), bool)
    if views:
        empty = outside_hull(points, views, cfg)
        candidates = np.flatnonzero(~empty & ~below)
        voxel_m = cfg.depth_thinning * cfg.pitch_m
        seen = thinned(scene if scene is not None else cloud, voxel_m)
        food = thinned(cloud, voxel_m) if scene is not None and cfg.food_depth_in_masks else None
        empty[candidates] |= seen_through(points[candidates], seen, views, cfg,
                                          food) >= cfg.depth_min_views
    side = surface_side(points, cloud, cfg)
    empty |= side > 0
    behind = (side < 0) & ~below & ~empty
    empty &= ~below
    stop = _thickened(behind.reshape(shape), cfg.plug_m / cfg.pitch_m) | below.reshape(shape)
    open_ = ~(empty | below).reshape(shape)
    up = None if support is None else np.asarray(support.normal, float)
    food = _enclosed(stop, open_, ray_directions(up, cfg.max_ray_down)) & open_
    state = np.where(food, FOOD, np.where(open_, UNKNOWN, EMPTY)).astype(np.int8)
    return SpaceGrid(lower, cfg.pitch_m, state, support)


@dataclass(frozen=True)
class VolumeBounds:
    """An estimate's volume bounds from the space around it."""

    low_ml: float
    """The estimate less its part in unknown space (all of that taken as empty)."""
    high_ml: float
    """The estimate plus the unknown space outside it (all of that taken as food)."""
    unknown_share: float
    """Share of the estimate's volume in unknown space: decided by the shape prior alone."""
    empty_share: float
    """Share of the estimate's volume in space the cameras saw empty."""
    high_open: bool
    """Unknown space reaches the grid's border: ``high_ml`` counts only what the grid holds."""

    def record(self) -> dict[str, Any]:
        """JSON-able form (``volume_bounds_ml`` as [low, high])."""
        return {"volume_bounds_ml": [round(self.low_ml, 2), round(self.high_ml, 2)],
                "unknown_share": round(self.unknown_share, 4),
                "empty_share": round(self.empty_share, 4), "high_open": self.high_open}


def volume_bounds(space: SpaceGrid, inside: np.ndarray, volume_ml: float) -> VolumeBounds:
    """The bounds of an estimate of ``volume_ml`` whose solid holds the grid points flagged
    ``inside`` (same order as :meth:`SpaceGrid.points`).

    Where the cameras saw the surface the estimate's own surface stands (its uncertainty
    there is the cloud's noise, a fraction of a millimetre); only unknown space is open
    either way."""
    inside = np.asarray(inside, bool).reshape(-1)
    states = space.state.reshape(-1)
    n_inside = max(int(inside.sum()), 1)
    unknown_in = int((inside & (states == UNKNOWN)).sum())
    unknown_out = int((~inside & (states == UNKNOWN)).sum())
    return VolumeBounds(
        low_ml=volume_ml - unknown_in * space.cell_ml,
        high_ml=volume_ml + unknown_out * space.cell_ml,
        unknown_share=unknown_in / n_inside,
        empty_share=int((inside & (states == EMPTY)).sum()) / n_inside,
        high_open=space.upper_open)


def visual_hull_mesh(cloud: PointCloud, views: list[SilhouetteView],
                     support: SupportPlane | None = None, cfg: SpaceConfig | None = None
                     ) -> trimesh.Trimesh:
    """The visual hull of the ``views``' food masks above the support plane, as a closed mesh
    (marching cubes at ``cfg.pitch_m``): the baseline that needs no depth at all. A point is
    outside when ``cfg.min_views`` views see it outside their masks (:func:`outside_hull`).
    The hull is only sought within the grid around ``cloud`` (its extent grown by
    ``cfg.margin_share``): where the views leave it open (the side a half orbit never saw) it
    is cut at that border."""
    from skimage.measure import marching_cubes

    cfg = cfg or SpaceConfig()
    lower, shape = grid_frame(cloud, support, cfg)
    grid = SpaceGrid(lower, cfg.pitch_m, np.zeros(shape, np.int8))
    points = grid.points()
    inside = ~outside_hull(points, views, cfg)
    if support is not None:
        inside &= support.height_m(points) >= 0
    # padded with empty space, so the surface closes at the grid's border
    occupancy = np.pad(inside.reshape(shape).astype(np.float32), 1)
    vertices, faces, _, _ = marching_cubes(occupancy, level=0.5, gradient_direction="ascent")
    mesh = trimesh.Trimesh(lower + (vertices - 1.0) * cfg.pitch_m, faces, process=True)
    if mesh.volume < 0:
        mesh.invert()
    return mesh
