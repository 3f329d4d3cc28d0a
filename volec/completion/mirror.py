"""The non-learned baseline: reflective symmetry completion.

In: a partial cloud (any frame, metres) and a :class:`MirrorConfig`. Out: the best mirror
plane of the cloud and the completed cloud (the partial plus its reflection). Optionally,
given the up direction, reflected points below the support plane (the lowest partial point:
food rests on a table) are dropped.

The plane is searched in the normalized frame (:mod:`volec.completion.preprocess`): candidate
normals spread over a hemisphere, offsets across the cloud, each scored by the mean
nearest-neighbour distance of the reflected points to the cloud, truncated at a couple of
point spacings (a reflection that lands in the missing part costs a constant; so does one
that lands near but not on the seen surface); the best is refined locally.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from volec.completion.preprocess import fit_normalization


@dataclass(frozen=True)
class MirrorConfig:
    """Search options of the mirror baseline (distances in normalized units: radius 1)."""

    n_directions: int = 200
    """Candidate plane normals on the hemisphere."""
    n_offsets: int = 11
    """Candidate offsets per normal, between the 10th and 90th percentile of the cloud."""
    n_sample: int = 512
    """Points of the cloud used to score a plane."""
    inlier_spacings: float = 2.0
    """Distances are truncated at this many point spacings (the cloud's median
    nearest-neighbour distance) when scoring: a plane must map points onto the surface, not
    near it."""
    n_refined: int = 8
    """The best this-many grid planes are refined locally..."""
    refine_rounds: int = 3
    """... in this many rounds of random perturbations, each round half as wide."""
    seed: int = 0
    """Seeds the scoring subsample."""


def _fibonacci_hemisphere(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    z = i / n  # upper hemisphere: a plane and its flip are the same
    phi = np.pi * (1 + 5**0.5) * i
    r = np.sqrt(1 - z**2)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def reflect(xyz: np.ndarray, normal: np.ndarray, offset: float) -> np.ndarray:
    """Mirror images of ``xyz`` in the plane ``normal . x = offset`` (unit normal)."""
    return xyz - 2.0 * (xyz @ normal - offset)[:, None] * normal


def plane_score(tree: cKDTree, sample: np.ndarray, normal: np.ndarray, offset: float,
                radius: float) -> float:
    """Mean truncated distance from the reflected sample to the cloud (lower is better)."""
    d, _ = tree.query(reflect(sample, normal, offset), distance_upper_bound=radius)
    return float(np.minimum(d, radius).mean())


def fit_mirror_plane(xyz: np.ndarray, cfg: MirrorConfig | None = None
                     ) -> tuple[np.ndarray, float]:
    """(unit normal, offset) of the best mirror plane of ``xyz``, in ``xyz``'s frame."""
    cfg = cfg or MirrorConfig()
    norm = fit_normalization(xyz)
    pts = norm.apply(xyz)
    rng = np.random.default_rng(cfg.seed)
    sample = pts[rng.choice(len(pts), min(cfg.n_sample, len(pts)), replace=False)]
    tree = cKDTree(pts)
    spacing = float(np.median(tree.query(sample, k=2)[0][:, 1]))
    radius = cfg.inlier_spacings * spacing
    candidates = []
    for normal in _fibonacci_hemisphere(cfg.n_directions):
        proj = pts @ normal
        for offset in np.linspace(*np.percentile(proj, [10, 90]), cfg.n_offsets):
            candidates.append((plane_score(tree, sample, normal, offset, radius), normal, offset))
    candidates.sort(key=lambda c: c[0])
    # The grid is coarse (about 10 degrees between normals) and a true plane's basin can be
    # narrower on elongated items: refine several of the best, keep the best refined.
    best = candidates[0]
    for start in candidates[: cfg.n_refined]:
        current = start
        step_rad, step_off = 0.1, 0.05
        for _ in range(cfg.refine_rounds):
            _, n0, o0 = current
            for _ in range(30):
                n = n0 + rng.normal(scale=step_rad, size=3)
                n /= np.linalg.norm(n)
                o = o0 + rng.normal(scale=step_off)
                score = plane_score(tree, sample, n, o, radius)
                if score < current[0]:
                    current = (score, n, o)
            step_rad, step_off = step_rad / 2, step_off / 2
        if current[0] < best[0]:
            best = current
    _, n_norm, o_norm = best
    # Back to the input frame: normal . (R (x - c) / s) = o  <=>  (R^T n) . x = o s + (R^T n).c
    normal = norm.rotation.T @ n_norm
    return normal, float(o_norm * norm.scale + normal @ norm.centre)


def mirrored_points(xyz: np.ndarray, cfg: MirrorConfig | None = None,
                    up: np.ndarray | None = None, fit_xyz: np.ndarray | None = None
                    ) -> np.ndarray:
    """The reflection of ``xyz`` in the best mirror plane of ``fit_xyz`` (default: ``xyz``
    itself; a subsample fits faster); with ``up``, the reflected points below the lowest
    point of ``xyz`` along ``up`` are dropped."""
    xyz = np.asarray(xyz, float)
    normal, offset = fit_mirror_plane(xyz if fit_xyz is None else fit_xyz, cfg)
    mirrored = reflect(xyz, normal, offset)
    if up is not None:
        up = np.asarray(up, float) / np.linalg.norm(up)
        mirrored = mirrored[mirrored @ up >= (xyz @ up).min()]
    return mirrored


def mirror_complete(xyz: np.ndarray, cfg: MirrorConfig | None = None,
                    up: np.ndarray | None = None) -> np.ndarray:
    """The partial ``xyz`` plus its reflection in its best mirror plane; with ``up``, the
    reflected points below the lowest partial point along ``up`` are dropped."""
    xyz = np.asarray(xyz, float)
    return np.concatenate([xyz, mirrored_points(xyz, cfg, up)])
