"""Small rigid-geometry helpers shared by the stages.

In: 4x4 homogeneous transforms and 3-vectors as numpy float64 arrays (metres, radians).
Out: the same. Cameras inside volec are OpenCV-style (x right, y down, z forward);
``T_a_from_b`` maps points in frame b to frame a.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

# Flips camera y and z: OpenGL/Blender camera axes (y up, z back) <-> OpenCV (y down, z forward).
GL_FROM_CV = np.diag([1.0, -1.0, -1.0, 1.0])


def opengl_c2w_to_opencv(T_world_from_cam_gl: np.ndarray) -> np.ndarray:
    """Camera-to-world with OpenGL camera axes -> camera-to-world with OpenCV camera axes."""
    return np.asarray(T_world_from_cam_gl, dtype=float) @ GL_FROM_CV


def opencv_c2w_to_opengl(T_world_from_cam: np.ndarray) -> np.ndarray:
    """Inverse of :func:`opengl_c2w_to_opencv` (the flip is its own inverse)."""
    return np.asarray(T_world_from_cam, dtype=float) @ GL_FROM_CV


def make_transform(rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """4x4 transform from a 3x3 rotation and a 3-vector translation."""
    T = np.eye(4)
    T[:3, :3] = rotation
    T[:3, 3] = translation
    return T


def invert_rigid(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid 4x4 transform, using R^T rather than a general inverse."""
    R = T[:3, :3]
    t = T[:3, 3]
    return make_transform(R.T, -R.T @ t)


def transform_points(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a 4x4 transform to an (N, 3) array of points."""
    return points @ T[:3, :3].T + T[:3, 3]


def rigid_problem(T: np.ndarray, tol: float = 1e-4) -> str | None:
    """Why ``T`` is not a finite proper rigid 4x4 transform, or None if it is one."""
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4):
        return f"shape is {T.shape}, expected (4, 4)"
    if not np.all(np.isfinite(T)):
        return "contains NaN or infinite values"
    if not np.allclose(T[3], [0, 0, 0, 1], atol=tol):
        return f"last row is {T[3].tolist()}, expected [0, 0, 0, 1]"
    R = T[:3, :3]
    det = np.linalg.det(R)
    if abs(det) < 1e-9:
        return "rotation block is singular (not invertible)"
    if not np.allclose(R.T @ R, np.eye(3), atol=tol) or det < 0:
        return f"rotation block is not a proper rotation (det {det:.6g}, or not orthonormal)"
    return None


def look_at_opencv(eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    """T_world_from_cam for an OpenCV camera at ``eye`` looking at ``target``.

    The image's y axis (down) points as close as possible to ``-up``.
    """
    z = np.asarray(target, float) - np.asarray(eye, float)
    z /= np.linalg.norm(z)
    x = np.cross(-np.asarray(up, float), z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return make_transform(np.stack([x, y, z], axis=1), eye)


def rotation_angle_deg(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """Angle in degrees of the relative rotation R_a^T R_b."""
    cos = (np.trace(R_a.T @ R_b) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def rotvec_to_matrix(rotvec: np.ndarray) -> np.ndarray:
    """Axis-angle vector (radians) -> 3x3 rotation matrix."""
    return Rotation.from_rotvec(rotvec).as_matrix()


def horizontal_axes(up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors perpendicular to ``up`` and to each other."""
    up = np.asarray(up, float) / np.linalg.norm(up)
    side = np.cross(up, [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    return side, np.cross(up, side)


def azimuths_deg(points: np.ndarray, centre: np.ndarray, up: np.ndarray) -> np.ndarray:
    """The azimuth (N,) in [0, 360) degrees of each of ``points`` (N, 3) around ``centre``,
    about the axis ``up`` (from :func:`horizontal_axes`' first axis)."""
    side, other = horizontal_axes(up)
    rel = np.asarray(points, float) - centre
    return np.degrees(np.arctan2(rel @ other, rel @ side)) % 360.0


def azimuth_span_deg(points: np.ndarray, centre: np.ndarray, up: np.ndarray) -> float:
    """How many degrees of azimuth around ``centre`` (about the axis ``up``) the ``points``
    (N, 3) span: 360 minus the widest gap between neighbouring azimuths (0 for fewer than
    two points)."""
    azimuth = np.sort(azimuths_deg(points, centre, up))
    if len(azimuth) < 2:
        return 0.0
    gaps = np.diff(np.concatenate([azimuth, azimuth[:1] + 360.0]))
    return float(360.0 - gaps.max())


def ransac_plane(points: np.ndarray, inlier_m: float, iterations: int, seed: int = 0,
                 max_scored_points: int = 20000) -> tuple[np.ndarray, float, np.ndarray]:
    """(unit normal, offset, inlier indices) of the plane ``normal @ x + offset = 0`` that the
    most of ``points`` (N, 3) lie within ``inlier_m`` of: ``iterations`` planes through three
    random points, each scored on at most ``max_scored_points`` of them, then the best one
    refitted by least squares to its inliers.

    Written here rather than taken from open3d: its ``segment_plane`` draws its samples from
    several threads, so even with its seed set the plane differed from run to run (the pear's
    support plane came out at three offsets up to 4 mm apart in eight runs)."""
    points = np.asarray(points, float)
    if len(points) < 3:
        raise ValueError(f"a plane needs at least 3 points, not {len(points)}")
    rng = np.random.default_rng(seed)
    scored = points
    if len(points) > max_scored_points:
        scored = points[rng.choice(len(points), max_scored_points, replace=False)]
    triples = points[rng.integers(0, len(points), size=(iterations, 3))]
    normals = np.cross(triples[:, 1] - triples[:, 0], triples[:, 2] - triples[:, 0])
    length = np.linalg.norm(normals, axis=1)
    usable = length > 1e-12
    if not usable.any():
        raise ValueError("the points lie on one line: no plane through them")
    normals = normals[usable] / length[usable, None]
    offsets = -np.einsum("ij,ij->i", normals, triples[usable, 0])
    counts = np.concatenate([
        (np.abs(scored @ normals[i:i + 256].T + offsets[i:i + 256]) < inlier_m).sum(axis=0)
        for i in range(0, len(normals), 256)])
    best = int(np.argmax(counts))
    inliers = np.flatnonzero(np.abs(points @ normals[best] + offsets[best]) < inlier_m)
    centre = points[inliers].mean(axis=0)
    normal = np.linalg.svd(points[inliers] - centre, full_matrices=False)[2][-1]
    offset = -float(normal @ centre)
    return normal, offset, np.flatnonzero(np.abs(points @ normal + offset) < inlier_m)
