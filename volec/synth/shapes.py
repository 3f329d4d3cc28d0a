"""Procedural food shapes: watertight meshes of known volume.

In: an item name (one of the 21 FoodKit items of the paper's Table I) or a shape family with
random parameters. Out: a closed, consistently oriented ``trimesh.Trimesh`` in metres, resting
on the plane z = 0 (z up), centred over the origin, scaled so its exact volume is the target.

Each shape is an implicit function (negative inside) built from a few primitives with smooth
blends, perturbed by seeded solid noise so that no item is perfectly symmetric, and meshed by
marching cubes (scikit-image). The volume of the mesh itself is the ground truth: scaling by
``(target / volume) ** (1/3)`` makes it exact. Items whose shape has a flat base settle onto it
(:attr:`ItemSpec.settle_mm`); the others rest on their lowest point.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import trimesh
from scipy.spatial import cKDTree
from skimage.measure import marching_cubes

from volec.errors import UnknownNameError
from volec.synth.noise import SolidNoise

Field = Callable[[np.ndarray], np.ndarray]
"""An implicit function: (N, 3) points -> (N,) values, negative inside, roughly a distance."""


# ----------------------------------------------------------------------------- primitives


def _smax(a: np.ndarray, b: np.ndarray, k: float) -> np.ndarray:
    """Smooth maximum (rounded intersection) with blend width ``k``."""
    h = np.clip(0.5 - 0.5 * (b - a) / k, 0.0, 1.0)
    return b + (a - b) * h + k * h * (1.0 - h)


def _smin(a: np.ndarray, b: np.ndarray, k: float) -> np.ndarray:
    """Smooth minimum (rounded union) with blend width ``k``."""
    return -_smax(-a, -b, k)


def _ellipsoid(p: np.ndarray, radii: tuple[float, float, float]) -> np.ndarray:
    r = np.asarray(radii, float)
    return (np.linalg.norm(p / r, axis=1) - 1.0) * r.min()


def _rho_theta(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.hypot(p[:, 0], p[:, 1]), np.arctan2(p[:, 1], p[:, 0])


def _tube(p: np.ndarray, centre: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """Distance-like field of a tube of varying radius around a densely sampled curve."""
    dist, idx = cKDTree(centre).query(p, k=1)
    return dist - radius[idx]


def _capsule_x(p: np.ndarray, half_length: float, radius: float) -> np.ndarray:
    q = p.copy()
    q[:, 0] = np.clip(q[:, 0], -half_length, half_length)
    return np.linalg.norm(p - q, axis=1) - radius


# ----------------------------------------------------------------------------- the items


def _apple(p: np.ndarray) -> np.ndarray:
    rho, _ = _rho_theta(p)
    widen = 1.0 + 0.1 * np.clip(p[:, 2], -1, 1)  # a little broader at the shoulders
    q = p / np.stack([widen, widen, np.full(len(p), 0.9)], axis=1)
    d = np.linalg.norm(q, axis=1) - 1.0
    d += 0.28 * np.exp(-(rho**2) / 0.05) * (p[:, 2] > 0)  # stalk cavity
    d += 0.12 * np.exp(-(rho**2) / 0.04) * (p[:, 2] < 0)  # calyx
    stalk = np.maximum(np.hypot(p[:, 0] - 0.03, p[:, 1]) - 0.06, np.abs(p[:, 2] - 0.78) - 0.22)
    return _smin(d, stalk, 0.04)


def _orange(p: np.ndarray) -> np.ndarray:
    return _ellipsoid(p, (1.0, 1.0, 0.92))


def _avocado(p: np.ndarray) -> np.ndarray:
    taper = 1.0 - 0.28 * np.clip(p[:, 0] / 1.4, -1, 1)
    q = np.stack([p[:, 0] / 1.4, p[:, 1] / (0.82 * taper), p[:, 2] / (0.78 * taper)], axis=1)
    return (np.linalg.norm(q, axis=1) - 1.0) * 0.7


def _lemon(p: np.ndarray) -> np.ndarray:
    body = _ellipsoid(p, (1.2, 0.88, 0.85))
    tips = [np.linalg.norm(p - np.array([s * 1.18, 0.0, 0.02]), axis=1) - 0.2 for s in (-1, 1)]
    return _smin(_smin(body, tips[0], 0.18), tips[1], 0.18)


def _donut(p: np.ndarray) -> np.ndarray:
    rho, theta = _rho_theta(p)
    R = 1.0 + 0.04 * np.cos(2 * theta + 0.5)
    return np.hypot(rho - R, p[:, 2] / 0.82) - 0.47


def _durum(p: np.ndarray) -> np.ndarray:
    t = np.linspace(-1.0, 1.0, 400)
    centre = np.stack([1.35 * t, 0.12 * t**2, np.zeros_like(t)], axis=1)
    radius = 0.52 * (1.0 - 0.12 * t) * np.sqrt(np.clip(1.0 - t**8, 0.05, 1.0))
    q = p * np.array([1.0, 1.0, 1.0 / 0.8])
    return _tube(q, centre, radius) * 0.8


def _pear(p: np.ndarray) -> np.ndarray:
    z = p[:, 2]
    lean = np.stack([0.12 * np.clip(z, 0, None) ** 2, np.zeros_like(z), np.zeros_like(z)], axis=1)
    q = p - lean
    body = np.linalg.norm(q, axis=1) - 1.0
    neck = np.linalg.norm(q - np.array([0.0, 0.0, 1.15]), axis=1) - 0.58
    d = _smin(body, neck, 0.55)
    rho = np.hypot(q[:, 0], q[:, 1])
    stalk = np.maximum(rho - 0.05, np.abs(z - 1.85) - 0.2)
    return _smin(d, stalk, 0.05)


def _chocolate_cake(p: np.ndarray) -> np.ndarray:
    half_angle = np.radians(24.0)
    rho, _ = _rho_theta(p)
    n1 = np.array([-np.sin(half_angle), np.cos(half_angle)])
    n2 = np.array([-np.sin(half_angle), -np.cos(half_angle)])
    side1 = p[:, :2] @ n1
    side2 = p[:, :2] @ n2
    disc = rho - 2.4
    slab = np.abs(p[:, 2]) - 0.55
    d = _smax(_smax(_smax(disc, slab, 0.08), side1, 0.08), side2, 0.08)
    return _smax(d, -p[:, 0] - 0.0, 0.08)  # the tip is rounded, not a knife edge


def _chocolate_croissant(p: np.ndarray) -> np.ndarray:
    t = np.linspace(0.0, 1.0, 500)
    angle = np.radians(-110 + 220 * t)
    centre = np.stack([1.3 * np.cos(angle), 1.3 * np.sin(angle), np.zeros_like(t)], axis=1)
    radius = (0.13 + 0.55 * np.sin(np.pi * t) ** 0.9) * (1.0 + 0.07 * np.sin(2 * np.pi * 5 * t))
    q = p * np.array([1.0, 1.0, 1.0 / 0.72])
    return _tube(q, centre, radius) * 0.72


def _samosa(p: np.ndarray) -> np.ndarray:
    # A tetrahedron resting on one face, corners and edges rounded by a soft maximum.
    normals = np.array(
        [[0.0, 0.0, -1.0], [0.943, 0.0, 0.333], [-0.471, 0.816, 0.333], [-0.471, -0.816, 0.333]]
    )
    planes = p @ normals.T - 0.55
    k = 0.18
    return k * np.log(np.exp(planes / k).sum(axis=1))


def _apple_pie(p: np.ndarray) -> np.ndarray:
    rho, theta = _rho_theta(p)
    R = 1.5 + 0.05 * np.sin(16 * theta)  # crimped rim
    top = 0.62 + 0.18 * (1.0 - np.clip(rho / 1.5, 0, 1) ** 2)
    side = rho - R
    z = p[:, 2]
    height = np.maximum(z - top, -z)
    return _smax(side, height, 0.12)


def _chocolate_bomb(p: np.ndarray) -> np.ndarray:
    sphere = np.linalg.norm(p, axis=1) - 1.0
    return _smax(sphere, -p[:, 2] - 0.45, 0.1)


def _empanadilla(p: np.ndarray) -> np.ndarray:
    rho, theta = _rho_theta(p)
    crimp = 0.045 * np.sin(22 * theta) * (p[:, 1] > 0)
    outline = _smax(rho - 1.45 + crimp, -p[:, 1] - 0.05, 0.15)  # a half disc, in 2D
    inside = np.clip(-outline / 0.7, 0.0, 1.0)
    half_thickness = 0.07 + 0.42 * np.sqrt(inside)
    z = p[:, 2]
    thickness = np.where(z > 0, z - half_thickness, -z - 0.65 * half_thickness)
    return _smax(thickness, outline, 0.05)


def _falafel(p: np.ndarray) -> np.ndarray:
    return _ellipsoid(p, (1.0, 0.97, 0.8))


def _french_bread(p: np.ndarray) -> np.ndarray:
    loaf = _ellipsoid(p, (2.6, 0.78, 0.62))
    loaf = _smax(loaf, -p[:, 2] - 0.38, 0.15)  # flat bottom
    u = p[:, 0] * 0.9 + p[:, 1] * 0.45
    slash = np.exp(-((np.mod(u, 1.0) - 0.5) / 0.09) ** 2) * (np.abs(p[:, 0]) < 2.0)
    return loaf + 0.07 * slash * np.clip(p[:, 2] * 3.0, 0.0, 1.0)


def _paxoco_mini(p: np.ndarray) -> np.ndarray:
    bun = _ellipsoid(p, (1.2, 1.15, 0.78))
    bun = _smax(bun, -p[:, 2] - 0.3, 0.12)
    cross = np.exp(-(p[:, 0] / 0.08) ** 2) + np.exp(-(p[:, 1] / 0.08) ** 2)
    return bun + 0.06 * np.clip(cross, 0, 1) * np.clip(p[:, 2] * 2.0, 0.0, 1.0)


def _napolitana(p: np.ndarray) -> np.ndarray:
    half = np.array([1.55, 0.85, 0.32])
    r = 0.22
    q = np.abs(p) - (half - r)
    box = np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0) - r
    layers = 0.018 * np.sin(p[:, 2] * 45.0) * (np.abs(p[:, 2]) < 0.25)
    dome = -0.1 * (1.0 - (p[:, 0] / 1.6) ** 2) * (p[:, 2] > 0)
    return box + layers + dome


def _capsicum(p: np.ndarray) -> np.ndarray:
    rho, theta = _rho_theta(p)
    z = p[:, 2]
    R = (1.0 + 0.12 * np.clip(z, -1, 1)) * (1.0 + 0.11 * np.cos(4 * theta + 0.25 * z))
    H = 0.95 + 0.1 * np.cos(4 * theta)
    body = _smax(rho - R, np.abs(z) - H, 0.35)
    body += 0.15 * np.exp(-(rho**2) / 0.08) * (z > 0)  # stem cavity
    stem = np.maximum(rho - 0.11, np.abs(z - 0.95) - 0.3)
    return _smin(body, stem, 0.06)


def _chocolate_panettone(p: np.ndarray) -> np.ndarray:
    rho, _ = _rho_theta(p)
    z = p[:, 2]
    cylinder = _smax(rho - 1.0, np.abs(z - 0.6) - 0.6, 0.08)
    cap = _ellipsoid(p - np.array([0.0, 0.0, 1.2]), (1.1, 1.1, 0.6))
    return _smin(cylinder, cap, 0.1)


def _banana(p: np.ndarray) -> np.ndarray:
    t = np.linspace(0.0, 1.0, 500)
    angle = np.radians(-55 + 110 * t)
    centre = np.stack(
        [3.0 * np.sin(angle), 3.0 * (1 - np.cos(angle)), 0.35 * (2 * t - 1) ** 2], axis=1
    )
    radius = 0.1 + 0.42 * np.sin(np.pi * np.clip(t * 1.05, 0, 1)) ** 0.6
    return _tube(p, centre, radius)


def _yellow_cane(p: np.ndarray) -> np.ndarray:
    x = p[:, 0]
    s = np.clip((x + 2.0) / 4.0, 0.0, 1.0)
    theta = np.arctan2(p[:, 2], p[:, 1])
    radius = (0.42 + 0.38 * s) * (1.0 + 0.06 * np.sin(2 * np.pi * (2.2 * x) + theta))
    d = np.hypot(p[:, 1], p[:, 2]) - radius
    d = _smax(d, np.abs(x) - 2.0, 0.12)
    cream = np.linalg.norm(p - np.array([2.0, 0.0, 0.0]), axis=1) - 0.62
    return _smin(d, cream, 0.15)


@dataclass(frozen=True)
class ItemSpec:
    """One benchmark item: its implicit shape and the ground-truth volume of Table I."""

    name: str
    """Identifier (snake_case), as Table I names the FoodKit item."""
    volume_ml: float
    """Ground-truth volume from the paper's Table I, millilitres."""
    field: Field
    """Implicit function in canonical units (about one unit per radius), z up."""
    extent: float
    """Half-width of the cube that surely contains the shape, canonical units."""
    bump: float = 0.03
    """Amplitude of the low-frequency noise that breaks symmetry, canonical units."""
    roughness: float = 0.006
    """Amplitude of fine surface relief (pits, crumbs), canonical units."""
    label: str = ""
    """Human-readable name for figures."""
    settle_mm: float = 0.0
    """Height, millimetres (about: the cut is made before the final scaling to the volume),
    of the slab cut off the item's underside, so that it rests on a flat patch as a bake
    rests on the tray it was baked on; 0: the item rests on its lowest point. The noise that
    breaks the items' symmetry also makes their undersides uneven, and an uneven underside on
    its lowest point leaves a thin gap above the plate (0.5-2 mm under most of a pastry),
    which a camera from above cannot see into and which no method could measure."""


FLAT_BASE_SETTLE_MM = 2.0
"""How far the items whose shape has a flat base (a slice, a pie, a loaf, a bun, a pastry, a samosa
on a face) settle onto the plate (:attr:`ItemSpec.settle_mm`): then 61-97 % of their footprint
touches it (the columns of :func:`volec.metrics.bottom_gap` under 0.2 mm; measured 2026-12-06),
against 2-12 % resting on the lowest bump of their noise. Items whose underside is curved by
design (fruit, tubes, the empanadilla's lens) rest on their lowest point, and the gap the camera
cannot see under them stays."""

# Volumes are Table I's ground truth (mL).
ITEMS: dict[str, ItemSpec] = {
    s.name: s
    for s in [
        ItemSpec("apple", 175, _apple, 1.4, label="Apple"),
        ItemSpec("orange", 200, _orange, 1.3, roughness=0.012, label="Orange"),
        ItemSpec("avocado", 85, _avocado, 1.6, bump=0.04, roughness=0.015, label="Avocado"),
        ItemSpec("lemon", 140, _lemon, 1.6, roughness=0.01, label="Lemon"),
        ItemSpec("donut", 245, _donut, 1.7, label="Donut"),
        ItemSpec("durum", 200, _durum, 1.8, bump=0.04, label="Durum"),
        ItemSpec("pear", 170, _pear, 2.2, label="Pear"),
        ItemSpec("chocolate_cake", 195, _chocolate_cake, 2.6, settle_mm=FLAT_BASE_SETTLE_MM,
                 label="Choc. cake"),
        ItemSpec("chocolate_croissant", 275, _chocolate_croissant, 2.3, bump=0.04,
                 label="Choc. croissant"),
        ItemSpec("samosa", 145, _samosa, 1.6, bump=0.04, settle_mm=FLAT_BASE_SETTLE_MM,
                 label="Samosa"),
        ItemSpec("apple_pie", 135, _apple_pie, 1.8, settle_mm=FLAT_BASE_SETTLE_MM,
                 label="Apple pie"),
        ItemSpec("chocolate_bomb", 200, _chocolate_bomb, 1.3, settle_mm=FLAT_BASE_SETTLE_MM,
                 label="Choc. bomb"),
        ItemSpec("empanadilla", 95, _empanadilla, 1.7, bump=0.03, label="Empanadilla"),
        ItemSpec("falafel", 48, _falafel, 1.3, bump=0.06, roughness=0.03, label="Falafel"),
        ItemSpec("french_bread", 163, _french_bread, 2.9, bump=0.04, settle_mm=FLAT_BASE_SETTLE_MM,
                 label="French bread"),
        ItemSpec("paxoco_mini", 150, _paxoco_mini, 1.5, bump=0.04, settle_mm=FLAT_BASE_SETTLE_MM,
                 label="Paxoco mini"),
        ItemSpec("napolitana", 233, _napolitana, 1.9, settle_mm=FLAT_BASE_SETTLE_MM,
                 label="Napolitana"),
        ItemSpec("capsicum", 320, _capsicum, 1.7, label="Capsicum"),
        ItemSpec("chocolate_panettone", 293, _chocolate_panettone, 1.9,
                 settle_mm=FLAT_BASE_SETTLE_MM, label="Choc. panettone"),
        ItemSpec("banana", 150, _banana, 3.2, label="Banana"),
        ItemSpec("yellow_cane", 350, _yellow_cane, 2.8, label="Yellow cane"),
    ]
}


def item_names() -> list[str]:
    """The 21 benchmark item names, in Table I order."""
    return list(ITEMS)


def stable_seed(text: str) -> int:
    """A seed derived from a string, the same on every machine and Python run."""
    return zlib.crc32(text.encode("utf-8"))


# ----------------------------------------------------------------------------- meshing


def perturbed(field: Field, seed: int, bump: float, roughness: float) -> Field:
    """``field`` plus seeded low-frequency bumps (asymmetry) and fine relief."""
    noise = SolidNoise(seed)

    def f(p: np.ndarray) -> np.ndarray:
        d = field(p)
        if bump:
            d = d + bump * (2.0 * noise.fractal(p, 0.8, octaves=2) - 1.0)
        if roughness:
            d = d + roughness * (2.0 * noise.value(p, 9.0, octave=5) - 1.0)
        return d

    return f


def mesh_field(field: Field, extent: float, resolution: int = 112) -> trimesh.Trimesh:
    """Marching-cubes mesh of the zero level set of ``field`` inside ``[-extent, extent]^3``.

    A coarse pass finds the shape's bounding box, so the fine grid's ``resolution`` cells
    span the shape's longest side. Raises ``ValueError`` if the shape touches the box.
    """
    coarse_n = 48
    axis = np.linspace(-extent, extent, coarse_n)
    grid = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
    inside = field(grid).reshape(coarse_n, coarse_n, coarse_n) < 0
    if not inside.any():
        raise ValueError("the implicit shape is empty inside its box")
    idx = np.argwhere(inside)
    if idx.min() == 0 or idx.max() == coarse_n - 1:
        raise ValueError("the implicit shape touches its bounding box; enlarge 'extent'")
    step = axis[1] - axis[0]
    lo = axis[idx.min(axis=0)] - 2 * step
    hi = axis[idx.max(axis=0)] + 2 * step
    spacing = (hi - lo).max() / resolution
    counts = np.ceil((hi - lo) / spacing).astype(int) + 1
    axes = [lo[i] + spacing * np.arange(counts[i]) for i in range(3)]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    values = field(pts).reshape(*counts)
    if (values[0] < 0).any() or (values[-1] < 0).any() or (values[:, 0] < 0).any() or (
        values[:, -1] < 0).any() or (values[:, :, 0] < 0).any() or (values[:, :, -1] < 0).any():
        raise ValueError("the implicit shape touches its fine grid; enlarge the margin")
    verts, faces, _, _ = marching_cubes(values, level=0.0, spacing=(spacing,) * 3)
    mesh = trimesh.Trimesh(verts + lo, faces, process=True)
    mesh.remove_unreferenced_vertices()
    if mesh.volume < 0:
        mesh.invert()
    if not mesh.is_watertight:
        raise ValueError("marching cubes gave a mesh that is not watertight")
    # Keep the largest closed component: noise can pinch off specks.
    parts = mesh.split(only_watertight=True)
    if len(parts) > 1:
        mesh = max(parts, key=lambda m: m.volume)
    return mesh


def scale_to_volume(mesh: trimesh.Trimesh, volume_ml: float) -> trimesh.Trimesh:
    """Scale uniformly so the mesh's volume is ``volume_ml`` millilitres (mesh in metres).

    The result rests on z = 0 with its bounding box centred over the origin.
    """
    target_m3 = volume_ml * 1e-6
    out = mesh.copy()
    out.apply_scale((target_m3 / out.volume) ** (1.0 / 3.0))
    lo, hi = out.bounds
    out.apply_translation([-(lo[0] + hi[0]) / 2, -(lo[1] + hi[1]) / 2, -lo[2]])
    return out


@lru_cache(maxsize=32)
def _item_mesh_cached(name: str, resolution: int) -> trimesh.Trimesh:
    spec = ITEMS[name]
    field = perturbed(spec.field, stable_seed(name), spec.bump, spec.roughness)
    mesh = mesh_field(field, spec.extent, resolution)
    if spec.settle_mm > 0:
        metres_per_unit = (spec.volume_ml * 1e-6 / mesh.volume) ** (1.0 / 3.0)
        cut_z = mesh.bounds[0, 2] + spec.settle_mm * 1e-3 / metres_per_unit
        mesh = mesh_field(flat_below(field, cut_z), spec.extent, resolution)
    return scale_to_volume(mesh, spec.volume_ml)


def flat_below(field: Field, cut_z: float) -> Field:
    """``field`` with everything below the plane z = ``cut_z`` removed: a flat underside."""
    return lambda p: np.maximum(field(p), cut_z - p[:, 2])


def item_mesh(name: str, resolution: int = 112) -> trimesh.Trimesh:
    """The benchmark item ``name`` as a watertight mesh in metres resting on z = 0.

    Deterministic: the item's noise seed comes from its name. A copy is returned.
    """
    if name not in ITEMS:
        raise UnknownNameError(f"unknown food item '{name}'; known items: {', '.join(ITEMS)}")
    return _item_mesh_cached(name, resolution).copy()
