"""The underside by a horizontal mirror: a prior for the wedge between an item's lowest
measured surface and its plate.

In: the observed food points with outward normals (the masked cloud, then the rim points of
:mod:`volec.rims`), the support plane, the sorted space (:class:`volec.space.SpaceGrid`) and an
:class:`UndersideConfig`. Out: a :class:`~volec.pointcloud.PointCloud` of prior surface points
with normals, in the space no camera constrained, and a record of the fit.

Cameras above a plate see an item down to where its surface turns away from them, and the rim
points reach a little lower; below that, down to where it rests on the plate, the meshing is
left with the visual hull, which bulges out between the views' outlines. On the benchmark's
full orbits that wedge is most of what is left: the lemon's mesh lay 0.8-1.2 mm outside its
truth in the lowest 5 mm (1.3 % of its volume), the croissant's 2 mm (3.8 %).

Much food lying on a plate is nearly symmetric about a horizontal plane through its widest
level (a round or oval fruit, a lemon or a pear on its side, a roll, a cane, a bun). Resting on
the plate, such food is symmetric about its mid-height; the level is searched about there as
the rotation baseline searches its axis (:mod:`volec.completion.rotation`): the part above a
candidate level is reflected below it and scored by its truncated distance to the cloud where
it lands in space the cameras saw, the lower part that stereo and the rim points did reach.
That lays the reflected top on the seen bottom, which is what is extended into the wedge (an
item whose bottom is fuller than its top gets a lower level). Food rests on its lowest point,
so a reflection that would reach below the plate (the food more than twice the level high) is
compressed vertically about the level until its lowest point rests on the plate: a lower part
flatter than the upper one, as under a pasty or a bun, is the upper one squashed. One that
would hover above the plate (a bottom fuller than the top, as an apple's under its stem's dip)
is stretched down to it. Cut by the plate instead, the plain reflection would lay a flat disc
under a dome-topped item. The top that counts is the body's (:func:`body_top`): a thin part
standing on it, as an apple's stalk, would rest its mirror image on the plate and lift the
reflected body off it, and so would the stereo noise scattered above a flat top, so the top is
read on locally averaged heights. A
cloud that half its reflected points do not meet within ``max_median_distance_m`` is not
symmetric and gets nothing.
Otherwise only what lands in unknown space, above the plate, away from the measured points, is
kept, as a prior's points (the meshing's checks drop them where the masks or the enclosed
space disagree), and only where its normal faces away from the item's vertical axis: a hollow
(an apple's stem cavity mirrored under it) does not bound the wedge. A hole through the item
does: where the axis is unknown at a point's height and seen empty higher up (a doughnut's
hole seen into from above, not down to the plate), a point facing the axis is its wall
(:func:`hole_above`); under an apple the axis runs into the flesh first.

No library fits a mirror plane with a visibility model, hence this small search (the rotation
baseline's truncated-distance score over seen space).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from volec.geometry import horizontal_axes
from volec.meshing import SupportPlane, near_points
from volec.pointcloud import PREDICTED_RGB, PointCloud
from volec.space import EMPTY, UNKNOWN, SpaceGrid, axis_states, first_known_above, thinned


@dataclass(frozen=True)
class UndersideConfig:
    """How the underside's mirror is fitted and used (:func:`underside_points`)."""

    enabled: bool = True
    """Reflect the food's upper part below its mirror level (False: the visual hull alone binds
    the wedge under the lowest measured surface). Used by the default (``auto``) completion."""
    levels: int = 21
    """Candidate mirror heights, evenly spaced from ``lowest_share`` to ``highest_share`` of
    the food's height (the 99.5th percentile of the points' heights above the plate). Food
    symmetric about a horizontal plane that rests on the plate is symmetric about its
    mid-height; the search only absorbs the top's noise (a mirror low on a wall would map the
    wall's foot onto itself whatever the rest)."""
    lowest_share: float = 0.4
    highest_share: float = 0.6
    rest_on_plate: bool = True
    """Where the part above a level, reflected, would reach below the plate (the food's top
    more than twice the level high), compress the reflection vertically about the level so
    that its lowest point rests on the plate: food rests on its lowest point, and a lower part
    flatter than the upper (a pasty's, a bun's) is the upper one squashed. False: the plain
    reflection, cut by the plate, which lays a flat disc under a dome-topped item."""
    stretch_to_plate: bool = True
    """Where the reflection would hover above the plate (the food's body top less than twice
    the level high), stretch it vertically below the level until its lowest point is
    ``min_hover_m`` above the plate (by at most ``max_stretch``), as ``rest_on_plate``
    compresses one that would reach below it: food rests on the plate, not above it. The
    level is still chosen without the stretch (:func:`fit_level`), so only the reflected
    points move. On the benchmark's full-orbit apple the plain reflection of its top hovered
    2.3 mm above the plate (its bottom fuller than its top): -1.76 % -> -0.57 %. Over the
    benchmark (``bench_underside.py``, docs/measurements.md, Completion) the default's MAPE
    went 0.740 -> 0.706 % on full orbits, 1.22 -> 1.06 % on half orbits, 1.30 -> 1.19 % sparse,
    1.29 -> 1.18 % on faint skins and 1.20 -> 1.24 % from low cameras."""
    max_stretch: float = 1.2
    """The largest vertical stretch (the benchmark's largest was 1.10, the low apple's)."""
    min_hover_m: float = 0.0003
    """A reflection hovering less than this above the plate is left as it is, and a higher one
    is stretched down to this height: the body's top is read on averaged heights
    (``top_neighbours``), about 0.1 mm under a dome's apex, and stretched by that much a
    sphere's reflection would reach out of it."""
    min_top_width_share: float = 0.15
    """The reflection rests on the plate by the food's body, not by a thin part on its top:
    the top that sets the squash is that of the highest horizontal slice
    (``top_slice_m`` thick) whose width is at least this share of the widest slice's
    (:func:`body_top`). An apple's stalk, 2.6 mm across against the body's 36 mm, had set
    it: the stalk's tip, 6 mm above the body, then rested on the plate and lifted the
    reflected body off it."""
    top_slice_m: float = 0.001
    """Thickness of the horizontal slices :func:`body_top` compares, metres."""
    top_neighbours: int = 64
    """:func:`body_top` reads each point's height as the mean over its this-many nearest
    points (1: the raw heights): the top of the surface, not of its noise. Stereo scatters
    points by about half a millimetre either side of a surface, and the highest half-percent
    of a flat top's points is that scatter's tail: on the benchmark's chocolate cake the
    points facing up lay at a median 45.40 mm above the plate, their 99th percentile at
    47.04 mm, the true top at 45.69 mm. Squashed to rest a top 1.3 mm too high on the plate,
    the reflection's floor hovered 0.5-1 mm above it under half the slice (-0.7 % of its
    volume). Averaged over 64 points (a patch about 2 mm across at the dense cloud's 0.5 mm
    spacing), a dome's apex comes down by well under a tenth of a millimetre."""
    fit_points: int = 3000
    """Points of the cloud that score a candidate level."""
    inlier_spacings: float = 4.0
    """A reflected point's distance to the cloud is truncated at this many point spacings."""
    min_checked_share: float = 0.2
    """A level is scored only where at least this share of the sample above it lands,
    reflected, above the plate in seen space (and at least ``min_checked_points`` points)."""
    min_checked_points: int = 50
    low_share: float = 0.5
    """The level is chosen by the reflected points that land in seen space lower than this
    share of the food's mid-height (nearest the wedge they fill), when at least
    ``min_checked_points`` of the sample lie that low; else by all that land in seen space
    below it."""
    max_median_distance_m: float = 0.0015
    """The cloud is taken as symmetric about the level when half the reflected points that land
    in seen space below it lie within this of it (the rotation baseline's threshold)."""
    min_facing_out: float = 0.3
    """A reflected point is kept only where its normal's horizontal part, dotted with the unit
    horizontal direction from the cloud's centroid to it, exceeds this (facing away from the
    vertical axis)."""
    through_holes: bool = True
    """Also keep a reflected point that faces the vertical axis where the axis itself is
    unknown at the point's height and, from there up, first meets seen-through space, not
    food (:func:`hole_above`): the wall of a hole through the item (a ring's, a doughnut's)
    whose lower part no camera saw into. The facing-out rule is for a hollow: the apple's stem
    cavity mirrored under it, where the axis runs through the apple's flesh before it reaches
    the cavity's air."""
    min_gap_m: float = 0.0015
    """Reflected points nearer than this to a measured point are left out."""
    voxel_m: float = 0.001
    """One reflected point is kept per voxel of this size."""
    seed: int = 0
    """Seeds the subsample that scores the levels."""


@dataclass(frozen=True)
class LevelFit:
    """The horizontal mirror of a cloud: its height and how well it maps the cloud on itself."""

    height_m: float
    """The mirror plane's height above the plate, metres (NaN when no level could be scored)."""
    median_distance_m: float
    """Median distance to the cloud of the sample points from above the level that land,
    reflected, in seen space below it (truncated at the score's reach)."""
    symmetric: bool
    squash: float = 1.0
    """The reflection's vertical scale below the level (1: a plain mirror; less where the
    food rests on the plate, :attr:`UndersideConfig.rest_on_plate`; more where the plain
    mirror would hover above it, :attr:`UndersideConfig.stretch_to_plate`)."""
    body_top_m: float = float("nan")
    """The height above the plate of the food's body top that sets the squash
    (:func:`body_top`), metres."""

    def record(self) -> dict[str, Any]:
        """JSON-able form."""
        finite = bool(np.isfinite(self.height_m))
        return {"mirror_height_mm": round(1000 * self.height_m, 2) if finite else None,
                "reflected_median_distance_mm":
                    round(1000 * self.median_distance_m, 3) if finite else None,
                "symmetric": self.symmetric, "squash": round(self.squash, 4),
                "body_top_mm": (round(1000 * self.body_top_m, 2)
                                if np.isfinite(self.body_top_m) else None)}


def reflected(xyz: np.ndarray, height_m: np.ndarray, level_m: float, up: np.ndarray,
              squash: float = 1.0) -> np.ndarray:
    """``xyz`` (N, 3), at ``height_m`` (N,) above the plate, reflected in the horizontal plane
    ``level_m`` above it (``up`` its unit normal), the reflection's distances below that plane
    scaled by ``squash``."""
    return xyz + np.outer((level_m - height_m) * (1.0 + squash), up)


def reflected_normals(normals: np.ndarray, up: np.ndarray, squash: float = 1.0) -> np.ndarray:
    """Unit ``normals`` (N, 3) of a surface reflected by :func:`reflected` with ``squash``: a
    vertical scale by ``-squash`` maps a normal's vertical part by ``-1 / squash``."""
    along = normals @ up
    if squash == 1.0:  # a plain mirror keeps unit length: no renormalising, same bits
        return normals - 2.0 * np.outer(along, up)
    out = normals - np.outer(along * (1.0 + 1.0 / squash), up)
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def resting_squash(level_m: float, top_m: float, cfg: UndersideConfig) -> float:
    """The vertical scale that lays the reflection at ``level_m`` of food ``top_m`` high onto
    the plate: at most 1, a reflection that stays above the plate left as it is, unless
    ``cfg.stretch_to_plate`` (then stretched down to ``cfg.min_hover_m`` above the plate, by
    at most ``cfg.max_stretch``); 1 without ``cfg.rest_on_plate``."""
    if not cfg.rest_on_plate or top_m <= level_m:
        return 1.0
    if top_m <= 2.0 * level_m:
        hover_m = 2.0 * level_m - top_m  # the plain reflection's lowest point's height
        if not cfg.stretch_to_plate or hover_m <= cfg.min_hover_m:
            return 1.0
        return min(1.0 + (hover_m - cfg.min_hover_m) / (top_m - level_m), cfg.max_stretch)
    return level_m / (top_m - level_m)


def surface_heights(xyz: np.ndarray, height_m: np.ndarray, neighbours: int) -> np.ndarray:
    """(N,) each point's ``height_m`` averaged with those of its nearest points, ``neighbours``
    in all (itself included; the raw heights when 1 or fewer)."""
    k = min(int(neighbours), len(xyz))
    if k <= 1:
        return height_m
    return height_m[cKDTree(xyz).query(xyz, k=k)[1]].mean(axis=1)


def body_top(xyz: np.ndarray, height_m: np.ndarray, up: np.ndarray, cfg: UndersideConfig
             ) -> float:
    """The height (metres) of the food's body top, on the points' heights averaged over
    ``cfg.top_neighbours`` (:func:`surface_heights`): their 99.5th percentile, but no higher
    than the top of the highest slice whose width is at least ``cfg.min_top_width_share`` of
    the widest slice's. A slice's width is twice the 90th percentile of its points'
    horizontal distances from their centroid (slices with fewer than ten points do not
    count)."""
    height_m = surface_heights(xyz, height_m, cfg.top_neighbours)
    top = float(np.percentile(height_m, 99.5))
    side, other = horizontal_axes(up)
    flat = np.column_stack([xyz @ side, xyz @ other])
    slices = np.floor(height_m / cfg.top_slice_m).astype(int)
    widths = {}
    for k in np.unique(slices):
        these = flat[slices == k]
        if len(these) >= 10:
            widths[int(k)] = 2.0 * float(np.percentile(
                np.linalg.norm(these - these.mean(axis=0), axis=1), 90))
    if not widths:
        return top
    wide_enough = max(widths.values()) * cfg.min_top_width_share
    highest = max(k for k, width in widths.items() if width >= wide_enough)
    return min(top, (highest + 1) * cfg.top_slice_m)


def fit_level(xyz: np.ndarray, normals: np.ndarray, height_m: np.ndarray, up: np.ndarray,
              space: SpaceGrid, cfg: UndersideConfig) -> LevelFit:
    """The horizontal mirror level whose reflection of the part of ``xyz`` above it lands
    nearest the cloud (with its ``normals``) where it lands in seen space low below it (mean
    truncated distance to the nearest point's tangent plane; ``cfg.levels`` levels, then a
    tenth of their step around the best), and whether the cloud is symmetric about it (the
    median distance to the nearest point of all that land in seen space below it). Only the
    reflection downwards is scored: it is what fills the wedge, so the level is the one that
    lays the reflected top best on the seen bottom."""
    rng = np.random.default_rng(cfg.seed)
    pick = rng.choice(len(xyz), min(cfg.fit_points, len(xyz)), replace=False)
    sample, sample_h = xyz[pick], height_m[pick]
    tree = cKDTree(xyz)
    radius = cfg.inlier_spacings * float(np.median(tree.query(sample, k=2)[0][:, 1]))

    top = float(np.percentile(height_m, 99.5))
    body = body_top(xyz, height_m, up, cfg)  # what rests on the plate when squashed
    # the level is judged where the reflection lands nearest the wedge it fills, when the
    # cloud reaches down there: below low_share of the mid-height (one band for every level)
    band_m = cfg.low_share * top / 2
    if (sample_h < band_m).sum() < cfg.min_checked_points:
        band_m = np.inf

    # the level is chosen without the stretch, which only moves the points it reflects
    unstretched = replace(cfg, stretch_to_plate=False)

    def score(level: float) -> tuple[float, float]:
        upper = sample_h > level
        squash = resting_squash(level, body, unstretched)
        moved = reflected(sample[upper], sample_h[upper], level, up, squash)
        # the plain mirror keeps its own arithmetic, so its levels come out bit for bit
        moved_h = (2.0 * level - sample_h[upper] if squash == 1.0
                   else level - (sample_h[upper] - level) * squash)
        checked = (moved_h > 0) & (space.states_at(moved) != UNKNOWN)
        if checked.sum() < max(cfg.min_checked_share * upper.sum(), cfg.min_checked_points):
            return np.inf, np.inf
        distance, index = tree.query(moved[checked], distance_upper_bound=radius)
        # the distance to the tangent planes chooses the level (the cloud's spacing is no
        # floor there); the distance to the points says whether the cloud is symmetric
        low = moved_h[checked] < band_m
        if not low.any():
            return np.inf, np.inf
        low_points, low_index = moved[checked][low], index[low]
        near = np.isfinite(distance[low])
        plane = np.full(len(low_points), radius)
        plane[near] = np.minimum(np.abs(np.einsum(
            "ij,ij->i", low_points[near] - xyz[low_index[near]], normals[low_index[near]])),
            radius)
        return float(plane.mean()), float(np.median(np.minimum(distance, radius)))

    coarse = np.linspace(cfg.lowest_share, cfg.highest_share, cfg.levels) * top
    step = float(coarse[1] - coarse[0]) if len(coarse) > 1 else 0.0
    best = (np.inf, np.inf, np.nan)
    for level in coarse:
        mean, median = score(float(level))
        if mean < best[0]:
            best = (mean, median, float(level))
    if np.isfinite(best[2]):  # refine around the best coarse level
        for level in best[2] + np.linspace(-step, step, 11):
            mean, median = score(float(level))
            if mean < best[0]:
                best = (mean, median, float(level))
    _, median, level = best
    symmetric = bool(np.isfinite(level) and median <= cfg.max_median_distance_m
                     and median < radius)
    squash = resting_squash(level, body, cfg) if np.isfinite(level) else 1.0
    return LevelFit(level, median, symmetric, squash, body)


def facing_out(points: np.ndarray, normals: np.ndarray, centre: np.ndarray, up: np.ndarray,
               min_share: float) -> np.ndarray:
    """(N,) True where a point's normal faces away from the vertical axis through ``centre``:
    its horizontal part dotted with the unit horizontal direction from the axis exceeds
    ``min_share``."""
    away = points - centre
    away -= np.outer(away @ up, up)
    level = normals - np.outer(normals @ up, up)
    reach = np.linalg.norm(away, axis=1)
    return np.einsum("ij,ij->i", away, level) > min_share * reach


def hole_above(points: np.ndarray, centre: np.ndarray, support: SupportPlane,
               space: SpaceGrid) -> np.ndarray:
    """(N,) True where the vertical axis through ``centre`` is unknown ``space`` at each
    point's height above the plate and, followed up from there, meets seen-empty space before
    it meets food: a hole through the item (a doughnut's) that the cameras saw into from above
    but not down to that height. False where the axis meets food first (a hollow under the
    item's body: above it on the axis lies the body), or where it is seen empty at the
    point's height (the hole seen through there bounds its own wall)."""
    heights_m, states = axis_states(space, centre, support)
    at = np.clip(np.searchsorted(heights_m, support.height_m(points)), 0, len(states) - 1)
    return (states[at] == UNKNOWN) & (first_known_above(states)[at] == EMPTY)


def underside_points(observed: PointCloud, support: SupportPlane, space: SpaceGrid,
                     cfg: UndersideConfig) -> tuple[PointCloud, dict[str, Any]]:
    """The reflected points (normals set, coloured as a prior's) that land in ``space``'s
    unknown part above the plate, farther than ``cfg.min_gap_m`` from every ``observed`` point
    (which must carry outward normals), none when the cloud is not symmetric about a horizontal
    plane; and a JSON-able record of the fit."""
    start = time.perf_counter()
    if observed.normals is None:
        raise ValueError("the underside's mirror needs the observed points' normals")
    up = np.asarray(support.normal, float)
    height = support.height_m(observed.xyz)
    fit = fit_level(observed.xyz, observed.normals, height, up, space, cfg)
    record: dict[str, Any] = {**fit.record(), "kept": 0}
    points = np.zeros((0, 3))
    normals = np.zeros((0, 3))
    if fit.symmetric:
        upper = height > fit.height_m
        points = reflected(observed.xyz[upper], height[upper], fit.height_m, up, fit.squash)
        normals = reflected_normals(observed.normals[upper], up, fit.squash)
        centre = observed.xyz.mean(axis=0)
        keep = (support.height_m(points) > 0) & (space.states_at(points) == UNKNOWN)
        away = facing_out(points, normals, centre, up, cfg.min_facing_out)
        if cfg.through_holes:
            away |= hole_above(points, centre, support, space)
        keep &= away
        cloud = PointCloud(points[keep], None, normals[keep])
        cloud = thinned(cloud.subset(~near_points(cloud.xyz, observed.xyz, cfg.min_gap_m)),
                        cfg.voxel_m)
        points, normals = cloud.xyz, cloud.normals
        record["kept"] = int(len(points))
    record["seconds"] = round(time.perf_counter() - start, 2)
    rgb = np.tile(np.array(PREDICTED_RGB, np.uint8), (len(points), 1))
    return PointCloud(points, rgb, normals), record
