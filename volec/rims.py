"""Rim points: where the food's outline in the images places its surface, below its widest level.

In: the views whose food masks carve (:class:`volec.meshing.SilhouetteView`), the observed food
cloud, the space around it (:class:`volec.space.SpaceGrid`), the up direction and a
:class:`RimConfig`. Out: a :class:`~volec.pointcloud.PointCloud` of surface points with
normals, where no depth was measured.

The ray through a point of a view's mask outline grazes the food: somewhere along it the
food's surface touches it, with the plane through the camera and the outline's tangent as its
tangent plane. Where along the ray is not known from that view, but the food lies inside
every other view's mask too, so the touching point lies on the stretch where the ray runs
inside the visual hull (the other views' masks, carved as the meshing carves). Its midpoint
is taken: off along the ray by at most half the stretch, which on a surface curving with
radius R puts it about (stretch / 2)^2 / (2 R) outside (a 3.5 mm stretch on a 30 mm radius:
0.05 mm). The hull itself, which the meshing otherwise keeps where no depth reached, bulges
out between such touching points. The points are kept only where the tangent plane faces down
(the band under an item's widest level: cameras above the plate see it only at grazing
angles, which dense stereo drops) and where stereo left no point near.

On the benchmark's full-orbit lemon (SfM poses, exact masks) the points lay a median 0.23 mm
outside the true surface (p10 0.10, p90 0.45 mm, part of it the capture's 0.4 % scale
error; ``benchmarks/bench_rims.py``); the "Rim points" paragraph of docs/measurements.md
(Completion) says what they do to the volumes.

The visual hull itself (:func:`volec.meshing.silhouette_field`) is volec's; no library
reconstructs surfaces from the tangency of outlines (the "rim" or "contour generator"
methods of the literature need matched outlines across views, which the hull avoids here).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from volec.meshing import SilhouetteView, SupportPlane, near_points, silhouette_field
from volec.pointcloud import RIM_RGB, PointCloud
from volec.space import EMPTY, SpaceGrid


@dataclass(frozen=True)
class RimConfig:
    """How rim points are found (:func:`rim_points`)."""

    enabled: bool = True
    """Find rim points and mesh with them (False: the visual hull alone binds where no depth
    reached)."""
    outline_step_px: float = 2.0
    """Spacing of the outline points whose rays are followed, pixels."""
    max_up: float = -0.1
    """Only outline points whose tangent plane's normal has an up component below this
    (facing down): the band under the widest level."""
    sample_m: float = 0.0005
    """Step along a ray when testing it against the other views' masks, metres."""
    max_contact_m: float = 0.008
    """A ray that runs inside the hull for longer than this does not place a point (the
    touching point is too uncertain)."""
    min_gap_m: float = 0.0015
    """Rim points nearer than this to an observed point are left out: there stereo
    measured the surface."""


def outline_rays(view: SilhouetteView, up: np.ndarray, cfg: RimConfig
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rays through points of ``view``'s mask outline whose tangent plane faces down: (N, 3)
    camera centre, (N, 3) unit directions and (N, 3) the tangent planes' outward unit normals,
    world frame. The outline is the zero level of the mask's signed distance (halfway between
    its inside and outside pixels), one point every ``cfg.outline_step_px``."""
    from skimage import measure

    signed = view.signed_distance_px
    grad_row, grad_col = np.gradient(signed)
    R_world_from_cam = view.T_cam_from_world[:3, :3].T
    centre = -R_world_from_cam @ view.T_cam_from_world[:3, 3]
    intr = view.intrinsics
    rows, cols, along_row, along_col = _outline_points(measure.find_contours(signed, 0.0),
                                                       cfg.outline_step_px)
    if not len(rows):
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3))
    # The outline's normal from the outline itself (the distance field's gradient at a pixel
    # is off by tens of degrees near the border), turned to the mask's outside.
    g = np.stack([along_row, -along_col], axis=1)  # (x, y): the tangent turned a right angle
    g /= np.linalg.norm(g, axis=1, keepdims=True) + 1e-12
    r_i = np.clip(np.round(rows).astype(int), 0, signed.shape[0] - 1)
    c_i = np.clip(np.round(cols).astype(int), 0, signed.shape[1] - 1)
    outward = grad_col[r_i, c_i] * g[:, 0] + grad_row[r_i, c_i] * g[:, 1]
    g *= np.where(outward < 0, -1.0, 1.0)[:, None]
    pixels = np.stack([cols, rows], axis=1)
    tangent = np.stack([-g[:, 1], g[:, 0]], axis=1)
    # The plane through the camera that projects onto the outline's tangent: spanned by the
    # rays a little either side along it (lens distortion removed), facing the mask's outside.
    ray, before, after, outside = (intr.unproject(pixels + shift) for shift in
                                   (0.0, -0.5 * tangent, 0.5 * tangent, 0.5 * g))
    normal_cam = np.cross(before, after)
    normal_cam *= np.sign(np.einsum("ij,ij->i", normal_cam, outside))[:, None]
    normals = normal_cam @ R_world_from_cam.T
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    directions = ray @ R_world_from_cam.T
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    down = normals @ np.asarray(up, float) < cfg.max_up
    return (np.repeat(centre[None], int(down.sum()), axis=0), directions[down],
            normals[down])


def _outline_points(contours: list[np.ndarray], step_px: float, reach_px: float = 2.0
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(rows, cols) of points every ``step_px`` along each contour (row, col polylines), and
    the contour's unit direction there (rows, cols), from its points ``reach_px`` either
    side."""
    out: list[list[np.ndarray]] = [[], [], [], []]
    for contour in contours:
        if len(contour) < 4:
            continue
        along = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(contour, axis=0),
                                                                axis=1))])
        at = np.arange(0.0, along[-1], step_px)
        closed = np.allclose(contour[0], contour[-1])
        ahead, behind = at + reach_px, at - reach_px
        if closed:  # wrap around
            ahead, behind = ahead % along[-1], behind % along[-1]
        point = np.stack([np.interp(at, along, contour[:, k]) for k in range(2)], axis=1)
        direction = (np.stack([np.interp(ahead, along, contour[:, k]) for k in range(2)], 1)
                     - np.stack([np.interp(behind, along, contour[:, k]) for k in range(2)], 1))
        direction /= np.linalg.norm(direction, axis=1, keepdims=True) + 1e-12
        for k, values in enumerate((point[:, 0], point[:, 1], direction[:, 0],
                                    direction[:, 1])):
            out[k].append(values)
    if not out[0]:
        return np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0)
    rows, cols, along_row, along_col = (np.concatenate(values) for values in out)
    return rows, cols, along_row, along_col


def open_stretch(origins: np.ndarray, directions: np.ndarray, space: SpaceGrid
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Per ray, the distances along it (metres) of the first and last of its points, one grid
    step apart, that the space grid does not hold empty (NaN where all are): the stretch
    where the food may lie."""
    extent = space.pitch_m * (np.array(space.state.shape) - 1)
    centre = space.lower + extent / 2
    reach = float(np.linalg.norm(extent)) / 2
    to_centre = np.einsum("ij,ij->i", centre - origins, directions)
    steps = np.arange(-reach, reach + space.pitch_m / 2, space.pitch_m / 2)
    first = np.full(len(origins), np.nan)
    last = np.full(len(origins), np.nan)
    for part in np.array_split(np.arange(len(origins)), max(1, len(origins) // 4000)):
        t = to_centre[part, None] + steps[None]
        points = origins[part, None] + directions[part, None] * t[..., None]
        open_ = (space.states_at(points.reshape(-1, 3)) != EMPTY).reshape(t.shape)
        any_open = open_.any(axis=1)
        lo = np.argmax(open_, axis=1)
        hi = open_.shape[1] - 1 - np.argmax(open_[:, ::-1], axis=1)
        first[part] = np.where(any_open, t[np.arange(len(part)), lo], np.nan)
        last[part] = np.where(any_open, t[np.arange(len(part)), hi], np.nan)
    return first, last


def longest_run(inside: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per row of ``inside`` (N, S) bool: the first index and the length of its longest run of
    True (length 0 where there is none; the first such run on a tie)."""
    n, s = inside.shape
    padded = np.zeros((n, s + 2), np.int8)
    padded[:, 1:-1] = inside
    change = np.diff(padded, axis=1)
    start_r, start_c = np.nonzero(change == 1)
    _, end_c = np.nonzero(change == -1)  # row by row, in the same order as the starts
    lengths = end_c - start_c
    first = np.zeros(n, int)
    length = np.zeros(n, int)
    order = np.lexsort((start_c, -lengths, start_r))  # per row: longest, then earliest
    keep = order[np.r_[True, start_r[order][1:] != start_r[order][:-1]]]
    first[start_r[keep]] = start_c[keep]
    length[start_r[keep]] = lengths[keep]
    return first, length


def contact_midpoints(origins: np.ndarray, directions: np.ndarray,
                      views: list[SilhouetteView], space: SpaceGrid, cfg: RimConfig,
                      hull: tuple[float, int], support: SupportPlane | None = None
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Per ray: the distance along it (metres) of the midpoint of its longest stretch inside
    the visual hull of ``views`` (and above the ``support`` plane: nothing lies below it),
    and that stretch's length (metres; 0 where the ray misses the hull). ``hull``: the
    carving's margin (pixels) and the views that must agree
    (:func:`volec.meshing.silhouette_field`)."""
    first, last = open_stretch(origins, directions, space)
    middle = np.full(len(origins), np.nan)
    length = np.zeros(len(origins))
    rays = np.flatnonzero(np.isfinite(first))
    run_start, run_length = _runs(origins[rays], directions[rays], first[rays] - space.pitch_m,
                                  last[rays] + space.pitch_m, cfg.sample_m, views, hull,
                                  support)
    middle[rays] = run_start + np.maximum(run_length - cfg.sample_m, 0.0) / 2
    length[rays] = run_length
    return middle, length


def _runs(origins: np.ndarray, directions: np.ndarray, start: np.ndarray, stop: np.ndarray,
          step_m: float, views: list[SilhouetteView], hull: tuple[float, int],
          support: SupportPlane | None) -> tuple[np.ndarray, np.ndarray]:
    """Per ray, sampled every ``step_m`` from ``start`` to ``stop`` (metres along it): where
    its longest run of samples inside the hull (and not below ``support``) starts, and its
    length (``step_m`` per sample; 0 where there is none)."""
    run_start = np.zeros(len(origins))
    run_length = np.zeros(len(origins))
    order = np.argsort(stop - start)  # rays of similar reach share a chunk's samples
    for part in np.array_split(order, max(1, len(order) // 1000)):
        if not len(part):
            continue
        steps = int(np.ceil((stop[part] - start[part]).max() / step_m)) + 1
        t = start[part, None] + step_m * np.arange(steps)[None]
        points = origins[part, None] + directions[part, None] * t[..., None]
        field = silhouette_field(points.reshape(-1, 3), views, *hull).reshape(t.shape)
        inside = (field <= 0) & (t <= stop[part, None])
        if support is not None:
            inside &= (support.height_m(points.reshape(-1, 3)) >= 0).reshape(t.shape)
        first, count = longest_run(inside)
        run_start[part] = t[np.arange(len(part)), first]
        run_length[part] = count * step_m
    return run_start, run_length


def rim_points(views: list[SilhouetteView], observed: PointCloud, space: SpaceGrid,
               up: np.ndarray, cfg: RimConfig, hull: tuple[float, int],
               support: SupportPlane | None = None) -> tuple[PointCloud, dict[str, Any]]:
    """The rim points of ``views`` (see the module docstring) farther than
    ``cfg.min_gap_m`` from the ``observed`` cloud, with the tangent planes' normals, and a
    record (rays followed, points placed and kept, the median stretch, seconds). ``hull``:
    the carving's margin (pixels) and the views that must agree, as the meshing carves; a
    ray's stretch ends at the ``support`` plane."""
    start = time.perf_counter()
    origins, directions, normals = (np.vstack(parts) for parts in
                                    zip(*[outline_rays(view, up, cfg) for view in views],
                                        strict=True))
    middle, length = contact_midpoints(origins, directions, views, space, cfg, hull, support)
    placed = (length > 0) & (length <= cfg.max_contact_m)
    points = origins[placed] + directions[placed] * middle[placed, None]
    far = ~near_points(points, observed.xyz, cfg.min_gap_m)
    record = {"rays": len(origins), "placed": int(placed.sum()), "kept": int(far.sum()),
              "median_stretch_mm": (round(float(np.median(length[length > 0])) * 1000, 2)
                                    if (length > 0).any() else None),
              "seconds": round(time.perf_counter() - start, 2)}
    return (PointCloud(points[far], np.tile(np.array(RIM_RGB, np.uint8), (int(far.sum()), 1)),
                       normals[placed][far]), record)
