"""Training shapes for completion: food kinds that are not benchmark items, with random sizes.

In: a family name and a seed (or a count and a base seed). Out: a watertight ``trimesh.Trimesh``
in metres resting on z = 0, like :func:`volec.synth.shapes.item_mesh`, with a random volume.

The 21 benchmark items must stay unseen by the completion network, so these are other kinds
(egg, tomato, potato, muffin, loaf, cookie, roll, carrot, strawberry, mango, peach, dumpling,
brownie, onion, kiwi, plum, sweet potato, cucumber, eggplant, scone, meatball, croquette, sushi
roll, macaron, mushroom, radish, pineapple ring, onigiri, sausage, drumstick: 30 kinds, as
the paper trains on 30 MetaFood3D objects) whose proportions are drawn at random per shape;
each is perturbed by its own solid noise. A shape is named ``FAMILY-SEED``; the same name gives
the same mesh everywhere.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import trimesh

from volec.errors import UnknownNameError
from volec.synth.shapes import (
    Field,
    _ellipsoid,
    _rho_theta,
    _smax,
    _smin,
    _tube,
    mesh_field,
    perturbed,
    scale_to_volume,
    stable_seed,
)

#: A family: random generator -> (implicit field in canonical units, bounding half-extent).
Family = Callable[[np.random.Generator], tuple[Field, float]]


def _egg(rng: np.random.Generator) -> tuple[Field, float]:
    a, taper = rng.uniform(1.15, 1.45), rng.uniform(0.1, 0.25)

    def f(p: np.ndarray) -> np.ndarray:
        k = 1.0 - taper * np.clip(p[:, 0] / a, -1, 1)
        q = np.stack([p[:, 0] / a, p[:, 1] / k, p[:, 2] / k], axis=1)
        return (np.linalg.norm(q, axis=1) - 1.0) * 0.8

    return f, a + 0.5


def _tomato(rng: np.random.Generator) -> tuple[Field, float]:
    lobes, depth, flat = int(rng.integers(4, 8)), rng.uniform(0.02, 0.07), rng.uniform(0.7, 0.85)

    def f(p: np.ndarray) -> np.ndarray:
        _, theta = _rho_theta(p)
        r = 1.0 + depth * np.cos(lobes * theta)
        q = np.stack([p[:, 0] / r, p[:, 1] / r, p[:, 2] / flat], axis=1)
        return (np.linalg.norm(q, axis=1) - 1.0) * flat

    return f, 1.4


def _potato(rng: np.random.Generator) -> tuple[Field, float]:
    radii = (rng.uniform(1.2, 1.7), rng.uniform(0.8, 1.0), rng.uniform(0.55, 0.8))
    return (lambda p: _ellipsoid(p, radii)), radii[0] + 0.5


def _muffin(rng: np.random.Generator) -> tuple[Field, float]:
    base_r, height, cap = rng.uniform(0.8, 1.0), rng.uniform(0.6, 0.9), rng.uniform(1.05, 1.25)

    def f(p: np.ndarray) -> np.ndarray:
        rho, _ = _rho_theta(p)
        flare = base_r * (1.0 + 0.15 * np.clip(p[:, 2] / height, 0, 1))
        cup = np.maximum(rho - flare, np.abs(p[:, 2] - height / 2) - height / 2)
        top = _ellipsoid(p - np.array([0.0, 0.0, height]), (cap, cap, 0.55 * cap))
        return _smin(cup, _smax(top, -(p[:, 2] - height * 0.9), 0.05), 0.1)

    return f, 1.9


def _loaf(rng: np.random.Generator) -> tuple[Field, float]:
    half = np.array([rng.uniform(1.3, 2.0), rng.uniform(0.7, 0.9), rng.uniform(0.5, 0.75)])
    round_k = rng.uniform(0.25, 0.45)

    def f(p: np.ndarray) -> np.ndarray:
        q = np.abs(p) - (half - round_k)
        outside = np.linalg.norm(np.maximum(q, 0), axis=1)
        return outside + np.minimum(q.max(axis=1), 0) - round_k

    return f, half[0] + 0.6


def _cookie(rng: np.random.Generator) -> tuple[Field, float]:
    radius, thick = rng.uniform(1.0, 1.3), rng.uniform(0.18, 0.32)

    def f(p: np.ndarray) -> np.ndarray:
        rho, _ = _rho_theta(p)
        return np.hypot(np.maximum(rho - radius, 0), np.maximum(np.abs(p[:, 2]) - thick, 0)) + \
            np.minimum(np.maximum(rho - radius, np.abs(p[:, 2]) - thick), 0) - 0.08

    return f, radius + 0.5


def _roll(rng: np.random.Generator) -> tuple[Field, float]:
    half_len, radius = rng.uniform(0.6, 1.4), rng.uniform(0.6, 0.9)

    def f(p: np.ndarray) -> np.ndarray:
        rho = np.hypot(p[:, 1], p[:, 2])
        a, b = rho - radius, np.abs(p[:, 0]) - half_len
        return np.hypot(np.maximum(a, 0), np.maximum(b, 0)) + np.minimum(np.maximum(a, b), 0) - 0.05

    return f, max(half_len, radius) + 0.5


def _carrot(rng: np.random.Generator) -> tuple[Field, float]:
    length, r0, bend = rng.uniform(2.2, 3.0), rng.uniform(0.3, 0.45), rng.uniform(0.0, 0.3)
    t = np.linspace(0.0, 1.0, 300)
    centre = np.stack([length * (t - 0.5), bend * (t - 0.5) ** 2, np.zeros_like(t)], axis=1)
    radius = r0 * (1.0 - 0.85 * t) + 0.03
    return (lambda p: _tube(p, centre, radius)), length / 2 + 0.7


def _strawberry(rng: np.random.Generator) -> tuple[Field, float]:
    length, width = rng.uniform(1.1, 1.5), rng.uniform(0.8, 1.0)

    def f(p: np.ndarray) -> np.ndarray:
        # a cone-like body along -z, rounded at the shoulders
        z = p[:, 2] / length
        rho, _ = _rho_theta(p)
        r = width * np.sqrt(np.clip((z + 1.0) * (1.2 - z), 0, None)) * 0.85
        return np.maximum(rho - r, np.abs(p[:, 2] - 0.1 * length) - 1.05 * length) * 0.8

    return f, 2.0


def _mango(rng: np.random.Generator) -> tuple[Field, float]:
    a, b, c, lean = rng.uniform(1.2, 1.5), rng.uniform(0.8, 1.0), rng.uniform(0.6, 0.75), \
        rng.uniform(0.1, 0.3)

    def f(p: np.ndarray) -> np.ndarray:
        q = p.copy()
        q[:, 1] -= lean * (p[:, 0] / a) ** 2
        return _ellipsoid(q, (a, b, c))

    return f, a + 0.6


def _peach(rng: np.random.Generator) -> tuple[Field, float]:
    groove, r = rng.uniform(0.05, 0.12), rng.uniform(0.95, 1.05)

    def f(p: np.ndarray) -> np.ndarray:
        d = np.linalg.norm(p, axis=1) - r
        return d + groove * np.exp(-(p[:, 1] ** 2) / 0.02) * (p[:, 2] > -0.5)

    return f, 1.5


def _dumpling(rng: np.random.Generator) -> tuple[Field, float]:
    radius, height, ridge = rng.uniform(1.1, 1.4), rng.uniform(0.45, 0.65), rng.uniform(0.1, 0.2)

    def f(p: np.ndarray) -> np.ndarray:
        # a half-disc pillow with a crimped ridge along its straight top edge
        body = _ellipsoid(p - np.array([0.0, 0.0, 0.0]), (radius, 0.6 * radius, height))
        crest = np.hypot(p[:, 1], p[:, 2] - height * 0.9) - ridge
        crest = np.maximum(crest, np.abs(p[:, 0]) - 0.85 * radius)
        return _smin(body, crest, 0.15)

    return f, radius + 0.6


def _brownie(rng: np.random.Generator) -> tuple[Field, float]:
    half = np.array([rng.uniform(0.8, 1.2), rng.uniform(0.8, 1.2), rng.uniform(0.35, 0.5)])

    def f(p: np.ndarray) -> np.ndarray:
        q = np.abs(p) - (half - 0.08)
        return np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0) - 0.08

    return f, max(half) + 0.5


def _onion(rng: np.random.Generator) -> tuple[Field, float]:
    flat, tip = rng.uniform(0.75, 0.95), rng.uniform(0.2, 0.4)

    def f(p: np.ndarray) -> np.ndarray:
        body = _ellipsoid(p, (1.0, 1.0, flat))
        rho, _ = _rho_theta(p)
        neck = np.maximum(rho - 0.12 - 0.1 * np.clip(1.0 - (p[:, 2] - flat) / tip, 0, 1),
                          np.abs(p[:, 2] - flat) - tip)
        return _smin(body, neck, 0.2)

    return f, 1.6


def _segment_distance_x(p: np.ndarray, half_length: float) -> np.ndarray:
    """Distance of ``p`` (N, 3) to the segment from -``half_length`` to ``half_length`` on
    the x axis."""
    on_axis = np.zeros_like(p)
    on_axis[:, 0] = np.clip(p[:, 0], -half_length, half_length)
    return np.linalg.norm(p - on_axis, axis=1)


def _kiwi(rng: np.random.Generator) -> tuple[Field, float]:
    radii = (rng.uniform(1.15, 1.35), rng.uniform(0.85, 0.95), rng.uniform(0.8, 0.9))
    return (lambda p: _ellipsoid(p, radii)), radii[0] + 0.5


def _plum(rng: np.random.Generator) -> tuple[Field, float]:
    tall, groove = rng.uniform(1.0, 1.2), rng.uniform(0.03, 0.08)

    def f(p: np.ndarray) -> np.ndarray:
        d = _ellipsoid(p, (0.95, 0.9, tall))
        return d + groove * np.exp(-(p[:, 0] ** 2) / 0.015) * (p[:, 1] > 0)

    return f, tall + 0.5


def _sweet_potato(rng: np.random.Generator) -> tuple[Field, float]:
    length, r0, bend = rng.uniform(2.0, 2.8), rng.uniform(0.5, 0.7), rng.uniform(-0.3, 0.3)
    t = np.linspace(-1.0, 1.0, 300)
    centre = np.stack([length / 2 * t, bend * t**2, np.zeros_like(t)], axis=1)
    radius = r0 * np.sqrt(np.clip(1.0 - t**2, 0.0, 1.0)) * (1.0 - 0.2 * t) + 0.05
    return (lambda p: _tube(p, centre, radius)), length / 2 + r0 + 0.5


def _cucumber(rng: np.random.Generator) -> tuple[Field, float]:
    half, radius = rng.uniform(1.6, 2.4), rng.uniform(0.35, 0.5)

    def f(p: np.ndarray) -> np.ndarray:
        taper = 1.0 - 0.1 * (p[:, 0] / half) ** 2
        return _segment_distance_x(p, half) - radius * np.clip(taper, 0.8, 1.0)

    return f, half + radius + 0.5


def _eggplant(rng: np.random.Generator) -> tuple[Field, float]:
    length, bulb, neck = rng.uniform(2.0, 2.6), rng.uniform(0.6, 0.8), rng.uniform(0.3, 0.4)
    t = np.linspace(0.0, 1.0, 300)
    centre = np.stack([length * (t - 0.5), 0.2 * np.sin(np.pi * t), np.zeros_like(t)], axis=1)
    widening = np.clip(t / 0.7, 0.0, 1.0)
    radius = neck + (bulb - neck) * widening**2 * (3 - 2 * widening)  # a smooth step
    radius = radius * np.sqrt(np.clip(1.0 - (2 * t - 1) ** 6, 0.05, 1.0))  # rounded ends
    return (lambda p: _tube(p, centre, radius)), length / 2 + bulb + 0.5


def _scone(rng: np.random.Generator) -> tuple[Field, float]:
    radius, height, dome = rng.uniform(0.9, 1.1), rng.uniform(0.6, 0.9), rng.uniform(0.1, 0.25)

    def f(p: np.ndarray) -> np.ndarray:
        rho, _ = _rho_theta(p)
        top = height + dome * (1.0 - np.clip(rho / radius, 0, 1) ** 2)
        return _smax(_smax(rho - radius, p[:, 2] - top, 0.15), -p[:, 2], 0.06)

    return f, max(radius, height + dome) + 0.5


def _meatball(rng: np.random.Generator) -> tuple[Field, float]:
    flat = rng.uniform(0.75, 0.9)
    return (lambda p: _smax(_ellipsoid(p, (1.0, 1.0, flat)), -p[:, 2] - 0.8 * flat, 0.1)), 1.5


def _croquette(rng: np.random.Generator) -> tuple[Field, float]:
    half, radius = rng.uniform(0.7, 1.1), rng.uniform(0.45, 0.6)

    def f(p: np.ndarray) -> np.ndarray:
        return _segment_distance_x(p, half) - radius

    return f, half + radius + 0.5


def _sushi_roll(rng: np.random.Generator) -> tuple[Field, float]:
    radius, half_height = rng.uniform(0.8, 1.0), rng.uniform(0.35, 0.5)

    def f(p: np.ndarray) -> np.ndarray:
        rho, _ = _rho_theta(p)
        return _smax(rho - radius, np.abs(p[:, 2]) - half_height, 0.05)

    return f, radius + 0.5


def _macaron(rng: np.random.Generator) -> tuple[Field, float]:
    radius, shell = rng.uniform(0.9, 1.1), rng.uniform(0.22, 0.3)

    def f(p: np.ndarray) -> np.ndarray:
        rho, _ = _rho_theta(p)
        shells = [_ellipsoid(p - np.array([0.0, 0.0, s * 0.55 * shell]), (radius, radius, shell))
                  for s in (-1, 1)]
        filling = _smax(rho - 0.85 * radius, np.abs(p[:, 2]) - 0.3 * shell, 0.05)
        return _smin(_smin(shells[0], shells[1], 0.05), filling, 0.05)

    return f, radius + 0.5


def _mushroom(rng: np.random.Generator) -> tuple[Field, float]:
    cap, stem, stem_h = rng.uniform(0.9, 1.2), rng.uniform(0.25, 0.35), rng.uniform(0.4, 0.7)

    def f(p: np.ndarray) -> np.ndarray:
        rho, _ = _rho_theta(p)
        head = _smax(_ellipsoid(p - np.array([0.0, 0.0, stem_h]), (cap, cap, 0.6 * cap)),
                     stem_h - p[:, 2], 0.1)
        column = _smax(rho - stem, np.abs(p[:, 2] - stem_h / 2) - stem_h / 2, 0.05)
        return _smin(head, column, 0.12)

    return f, cap + 0.6


def _radish(rng: np.random.Generator) -> tuple[Field, float]:
    radius, tail = rng.uniform(0.8, 1.0), rng.uniform(0.6, 1.0)
    t = np.linspace(0.0, 1.0, 200)
    centre = np.stack([radius * 0.8 + tail * t, np.zeros_like(t), np.zeros_like(t)], axis=1)
    taper = 0.35 * radius * (1.0 - t) + 0.03

    def f(p: np.ndarray) -> np.ndarray:
        body = np.linalg.norm(p, axis=1) - radius
        return _smin(body, _tube(p, centre, taper), 0.2)

    return f, radius + tail + 0.6


def _pineapple_ring(rng: np.random.Generator) -> tuple[Field, float]:
    outer, inner, half = rng.uniform(1.1, 1.4), rng.uniform(0.25, 0.4), rng.uniform(0.2, 0.3)

    def f(p: np.ndarray) -> np.ndarray:
        rho, _ = _rho_theta(p)
        ring = np.maximum(rho - outer, inner - rho)
        return _smax(ring, np.abs(p[:, 2]) - half, 0.05)

    return f, outer + 0.5


def _onigiri(rng: np.random.Generator) -> tuple[Field, float]:
    size, half = rng.uniform(1.0, 1.2), rng.uniform(0.35, 0.5)
    normals = np.array([[np.cos(a), np.sin(a)] for a in np.radians([270.0, 30.0, 150.0])])

    def f(p: np.ndarray) -> np.ndarray:
        # a rounded triangle standing on one side, about y: its faces are the triangle's sides
        xz = np.stack([p[:, 0], p[:, 2]], axis=1)
        sides = xz @ normals.T - 0.5 * size
        k = 0.25
        triangle = k * np.log(np.exp(sides / k).sum(axis=1))
        return _smax(triangle, np.abs(p[:, 1]) - half, 0.15)

    return f, size + 0.6


def _sausage(rng: np.random.Generator) -> tuple[Field, float]:
    length, radius, bend = rng.uniform(2.2, 3.0), rng.uniform(0.25, 0.35), rng.uniform(0.2, 0.6)
    t = np.linspace(-1.0, 1.0, 300)
    centre = np.stack([length / 2 * t, bend * (1 - t**2), np.zeros_like(t)], axis=1)
    radius_t = radius * np.sqrt(np.clip(1.0 - t**10, 0.05, 1.0))
    return (lambda p: _tube(p, centre, radius_t)), length / 2 + radius + 0.6


def _drumstick(rng: np.random.Generator) -> tuple[Field, float]:
    length, bulb, bone = rng.uniform(2.0, 2.6), rng.uniform(0.55, 0.7), rng.uniform(0.15, 0.2)
    t = np.linspace(0.0, 1.0, 300)
    centre = np.stack([length * (t - 0.5), np.zeros_like(t), np.zeros_like(t)], axis=1)
    radius = bone + (bulb - bone) * np.sin(np.pi * np.clip(t / 0.75, 0, 1)) ** 0.7 * (t < 0.75)
    radius = np.maximum(radius, bone)
    return (lambda p: _tube(p, centre, radius)), length / 2 + bulb + 0.5


FAMILIES: dict[str, Family] = {
    "egg": _egg, "tomato": _tomato, "potato": _potato, "muffin": _muffin, "loaf": _loaf,
    "cookie": _cookie, "roll": _roll, "carrot": _carrot, "strawberry": _strawberry,
    "mango": _mango, "peach": _peach, "dumpling": _dumpling, "brownie": _brownie,
    "onion": _onion, "kiwi": _kiwi, "plum": _plum, "sweet_potato": _sweet_potato,
    "cucumber": _cucumber, "eggplant": _eggplant, "scone": _scone, "meatball": _meatball,
    "croquette": _croquette, "sushi_roll": _sushi_roll, "macaron": _macaron,
    "mushroom": _mushroom, "radish": _radish, "pineapple_ring": _pineapple_ring,
    "onigiri": _onigiri, "sausage": _sausage, "drumstick": _drumstick,
}
"""Training shape families (none of them a benchmark item)."""


def family_mesh(name: str, seed: int, resolution: int = 72) -> trimesh.Trimesh:
    """The shape ``FAMILY-SEED``: random proportions, orientation about z, noise and volume
    (30-400 mL, log-uniform), as a watertight mesh in metres resting on z = 0."""
    if name not in FAMILIES:
        raise UnknownNameError(f"unknown shape family '{name}'; known: {', '.join(FAMILIES)}")
    rng = np.random.default_rng(stable_seed(f"{name}-{seed}"))
    field, extent = FAMILIES[name](rng)
    bump, rough = rng.uniform(0.02, 0.06), rng.uniform(0.004, 0.015)
    mesh = mesh_field(perturbed(field, int(rng.integers(2**31)), bump, rough), extent, resolution)
    mesh.apply_transform(trimesh.transformations.rotation_matrix(rng.uniform(0, 2 * np.pi),
                                                                 [0, 0, 1]))
    volume_ml = float(np.exp(rng.uniform(np.log(30.0), np.log(400.0))))
    return scale_to_volume(mesh, volume_ml)


def training_shapes(per_family: int, first_seed: int = 0,
                    families: list[str] | None = None) -> list[tuple[str, int]]:
    """(family, seed) pairs: ``per_family`` seeds per family (all families, or ``families``),
    from ``first_seed`` on."""
    names = families or list(FAMILIES)
    unknown = set(names) - set(FAMILIES)
    if unknown:
        raise UnknownNameError(f"unknown shape families: {', '.join(sorted(unknown))}")
    return [(f, s) for f in names for s in range(first_seed, first_seed + per_family)]
