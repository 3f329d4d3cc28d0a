"""Handheld phone trajectories around a food item, and what an AR phone reports of them.

In: a :class:`TrajectoryConfig`, the object's centre and bounding radius (metres, scene frame,
z up) and a random generator. Out: exact ``T_scene_from_cam`` poses (N, 4, 4), OpenCV axes,
portrait camera; and, from those, the poses an AR phone would report: the exact poses plus a
smooth low-frequency drift that starts at zero and grows over the capture, plus jitter.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from volec.errors import ConfigError
from volec.geometry import look_at_opencv, make_transform, rotvec_to_matrix


@dataclass(frozen=True)
class TrajectoryConfig:
    """A handheld orbit around the plate."""

    n_frames: int = 100
    """Number of frames."""
    arc_deg: float = 360.0
    """Azimuth covered by the orbit, degrees (180 gives a half-orbit capture)."""
    elevation_min_deg: float = 20.0
    """Lowest camera elevation above the table, degrees."""
    elevation_max_deg: float = 60.0
    """Highest camera elevation, degrees."""
    distance_per_radius: float = 3.6
    """Camera distance as a multiple of the object's bounding radius (before clipping)."""
    distance_min_m: float = 0.2
    """Closest a hand holds a phone to food, metres."""
    distance_max_m: float = 0.5
    """Farthest, metres."""
    distance_variation: float = 0.12
    """Relative slow in-and-out motion of the hand."""
    shake_m: float = 0.003
    """Hand shake of the camera centre (smooth, per axis), metres."""
    aim_error_m: float = 0.008
    """How far from the object's centre the user aims (smooth), metres."""
    roll_deg: float = 3.0
    """Smooth roll of the phone about its optical axis, degrees."""


@dataclass(frozen=True)
class DriftConfig:
    """How AR tracking errs: a smooth random-walk drift from zero, plus frame-to-frame jitter."""

    position_m: float = 0.005
    """Largest camera-centre drift over the capture, metres."""
    rotation_deg: float = 0.3
    """Largest orientation drift over the capture, degrees."""
    jitter_position_m: float = 0.0003
    """Standard deviation of per-frame position jitter, metres."""
    jitter_rotation_deg: float = 0.02
    """Standard deviation of per-frame rotation jitter, degrees."""


def _smooth_curve(
    rng: np.random.Generator, t: np.ndarray, dims: int, max_freq: float
) -> np.ndarray:
    """A smooth random curve (len(t), dims) with values in about [-1, 1]."""
    out = np.zeros((len(t), dims))
    for k in range(4):
        freq = rng.uniform(0.3, max_freq)
        phase = rng.uniform(0, 2 * np.pi, size=dims)
        amp = rng.normal(size=dims) / (k + 1)
        out += amp * np.sin(2 * np.pi * freq * t[:, None] + phase)
    return out / max(np.abs(out).max(), 1e-12)


def _random_walk(rng: np.random.Generator, n: int, largest: float) -> np.ndarray:
    """(n, 3) smooth random walk from zero whose largest norm is ``largest``.

    Visual-inertial tracking drifts because sensor noise is integrated: a random walk that
    starts at zero when the session starts. Its increments are independent of how the phone
    moves, which is what lets short-baseline displacements measure scale (volec.sfm).
    """
    steps = rng.normal(size=(n, 3))
    walk = np.cumsum(steps, axis=0)
    walk = gaussian_filter1d(walk, sigma=max(n / 50.0, 1.0), axis=0, mode="nearest")
    walk -= walk[0]
    return walk * (largest / max(np.linalg.norm(walk, axis=1).max(), 1e-12))


def handheld_orbit(
    cfg: TrajectoryConfig, centre: np.ndarray, radius_m: float, rng: np.random.Generator
) -> np.ndarray:
    """Exact camera poses ``T_scene_from_cam`` (N, 4, 4) of a handheld orbit around ``centre``."""
    if cfg.n_frames < 2:
        raise ConfigError(f"n_frames must be at least 2, got {cfg.n_frames}")
    t = np.linspace(0.0, 1.0, cfg.n_frames)
    closed = abs(cfg.arc_deg) >= 360.0
    # A full orbit does not repeat its first view at the end.
    s = t * (cfg.n_frames - 1) / cfg.n_frames if closed else t
    azimuth = rng.uniform(0, 2 * np.pi) + np.radians(cfg.arc_deg) * s
    lo, hi = np.radians(cfg.elevation_min_deg), np.radians(cfg.elevation_max_deg)
    cycles = 1.5 * max(abs(cfg.arc_deg) / 360.0, 0.5)
    wave = np.sin(2 * np.pi * cycles * t + rng.uniform(0, 2 * np.pi))
    elevation = (lo + hi) / 2 + (hi - lo) / 2 * wave
    base = np.clip(cfg.distance_per_radius * radius_m, cfg.distance_min_m, cfg.distance_max_m)
    distance = base * (1 + cfg.distance_variation * _smooth_curve(rng, t, 1, 2.0)[:, 0])
    direction = np.stack(
        [
            np.cos(elevation) * np.cos(azimuth),
            np.cos(elevation) * np.sin(azimuth),
            np.sin(elevation),
        ],
        axis=1,
    )
    eyes = centre + distance[:, None] * direction + cfg.shake_m * _smooth_curve(rng, t, 3, 12.0)
    aims = centre + cfg.aim_error_m * _smooth_curve(rng, t, 3, 3.0)
    roll = np.radians(cfg.roll_deg) * _smooth_curve(rng, t, 1, 4.0)[:, 0]
    up = np.array([0.0, 0.0, 1.0])
    poses = np.empty((cfg.n_frames, 4, 4))
    for i in range(cfg.n_frames):
        T = look_at_opencv(eyes[i], aims[i], up)
        T[:3, :3] = T[:3, :3] @ rotvec_to_matrix(np.array([0.0, 0.0, roll[i]]))
        poses[i] = T
    return poses


def ar_reported_poses(
    exact: np.ndarray, cfg: DriftConfig, rng: np.random.Generator
) -> np.ndarray:
    """What AR tracking reports for the ``exact`` poses: drift (zero at the first frame) + jitter.

    Drift moves each camera centre by up to ``position_m`` and turns it by up to
    ``rotation_deg`` (about its own centre); both are smooth random walks from zero.
    """
    n = len(exact)
    pos = _random_walk(rng, n, cfg.position_m)
    rot = _random_walk(rng, n, np.radians(cfg.rotation_deg))
    pos = pos + rng.normal(scale=cfg.jitter_position_m, size=(n, 3))
    rot = rot + rng.normal(scale=np.radians(cfg.jitter_rotation_deg), size=(n, 3))
    out = np.empty_like(exact)
    for i in range(n):
        R = rotvec_to_matrix(rot[i]) @ exact[i, :3, :3]
        out[i] = make_transform(R, exact[i, :3, 3] + pos[i])
    return out
