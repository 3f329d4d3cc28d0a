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
        self._vertex_normals = np.asarray(self.mesh.vertex_normals)

    def render(
        self, K: np.ndarray, width: int, height: int, T_scene_from_cam: np.ndarray,
        look: LookConfig | None = None,
    ) -> Rendering:
        """Render the view of a camera with calibration ``K`` at pose ``T_scene_from_cam``
        (the sharp look unless ``look`` says otherwise)."""
        look = look or LOOKS["sharp"]
        u, v = np.meshgrid(np.arange(width, dtype=float), np.arange(height, dtype=float))
        pix = np.stack([u.ravel(), v.ravel()], axis=1)
        rgb, label, depth, shadow = self._shade(K, T_scene_from_cam, pix, look,
                                                (height, width))
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

    def _camera_rays(self, K: np.ndarray, T_scene_from_cam: np.ndarray, pix: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
        """(origin (3,), unit directions (N, 3)) of the rays through pixel positions ``pix``
        (N, 2), OpenCV pixel coordinates (the first pixel's centre at 0, 0)."""
        dirs_cam = np.stack([(pix[:, 0] - K[0, 2]) / K[0, 0], (pix[:, 1] - K[1, 2]) / K[1, 1],
                             np.ones(len(pix))], axis=-1)
        R = T_scene_from_cam[:3, :3]
        dirs = np.einsum("ij,kj->ik", dirs_cam, R)  # no BLAS threads (see noise.py)
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        return T_scene_from_cam[:3, 3], dirs

    def _shade(self, K: np.ndarray, T_scene_from_cam: np.ndarray, pix: np.ndarray,
               look: LookConfig, grid: tuple[int, int] | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Linear RGB (N, 3), label (N,), z-depth (N,) and whether the light is mostly hidden
        (N,) of one ray per pixel position.
        ``grid`` (H, W): ``pix`` is every pixel centre, row by row; else they are the n x n
        sub-pixel positions of some pixels, pixel by pixel."""
        origin, dirs = self._camera_rays(K, T_scene_from_cam, pix)
        tri = self._rays.intersects_first(np.broadcast_to(origin, dirs.shape), dirs)
        hit = tri >= 0
        n = len(dirs)
        rgb = np.tile(BACKGROUND, (n, 1))
        label = np.full(n, -1, dtype=np.int8)
        depth = np.full(n, np.inf)
        shadow = np.zeros(n, bool)
        if hit.any():
            points, normals = self._surface(tri[hit], origin, dirs[hit])
            lab = self.scene.face_label[tri[hit]]
            albedo = np.empty((len(points), 3))
            for obj in np.unique(lab):
                sel = lab == obj
                albedo[sel] = self.scene.colour(int(obj), points[sel], normals[sel])
            lit = self._light(points, normals, hit, look, grid)
            cos_sun = np.clip(np.einsum("ij,j->i", normals, SUN_DIRECTION), 0.0, None)
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
        sub_rgb, sub_label, _, _ = self._shade(K, T_scene_from_cam, pix, look)
        out = rgb.copy()
        out[rows, cols] = sub_rgb.reshape(len(rows), n * n, 3).mean(axis=1)
        coverage[rows, cols] = (sub_label.reshape(len(rows), n * n) == FOOD).mean(axis=1)
        return out, coverage

    def depth(self, K: np.ndarray, width: int, height: int, T_scene_from_cam: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
        """The exact z-depth (H, W) metres along each pixel centre's ray (inf where it hits
        nothing) and the object label (H, W) it hits, without shading: what a perfect depth
        sensor would see."""
        u, v = np.meshgrid(np.arange(width, dtype=float), np.arange(height, dtype=float))
        origin, dirs = self._camera_rays(K, T_scene_from_cam, np.stack([u.ravel(), v.ravel()], 1))
        tri = self._rays.intersects_first(np.broadcast_to(origin, dirs.shape), dirs)
        hit = tri >= 0
        depth = np.full(len(dirs), np.inf)
        label = np.full(len(dirs), -1, dtype=np.int8)
        if hit.any():
            points, _ = self._surface(tri[hit], origin, dirs[hit])
            depth[hit] = np.einsum("ij,j->i", points - origin, T_scene_from_cam[:3, 2])
            label[hit] = self.scene.face_label[tri[hit]]
        return depth.reshape(height, width), label.reshape(height, width)

    def _surface(
        self, tri: np.ndarray, origin: np.ndarray, dirs: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Exact hit points (float64 ray-plane intersection) and shading normals.

        Normals are interpolated from the vertices on the food only; table and plate are
        flat, so their face normals are exact there.
        """
        faces = self.mesh.faces[tri]
        v0 = self.mesh.vertices[faces[:, 0]]
        face_n = self.mesh.face_normals[tri]
        t = np.einsum("ij,ij->i", v0 - origin, face_n) / np.einsum("ij,ij->i", dirs, face_n)
        points = origin + dirs * t[:, None]
        normals = face_n.copy()
        smooth = self.scene.face_label[tri] == FOOD
        if smooth.any():
            corners = self.mesh.vertices[faces[smooth]]
            bary = _barycentric(corners, points[smooth])
            vn = self._vertex_normals[faces[smooth]]
            ns = np.einsum("ij,ijk->ik", np.clip(bary, 0, 1), vn)
            normals[smooth] = ns / np.linalg.norm(ns, axis=1, keepdims=True)
        # Face the camera: a grazing interpolated normal, or a back face, may point away.
        away = np.einsum("ij,ij->i", normals, dirs) > 0
        if away.any():
            fn = face_n[away]
            sign = np.where(np.einsum("ij,ij->i", fn, dirs[away]) > 0, -1.0, 1.0)
            normals[away] = fn * sign[:, None]
        return points, normals

    def _visible(self, points: np.ndarray, normals: np.ndarray, direction: np.ndarray
                 ) -> np.ndarray:
        """(N,) True where the light in ``direction`` (one (3,) or (N, 3)) is unblocked."""
        start = points + normals * 2e-4
        direction = np.broadcast_to(direction, start.shape)
        return ~self._rays.intersects_any(start, direction)

    def _light(self, points: np.ndarray, normals: np.ndarray, hit: np.ndarray,
               look: LookConfig, grid: tuple[int, int] | None) -> np.ndarray:
        """The share of the light (a disc of ``look.light_radius_deg``; a point when 0) that
        each hit point sees: hard visibility from the disc's centre, refined by
        ``shadow_rays`` rays where it changes nearby (grid pass), or one disc sample per
        sub-pixel ray, stratified over each pixel's n x n rays (edge pass)."""
        lit = np.zeros(len(points))
        facing = np.einsum("ij,j->i", normals, SUN_DIRECTION) > 0
        if not facing.any():
            return lit
        if look.light_radius_deg <= 0:
            lit[facing] = self._visible(points[facing], normals[facing], SUN_DIRECTION)
            return lit
        if grid is None:  # sub-pixel rays: the k-th ray of a pixel samples the k-th stratum
            n2 = look.edge_samples**2
            disc = light_directions(n2, look.light_radius_deg)
            k = np.flatnonzero(hit) % n2
            idx = np.flatnonzero(facing)
            lit[idx] = self._visible(points[idx], normals[idx], disc[k[idx]])
            return lit
        lit[facing] = self._visible(points[facing], normals[facing], SUN_DIRECTION)
        hard = np.full(grid[0] * grid[1], np.nan)
        hard[np.flatnonzero(hit)] = lit
        image = hard.reshape(grid)
        lit_pix = np.nan_to_num(image, nan=0.0) > 0.5
        changes = lit_pix ^ ndimage.binary_erosion(lit_pix, border_value=1)
        changes |= ~lit_pix ^ ndimage.binary_erosion(~lit_pix, border_value=1)
        near = ndimage.binary_dilation(changes, iterations=look.penumbra_px).ravel()
        soft = np.flatnonzero(near[np.flatnonzero(hit)] & facing)
        if len(soft):
            disc = light_directions(look.shadow_rays, look.light_radius_deg)
            seen = np.zeros(len(soft))
            for direction in disc:
                seen += self._visible(points[soft], normals[soft], direction)
            lit[soft] = seen / len(disc)
        return lit


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


def _barycentric(corners: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (M, 3) of ``points`` in triangles ``corners`` (M, 3, 3).

    Written with einsum rather than trimesh's helper, which calls BLAS: BLAS threads in
    parallel render workers on a 2-core machine cost about a third of the speed.
    """
    e1 = corners[:, 1] - corners[:, 0]
    e2 = corners[:, 2] - corners[:, 0]
    d = points - corners[:, 0]
    d11 = np.einsum("ij,ij->i", e1, e1)
    d12 = np.einsum("ij,ij->i", e1, e2)
    d22 = np.einsum("ij,ij->i", e2, e2)
    dp1 = np.einsum("ij,ij->i", d, e1)
    dp2 = np.einsum("ij,ij->i", d, e2)
    denom = d11 * d22 - d12 * d12
    denom[denom == 0] = 1e-30
    b1 = (d22 * dp1 - d12 * dp2) / denom
    b2 = (d11 * dp2 - d12 * dp1) / denom
    return np.stack([1.0 - b1 - b2, b1, b2], axis=1)


def to_srgb8(rgb: np.ndarray) -> np.ndarray:
    """Linear [0, 1] RGB -> 8-bit sRGB-like (gamma 2.2)."""
    return np.round(np.clip(rgb, 0.0, 1.0) ** (1 / 2.2) * 255.0).astype(np.uint8)
