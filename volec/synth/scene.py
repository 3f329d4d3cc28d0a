"""A food item on a plate on a table, with solid textures, for rendering.

In: a food mesh in metres resting on z = 0 (from :mod:`volec.synth.shapes`), an item name for
its colours, and a seed. Out: a :class:`Scene` (scene frame: z up, plate top at z = 0) holding
one combined mesh with a per-face object label, and the colour function of each object.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh

from volec.synth.noise import SolidNoise, smoothstep

TABLE, PLATE, FOOD, OTHER = 0, 1, 2, 3
"""Object labels stored per face of :attr:`Scene.mesh` (``OTHER``: a cup or a fork)."""

PLATE_THICKNESS_M = 0.012


@dataclass(frozen=True)
class Palette:
    """Colours (linear RGB in [0, 1]) and texture scales of one surface."""

    base: tuple[float, float, float]
    """Main colour."""
    second: tuple[float, float, float]
    """Colour mixed in by low-frequency noise (blotches, ripeness)."""
    speckle: tuple[float, float, float]
    """Colour of small spots (seeds, pores, crumbs)."""
    blotch_size_m: float = 0.015
    """Typical size of the blotches, metres."""
    detail_size_m: float = 0.0025
    """Typical size of the fine grain that feature detectors lock on to, metres."""
    speckle_density: float = 0.12
    """Fraction of the surface covered by speckles."""
    top: tuple[float, float, float] | None = None
    """Colour of upward-facing surface (icing, crust, chocolate), or None."""
    grain: float = 1.0
    """Contrast of the fine grain and the speckles relative to the others (smooth, glossy
    skins below 1)."""


FOOD_PALETTES: dict[str, Palette] = {
    "apple": Palette((0.55, 0.05, 0.04), (0.75, 0.55, 0.1), (0.9, 0.8, 0.45), 0.02, grain=0.7),
    "orange": Palette((0.9, 0.42, 0.04), (0.95, 0.55, 0.1), (0.7, 0.3, 0.02), 0.02, grain=0.8),
    "avocado": Palette((0.08, 0.14, 0.04), (0.18, 0.22, 0.06), (0.35, 0.38, 0.15), 0.01),
    "lemon": Palette((0.9, 0.8, 0.12), (0.8, 0.75, 0.2), (0.6, 0.55, 0.05), 0.02, grain=0.8),
    "donut": Palette((0.7, 0.42, 0.18), (0.55, 0.3, 0.12), (0.95, 0.9, 0.8), 0.015,
                     top=(0.28, 0.14, 0.07)),
    "durum": Palette((0.85, 0.72, 0.5), (0.65, 0.45, 0.25), (0.45, 0.3, 0.15), 0.012),
    "pear": Palette((0.55, 0.6, 0.12), (0.7, 0.55, 0.15), (0.35, 0.3, 0.1), 0.02, grain=0.8),
    "chocolate_cake": Palette((0.2, 0.1, 0.05), (0.3, 0.16, 0.08), (0.55, 0.4, 0.3), 0.01,
                              top=(0.12, 0.06, 0.03)),
    "chocolate_croissant": Palette((0.72, 0.42, 0.14), (0.5, 0.26, 0.08), (0.9, 0.75, 0.5),
                                   0.012),
    "samosa": Palette((0.78, 0.55, 0.22), (0.6, 0.38, 0.12), (0.35, 0.2, 0.08), 0.012),
    "apple_pie": Palette((0.8, 0.58, 0.3), (0.6, 0.38, 0.15), (0.95, 0.85, 0.6), 0.012,
                         top=(0.68, 0.42, 0.16)),
    "chocolate_bomb": Palette((0.18, 0.09, 0.05), (0.3, 0.18, 0.1), (0.75, 0.65, 0.5), 0.015,
                              grain=0.5),
    "empanadilla": Palette((0.82, 0.6, 0.28), (0.65, 0.42, 0.16), (0.4, 0.25, 0.1), 0.012),
    "falafel": Palette((0.45, 0.3, 0.12), (0.3, 0.2, 0.08), (0.25, 0.35, 0.1), 0.006),
    "french_bread": Palette((0.82, 0.6, 0.3), (0.6, 0.38, 0.14), (0.95, 0.9, 0.75), 0.015),
    "paxoco_mini": Palette((0.75, 0.5, 0.22), (0.55, 0.32, 0.12), (0.95, 0.9, 0.8), 0.012),
    "napolitana": Palette((0.8, 0.55, 0.22), (0.55, 0.32, 0.1), (0.25, 0.12, 0.06), 0.012),
    "capsicum": Palette((0.7, 0.04, 0.03), (0.5, 0.05, 0.02), (0.9, 0.5, 0.4), 0.025, grain=0.5),
    "chocolate_panettone": Palette((0.62, 0.38, 0.15), (0.4, 0.22, 0.08), (0.15, 0.07, 0.04),
                                   0.015, top=(0.45, 0.25, 0.1)),
    "banana": Palette((0.88, 0.75, 0.12), (0.7, 0.62, 0.1), (0.3, 0.2, 0.05), 0.02,
                      speckle_density=0.08, grain=0.6),
    "yellow_cane": Palette((0.9, 0.72, 0.3), (0.7, 0.5, 0.2), (0.98, 0.95, 0.85), 0.015),
}

DEFAULT_FOOD_PALETTE = Palette((0.7, 0.5, 0.25), (0.5, 0.32, 0.12), (0.9, 0.8, 0.6), 0.015)


@dataclass(frozen=True)
class Setup:
    """What surrounds the food: the plate, a second object, where the food lies, the light.
    The default is the first benchmark's (a white plate with a blue printed rim, centred)."""

    plate: str = "blue_rim"
    """``blue_rim``, ``white`` (plain), ``dark`` (slate), ``checked`` (red and white squares)
    or ``like_food`` (the food's own colour)."""
    pale_food: bool = False
    """Make the food nearly white (white food on a white plate)."""
    food_offset: float = 0.0
    """How far off the plate's centre the food lies, as a share of the plate's radius (about
    0.85 puts it across the rim, partly on the table)."""
    second_object: str = "none"
    """``none``, ``cup`` (beside the plate) or ``fork`` (on the plate beside the food)."""
    light: float = 1.0
    """Scale of all light (0.6: dim, 1.5: bright)."""
    sun: float = 1.0
    """Scale of the directional light alone (2: strong cast shadows)."""


#: The hard setups of the segmentation benchmark; :func:`hard_setup` gives each item one.
HARD_SETUPS: dict[str, Setup] = {
    "white_on_white": Setup(plate="white", pale_food=True),
    "plate_like_food": Setup(plate="like_food"),
    "across_the_rim": Setup(food_offset=0.85),
    "strong_shadows": Setup(sun=2.2, light=0.8),
    "cup_beside": Setup(second_object="cup"),
    "fork_beside": Setup(second_object="fork", plate="dark"),
    "dim": Setup(light=0.55, plate="checked"),
    "bright": Setup(light=1.5),
}


def hard_setup(item: str) -> tuple[str, Setup]:
    """The hard setup of ``item``: the items take the setups of :data:`HARD_SETUPS` in turn,
    in the order of the benchmark's item list (every setup covers two or three items)."""
    from volec.synth.shapes import item_names

    names = list(HARD_SETUPS)
    name = names[item_names().index(item) % len(names)] if item in item_names() else names[0]
    return name, HARD_SETUPS[name]


@dataclass
class Scene:
    """Everything the renderer needs; built by :func:`build_scene`."""

    mesh: trimesh.Trimesh
    """Table, plate and food in one mesh (scene frame, metres, z up)."""
    face_label: np.ndarray
    """(F,) object label of each face: TABLE, PLATE or FOOD."""
    food_palette: Palette
    """Appearance of the food."""
    plate_radius_m: float
    """Radius of the plate, metres."""
    food: trimesh.Trimesh
    """The food alone, as placed in the scene (the ground-truth mesh)."""
    noise: SolidNoise = field(repr=False, default_factory=lambda: SolidNoise(0))
    """Texture noise (seeded)."""
    texture_contrast: float = 1.0
    """Scale of the food's fine grain and speckles (with the palette's own ``grain``)."""
    setup: Setup = field(default_factory=Setup)
    """The plate, a second object, the light."""

    def colour(self, label: int, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """Albedo (N, 3) of object ``label`` at world ``points`` with unit ``normals``."""
        if label == FOOD:
            c = _palette_colour(self.food_palette, self.noise, points, normals,
                                self.texture_contrast * self.food_palette.grain)
            return 0.25 * c + 0.75 * np.array([0.88, 0.86, 0.8]) if self.setup.pale_food else c
        if label == PLATE:
            centre = np.array([-self.setup.food_offset * self.plate_radius_m, 0.0, 0.0])
            return _plate_colour(self.noise, points - centre, self.plate_radius_m,
                                 self.setup.plate, self.food_palette)
        if label == OTHER:
            return _other_colour(self.noise, points, self.setup.second_object)
        return _table_colour(self.noise, points)


def _palette_colour(
    pal: Palette, noise: SolidNoise, p: np.ndarray, normals: np.ndarray, contrast: float = 1.0
) -> np.ndarray:
    blotch = smoothstep(0.35, 0.65, noise.fractal(p, 1.0 / pal.blotch_size_m, octaves=2))
    c = np.asarray(pal.base) * (1 - blotch[:, None]) + np.asarray(pal.second) * blotch[:, None]
    if pal.top is not None:
        upward = smoothstep(0.25, 0.5, normals[:, 2])[:, None]
        top = np.asarray(pal.top) * (0.85 + 0.3 * blotch[:, None])
        c = c * (1 - upward) + top * upward
    grain = noise.fractal(p, 1.0 / pal.detail_size_m, octaves=2)
    c = c * (1.0 - 0.3 * contrast + 0.6 * contrast * grain)[:, None]
    spots = noise.value(p, 0.5 / pal.detail_size_m, octave=6)
    speck = smoothstep(1.0 - pal.speckle_density, 1.0 - pal.speckle_density + 0.05, spots)
    mix = min(0.85 * contrast, 0.85) * speck[:, None]
    c = c * (1 - mix) + np.asarray(pal.speckle) * mix
    return np.clip(c, 0.0, 1.0)


def _plate_colour(noise: SolidNoise, p: np.ndarray, radius: float, style: str = "blue_rim",
                  food: Palette | None = None) -> np.ndarray:
    rho = np.hypot(p[:, 0], p[:, 1])
    theta = np.arctan2(p[:, 1], p[:, 0])
    base = {"dark": (0.12, 0.12, 0.13), "like_food": food.base if food else (0.5, 0.4, 0.3)
            }.get(style, (0.86, 0.85, 0.8))
    c = np.tile(np.asarray(base, float), (len(p), 1))
    c *= (0.93 + 0.07 * noise.value(p, 400.0, octave=3))[:, None]
    if style == "checked":
        squares = (np.floor(p[:, 0] / 0.015) + np.floor(p[:, 1] / 0.015)) % 2 == 0
        c[squares] = np.array([0.65, 0.1, 0.1]) * (0.93 + 0.07 * noise.value(
            p[squares], 400.0, octave=3))[:, None]
    if style != "blue_rim":
        return c
    # A printed rim: a blue band with a ring of flowers that give the matcher something.
    band = (rho > 0.78 * radius) & (rho < 0.95 * radius)
    flowers = np.cos(24 * theta) * np.cos(2 * np.pi * (rho / radius - 0.865) / 0.17) > 0.55
    c[band] = [0.2, 0.3, 0.6]
    c[band & flowers] = [0.85, 0.75, 0.2]
    speck = noise.value(p, 350.0, octave=4) > 0.8
    c[band & speck] *= 0.5
    return c


def _other_colour(noise: SolidNoise, p: np.ndarray, kind: str) -> np.ndarray:
    """A glazed white cup with a blue band, or a steel fork."""
    if kind == "fork":
        return np.tile([0.55, 0.56, 0.58], (len(p), 1)) * (
            0.9 + 0.1 * noise.value(p, 300.0, octave=5))[:, None]
    c = np.tile([0.9, 0.9, 0.88], (len(p), 1))
    band = np.abs(p[:, 2] - 0.045) < 0.008
    c[band] = [0.2, 0.3, 0.65]
    return c * (0.95 + 0.05 * noise.value(p, 300.0, octave=5))[:, None]


def _second_object(kind: str, plate_radius: float, food: trimesh.Trimesh
                   ) -> trimesh.Trimesh | None:
    """A cup standing on the table beside the plate, or a fork lying on the plate beside the
    food (scene frame, z up, the plate's top at z = 0)."""
    if kind == "cup":
        cup = trimesh.creation.cylinder(radius=0.038, height=0.085, sections=64)
        cup.apply_translation([plate_radius + 0.06, 0.04, -PLATE_THICKNESS_M + 0.0425])
        return cup
    if kind == "fork":
        fork = trimesh.creation.box(extents=[0.17, 0.014, 0.005])
        side = food.bounds[1, 1] + 0.02
        fork.apply_translation([0.0, min(side, 0.9 * plate_radius - 0.01), 0.0025])
        return fork
    return None


def _table_colour(noise: SolidNoise, p: np.ndarray) -> np.ndarray:
    # Wood: grain stretched along x, growth rings, dark knots.
    q = p * np.array([0.15, 1.0, 1.0])
    rings = np.sin(2 * np.pi * (p[:, 1] * 90 + 3.0 * noise.fractal(q, 20.0, octaves=2)))
    fine = noise.value(q, 600.0, octave=2)
    c = np.array([0.45, 0.27, 0.13]) * (0.8 + 0.15 * rings + 0.35 * (fine - 0.5))[:, None]
    knots = noise.value(p, 12.0, octave=7) > 0.9
    c[knots] *= 0.55
    return np.clip(c, 0.0, 1.0)


def build_scene(food: trimesh.Trimesh, item: str, seed: int, yaw_rad: float = 0.0,
                texture_contrast: float = 1.0, setup: Setup | None = None) -> Scene:
    """Put ``food`` (resting on z = 0) on a plate on a table, turned by ``yaw_rad``; the
    food's fine texture at ``texture_contrast`` (1: the first benchmark's); the plate, its
    place on it, a second object and the light as ``setup`` says. The food keeps resting on
    z = 0 (the plate's top) whatever the setup."""
    setup = setup or Setup()
    food = food.copy()
    food.apply_transform(trimesh.transformations.rotation_matrix(yaw_rad, [0, 0, 1]))
    lo, hi = food.bounds
    food.apply_translation([-(lo[0] + hi[0]) / 2, -(lo[1] + hi[1]) / 2, 0.0])
    footprint = float(np.hypot(*(food.bounds[1, :2] - food.bounds[0, :2])) / 2)
    plate_radius = float(np.clip(1.35 * footprint, 0.09, 0.16))
    plate = trimesh.creation.cylinder(radius=plate_radius, height=PLATE_THICKNESS_M, sections=160)
    plate.apply_translation([-setup.food_offset * plate_radius, 0, -PLATE_THICKNESS_M / 2])
    table = trimesh.creation.box(extents=[1.6, 1.6, 0.03])
    table.apply_translation([0.05, -0.1, -PLATE_THICKNESS_M - 0.015])
    parts = [table, plate, food]
    other = _second_object(setup.second_object, plate_radius, food)
    if other is not None:
        other.apply_translation([-setup.food_offset * plate_radius, 0, 0])
        parts.append(other)
    labels = np.concatenate([np.full(len(m.faces), lab) for lab, m in enumerate(parts)])
    mesh = trimesh.util.concatenate(parts)
    return Scene(
        mesh=mesh,
        face_label=labels.astype(np.int8),
        food_palette=FOOD_PALETTES.get(item, DEFAULT_FOOD_PALETTE),
        plate_radius_m=plate_radius,
        food=food,
        noise=SolidNoise(seed),
        texture_contrast=texture_contrast,
        setup=setup,
    )
