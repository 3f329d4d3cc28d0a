"""Metric camera poses: pycolmap structure-from-motion aligned to the phone's AR poses.

In: a :class:`~volec.capture.Capture` (images, intrinsics, AR camera-to-world poses in metres)
and an :class:`SfmConfig`. Out: an :class:`SfmResult` with refined metric poses in the
capture's world frame, the sparse metric point cloud, which frames registered, the
world-from-model similarity, and a summary (counts, reprojection error, residuals, timings).
On disk (:func:`run_sfm` with a work folder): ``sfm/database.db``, ``sfm/pairs.txt``, the
metric COLMAP model in ``sfm/model`` (openable in COLMAP's GUI), ``sfm/points.ply`` (to look
at), ``sfm/points.npz`` (the sparse points exactly as the result holds them) and
``sfm/summary.json``.

Why the alignment is done this way: AR poses are metric but drift; COLMAP's are consistent
but unscaled. Visual-inertial drift is a random walk that is zero where the AR session starts.
A Sim(3) fitted to all camera centres absorbs the drift into its scale and offset;
:func:`short_baseline_scale` uses only displacements between nearby frames, where drift
nearly cancels; :func:`drift_model_alignment` solves for scale, translation and the drift
itself by generalised least squares under that random-walk model, which also removes the
drift's offset from the camera centres. All three are computed and reported;
``SfmConfig.scale_method`` picks one (``benchmarks/bench_sfm.py`` measured the default).
"""

from __future__ import annotations

import json
import logging
import shutil
import time
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from volec.capture import PIXEL_CENTRE_OFFSET, Capture
from volec.errors import ConfigError, VolecError
from volec.geometry import invert_rigid, make_transform, rotation_angle_deg
from volec.io import atomic_folder, write_json_atomic
from volec.provenance import file_digest

log = logging.getLogger(__name__)


#: The files of a finished SfM stage (besides ``model/``) that ``summary.json`` lists.
SFM_FILES = ("T_world_from_cam.npy", "registered.npy", "points.npz", "points.ply")


class SfmError(VolecError):
    """Structure from motion could not give trustworthy metric poses for this capture."""


@dataclass(frozen=True)
class SfmConfig:
    """Options of the SfM stage; the defaults suit a 100-frame phone orbit."""

    max_image_size_px: int = 1024
    """Images are downscaled to at most this many pixels on the long side for SIFT (both
    backends); keypoints are reported in full-image pixels."""
    features: Literal["opencv_sift", "colmap_sift"] = "opencv_sift"
    """SIFT implementation. ``opencv_sift``: OpenCV's SIFT, written into COLMAP's database as
    RootSIFT (3 times faster on the CPU than COLMAP's at the same feature count);
    ``colmap_sift``: pycolmap's own extractor."""
    opencv_contrast_threshold: float = 0.006
    """OpenCV SIFT contrast threshold (its default 0.04 finds few features on food)."""
    max_num_features: int = 4096
    """SIFT features kept per image."""
    sift_peak_threshold: float = 0.0066667
    """``colmap_sift`` only: SIFT's contrast threshold (COLMAP's default 0.02/3); lower finds
    more, weaker features."""
    sift_first_octave: int = -1
    """``colmap_sift`` only: SIFT's first octave; -1 upsamples the image twice (more, smaller
    features, slower; 0 broke the loop closure of 480x640 captures)."""
    pairing: Literal["ar_guided", "sequential", "exhaustive"] = "ar_guided"
    """How image pairs are chosen for matching. ``ar_guided``: frames whose AR viewing
    directions to the scene centre are within ``pair_max_angle_deg`` (this closes loops
    without a vocabulary tree); ``sequential``: the ``sequential_overlap`` next frames;
    ``exhaustive``: all pairs (small captures only)."""
    pair_max_angle_deg: float = 35.0
    """Largest angle between two frames' viewing directions for ``ar_guided`` pairing."""
    pair_max_per_image: int = 12
    """At most this many partners per image for ``ar_guided`` pairing (nearest first)."""
    sequential_overlap: int = 8
    """Partners per image for ``sequential`` pairing (also always added by ``ar_guided``)."""
    mapping: Literal["known_poses", "incremental"] = "known_poses"
    """How the model is built from the matches. ``known_poses``: points are triangulated from
    the AR poses, then poses and points are bundle-adjusted and the points re-triangulated
    (``known_pose_rounds`` times); ``incremental``: COLMAP's incremental mapping from scratch,
    which ignores the AR poses (its mapping step took 1.7 times as long on six 100-frame
    orbits, for the same pose accuracy: ``benchmarks/bench_sfm_mapping.py``). A known-pose
    model that keeps fewer than ``min_registered_fraction`` of the frames (AR poses far off)
    falls back to incremental mapping; ``summary.json`` records which one ran."""
    known_pose_rounds: int = 1
    """``known_poses``: re-triangulation and bundle adjustment rounds after the first one.
    Zero would take the mapping from 11.0 to 6.0 s on three 100-frame orbits (apple, banana,
    pear) for the same pose accuracy (camera centres 0.90 mm both, rotations 0.112 against
    0.108 degrees: ``benchmarks/bench_sfm_mapping.py --variants known_poses rounds_0``), and
    moved the 21 full orbits' default MAPE from 1.73 to 1.76 % (p = 0.76), but the half
    orbits' from 3.12 to 3.48 % (p = 0.051; without completion 3.86 to 3.90 %): kept at one."""
    max_ar_epipolar_error_deg: float = 3.0
    """``known_poses``: a frame whose verified matches lie farther than this (median Sampson
    distance over its pairs, as an angle at the camera) from the epipolar lines its AR pose
    predicts is not triangulated from (:func:`ar_epipolar_error_deg`). Measured with 5 mm AR
    drift: 0.1-0.5 degrees on 100-frame and 16-frame orbits, up to 2.7 on 30-frame ones (wide
    baselines); shuffled AR poses or OpenGL axes read as OpenCV: 2.2-8 degrees. A wrong pose
    that passes triangulates few points and is dropped (``min_observations_per_frame``)."""
    min_observations_per_frame: int = 40
    """``known_poses``: a frame with fewer triangulated observations is left unregistered
    (its AR pose disagrees with its matches, or it sees too little)."""
    ba_global_growth_ratio: float = 1.4
    """Global bundle adjustment runs when the model has grown by this factor (COLMAP: 1.1)."""
    ba_max_iterations: int = 30
    """Iteration cap of each bundle adjustment (COLMAP: unlimited)."""
    min_frames: int = 8
    """Fewer frames than this is an error."""
    min_registered_fraction: float = 0.5
    """Fewer registered frames than this fraction is an error."""
    scale_method: Literal["drift_model", "short_baseline", "sim3_all"] = "drift_model"
    """Which metric alignment to keep (all three are computed and reported).
    ``drift_model``: generalised least squares with the AR drift as a random walk from zero
    (scale, translation and per-frame drift jointly; orientation by a mean weighted the same
    way); ``short_baseline``: scale from displacements between nearby frames;
    ``sim3_all``: a Sim(3) fitted to all camera centres."""
    ar_jitter_m: float = 0.0003
    """Drift model: standard deviation of the AR position noise of one frame, metres."""
    ar_drift_m: float = 0.005
    """Drift model: standard deviation of the AR position drift at the end of the recording,
    metres. It is a random walk from zero: at a share ``e`` of the recording
    (:attr:`volec.capture.Frame.elapsed_share`) its variance is ``e * ar_drift_m**2``, so a
    subset of the frames (keyframes, 30 frames of 100) keeps the recording's drift between
    them. (It used to grow per frame, 0.5 mm per square-root frame: the same on a 100-frame
    capture, but too little drift between the frames a subset kept apart.)"""
    ar_rot_jitter_deg: float = 0.02
    """Drift model: standard deviation of the AR orientation noise of one frame, degrees."""
    ar_rot_drift_deg: float = 0.3
    """Drift model: standard deviation of the AR orientation drift at the end of the
    recording, degrees (a random walk like ``ar_drift_m``)."""
    short_baseline_max_frames: int = 6
    """Largest frame separation of the displacement pairs used by ``short_baseline``."""
    alignment_inlier_m: float = 0.02
    """RANSAC inlier threshold of the Sim(3) fit on camera centres, metres."""
    max_alignment_residual_m: float = 0.03
    """Median camera-centre residual (metres) above which the AR poses are taken to
    disagree with the images, and the stage fails."""
    num_threads: int = 1
    """Threads for COLMAP's extraction, matching, mapping and bundle adjustment (-1: all
    cores). One makes the stage repeatable: with all cores the same 100-frame pear came out
    differently in every run (14,575, 14,551 and 14,530 points, camera centres up to 0.27 mm
    apart), and four items' volumes moved by 0.1-0.8 % when their SfM was redone (capsicum
    -1.23 % then -0.44 % without completion); with one thread, three runs gave the same poses
    bit for bit. Multi-threaded extraction alone was enough to lose that. The cost, the pear
    alone on 2 cores: 34.3 s against 41.7 s (1.22 times); none where each capture has a core of
    its own (``volec batch``, the experiments). Matching too: it once took OpenCV's thread
    count, its verification's RANSAC seeded, which repeated on the apple's 600 pairs; but
    COLMAP's random generator is one per thread, so which pair draws which numbers likely
    follows the threads' timing. The 16-frame cake of the tests, matched on two threads,
    came out with 91 instead of 92 verified pairs in one run of six (camera centres 0.3 mm
    apart); on one thread, ten runs gave the same poses bit for bit. So the pairs are matched
    in parts, each on one thread (``matching_parts``)."""
    seed: int = 0
    """Seed for COLMAP's and the alignment's RANSAC."""
    matching_parts: int = 2
    """The pairs are matched in this many parts, each on one thread into its own copy of the
    database (:func:`match_pairs`), as many at once as OpenCV may use threads: the matches
    do not depend on how many ran at once, so the same capture gives the same poses on any
    machine, and on 2 cores matching takes about the time it took on two threads."""


PRESETS: dict[str, SfmConfig] = {
    "default": SfmConfig(),
    "exhaustive": SfmConfig(pairing="exhaustive"),
    "colmap_sift": SfmConfig(features="colmap_sift", sift_peak_threshold=0.003),
}


@dataclass(eq=False)
class SfmResult:
    """Refined metric poses and the sparse cloud, in the capture's world frame."""

    frame_names: list[str]
    """Frame names, in capture order."""
    T_world_from_cam: np.ndarray
    """(N, 4, 4) refined camera-to-world poses, OpenCV axes, metres. Frames that did not
    register keep their AR pose (see ``registered``)."""
    registered: np.ndarray
    """(N,) True where the frame registered in the SfM model."""
    points_xyz: np.ndarray
    """(M, 3) sparse points, metres, world frame."""
    points_rgb: np.ndarray
    """(M, 3) uint8 colours of the sparse points."""
    world_from_model: np.ndarray
    """4x4 similarity (scale * rotation | translation) mapping the COLMAP model to the world."""
    summary: dict[str, Any] = field(default_factory=dict)
    """Counts, reprojection error, scale estimates, residuals and timings (JSON-able)."""

    @property
    def scale(self) -> float:
        """Metres per COLMAP model unit."""
        return float(np.cbrt(np.linalg.det(self.world_from_model[:3, :3])))

    @property
    def elapsed_shares(self) -> np.ndarray:
        """(N,) when each frame was taken, as a share of the recording: the clock the AR
        drift model ran on (``summary["frame_elapsed_shares"]``; without it, each frame's
        place, as :attr:`volec.capture.Capture.elapsed_shares` gives it)."""
        n = len(self.frame_names)
        shares = self.summary.get("frame_elapsed_shares")
        if shares is None:
            return np.arange(n) / max(n - 1, 1)
        return np.asarray(shares, float)


# ----------------------------------------------------------------------------- pairing


def _viewing_directions(capture: Capture) -> np.ndarray:
    """Unit vectors from each camera towards the point the cameras jointly look at."""
    centres = capture.camera_centres
    axes = np.stack([f.T_world_from_cam[:3, 2] for f in capture.frames])
    # Least-squares point closest to all optical axes.
    A = np.zeros((3, 3))
    b = np.zeros(3)
    for c, a in zip(centres, axes, strict=True):
        P = np.eye(3) - np.outer(a, a)
        A += P
        b += P @ c
    target = np.linalg.lstsq(A, b, rcond=None)[0]
    d = target - centres
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def select_pairs(capture: Capture, cfg: SfmConfig) -> list[tuple[int, int]]:
    """Image pairs (i < j) to match, by ``cfg.pairing``."""
    n = len(capture)
    pairs: set[tuple[int, int]] = set()
    if cfg.pairing == "exhaustive":
        return [(i, j) for i in range(n) for j in range(i + 1, n)]
    for i in range(n):
        for j in range(i + 1, min(n, i + 1 + cfg.sequential_overlap)):
            pairs.add((i, j))
    if cfg.pairing == "ar_guided":
        d = _viewing_directions(capture)
        cos = np.clip(d @ d.T, -1, 1)
        limit = np.cos(np.radians(cfg.pair_max_angle_deg))
        for i in range(n):
            order = np.argsort(-cos[i])
            partners = [j for j in order if j != i and cos[i, j] >= limit]
            for j in partners[: cfg.pair_max_per_image]:
                pairs.add((min(i, j), max(i, j)))
    elif cfg.pairing != "sequential":
        raise ConfigError(f"unknown pairing '{cfg.pairing}'")
    return sorted(pairs)


# ----------------------------------------------------------------------------- scale


def fit_similarity(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Least-squares similarity ``dst ~ s R src + t`` (pycolmap's Umeyama) as a 4x4 matrix."""
    import pycolmap

    sim = pycolmap.estimate_sim3d(np.asarray(src, float), np.asarray(dst, float))
    if sim is None:
        raise SfmError("no similarity fits these camera centres (too few, or degenerate)")
    return np.vstack([sim.matrix(), [0.0, 0.0, 0.0, 1.0]])


def rotation_mean(rotations: np.ndarray) -> np.ndarray:
    """Chordal L2 mean of (N, 3, 3) rotations: the rotation nearest their arithmetic mean."""
    return rotation_weighted_mean(rotations, np.ones(len(rotations)))


def short_baseline_scale(
    model_centres: np.ndarray, ar_centres: np.ndarray, rotation: np.ndarray, max_sep: int
) -> float:
    """Metres per model unit from displacements between frames at most ``max_sep`` apart.

    Slow AR drift nearly cancels in such displacements; the scale is the least-squares fit
    ``delta_ar ~ s R delta_model`` over all of them (``rotation`` from a first Sim(3) fit).
    Frames are in capture order; both arrays hold only frames present in both.
    """
    num, den = 0.0, 0.0
    for k in range(1, max_sep + 1):
        dm = (model_centres[k:] - model_centres[:-k]) @ rotation.T
        da = ar_centres[k:] - ar_centres[:-k]
        num += float(np.einsum("ij,ij->", da, dm))
        den += float(np.einsum("ij,ij->", dm, dm))
    if den <= 0:
        raise SfmError("the cameras did not move: no baseline to measure the scale from")
    return num / den


def rotation_weighted_mean(rotations: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Weighted chordal L2 mean of (N, 3, 3) rotations."""
    M = np.einsum("n,nij->ij", weights, rotations)
    U, _, Vt = np.linalg.svd(M)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


TIME_FLOOR = 1e-8
"""The drift model's least time between two frames, or before the first (units of its times)."""


def drift_weights(times: np.ndarray, jitter: float, drift_per_sqrt_time: float) -> np.ndarray:
    """Inverse variances of AR measurements taken at ``times`` whose error is jitter plus a
    random walk from time 0: frames early in the session are trusted most."""
    return 1.0 / (jitter**2 + drift_per_sqrt_time**2 * np.asarray(times, float))


def drift_model_alignment(
    model_centres: np.ndarray,
    ar_centres: np.ndarray,
    times: np.ndarray,
    rotation: np.ndarray,
    jitter_m: float,
    drift_m_per_sqrt_time: float,
) -> tuple[float, np.ndarray, np.ndarray]:
    """Scale, translation and AR drift by generalised least squares.

    Model: ``ar_i = s R m_i + t + d_i + noise_i`` with ``d`` a random walk that is zero at
    time 0 (the AR world is defined where the session starts) whose variance grows by
    ``drift_m_per_sqrt_time**2`` per unit of ``times`` (when each frame was taken, e.g. its
    share of the recording), and white ``noise`` of std ``jitter_m``. With the
    rotation ``R`` fixed the problem is linear in (s, t, d_1..d_n); it is solved densely
    (a few hundred unknowns). Returns (s, t, drift (N, 3)).
    """
    n = len(model_centres)
    times = np.asarray(times, float)
    if np.any(np.diff(times) < 0):
        raise ValueError("frames must be in the order they were taken")
    rm = model_centres @ rotation.T
    n_unknown = 4 + 3 * n  # s, t, d_0..d_{n-1}; d_0 is pinned by a strong prior
    rows, rhs = [], []
    for i in range(n):
        for k in range(3):
            r = np.zeros(n_unknown)
            r[0], r[1 + k], r[4 + 3 * i + k] = rm[i, k], 1.0, 1.0
            rows.append(r / jitter_m)
            rhs.append(ar_centres[i, k] / jitter_m)
    # drift accumulated before the first registered frame, and between frames (the floor pins
    # a frame at time 0 and ties frames taken at one instant together)
    gaps = np.maximum(np.diff(times, prepend=0.0), TIME_FLOOR)
    for k in range(3):
        r = np.zeros(n_unknown)
        r[4 + k] = 1.0
        rows.append(r / (drift_m_per_sqrt_time * np.sqrt(gaps[0])))
        rhs.append(0.0)
    for i in range(1, n):
        step = drift_m_per_sqrt_time * np.sqrt(gaps[i])
        for k in range(3):
            r = np.zeros(n_unknown)
            r[4 + 3 * i + k], r[4 + 3 * (i - 1) + k] = 1.0, -1.0
            rows.append(r / step)
            rhs.append(0.0)
    x = np.linalg.lstsq(np.asarray(rows), np.asarray(rhs), rcond=None)[0]
    return float(x[0]), x[1:4], x[4:].reshape(n, 3)


def match_pairs(db: Path, pairs: list[str], cfg: SfmConfig) -> None:
    """COLMAP's matching and geometric verification of ``pairs`` (``"NAME_A NAME_B"``) into
    the database ``db``. With ``cfg.num_threads`` 1, the pairs are dealt into
    ``cfg.matching_parts`` parts, each matched on one thread into a copy of ``db``, in as many
    processes at once as OpenCV may use threads (``volec batch`` workers: one, so one part
    after the other), and their matches and geometries are then written into ``db`` part by
    part. Matching on several threads did not repeat (once in six runs the tests' cake lost
    a verified pair), nor did two one-thread matchings in one process (two runs in eight):
    a part alone in its process draws its random numbers in a fixed order.

    COLMAP has no option to match one list of pairs on several threads repeatably; hence the
    parts and the merge here."""
    import cv2
    import pycolmap

    parts = max(1, min(cfg.matching_parts, len(pairs))) if cfg.num_threads == 1 else 1
    if parts == 1:
        _match_part(db, pairs, cfg, cfg.num_threads)
        return
    copies = [db.with_name(f"{db.stem}.part{k}{db.suffix}") for k in range(parts)]
    for copy in copies:
        shutil.copyfile(db, copy)
    try:
        at_once = max(1, min(parts, cv2.getNumThreads()))
        jobs = [(copies[k], pairs[k::parts], cfg, 1) for k in range(parts)]
        if at_once == 1:
            for job in jobs:
                _match_part(*job)
        else:  # processes: two matchings in one process disturb each other's random draws
            import multiprocessing

            with ProcessPoolExecutor(at_once, multiprocessing.get_context("fork")) as pool:
                list(pool.map(_match_part, *zip(*jobs, strict=True)))
        with pycolmap.Database.open(db) as database:
            for copy in copies:
                with pycolmap.Database.open(copy) as part:
                    for pair_id, matches in zip(*part.read_all_matches(), strict=True):
                        database.write_matches(*pycolmap.pair_id_to_image_pair(pair_id),
                                               matches)
                    for pair_id, geometry in zip(*part.read_two_view_geometries(), strict=True):
                        database.write_two_view_geometry(
                            *pycolmap.pair_id_to_image_pair(pair_id), geometry)
    finally:
        for copy in copies:
            copy.unlink(missing_ok=True)


def _match_part(db: Path, pairs: list[str], cfg: SfmConfig, threads: int) -> None:
    """COLMAP's matching of ``pairs`` into ``db`` on ``threads`` threads."""
    import pycolmap

    pairs_file = db.with_suffix(".pairs.txt")
    pairs_file.write_text("".join(f"{pair}\n" for pair in pairs))
    try:
        pycolmap.match_image_pairs(
            db, matching_options=pycolmap.FeatureMatchingOptions(num_threads=threads),
            pairing_options=pycolmap.ImportedPairingOptions(match_list_path=pairs_file),
            verification_options=verification_options(cfg), device=pycolmap.Device.cpu,
        )
    finally:
        pairs_file.unlink(missing_ok=True)


def verification_options(cfg: SfmConfig) -> Any:
    """COLMAP's two-view geometric verification options (``pycolmap.TwoViewGeometryOptions``)
    with the RANSAC seeded by ``cfg.seed`` (COLMAP's default seeds from the clock), so a run
    on one thread repeats."""
    import pycolmap

    options = pycolmap.TwoViewGeometryOptions()
    options.ransac.random_seed = cfg.seed
    return options


def _robust_sim3(src: np.ndarray, dst: np.ndarray, inlier_m: float, seed: int) -> np.ndarray:
    """RANSAC Sim(3) (pycolmap LO-RANSAC) refined by Umeyama on the inliers."""
    import pycolmap

    opts = pycolmap.RANSACOptions(max_error=inlier_m, random_seed=seed)
    found = pycolmap.estimate_sim3d_robust(src, dst, opts)  # a dict, or None
    if not found or found.get("num_inliers", 0) < 3:
        raise SfmError("no similarity maps the SfM camera centres onto the AR ones")
    M = make_transform(np.zeros((3, 3)), np.zeros(3))
    M[:3, :4] = found["tgt_from_src"].matrix()
    residual = np.linalg.norm(src @ M[:3, :3].T + M[:3, 3] - dst, axis=1)
    inliers = residual < inlier_m
    return fit_similarity(src[inliers], dst[inliers]) if inliers.sum() >= 3 else M


# ----------------------------------------------------------------------------- the stage


def _camera_params(capture: Capture) -> tuple[str, str]:
    intr = capture.frames[0].intrinsics
    if any(f.intrinsics != intr for f in capture.frames):
        raise SfmError(
            "frames have different intrinsics; volec's SfM stage expects one camera per "
            "capture (a phone capture at one zoom)"
        )
    cx, cy = intr.cx + PIXEL_CENTRE_OFFSET, intr.cy + PIXEL_CENTRE_OFFSET  # COLMAP convention
    if intr.is_undistorted:
        return "PINHOLE", f"{intr.fx},{intr.fy},{cx},{cy}"
    if intr.model == "OPENCV":
        k = ",".join(str(x) for x in intr.distortion)
        return "OPENCV", f"{intr.fx},{intr.fy},{cx},{cy},{k}"
    raise SfmError(f"camera model {intr.model} with distortion is not supported by SfM yet")


def rootsift_uint8(descriptors: np.ndarray) -> np.ndarray:
    """SIFT descriptors -> RootSIFT (L1-normalised, square-rooted: unit L2 norm) as COLMAP
    stores them: ``round(512 * x)`` clipped to uint8."""
    d = np.asarray(descriptors, np.float64)
    d = np.sqrt(d / np.maximum(d.sum(axis=1, keepdims=True), 1e-12))
    return np.clip(np.round(512.0 * d), 0, 255).astype(np.uint8)


def opencv_sift_features(gray: np.ndarray, cfg: SfmConfig) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV SIFT on a grayscale image, as COLMAP stores features.

    The image is downscaled to ``cfg.max_image_size_px`` on its long side first. Returns
    keypoints (N, 4) float32 ``x, y, scale, orientation`` in full-image pixels with COLMAP's
    convention (first pixel centre at 0.5), and RootSIFT descriptors (N, 128) uint8.
    """
    import cv2

    factor = min(1.0, cfg.max_image_size_px / max(gray.shape))
    if factor < 1.0:
        gray = cv2.resize(gray, None, fx=factor, fy=factor, interpolation=cv2.INTER_AREA)
    # enable_precise_upscale: without it OpenCV's internal 2x upsampling shifts every
    # keypoint by about +0.24 px in x and y (measured on blobs of known centre).
    sift = cv2.SIFT_create(
        nfeatures=cfg.max_num_features, contrastThreshold=cfg.opencv_contrast_threshold,
        enable_precise_upscale=True,
    )
    kps, desc = sift.detectAndCompute(gray, None)
    # With pixel centres at 0.5 (COLMAP), resizing is a pure scale of the coordinates.
    xy = np.array(
        [[(k.pt[0] + PIXEL_CENTRE_OFFSET) / factor, (k.pt[1] + PIXEL_CENTRE_OFFSET) / factor,
          k.size / 2 / factor, np.radians(k.angle)] for k in kps], np.float32
    ).reshape(-1, 4)
    desc8 = rootsift_uint8(desc) if desc is not None else np.zeros((0, 128), np.uint8)
    return xy, desc8


def sift_of_images(paths: list[Path], cfg: SfmConfig) -> list[tuple[np.ndarray, np.ndarray]]:
    """:func:`opencv_sift_features` of each image file, in order, one image per thread on as
    many threads as OpenCV may use (``cv2.getNumThreads()``; ``volec batch`` workers limit
    it), each image's SIFT itself on one thread. On 2 cores that is 1.8 times faster than
    OpenCV's own parallel loops inside one image (0.040 against 0.073 s per 480x640 frame),
    and the features do not depend on the number of threads."""
    import cv2

    def features(path: Path) -> tuple[np.ndarray, np.ndarray]:
        gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        if gray is None:
            raise SfmError(f"{path}: cannot be read as an image")
        return opencv_sift_features(gray, cfg)

    threads = max(1, cv2.getNumThreads())
    cv2.setNumThreads(1)
    try:
        if threads == 1:
            return [features(path) for path in paths]
        with ThreadPoolExecutor(threads) as pool:
            return list(pool.map(features, paths))
    finally:
        cv2.setNumThreads(threads)


def _replace_with_opencv_sift(db: Path, image_root: Path, cfg: SfmConfig) -> None:
    """Overwrite the keypoints and descriptors of every image in ``db`` with OpenCV SIFT.

    Written because pycolmap's CPU SIFT takes 0.28 s per 480x640 frame here and OpenCV's
    0.09 s (0.04 s on two threads, :func:`sift_of_images`).
    """
    import pycolmap

    with pycolmap.Database.open(db) as database:
        images = database.read_all_images()
        database.clear_keypoints()
        database.clear_descriptors()
        found = sift_of_images([Path(image_root) / image.name for image in images], cfg)
        for image, (xy, desc8) in zip(images, found, strict=True):
            database.write_keypoints(image.image_id, xy)
            database.write_descriptors(
                image.image_id,
                pycolmap.FeatureDescriptors(pycolmap.FeatureExtractorType.SIFT, desc8),
            )


def run_sfm(capture: Capture, work_dir: Path, cfg: SfmConfig | None = None,
            provenance: dict[str, Any] | None = None) -> SfmResult:
    """Run SfM on ``capture`` in ``work_dir/sfm`` (replaced on success) and align it to the
    AR poses. Raises :class:`SfmError` with advice when the result cannot be trusted.
    ``provenance`` (:mod:`volec.provenance`) goes into ``summary.json``, which is written last
    and lists the digests of the stage's other files."""
    cfg = cfg or SfmConfig()
    n = len(capture)
    if n < cfg.min_frames:
        raise SfmError(f"the capture has {n} frames; SfM needs at least {cfg.min_frames}")
    # Built in a temporary sibling and swapped in at the end: an earlier result survives a
    # failed or interrupted run.
    import pycolmap

    # COLMAP logs every image at INFO; keep its warnings unless volec is debugging.
    saved_level = pycolmap.logging.minloglevel
    if not log.isEnabledFor(logging.DEBUG):
        pycolmap.logging.minloglevel = 1
    try:
        with atomic_folder(Path(work_dir) / "sfm", overwrite=True) as sfm_dir:
            return _run_sfm_in(capture, sfm_dir, cfg, provenance)
    finally:
        pycolmap.logging.minloglevel = saved_level


def _run_sfm_in(capture: Capture, sfm_dir: Path, cfg: SfmConfig,
                provenance: dict[str, Any] | None) -> SfmResult:
    import pycolmap

    n = len(capture)
    db = sfm_dir / "database.db"
    names = [f.name for f in capture.frames]
    timings: dict[str, float] = {}

    t = time.perf_counter()
    log.info("SfM 1/4: SIFT features of %d frames", n)
    model, params = _camera_params(capture)
    reader = pycolmap.ImageReaderOptions(camera_model=model, camera_params=params)
    extraction = pycolmap.FeatureExtractionOptions(
        max_image_size=cfg.max_image_size_px, num_threads=cfg.num_threads
    )
    extraction.sift.max_num_features = cfg.max_num_features
    extraction.sift.first_octave = cfg.sift_first_octave
    extraction.sift.peak_threshold = cfg.sift_peak_threshold
    if cfg.features == "opencv_sift":
        # COLMAP creates the camera, rig, frame and image records from a 64-pixel thumbnail
        # (cheap); the features are then replaced by OpenCV's.
        extraction.max_image_size = 64
    pycolmap.extract_features(
        db, capture.root, image_names=names, camera_mode=pycolmap.CameraMode.SINGLE,
        reader_options=reader, extraction_options=extraction, device=pycolmap.Device.cpu,
    )
    if cfg.features == "opencv_sift":
        _replace_with_opencv_sift(db, capture.root, cfg)
    timings["extract_s"] = time.perf_counter() - t
    with pycolmap.Database.open(db) as database:
        n_kp = [database.num_keypoints_for_image(im.image_id) for im in
                database.read_all_images()]
    textureless = [names[i] for i, k in enumerate(n_kp) if k < 50]
    if len(textureless) > n / 2:
        raise SfmError(
            f"{len(textureless)} of {n} frames have fewer than 50 SIFT features (textureless "
            "or blurred); recapture with more of the table in view and steadier motion"
        )

    t = time.perf_counter()
    pairs = select_pairs(capture, cfg)
    log.info("SfM 2/4: matching %d image pairs (%s)", len(pairs), cfg.pairing)
    (sfm_dir / "pairs.txt").write_text("".join(f"{names[i]} {names[j]}\n" for i, j in pairs))
    match_pairs(db, [f"{names[i]} {names[j]}" for i, j in pairs], cfg)
    timings["match_s"] = time.perf_counter() - t

    t = time.perf_counter()
    rec, mapping = _map(capture, db, sfm_dir, cfg)
    timings["map_s"] = time.perf_counter() - t

    t = time.perf_counter()
    log.info("SfM 4/4: aligning %d registered frames to the AR poses", rec.num_reg_images())
    result = align_to_ar(capture, rec, cfg)
    timings["align_s"] = time.perf_counter() - t
    result.summary["timings_s"] = {k: round(v, 3) for k, v in timings.items()}
    result.summary["pairs"] = len(pairs)
    result.summary["mapping"] = mapping
    result.summary["keypoints_median"] = int(np.median(n_kp))
    result.summary["textureless_frames"] = textureless
    result.summary["config"] = asdict(cfg)

    sim = pycolmap.Sim3d(
        result.scale,
        pycolmap.Rotation3d(result.world_from_model[:3, :3] / result.scale),
        result.world_from_model[:3, 3],
    )
    rec.transform(sim)
    (sfm_dir / "model").mkdir()
    rec.write(sfm_dir / "model")
    rec.export_PLY(sfm_dir / "points.ply")
    shutil.rmtree(sfm_dir / "colmap", ignore_errors=True)
    np.save(sfm_dir / "T_world_from_cam.npy", result.T_world_from_cam)
    np.save(sfm_dir / "registered.npy", result.registered)
    # The points as the result holds them (float64): COLMAP's PLY rounds them to float32, and
    # dense stereo's depth range from the rounded points (60 nm off) gave another cloud (the
    # apple: 76,138 points instead of 76,124), so a stage resumed from disk differed from the
    # run that wrote it.
    np.savez(sfm_dir / "points.npz", xyz=result.points_xyz, rgb=result.points_rgb)
    if provenance is not None:
        result.summary["provenance"] = provenance
    result.summary["files"] = {name: file_digest(sfm_dir / name) for name in SFM_FILES}
    write_json_atomic(sfm_dir / "summary.json", result.summary)  # last: the stage is done
    log.info(
        "SfM: %d/%d frames registered, scale %.5f m/unit (%s), residual median %.2f mm",
        result.summary["registered"], n, result.scale, cfg.scale_method,
        result.summary["residual_median_m"] * 1000,
    )
    return result


def _map(capture: Capture, db: Path, sfm_dir: Path, cfg: SfmConfig) -> tuple[Any, str]:
    """The model of ``capture`` from the matches in ``db``, and a line saying how it was made."""
    if cfg.mapping == "known_poses":
        log.info("SfM 3/4: triangulating from the AR poses, then bundle adjustment")
        trusted = ar_epipolar_error_deg(capture, db) <= cfg.max_ar_epipolar_error_deg
        kept = int(trusted.sum())
        if kept >= cfg.min_registered_fraction * len(capture):
            rec = known_pose_mapping(capture, db, sfm_dir / "colmap", cfg, trusted)
            kept = rec.num_reg_images()
            if kept >= cfg.min_registered_fraction * len(capture):
                return rec, "known_poses"
        log.warning("only %d of %d frames agree with their AR poses; mapping from scratch",
                    kept, len(capture))
        how = (f"incremental (known-pose triangulation kept {kept} of {len(capture)} frames; "
               f"{int((~trusted).sum())} AR poses disagreed with the matches)")
    else:
        how = "incremental"
    log.info("SfM 3/4: incremental mapping")
    return _incremental_mapping(capture, db, sfm_dir, cfg), how


def _incremental_mapping(capture: Capture, db: Path, sfm_dir: Path, cfg: SfmConfig) -> Any:
    import pycolmap

    opts = pycolmap.IncrementalPipelineOptions(
        ba_refine_focal_length=False, ba_refine_principal_point=False,
        ba_refine_extra_params=False, multiple_models=False,
        num_threads=cfg.num_threads, random_seed=cfg.seed,
        # Global bundle adjustment after each 40 % growth of the model rather than each 10 %,
        # and capped iterations: the largest cost on 2 cores, with no loss of accuracy on the
        # benchmark (benchmarks/bench_sfm.py).
        ba_global_frames_ratio=cfg.ba_global_growth_ratio,
        ba_global_points_ratio=cfg.ba_global_growth_ratio,
        ba_global_max_num_iterations=cfg.ba_max_iterations,
        ba_local_max_num_iterations=cfg.ba_max_iterations,
    )
    maps = pycolmap.incremental_mapping(db, capture.root, sfm_dir / "colmap", opts)
    if not maps:
        raise SfmError(
            "COLMAP could not build a model: too few matches between frames. Check that the "
            "frames overlap (a slow orbit) and are sharp"
        )
    return max(maps.values(), key=lambda r: r.num_reg_images())


def _normalised_keypoints(capture: Capture, database: Any, image_id: int, i: int) -> np.ndarray:
    """Frame ``i``'s keypoints as undistorted normalised image coordinates (N, 2)."""
    import cv2

    intr = capture.frames[i].intrinsics
    xy = database.read_keypoints(image_id)[:, :2] - PIXEL_CENTRE_OFFSET
    return cv2.undistortPoints(xy.reshape(-1, 1, 2).astype(np.float64), intr.K,
                               np.asarray(intr.distortion, float)).reshape(-1, 2)


def sampson_distance(E: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """First-order distance of matches ``x1 <-> x2`` (N, 2, normalised coordinates) to the
    epipolar geometry ``E`` (``x2' E x1 = 0``), in the same units."""
    h1 = np.column_stack([x1, np.ones(len(x1))])
    h2 = np.column_stack([x2, np.ones(len(x2))])
    Ex1 = h1 @ E.T
    Etx2 = h2 @ E
    numerator = np.einsum("ij,ij->i", h2, Ex1) ** 2
    denominator = Ex1[:, 0] ** 2 + Ex1[:, 1] ** 2 + Etx2[:, 0] ** 2 + Etx2[:, 1] ** 2
    return np.sqrt(numerator / np.maximum(denominator, 1e-30))


def ar_epipolar_error_deg(capture: Capture, db: Path) -> np.ndarray:
    """Per frame, how far its verified matches lie from the epipolar lines that the AR poses
    predict: the median over the frame's pairs of each pair's median Sampson distance, as an
    angle at the camera in degrees (infinite for a frame with no verified pair). The check
    uses the images alone through the matches, so AR poses that are wrong (shuffled, another
    convention) stand out by degrees while AR drift gives tenths of one."""
    import pycolmap

    index = {f.name: i for i, f in enumerate(capture.frames)}
    per_frame: list[list[float]] = [[] for _ in capture.frames]
    with pycolmap.Database.open(db) as database:
        frame_of = {im.image_id: index[im.name] for im in database.read_all_images()}
        points = {image_id: _normalised_keypoints(capture, database, image_id, i)
                  for image_id, i in frame_of.items()}
        pair_ids, geometries = database.read_two_view_geometries()
    for pair_id, geometry in zip(pair_ids, geometries, strict=True):
        matches = np.asarray(geometry.inlier_matches)
        if len(matches) == 0:
            continue
        id1, id2 = pycolmap.pair_id_to_image_pair(pair_id)
        i, j = frame_of[id1], frame_of[id2]
        T_cam2_from_cam1 = invert_rigid(capture.frames[j].T_world_from_cam) \
            @ capture.frames[i].T_world_from_cam
        t = T_cam2_from_cam1[:3, 3] / max(np.linalg.norm(T_cam2_from_cam1[:3, 3]), 1e-12)
        E = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]]) \
            @ T_cam2_from_cam1[:3, :3]
        distance = sampson_distance(E, points[id1][matches[:, 0]], points[id2][matches[:, 1]])
        error = float(np.degrees(np.arctan(np.median(distance))))
        per_frame[i].append(error)
        per_frame[j].append(error)
    return np.array([np.median(e) if e else np.inf for e in per_frame])


def _ar_posed_reconstruction(capture: Capture, db: Path, trusted: np.ndarray) -> Any:
    """A pycolmap model holding the database's cameras and images, the ``trusted`` frames
    registered at their AR poses, no points."""
    import pycolmap

    rec = pycolmap.Reconstruction()
    with pycolmap.Database.open(db) as database:
        for camera in database.read_all_cameras():
            rec.add_camera(camera)
        for rig in database.read_all_rigs():
            rec.add_rig(rig)
        for frame in database.read_all_frames():
            rec.add_frame(frame)
        images = database.read_all_images()
    index = {f.name: i for i, f in enumerate(capture.frames)}
    for image in images:
        rec.add_image(image)
        i = index[image.name]
        if trusted[i]:
            cam_from_world = invert_rigid(capture.frames[i].T_world_from_cam)[:3]
            rec.frame(image.frame_id).rig_from_world = pycolmap.Rigid3d(cam_from_world)
            rec.register_frame(image.frame_id)
    return rec


def _drop_weak_frames(rec: Any, min_observations: int) -> None:
    """Unregister the frames with fewer than ``min_observations`` triangulated points."""
    import pycolmap

    manager = pycolmap.ObservationManager(rec)
    for image in list(rec.images.values()):
        if image.has_pose and image.num_points3D < min_observations:
            manager.deregister_frame(image.frame_id)


def known_pose_mapping(capture: Capture, db: Path, scratch: Path, cfg: SfmConfig,
                       trusted: np.ndarray) -> Any:
    """Triangulate the matches in ``db`` from the AR poses of the ``trusted`` frames of
    ``capture``, then refine poses and points by bundle adjustment and re-triangulate with the
    refined poses.

    The AR poses are within millimetres and a few tenths of a degree of the truth, well inside
    the triangulator's 2-degree ray tolerance, so the tracks form as they would from exact
    poses; bundle adjustment then removes the AR error up to a similarity, which
    :func:`align_to_ar` fits. Frames whose AR pose disagrees with their matches triangulate
    few points and are left unregistered.
    """
    import pycolmap

    rec = _ar_posed_reconstruction(capture, db, trusted)
    scratch.mkdir(parents=True, exist_ok=True)  # pycolmap writes each round's model there
    triangulation = pycolmap.IncrementalPipelineOptions(num_threads=cfg.num_threads,
                                                        random_seed=cfg.seed)
    ba = pycolmap.BundleAdjustmentOptions(refine_focal_length=False,
                                          refine_principal_point=False,
                                          refine_extra_params=False, print_summary=False)
    ba.ceres.solver_options.max_num_iterations = cfg.ba_max_iterations
    ba.ceres.solver_options.num_threads = cfg.num_threads
    for round_ in range(cfg.known_pose_rounds + 1):
        rec = pycolmap.triangulate_points(rec, db, capture.root, scratch / f"round{round_}",
                                          options=triangulation)
        _drop_weak_frames(rec, cfg.min_observations_per_frame)
        if rec.num_reg_images() < 3:
            break
        pycolmap.bundle_adjustment(rec, ba)
    return rec


def align_to_ar(capture: Capture, rec: Any, cfg: SfmConfig) -> SfmResult:
    """Map a pycolmap reconstruction of ``capture`` into its metric world frame."""
    names = [f.name for f in capture.frames]
    index = {name: i for i, name in enumerate(names)}
    reg_idx, model_T = [], []
    for image in rec.images.values():
        if image.has_pose and image.name in index:
            reg_idx.append(index[image.name])
            cfw = np.vstack([image.cam_from_world().matrix(), [0, 0, 0, 1]])
            model_T.append(invert_rigid(cfw))
    n = len(names)
    order = np.argsort(reg_idx)
    reg_idx = np.asarray(reg_idx)[order]
    model_T = np.asarray(model_T)[order]
    registered = np.zeros(n, bool)
    registered[reg_idx] = True
    if registered.sum() < max(3, cfg.min_registered_fraction * n):
        raise SfmError(
            f"only {registered.sum()} of {n} frames registered; the capture needs more "
            "overlap between frames or more texture"
        )
    model_c = model_T[:, :3, 3]
    ar_c = capture.camera_centres[reg_idx]

    sim_all = _robust_sim3(model_c, ar_c, cfg.alignment_inlier_m, cfg.seed)
    s_all = float(np.cbrt(np.linalg.det(sim_all[:3, :3])))
    R_centres = sim_all[:3, :3] / s_all
    # The rotation from camera centres is only as good as drift / orbit radius (about half a
    # degree); the AR orientations drift a few tenths of a degree at most, so their mean
    # offset from the SfM orientations is the better world-from-model rotation.
    ar_R = np.stack([capture.frames[i].T_world_from_cam[:3, :3] for i in reg_idx])
    offsets = np.einsum("nij,nkj->nik", ar_R, model_T[:, :3, :3])
    shares = capture.elapsed_shares
    if cfg.scale_method == "drift_model":
        w = drift_weights(shares[reg_idx], cfg.ar_rot_jitter_deg, cfg.ar_rot_drift_deg)
        R = rotation_weighted_mean(offsets, w)
    else:
        R = rotation_mean(offsets)
    s_short = short_baseline_scale(model_c, ar_c, R, cfg.short_baseline_max_frames)
    s_drift, t_drift, drift = drift_model_alignment(
        model_c, ar_c, shares[reg_idx], R, cfg.ar_jitter_m, cfg.ar_drift_m
    )
    if cfg.scale_method == "drift_model":
        s, t = s_drift, t_drift
    else:
        s = s_short if cfg.scale_method == "short_baseline" else s_all
        t = (ar_c - s * model_c @ R.T).mean(axis=0)  # least squares with R and s fixed
    W = make_transform(s * R, t)
    residual = np.linalg.norm(model_c @ W[:3, :3].T + W[:3, 3] - ar_c, axis=1)
    if np.median(residual) > cfg.max_alignment_residual_m:
        raise SfmError(
            f"the AR poses disagree with the images: after alignment the camera centres "
            f"differ by {np.median(residual) * 1000:.0f} mm (median), far above AR drift. Is "
            "transform_matrix camera-to-world, in metres, with OpenGL camera axes?"
        )

    T = np.stack([f.T_world_from_cam for f in capture.frames]).copy()
    for k, i in enumerate(reg_idx):
        Tm = model_T[k]
        T[i] = make_transform(R @ Tm[:3, :3], W[:3, :3] @ Tm[:3, 3] + W[:3, 3])

    xyz, rgb = [], []
    for p in rec.points3D.values():
        xyz.append(p.xyz)
        rgb.append(p.color)
    xyz = np.asarray(xyz, float).reshape(-1, 3) @ W[:3, :3].T + W[:3, 3]
    rgb = np.asarray(rgb, np.uint8).reshape(-1, 3)
    summary = {
        "frame_names": names,
        "frame_elapsed_shares": shares.tolist(),
        "world_from_model": W.tolist(),
        "frames": n,
        "registered": int(registered.sum()),
        "unregistered_frames": [names[i] for i in np.flatnonzero(~registered)],
        "points": len(xyz),
        "reprojection_error_px": float(rec.compute_mean_reprojection_error()),
        "scale_method": cfg.scale_method,
        "scale_sim3_all": s_all,
        "scale_short_baseline": s_short,
        "scale_drift_model": s_drift,
        "scale_short_vs_all_pct": (s_short / s_all - 1) * 100,
        "ar_drift_estimate_max_m": float(np.linalg.norm(drift, axis=1).max()),
        "rotation_centres_vs_orientations_deg": rotation_angle_deg(R_centres, R),
        "residual_median_m": float(np.median(residual)),
        "residual_max_m": float(residual.max()),
    }
    if summary["unregistered_frames"]:
        log.warning("%d frames did not register and keep their AR pose: %s",
                    n - registered.sum(), ", ".join(summary["unregistered_frames"][:10]))
    return SfmResult(names, T, registered, xyz, rgb, W, summary)


def load_sfm(work_dir: Path) -> SfmResult:
    """Read a finished SfM stage back from ``work_dir/sfm``."""
    sfm_dir = Path(work_dir) / "sfm"
    summary = json.loads((sfm_dir / "summary.json").read_text())
    with np.load(sfm_dir / "points.npz") as points:
        xyz, rgb = points["xyz"], points["rgb"]
    return SfmResult(
        frame_names=list(summary["frame_names"]),
        T_world_from_cam=np.load(sfm_dir / "T_world_from_cam.npy"),
        registered=np.load(sfm_dir / "registered.npy"),
        points_xyz=xyz,
        points_rgb=rgb,
        world_from_model=np.asarray(summary["world_from_model"]),
        summary=summary,
    )


def evaluate_sfm(result: SfmResult, exact: Capture, reported: Capture) -> dict[str, float]:
    """Errors of ``result`` and of the AR poses (``reported``) against the ``exact`` poses.

    Camera-centre errors in metres and rotation errors in degrees over registered frames;
    the scale error of each scale estimate in percent (the true metres-per-unit is the
    Umeyama scale that maps the refined centres onto the exact ones, times the chosen one).
    """
    reg = result.registered
    refined_c = result.T_world_from_cam[reg, :3, 3]
    exact_c = exact.camera_centres[reg]
    ar_c = reported.camera_centres[reg]
    exact_R = [exact.frames[i].T_world_from_cam[:3, :3] for i in np.flatnonzero(reg)]
    ar_R = [reported.frames[i].T_world_from_cam[:3, :3] for i in np.flatnonzero(reg)]
    ref_R = result.T_world_from_cam[reg, :3, :3]
    fit = fit_similarity(refined_c, exact_c)
    s_fit = float(np.cbrt(np.linalg.det(fit[:3, :3])))
    s_true = result.scale * s_fit
    rot_ref = [rotation_angle_deg(a, b) for a, b in zip(ref_R, exact_R, strict=True)]
    rot_ar = [rotation_angle_deg(a, b) for a, b in zip(ar_R, exact_R, strict=True)]
    return {
        "registered_fraction": float(reg.mean()),
        "ar_centre_err_median_m": float(np.median(np.linalg.norm(ar_c - exact_c, axis=1))),
        "centre_err_median_m": float(np.median(np.linalg.norm(refined_c - exact_c, axis=1))),
        "centre_err_max_m": float(np.max(np.linalg.norm(refined_c - exact_c, axis=1))),
        "ar_rot_err_median_deg": float(np.median(rot_ar)),
        "rot_err_median_deg": float(np.median(rot_ref)),
        "rot_err_max_deg": float(np.max(rot_ref)),
        "scale_err_pct": (result.scale / s_true - 1) * 100,
        "scale_err_sim3_all_pct": (result.summary["scale_sim3_all"] / s_true - 1) * 100,
        "scale_err_short_baseline_pct": (result.summary["scale_short_baseline"] / s_true - 1)
        * 100,
        "scale_err_drift_model_pct": (result.summary["scale_drift_model"] / s_true - 1) * 100,
    }
