"""Training data for completion: realistic partial views of procedural food shapes.

In: training shapes (:mod:`volec.synth.families`, never the benchmark items) and a
:class:`ViewConfig`. Out: per shape, the complete surface (uniform samples) and
``views_per_shape`` partial clouds, each what a phone orbit would reconstruct: the points that
at least two cameras of a random orbit see, none of them edge-on (an arc of random length, so
part of the item can be missing), never the bottom (it rests on the table), with a few holes
(patches stereo missed) and the dense cloud's noise. Stored as one ``.npz`` per shape;
:class:`CompletionDataset` serves normalized (partial, complete) pairs.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from volec.capture import Capture, Frame, Intrinsics
from volec.completion.preprocess import frame_normalization, resample
from volec.geometry import look_at_opencv
from volec.io import write_bytes_atomic
from volec.metrics import sample_surface, sample_surface_with_normals, views_seeing
from volec.progress import Progress
from volec.synth.families import family_mesh

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ViewConfig:
    """How partial views are simulated."""

    n_surface_points: int = 8000
    """Surface samples tested for visibility per view (the partial is a subset)."""
    n_complete_points: int = 8192
    """Uniform samples of the complete surface stored as the target."""
    cameras: int = 10
    """Cameras along each view's orbit."""
    arc_deg: tuple[float, float] = (150.0, 360.0)
    """Range of the orbit's arc, degrees (less than 360: part of the side is unseen)."""
    elevation_deg: tuple[float, float] = (15.0, 60.0)
    """Range of camera elevations above the table, degrees."""
    min_views: int = 2
    """A point must be seen by this many cameras (stereo needs two)..."""
    min_view_cosine: float = 0.5
    """... each seeing it no more obliquely than this cosine between the surface normal and
    the direction to the camera: the dense stage drops depths seen more obliquely
    (``DenseConfig.min_oblique_cosine``), so a real cloud stops short of grazing rims and of
    the underside a camera above the table sees only edge-on. The network trained on views
    without this limit put its underside just below the lowest observed points, inside the
    truth (on the benchmark's sparse captures: pear -4.5 %, capsicum -3.0 %)."""
    contact_height_m: float = 0.002
    """Points this close to the table are hidden (the food rests on it)."""
    noise_m: float = 0.0004
    """Standard deviation of the Gaussian noise added to the partial points, metres (the
    benchmark's phone-look masked clouds lie within -0.6/+0.6 mm of the true surface at their
    10th/90th percentiles: a Gaussian of about 0.45 mm)."""
    holes: tuple[int, int] = (0, 3)
    """Range of the number of holes cut into each view (both ends included): patches dense
    stereo misses, on faint skins and specular spots."""
    hole_radius_share: tuple[float, float] = (0.05, 0.15)
    """Range of a hole's radius, as a share of the shape's largest extent."""


def orbit_cameras(mesh: trimesh.Trimesh, rng: np.random.Generator, cfg: ViewConfig) -> Capture:
    """A random orbit of ``cfg.cameras`` pinhole cameras looking at the mesh from above the
    table (z = 0)."""
    centre = mesh.bounds.mean(axis=0)
    radius = float(np.linalg.norm(mesh.extents)) / 2
    arc = np.radians(rng.uniform(*cfg.arc_deg))
    start = rng.uniform(0, 2 * np.pi)
    intr = Intrinsics(320, 240, 260.0, 260.0, 159.5, 119.5)
    frames = []
    for i in range(cfg.cameras):
        a = start + arc * i / max(cfg.cameras - 1, 1)
        e = np.radians(rng.uniform(*cfg.elevation_deg))
        eye = centre + 3.5 * radius * np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a),
                                                np.sin(e)])
        T = look_at_opencv(eye, centre, np.array([0.0, 0.0, 1.0]))
        frames.append(Frame(f"cam{i}", Path(f"cam{i}"), intr, T))
    return Capture(Path("."), tuple(frames))


def partial_view(mesh: trimesh.Trimesh, rng: np.random.Generator, cfg: ViewConfig) -> np.ndarray:
    """(N, 3) points of ``mesh`` that one random orbit reconstructs, metres."""
    points, normals = sample_surface_with_normals(mesh, cfg.n_surface_points,
                                                  seed=int(rng.integers(2**31)))
    seen = views_seeing(points, mesh, orbit_cameras(mesh, rng, cfg), normals=normals,
                        min_cosine=cfg.min_view_cosine) >= cfg.min_views
    seen &= points[:, 2] > mesh.bounds[0, 2] + cfg.contact_height_m
    seen &= ~in_holes(points, seen, float(mesh.extents.max()), rng, cfg)
    return points[seen] + rng.normal(scale=cfg.noise_m, size=(int(seen.sum()), 3))


def in_holes(points: np.ndarray, seen: np.ndarray, size_m: float, rng: np.random.Generator,
             cfg: ViewConfig) -> np.ndarray:
    """(N,) which of ``points`` fall in the view's holes: balls of random radius (a share of
    ``size_m``) around random ``seen`` points, as many as ``cfg.holes`` draws."""
    out = np.zeros(len(points), bool)
    candidates = np.flatnonzero(seen)
    count = int(rng.integers(cfg.holes[0], cfg.holes[1] + 1))
    if not len(candidates) or count == 0:
        return out
    for centre in points[rng.choice(candidates, count)]:
        radius = rng.uniform(*cfg.hole_radius_share) * size_m
        out |= np.linalg.norm(points - centre, axis=1) < radius
    return out


def shape_sample(family: str, seed: int, views: int, cfg: ViewConfig) -> dict[str, np.ndarray]:
    """The complete samples and ``views`` partial views of the shape ``family-seed``."""
    mesh = family_mesh(family, seed)
    rng = np.random.default_rng([seed, views, len(family)])
    partials = [partial_view(mesh, rng, cfg) for _ in range(views)]
    return {
        "complete": sample_surface(mesh, cfg.n_complete_points, seed=seed),
        "partial_points": np.concatenate(partials).astype(np.float32),
        "partial_sizes": np.array([len(p) for p in partials]),
        "volume_ml": np.array(mesh.volume * 1e6),
    }


def _write_shape(args: tuple[str, int, int, ViewConfig, Path]) -> Path:
    import io

    family, seed, views, cfg, path = args
    buf = io.BytesIO()
    np.savez_compressed(buf, **shape_sample(family, seed, views, cfg))
    write_bytes_atomic(path, buf.getvalue())
    return path


def write_dataset(shapes: list[tuple[str, int]], views: int, out_dir: Path,
                  cfg: ViewConfig | None = None, workers: int = 2,
                  progress: bool = True) -> list[Path]:
    """One ``FAMILY-SEED.npz`` per shape in ``out_dir``, made by ``workers`` processes. An
    existing file is kept: its name and the config fix its content (the config's hash is in
    the folder name the callers choose)."""
    from concurrent.futures import ProcessPoolExecutor

    cfg = cfg or ViewConfig()
    out_dir = Path(out_dir)
    paths = [out_dir / f"{family}-{seed}.npz" for family, seed in shapes]
    todo = [(f, s, views, cfg, p) for (f, s), p in zip(shapes, paths, strict=True)
            if not p.exists()]
    if todo:
        with Progress(len(todo), "completion training data", "shapes", progress) as bar:
            if workers > 1:
                with ProcessPoolExecutor(workers) as pool:
                    for _ in pool.map(_write_shape, todo):
                        bar.update()
            else:
                for args in todo:
                    _write_shape(args)
                    bar.update()
    return paths


TABLE_UP = np.array([0.0, 0.0, 1.0])
"""The training shapes' up: they rest on the table at z = 0."""


class CompletionDataset:
    """Normalized (partial, complete) pairs from the files of :func:`write_dataset`.

    Item ``i`` is view ``i % views`` of shape ``i // views``; each draw resamples the partial
    to ``n_input`` points and the complete cloud to ``n_complete`` with ``rng``, and maps both
    with the partial's normalization in ``frame`` (the shapes rest on the table, up
    :data:`TABLE_UP`), as inference will.
    """

    def __init__(self, paths: list[Path], n_input: int, n_complete: int,
                 frame: str = "pca") -> None:
        self.n_input, self.n_complete, self.frame = n_input, n_complete, frame
        self.partials: list[np.ndarray] = []
        self.completes: list[np.ndarray] = []
        self.owner: list[int] = []
        for k, path in enumerate(paths):
            with np.load(path) as data:
                self.completes.append(data["complete"].astype(float))
                splits = np.cumsum(data["partial_sizes"])[:-1]
                for part in np.split(data["partial_points"].astype(float), splits):
                    self.partials.append(part)
                    self.owner.append(k)

    def __len__(self) -> int:
        return len(self.partials)

    def pair(self, i: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """(partial (n_input, 3), complete (n_complete, 3)) of item ``i``, normalized."""
        partial = self.partials[i]
        norm = frame_normalization(partial, self.frame, TABLE_UP)
        complete = resample(self.completes[self.owner[i]], self.n_complete, rng)
        return norm.apply(resample(partial, self.n_input, rng)), norm.apply(complete)

    def batch(self, indices: np.ndarray, rng: np.random.Generator
              ) -> tuple[np.ndarray, np.ndarray]:
        """Stacked float32 pairs of :meth:`pair` for ``indices``."""
        pairs = [self.pair(int(i), rng) for i in indices]
        return (np.stack([p for p, _ in pairs]).astype(np.float32),
                np.stack([c for _, c in pairs]).astype(np.float32))
