"""Seeded solid (3D) value noise for shape irregularity and surface texture.

In: (N, 3) points and a frequency in cycles per unit. Out: (N,) values in [0, 1].
A random periodic lattice sampled with trilinear interpolation; octaves are summed for
fractal noise. Solid noise keeps a texture fixed to the surface from every viewpoint,
which is what multi-view matching needs.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import map_coordinates


class SolidNoise:
    """Periodic 3D value noise on a ``size``^3 lattice, deterministic for a seed."""

    def __init__(self, seed: int, size: int = 48) -> None:
        rng = np.random.default_rng(seed)
        self.size = size
        self.lattice = rng.random((size, size, size))
        # A random rotation and offset per octave hides the lattice axes.
        self._rotations = [_random_rotation(rng) for _ in range(8)]
        self._offsets = rng.random((8, 3)) * size

    def value(self, points: np.ndarray, frequency: float, octave: int = 0) -> np.ndarray:
        """One octave: values in [0, 1] at ``points * frequency`` lattice cells."""
        # einsum, not @: a BLAS call here would start threads that fight the worker processes.
        q = np.einsum("ij,kj->ik", np.asarray(points, float), self._rotations[octave % 8])
        q *= frequency
        q += self._offsets[octave % 8]
        return map_coordinates(self.lattice, q.T, order=1, mode="grid-wrap")

    def fractal(
        self, points: np.ndarray, frequency: float, octaves: int = 3, gain: float = 0.5
    ) -> np.ndarray:
        """Sum of octaves (each twice the frequency, ``gain`` times the amplitude), in [0, 1]."""
        total = np.zeros(len(points))
        amp, norm = 1.0, 0.0
        for o in range(octaves):
            total += amp * self.value(points, frequency * 2.0**o, octave=o)
            norm += amp
            amp *= gain
        return total / norm


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def smoothstep(edge0: float, edge1: float, x: np.ndarray) -> np.ndarray:
    """Hermite step from 0 at ``edge0`` to 1 at ``edge1``."""
    t = np.clip((x - edge0) / (edge1 - edge0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)
