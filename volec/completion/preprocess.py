"""Pre- and post-processing around the completion network (paper section III-C).

In: a metric partial cloud of one item in any frame. Out: the network's input (centred, scaled
into the unit sphere, PCA-aligned, resampled to a fixed count) and the :class:`Normalization`
that did it, whose exact inverse maps the network's output back into the input's frame;
and statistical outlier removal for the result.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from volec.errors import DataError


@dataclass(frozen=True, eq=False)
class Normalization:
    """``normalized = rotation @ (x - centre) / scale``, applied row-wise."""

    centre: np.ndarray
    """(3,) the cloud's centroid, input units."""
    scale: float
    """Distance of the farthest point from the centroid, input units."""
    rotation: np.ndarray
    """3x3 proper rotation whose rows are the principal axes (largest variance first)."""

    def apply(self, xyz: np.ndarray) -> np.ndarray:
        """Input frame -> normalized frame."""
        return (np.asarray(xyz, float) - self.centre) @ self.rotation.T / self.scale

    def invert(self, xyz: np.ndarray) -> np.ndarray:
        """Normalized frame -> input frame (the exact inverse of :meth:`apply`)."""
        return np.asarray(xyz, float) * self.scale @ self.rotation + self.centre


def _centred(xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """(centroid, the points less it, the farthest point's distance from it); a clear error
    for clouds that cannot be normalised."""
    xyz = np.asarray(xyz, float)
    if len(xyz) < 4:
        raise DataError(f"a cloud of {len(xyz)} points cannot be normalised; need 4 or more")
    centre = xyz.mean(axis=0)
    centred = xyz - centre
    scale = float(np.linalg.norm(centred, axis=1).max())
    if scale <= 0:
        raise DataError("all points coincide; the cloud has no extent")
    return centre, centred, scale


def fit_normalization(xyz: np.ndarray) -> Normalization:
    """Centre on the centroid, scale the farthest point to radius 1, rotate the principal axes
    onto x, y, z. Each axis's sign makes the cloud's third moment along it non-negative (and
    z completes a right-handed frame), so the same cloud always gets the same frame."""
    centre, centred, scale = _centred(xyz)
    _, vectors = np.linalg.eigh(centred.T @ centred)
    axes = vectors[:, ::-1].T.copy()  # rows, largest variance first
    for i in range(2):
        if np.sum((centred @ axes[i]) ** 3) < 0:
            axes[i] *= -1
    axes[2] = np.cross(axes[0], axes[1])
    return Normalization(centre, scale, axes)


def fit_upright_normalization(xyz: np.ndarray, up: np.ndarray) -> Normalization:
    """As :func:`fit_normalization`, but z is ``up`` (the support plane's normal) whatever the
    cloud's shape, and x the horizontal principal axis (its sign by the third moment), so a
    network sees where the table is: a round item's PCA frame is arbitrary, and with it
    which side is the unseen underside."""
    centre, centred, scale = _centred(xyz)
    z = np.asarray(up, float) / np.linalg.norm(up)
    flat = centred - np.outer(centred @ z, z)
    _, vectors = np.linalg.eigh(flat.T @ flat)
    x = vectors[:, -1] - (vectors[:, -1] @ z) * z
    x /= np.linalg.norm(x)
    if np.sum((centred @ x) ** 3) < 0:
        x = -x
    return Normalization(centre, scale, np.stack([x, np.cross(z, x), z]))


FRAMES = ("pca", "upright")
"""How a partial is framed for the network: by its own principal axes (the paper's), or
upright about the support plane's normal."""


def frame_needs_up(frame: str) -> bool:
    """Whether partials framed by ``frame`` need the support plane's normal."""
    return frame == "upright"


def frame_normalization(xyz: np.ndarray, frame: str, up: np.ndarray | None) -> Normalization:
    """The normalization of ``xyz`` in ``frame`` (one of :data:`FRAMES`); ``upright`` needs
    ``up``, the support plane's normal."""
    if frame == "pca":
        return fit_normalization(xyz)
    if frame not in FRAMES:
        raise DataError(f"unknown input frame {frame!r}; expected one of {', '.join(FRAMES)}")
    if up is None and frame_needs_up(frame):
        raise DataError("this completion checkpoint frames its input upright: it needs the "
                        "support plane's normal or the capture's up direction")
    return fit_upright_normalization(xyz, up)


def resample(xyz: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """Exactly ``n`` points: a uniform random subset, or every point plus random repeats."""
    xyz = np.asarray(xyz, float)
    if len(xyz) == 0:
        raise DataError("cannot resample an empty cloud")
    if len(xyz) >= n:
        return xyz[rng.choice(len(xyz), n, replace=False)]
    extra = rng.choice(len(xyz), n - len(xyz), replace=True)
    return np.concatenate([xyz, xyz[extra]])


def remove_statistical_outliers(xyz: np.ndarray, neighbours: int = 16,
                                std_ratio: float = 2.0) -> np.ndarray:
    """Points whose mean distance to their ``neighbours`` nearest is within ``std_ratio``
    standard deviations of the cloud's average (open3d's statistical outlier removal)."""
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(xyz, float)))
    _, kept = pcd.remove_statistical_outlier(nb_neighbors=neighbours, std_ratio=std_ratio)
    return np.asarray(xyz, float)[np.sort(np.asarray(kept, int))]
