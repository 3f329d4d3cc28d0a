"""CPU ray casting of a :class:`~volec.synth.scene.Scene` through a pinhole camera.

In: a scene, OpenCV intrinsics (K, width, height), ``T_scene_from_cam`` and a
:class:`LookConfig`. Out: a :class:`Rendering` with linear RGB in [0, 1], the per-pixel object
label (-1 where the ray hits nothing), the food's coverage of each pixel and the depth along the
optical axis in metres.

Uses Embree through trimesh (``embreex``), Lambertian shading with a light and a sky term.
What a phone records (``LookConfig()``, the default): pixels where the first hit changes object
or jumps in depth, or the colour changes sharply, are integrated over their area with n x n
stratified rays (elsewhere one ray through the centre suffices: the optics' blur that follows
removes what one sample would alias); the light is a disc, so shadows are soft (several shadow
rays where it is partly hidden); a Gaussian point spread function blurs the image. The old
look (``LOOKS["sharp"]``): one ray per pixel centre, a point light, no blur. No display or GPU is
needed; results are deterministic.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import trimesh
from scipy import ndimage
from trimesh.ray.ray_pyembree import RayMeshIntersector

from volec.synth.scene import FOOD, Scene

SUN_DIRECTION = np.array([0.45, -0.3, 1.0]) / np.linalg.norm([0.45, -0.3, 1.0])
SUN_STRENGTH = 0.75
SKY_STRENGTH = 0.38
BACKGROUND = np.array([0.62, 0.64, 0.66])


@dataclass(frozen=True)
class LookConfig:
    """How the camera and the light look."""

    edge_samples: int = 3
    """Rays per pixel side (n x n, stratified) where the first hit changes object or jumps in
    depth, or the colour changes sharply; 1: one ray through every pixel centre."""
    edge_depth_jump: float = 0.01
    """A relative depth change to a neighbouring pixel beyond this is an edge."""
    edge_colour_jump: float = 0.2
    """A change of linear colour to a neighbouring pixel beyond this is an edge."""
    blur_sigma_px: float = 0.7
    """Optical blur: the standard deviation of a Gaussian point spread function, pixels
    (phones: about 0.5-1 px); 0 for none."""
    light_radius_deg: float = 5.0
    """Angular radius of the light, a disc (a lamp or a window more than the sun): shadows
    with soft edges; 0: a point light and hard shadows."""
    shadow_rays: int = 16
    """Shadow rays towards the disc where it is partly hidden."""
    penumbra_px: int = 14
    """Pixels this close to a change of the centre ray's shadow get the extra shadow rays."""


LOOKS: dict[str, LookConfig] = {
    "phone": LookConfig(),
    "sharp": LookConfig(edge_samples=1, blur_sigma_px=0.0, light_radius_deg=0.0),
}
"""``phone``: what a phone records (the default); ``sharp``: the benchmark's first look."""


@dataclass
class Rendering:
    """One rendered view."""

    rgb: np.ndarray
    """(H, W, 3) linear RGB in [0, 1]."""
    label: np.ndarray
    """(H, W) object label per pixel (TABLE, PLATE, FOOD) or -1 for background."""
    depth_m: np.ndarray
    """(H, W) z-depth in the camera frame, metres (inf for background)."""
    food_coverage: np.ndarray | None = None
    """(H, W) share of each pixel's area the food covers (None: one ray per pixel, the
    centre's label decides)."""
    shadow: np.ndarray | None = None
    """(H, W) pixels of other objects than the food where the light is mostly hidden (the
    food's cast shadow among them)."""

    @property
    def food_mask(self) -> np.ndarray:
        """(H, W) bool: pixels at least half covered by the food (with one ray per pixel:
        whose centre's first hit is the food)."""
        if self.food_coverage is not None:
            return self.food_coverage >= 0.5
        return self.label == FOOD


class Renderer:
    """Holds the scene's acceleration structure so that many views reuse it."""

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        self.mesh: trimesh.Trimesh = scene.mesh
        self._rays = RayMeshIntersector(self.mesh)
        # Plain numpy copies: trimesh's arrays hash themselves on every access to check
        # their caches (about 2 % of a frame's time).
        self._faces = np.array(self.mesh.faces)
        self._vertices = np.array(self.mesh.vertices)
        self._face_normals = np.array(self.mesh.face_normals)
        self._vertex_normals = np.array(self.mesh.vertex_normals)
        self._face_label = np.asarray(scene.face_label)
        # Per-face tables, so that a frame gathers by triangle rather than by vertex. The
        # barycentric set-up depends on the triangle alone; einsum gives every row the same
        # bits whatever the other rows of its array, so computing it once here changes
        # nothing.
        self._triangle_frames = _triangle_frames(self._vertices[self._faces])
        self._first_corner = self._triangle_frames[0]
        self._corner_normals = self._vertex_normals[self._faces]
        # The intersector's embree scene, queried directly (see _embree_origins); its
        # vertices are shifted and scaled to about a unit cube for precision.
        self._embree = self._rays._scene
        self._sun = _embree_directions(SUN_DIRECTION[None])
        self._discs: dict[tuple[int, float], np.ndarray] = {}
        self._grid: tuple[tuple | None, np.ndarray] = (None, np.empty((0, 3)))

    def render(
        self, K: np.ndarray, width: int, height: int, T_scene_from_cam: np.ndarray,
        look: LookConfig | None = None,
    ) -> Rendering:
        """Render the view of a camera with calibration ``K`` at pose ``T_scene_from_cam``
        (the sharp look unless ``look`` says otherwise)."""
        look = look or LOOKS["sharp"]
        rgb, label, depth, shadow = self._shade(T_scene_from_cam,
                                                self._pixel_directions(K, width, height),
                                                look, (height, width))
        rgb, label, depth = (rgb.reshape(height, width, 3), label.reshape(height, width),
                             depth.reshape(height, width))
        coverage = None
        if look.edge_samples > 1:
            edges = _edges(label, depth, rgb, look)
            rgb, coverage = self._supersample(K, T_scene_from_cam, rgb, label, edges, look)
        if look.blur_sigma_px > 0:
            rgb = ndimage.gaussian_filter(rgb, (look.blur_sigma_px, look.blur_sigma_px, 0),
                                          mode="nearest")
        return Rendering(rgb=np.clip(rgb, 0.0, 1.0), label=label, depth_m=depth,
                         food_coverage=coverage,
                         shadow=shadow.reshape(height, width) & (label != FOOD))

    def _pixel_directions(self, K: np.ndarray, width: int, height: int) -> np.ndarray:
        """:func:`camera_directions` of every pixel centre, row by row; the same for every
        view of a capture, so kept from the last call."""
        key = (width, height, K.tobytes())
        if self._grid[0] != key:
            u, v = np.meshgrid(np.arange(width, dtype=float), np.arange(height, dtype=float))
            self._grid = (key, camera_directions(K, np.stack([u.ravel(), v.ravel()], axis=1)))
        return self._grid[1]

    @staticmethod
    def _camera_rays(T_scene_from_cam: np.ndarray, dirs_cam: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
        """(origin (3,), unit directions (N, 3)) in the scene of the rays along ``dirs_cam``
        (N, 3) in the camera (:func:`camera_directions`)."""
        R = T_scene_from_cam[:3, :3]
        dirs = np.einsum("ij,kj->ik", dirs_cam, R)  # no BLAS threads (see noise.py)
        dirs /= _row_norms(dirs)[:, None]
        return T_scene_from_cam[:3, 3], dirs

    def _shade(self, T_scene_from_cam: np.ndarray, dirs_cam: np.ndarray,
               look: LookConfig, grid: tuple[int, int] | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Linear RGB (N, 3), label (N,), z-depth (N,) and whether the light is mostly hidden
        (N,) of one ray per pixel position, along ``dirs_cam`` (:func:`camera_directions`).
        ``grid`` (H, W): the rays pass through every pixel centre, row by row; else through
        the n x n sub-pixel positions of some pixels, pixel by pixel."""
        origin, dirs = self._camera_rays(T_scene_from_cam, dirs_cam)
        tri = self._first_hits(origin, dirs)
        # Index arrays and np.take rather than boolean masks: the same values, gathered
        # several times faster.
        hit = np.flatnonzero(tri >= 0)
        n = len(dirs)
        rgb = np.tile(BACKGROUND, (n, 1))
        label = np.full(n, -1, dtype=np.int8)
        depth = np.full(n, np.inf)
        shadow = np.zeros(n, bool)
        if len(hit):
            points, normals, lab = self._surface(tri.take(hit), origin, dirs.take(hit, axis=0))
            albedo = np.empty((len(points), 3))
            for obj in np.unique(lab):
                sel = np.flatnonzero(lab == obj)
                albedo[sel] = self.scene.colour(int(obj), points.take(sel, axis=0),
                                                normals.take(sel, axis=0))
            cos_sun = np.einsum("ij,j->i", normals, SUN_DIRECTION)
            lit = self._light(points, normals, cos_sun > 0, hit, look, grid)
            cos_sun = np.clip(cos_sun, 0.0, None)
            setup = self.scene.setup
            sky = SKY_STRENGTH * (0.75 + 0.25 * normals[:, 2])
            rgb[hit] = setup.light * albedo * (sky + setup.sun * SUN_STRENGTH * cos_sun
                                               * lit)[:, None]
            label[hit] = lab
            depth[hit] = np.einsum("ij,j->i", points - origin, T_scene_from_cam[:3, 2])
            shadow[hit] = lit < 0.5
        return rgb, label, depth, shadow

    def _supersample(self, K: np.ndarray, T_scene_from_cam: np.ndarray, rgb: np.ndarray,
                     label: np.ndarray, edges: np.ndarray, look: LookConfig
                     ) -> tuple[np.ndarray, np.ndarray]:
        """``rgb`` with the ``edges`` pixels integrated over their area by n x n stratified
        rays, and the food's coverage of every pixel."""
        n = look.edge_samples
        coverage = (label == FOOD).astype(float)
        rows, cols = np.nonzero(edges)
        if not len(rows):
            return rgb, coverage
        offsets = (np.arange(n) + 0.5) / n - 0.5
        du, dv = (a.ravel() for a in np.meshgrid(offsets, offsets))
        pix = np.stack([(cols[:, None] + du).ravel(), (rows[:, None] + dv).ravel()], axis=1)
        sub_rgb, sub_label, _, _ = self._shade(T_scene_from_cam, camera_directions(K, pix),
                                               look)
        out = rgb.copy()
        out[rows, cols] = sub_rgb.reshape(len(rows), n * n, 3).mean(axis=1)
        coverage[rows, cols] = (sub_label.reshape(len(rows), n * n) == FOOD).mean(axis=1)
        return out, coverage

    def depth(self, K: np.ndarray, width: int, height: int, T_scene_from_cam: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
        """The exact z-depth (H, W) metres along each pixel centre's ray (inf where it hits
        nothing) and the object label (H, W) it hits, without shading: what a perfect depth
        sensor would see."""
        origin, dirs = self._camera_rays(T_scene_from_cam, self._pixel_directions(K, width, height))
        tri = self._first_hits(origin, dirs)
        hit = np.flatnonzero(tri >= 0)
        depth = np.full(len(dirs), np.inf)
        label = np.full(len(dirs), -1, dtype=np.int8)
        if len(hit):
            points, _, label[hit] = self._surface(tri.take(hit), origin,
                                                  dirs.take(hit, axis=0))
            depth[hit] = np.einsum("ij,j->i", points - origin, T_scene_from_cam[:3, 2])
        return depth.reshape(height, width), label.reshape(height, width)

    def _surface(
        self, tri: np.ndarray, origin: np.ndarray, dirs: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Exact hit points (float64 ray-plane intersection), shading normals and object
        labels of the rays ``dirs`` from ``origin`` that hit triangles ``tri``.

        Normals are interpolated from the vertices on the food only; table and plate are
        flat, so their face normals are exact there.
        """
        v0 = self._first_corner.take(tri, axis=0)
        face_n = self._face_normals.take(tri, axis=0)
        t = np.einsum("ij,ij->i", v0 - origin, face_n) / np.einsum("ij,ij->i", dirs, face_n)
        points = origin + dirs * t[:, None]
        normals = face_n.copy()
        labels = self._face_label.take(tri)
        smooth = np.flatnonzero(labels == FOOD)
        if len(smooth):
            on_food = tri.take(smooth)
            frames = tuple(a.take(on_food, axis=0) for a in self._triangle_frames)
            bary = _barycentric_in(frames, points.take(smooth, axis=0))
            vn = self._corner_normals.take(on_food, axis=0)
            ns = np.einsum("ij,ijk->ik", np.clip(bary, 0, 1), vn)
            normals[smooth] = ns / _row_norms(ns)[:, None]
        # Face the camera: a grazing interpolated normal, or a back face, may point away.
        away = np.flatnonzero(np.einsum("ij,ij->i", normals, dirs) > 0)
        if len(away):
            fn = face_n.take(away, axis=0)
            sign = np.where(np.einsum("ij,ij->i", fn, dirs.take(away, axis=0)) > 0, -1.0, 1.0)
            normals[away] = fn * sign[:, None]
        return points, normals, labels

    def _first_hits(self, origin: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """(N,) index of the first triangle each ray from ``origin`` (3,) along ``dirs``
        (N, 3) hits, -1 for none: ``RayMeshIntersector.intersects_first``'s answer, with the
        shared origin converted once."""
        start = _embree_origins(self._embree, origin[None])
        return self._embree.scene.run(np.broadcast_to(start, dirs.shape),
                                      _embree_directions(dirs))

    def _hidden(self, start: np.ndarray, direction: np.ndarray) -> np.ndarray:
        """(N,) True where a ray from ``start`` (N, 3) along ``direction`` ((1, 3) or
        (N, 3)), both in embree's frame (:func:`_embree_origins`,
        :func:`_embree_directions`), hits anything: an occlusion query, which stops at the
        first hit found rather than the nearest (the same triangle test, so the same
        answer as ``intersects_any``)."""
        return self._embree.scene.run(start, direction, query="OCCLUDED") == 0

    def _light_disc(self, n: int, radius_deg: float) -> np.ndarray:
        """:func:`light_directions` in embree's form (float32, as trimesh normalises
        them), computed once per look."""
        key = (n, radius_deg)
        if key not in self._discs:
            self._discs[key] = _embree_directions(light_directions(n, radius_deg))
        return self._discs[key]

    def _light(self, points: np.ndarray, normals: np.ndarray, facing: np.ndarray,
               hit: np.ndarray, look: LookConfig, grid: tuple[int, int] | None
               ) -> np.ndarray:
        """The share of the light (a disc of ``look.light_radius_deg``; a point when 0) that
        each hit point sees: hard visibility from the disc's centre, refined by
        ``shadow_rays`` rays where it changes nearby (grid pass), or one disc sample per
        sub-pixel ray, stratified over each pixel's n x n rays (edge pass). ``facing``:
        (N,) whether each normal faces the light; ``hit``: the rays' indices (N,) among all
        rays of the pass."""
        lit = np.zeros(len(points))
        facing = np.flatnonzero(facing)
        if not len(facing):
            return lit
        # The shadow rays' origins, converted once for all the rays from each point.
        start = _embree_origins(self._embree, points[facing] + normals[facing] * 2e-4)
        if look.light_radius_deg <= 0:
            lit[facing] = ~self._hidden(start, self._sun)
            return lit
        if grid is None:  # sub-pixel rays: the k-th ray of a pixel samples the k-th stratum
            n2 = look.edge_samples**2
            disc = self._light_disc(n2, look.light_radius_deg)
            k = hit[facing] % n2
            lit[facing] = ~self._hidden(start, disc[k])
            return lit
        lit[facing] = ~self._hidden(start, self._sun)
        hard = np.full(grid[0] * grid[1], np.nan)
        hard[hit] = lit
        image = hard.reshape(grid)
        lit_pix = np.nan_to_num(image, nan=0.0) > 0.5
        changes = lit_pix ^ ndimage.binary_erosion(lit_pix, border_value=1)
        changes |= ~lit_pix ^ ndimage.binary_erosion(~lit_pix, border_value=1)
        near = ndimage.binary_dilation(changes, iterations=look.penumbra_px).ravel()
        soft = np.flatnonzero(near[hit[facing]])  # positions among the facing points
        if len(soft):
            disc = self._light_disc(look.shadow_rays, look.light_radius_deg)
            soft_start = start[soft]
            seen = np.zeros(len(soft))
            for direction in disc:
                seen += ~self._hidden(soft_start, direction[None])
            lit[facing[soft]] = seen / len(disc)
        return lit


def _embree_origins(embree: Any, points: np.ndarray) -> np.ndarray:
    """``points`` (N, 3) in the frame of trimesh's embree scene ``embree``, float32, rounded
    as ``RayMeshIntersector.intersects_first`` rounds them (to float32 first, then shifted
    and scaled in float64): the same rays give the same triangles, bit for bit."""
    scaled = np.asarray(points, np.float32).astype(np.float64)
    return ((scaled - embree.origin) * embree.scale).astype(np.float32)


def _embree_directions(dirs: np.ndarray) -> np.ndarray:
    """Unit directions ``dirs`` (N, 3) as ``intersects_first`` hands them to embree:
    rounded to float32, normalised again by ``trimesh.util.unitize``, rounded again."""
    return trimesh.util.unitize(np.asarray(dirs, np.float32)).astype(np.float32)


def camera_directions(K: np.ndarray, pix: np.ndarray) -> np.ndarray:
    """(N, 3) directions in the camera frame, z = 1, of the rays through pixel positions
    ``pix`` (N, 2), OpenCV pixel coordinates (the first pixel's centre at 0, 0)."""
    return np.stack([(pix[:, 0] - K[0, 2]) / K[0, 0], (pix[:, 1] - K[1, 2]) / K[1, 1],
                     np.ones(len(pix))], axis=-1)


def _row_norms(v: np.ndarray) -> np.ndarray:
    """(N, 3) -> (N,): ``np.linalg.norm(v, axis=1)`` bit for bit (its reduction adds the
    three squares in order), written elementwise: 3x as fast."""
    sq = v * v
    return np.sqrt((sq[:, 0] + sq[:, 1]) + sq[:, 2])


def light_directions(n: int, radius_deg: float) -> np.ndarray:
    """``n`` unit directions spread evenly (a sunflower pattern) over a disc of angular radius
    ``radius_deg`` around the light's direction."""
    from volec.geometry import horizontal_axes

    e1, e2 = horizontal_axes(SUN_DIRECTION)
    k = np.arange(n) + 0.5
    r = np.sqrt(k / n) * np.tan(np.radians(radius_deg))
    a = k * np.pi * (3.0 - np.sqrt(5.0))
    d = SUN_DIRECTION + r[:, None] * (np.cos(a)[:, None] * e1 + np.sin(a)[:, None] * e2)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _edges(label: np.ndarray, depth: np.ndarray, rgb: np.ndarray, look: LookConfig
           ) -> np.ndarray:
    """(H, W) pixels whose 8-neighbourhood holds another object, a depth jump or a sharp
    change of colour: those one ray per pixel would alias."""
    H, W = label.shape
    edges = np.zeros((H, W), bool)
    finite = np.where(np.isfinite(depth), depth, 1e6)
    for dy, dx in ((0, 1), (1, 0), (1, 1), (1, -1)):
        a = (slice(0, H - dy), slice(max(0, -dx), W - max(0, dx)))
        b = (slice(dy, H), slice(max(0, dx), W + min(0, dx)))
        differ = ((label[a] != label[b])
                  | (np.abs(finite[a] - finite[b]) > look.edge_depth_jump * np.minimum(
                      finite[a], finite[b]))
                  | (_largest_channel(np.abs(rgb[a] - rgb[b])) > look.edge_colour_jump))
        edges[a] |= differ
        edges[b] |= differ
    return edges


def _largest_channel(rgb: np.ndarray) -> np.ndarray:
    """(..., 3) -> (...): the largest of the three channels, as ``rgb.max(axis=-1)`` gives it
    but elementwise (a reduction over a last axis of 3 took 8 % of a frame's time)."""
    return np.maximum(np.maximum(rgb[..., 0], rgb[..., 1]), rgb[..., 2])


def _triangle_frames(corners: np.ndarray) -> tuple[np.ndarray, ...]:
    """What :func:`_barycentric_in` needs of triangles ``corners`` (M, 3, 3): the first
    corner, the two edges from it, their dot products and the determinant (M,)."""
    e1 = corners[:, 1] - corners[:, 0]
    e2 = corners[:, 2] - corners[:, 0]
    d11 = np.einsum("ij,ij->i", e1, e1)
    d12 = np.einsum("ij,ij->i", e1, e2)
    d22 = np.einsum("ij,ij->i", e2, e2)
    denom = d11 * d22 - d12 * d12
    denom[denom == 0] = 1e-30
    return np.ascontiguousarray(corners[:, 0]), e1, e2, d11, d12, d22, denom


def _barycentric_in(frames: tuple[np.ndarray, ...], points: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (M, 3) of ``points`` in the triangles of ``frames``
    (:func:`_triangle_frames`).

    Written with einsum rather than trimesh's helper, which calls BLAS: BLAS threads in
    parallel render workers on a 2-core machine cost about a third of the speed.
    """
    c0, e1, e2, d11, d12, d22, denom = frames
    d = points - c0
    dp1 = np.einsum("ij,ij->i", d, e1)
    dp2 = np.einsum("ij,ij->i", d, e2)
    b1 = (d22 * dp1 - d12 * dp2) / denom
    b2 = (d11 * dp2 - d12 * dp1) / denom
    return np.stack([1.0 - b1 - b2, b1, b2], axis=1)


def to_srgb8(rgb: np.ndarray) -> np.ndarray:
    """Linear [0, 1] RGB -> 8-bit sRGB-like (gamma 2.2)."""
    return np.round(np.clip(rgb, 0.0, 1.0) ** (1 / 2.2) * 255.0).astype(np.uint8)
