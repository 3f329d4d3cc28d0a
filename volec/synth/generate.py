"""Synthetic FoodKit captures: what a phone would record of a food item, and the truth.

In: an item name, a :class:`SynthConfig` (or a named preset) and an output folder.
Out, written atomically (a folder appears complete or not at all)::

    OUT/capture/          what the pipeline reads
        images/frame_00000.jpg ...   portrait JPEGs
        masks/frame_00000.png ...    food masks (when ``masks_in_capture``; a perfect segmenter)
        transforms.json              nerfstudio layout, AR-reported (drifting) metric poses
    OUT/ground_truth/     what only evaluation reads
        food_mesh.ply                the exact watertight food mesh, world frame, metres
        transforms_exact.json        the exact poses (same layout)
        masks/frame_00000.png ...    exact food masks
        masks_noisy/frame_00000.png  what a real segmenter might give (see ``mask_noise``)
        truth.json                   volume, seed, config, world-from-scene transform, AR errors

The capture's world frame is the AR session's: gravity-aligned with +y up (as ARKit), its
origin and heading unrelated to the plate, so nothing downstream may assume the object sits
at the origin or that z is up.
"""

from __future__ import annotations

import io
import json
import logging
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import trimesh
from PIL import Image

from volec.capture import Capture, Frame, Intrinsics, write_transforms_json
from volec.errors import ConfigError, OutputExistsError, UnknownNameError
from volec.geometry import look_at_opencv, make_transform, rotation_angle_deg, rotvec_to_matrix
from volec.io import (
    ensure_writable_output,
    fill_folder_atomic,
    write_bytes_atomic,
    write_json_atomic,
)
from volec.progress import Progress, progress_over
from volec.synth.render import LOOKS, LookConfig, Renderer, to_srgb8
from volec.synth.scene import HARD_SETUPS, Scene, Setup, build_scene, hard_setup
from volec.synth.shapes import ITEMS, item_mesh, stable_seed
from volec.synth.trajectory import (
    DriftConfig,
    TrajectoryConfig,
    ar_reported_poses,
    handheld_orbit,
)

log = logging.getLogger(__name__)

#: Maps the scene frame (z up) to an ARKit-like world frame (y up).
WORLD_FROM_SCENE_AXES = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


@dataclass(frozen=True)
class SynthConfig:
    """Everything that decides a synthetic capture; the same config and seed give the same bytes."""

    trajectory: TrajectoryConfig = field(default_factory=TrajectoryConfig)
    """The handheld orbit."""
    drift: DriftConfig = field(default_factory=DriftConfig)
    """How the AR poses written to the capture err."""
    width: int = 480
    """Image width, pixels (portrait)."""
    height: int = 640
    """Image height, pixels."""
    focal_px: float = 520.0
    """Focal length, pixels (about 63 degrees across the long side, like a phone)."""
    principal_offset_px: tuple[float, float] = (1.3, -0.9)
    """Principal point offset from the image centre, pixels."""
    look: LookConfig = field(default_factory=LookConfig)
    """The camera's optics and the light (:data:`volec.synth.render.LOOKS`): by default what a
    phone records (edges integrated over the pixel, a soft light, optical blur)."""
    texture_contrast: float = 0.6
    """Contrast of the food's fine grain and speckles, relative to the first benchmark's
    procedural textures (which were sharper and more contrasted than real skins); items with
    smooth skins are fainter still (:attr:`volec.synth.scene.Palette.grain`)."""
    shot_noise: float = 1e-4
    """Photon noise: its variance in linear intensity (0..1) per unit of intensity."""
    image_noise_std: float = 1.0
    """Read noise standard deviation, in 8-bit levels."""
    exposure_variation: float = 0.03
    """Relative frame-to-frame auto-exposure change."""
    jpeg_quality: int = 90
    """JPEG quality of the frames."""
    motion_blur_share: float = 0.0
    """Share of frames smeared by hand motion (a phone video's shaken frames); 0: none."""
    motion_blur_px: float = 12.0
    """The longest smear of a shaken frame, pixels (each shaken frame draws its length between
    a quarter of this and this, and its direction near the orbit's, horizontal, one)."""
    mask_noise: bool = False
    """The capture's masks are what a real segmenter might give (boundaries a few pixels
    off, the shadow leaking in on some frames, a missed chunk or a false blob on a few, two
    empty), not the exact ones (:mod:`volec.synth.masknoise`); the ground truth keeps those."""
    setup: str = "plain"
    """What surrounds the food: ``plain`` (the benchmark's plate, centred), ``hard`` (each
    item one of :data:`volec.synth.scene.HARD_SETUPS`: a plate like the food, white on white,
    across the rim, strong shadows, a cup or a fork beside it, dim or bright light) or one of
    those names for every item."""
    masks_in_capture: bool = True
    """Also give the capture the exact food masks (as a perfect segmentation model would)."""
    mesh_resolution: int = 112
    """Marching-cubes cells along the food's longest side."""
    seed: int = 0
    """Seed for the trajectory, drift, placement, textures and noise."""
    workers: int = 2
    """Processes rendering frames in parallel (1 renders in this process)."""

    def __post_init__(self) -> None:
        if self.width < 16 or self.height < 16:
            raise ConfigError(f"image size {self.width}x{self.height} is too small")
        if not 1 <= self.jpeg_quality <= 100:
            raise ConfigError(f"jpeg_quality must be in 1..100, got {self.jpeg_quality}")
        if self.workers < 1:
            raise ConfigError(f"workers must be at least 1, got {self.workers}")
        if not 0.0 <= self.motion_blur_share <= 1.0:
            raise ConfigError(f"motion_blur_share must be in 0..1, got {self.motion_blur_share}")

    @property
    def intrinsics(self) -> Intrinsics:
        """The phone camera's intrinsics (pinhole, no distortion)."""
        return Intrinsics(
            width=self.width,
            height=self.height,
            fx=self.focal_px,
            fy=self.focal_px,
            cx=(self.width - 1) / 2 + self.principal_offset_px[0],
            cy=(self.height - 1) / 2 + self.principal_offset_px[1],
        )

    def recorded(self) -> dict[str, Any]:
        """The fields that decide the output (``workers`` does not), as plain JSON data."""
        data = json.loads(json.dumps(asdict(self)))
        data.pop("workers")
        return data

    def with_(self, **changes: Any) -> SynthConfig:
        """A copy with top-level fields, or ``n_frames``, ``arc_deg``, ``drift_m`` changed."""
        traj = {k: changes.pop(k) for k in ("n_frames", "arc_deg") if k in changes}
        drift_m = changes.pop("drift_m", None)
        cfg = replace(self, **changes)
        if traj:
            cfg = replace(cfg, trajectory=replace(cfg.trajectory, **traj))
        if drift_m is not None:
            cfg = replace(cfg, drift=replace(cfg.drift, position_m=drift_m))
        return cfg


#: The first benchmark's look: one ray per pixel centre, a point light, no blur, no photon
#: noise, the full procedural texture contrast.
SHARP = {"look": LOOKS["sharp"], "texture_contrast": 1.0, "shot_noise": 0.0,
         "image_noise_std": 1.5, "jpeg_quality": 92}

#: The ``smooth`` preset's texture contrast (the default's is 0.6).
SMOOTH_TEXTURE_CONTRAST = 0.15

PRESETS: dict[str, SynthConfig] = {
    "default": SynthConfig(),
    "sharp": SynthConfig(**SHARP),
    "half_orbit": SynthConfig(trajectory=TrajectoryConfig(arc_deg=180.0)),
    "drift_1cm": SynthConfig(drift=DriftConfig(position_m=0.01, rotation_deg=0.6)),
    "quick": SynthConfig(
        trajectory=TrajectoryConfig(n_frames=12), width=240, height=320, focal_px=260.0,
        mesh_resolution=64,
    ),
    "video": SynthConfig(trajectory=TrajectoryConfig(n_frames=1000), motion_blur_share=0.25),
    "low": SynthConfig(trajectory=TrajectoryConfig(n_frames=60, elevation_min_deg=10.0,
                                                   elevation_max_deg=25.0)),
    "smooth": SynthConfig(texture_contrast=SMOOTH_TEXTURE_CONTRAST),
}
"""Named configs: ``default`` (100 frames, full orbit, a phone's look), ``sharp`` (the same with
the first benchmark's look), ``half_orbit``, ``drift_1cm``, ``quick``, ``video`` (30 s of phone
video: 1000 frames, a quarter of them smeared by hand motion), ``low`` (60 frames at 10-25
degrees of elevation: the top seen obliquely, more of the item hidden by itself) and
``smooth`` (the full orbit with skins as faint as a peach's or a plum's: at 0.15, dense
stereo covered 70 % of the seen surface of the benchmark pear and 82 % of the apple's)."""


# ----------------------------------------------------------------------------- rendering

_WORKER: dict[str, Any] = {}


def _init_worker(scene: Scene) -> None:
    _WORKER["renderer"] = Renderer(scene)


def _png(mask: np.ndarray) -> bytes:
    buf = io.BytesIO()
    Image.fromarray((mask * 255).astype(np.uint8)).save(buf, format="PNG")
    return buf.getvalue()


def _render_frame(args: tuple[int, np.ndarray, SynthConfig]
                  ) -> tuple[bytes, bytes, np.ndarray]:
    """Render one frame; returns (JPEG bytes, mask PNG bytes, the shadow beside the food as a
    packed bit array). Seeded by frame index."""
    index, T_scene_from_cam, cfg = args
    renderer: Renderer = _WORKER["renderer"]
    K = cfg.intrinsics.K
    view = renderer.render(K, cfg.width, cfg.height, T_scene_from_cam, cfg.look)
    rng = np.random.default_rng([cfg.seed, index, 7])
    gain = 1.0 + cfg.exposure_variation * np.sin(0.15 * index + cfg.seed)
    linear = np.clip(view.rgb * gain, 0.0, 1.0)
    smear = hand_shake(cfg, index)
    if smear is not None:
        linear = motion_blur(linear, *smear)
    if cfg.shot_noise > 0:
        linear = linear + rng.normal(size=linear.shape) * np.sqrt(cfg.shot_noise * linear)
    img = to_srgb8(linear).astype(float)
    img += rng.normal(scale=cfg.image_noise_std, size=img.shape)
    img8 = np.clip(np.round(img), 0, 255).astype(np.uint8)
    jpg = io.BytesIO()
    Image.fromarray(img8).save(jpg, format="JPEG", quality=cfg.jpeg_quality)
    return jpg.getvalue(), _png(view.food_mask), np.packbits(view.shadow)


def hand_shake(cfg: SynthConfig, index: int) -> tuple[float, float] | None:
    """(smear length in pixels, its angle in degrees) of frame ``index`` when hand motion blurs
    it, else None; seeded by the frame index."""
    rng = np.random.default_rng([cfg.seed, index, 11])
    if cfg.motion_blur_share <= 0 or rng.random() >= cfg.motion_blur_share:
        return None
    return float(rng.uniform(0.25, 1.0) * cfg.motion_blur_px), float(rng.normal(scale=20.0))


def motion_blur(linear: np.ndarray, length_px: float, angle_deg: float) -> np.ndarray:
    """``linear`` (H, W, 3) smeared along a line of ``length_px`` at ``angle_deg`` from the
    image's horizontal: what moving the phone during the exposure gives."""
    import cv2

    size = int(np.ceil(length_px)) | 1
    kernel = np.zeros((size, size), np.float32)
    c = size // 2
    t = np.linspace(-length_px / 2, length_px / 2, 4 * size)
    a = np.radians(angle_deg)
    cols = np.clip(np.round(c + t * np.cos(a)).astype(int), 0, size - 1)
    rows = np.clip(np.round(c - t * np.sin(a)).astype(int), 0, size - 1)
    np.add.at(kernel, (rows, cols), 1.0)
    kernel /= kernel.sum()
    return cv2.filter2D(linear.astype(np.float32), -1, kernel, borderType=cv2.BORDER_REFLECT
                        ).astype(linear.dtype)


def render_frames(
    scene: Scene, poses: np.ndarray, cfg: SynthConfig, progress: bool = True
) -> list[tuple[bytes, bytes, np.ndarray]]:
    """Render every pose of ``poses`` (scene frame) to (JPEG, mask PNG, packed shadow), in
    order."""
    jobs = [(i, poses[i], cfg) for i in range(len(poses))]
    results: list[tuple[bytes, bytes, np.ndarray]] = []
    with Progress(len(jobs), "render", "frames", progress) as bar:
        if cfg.workers == 1 or len(jobs) < 4:
            _init_worker(scene)
            for job in jobs:
                results.append(_render_frame(job))
                bar.update()
        else:
            with ProcessPoolExecutor(cfg.workers, initializer=_init_worker,
                                     initargs=(scene,)) as ex:
                for r in ex.map(_render_frame, jobs, chunksize=2):
                    results.append(r)
                    bar.update()
    return results


# ----------------------------------------------------------------------------- the capture


@dataclass
class SynthScene:
    """The deterministic part of a synthetic capture, before rendering."""

    item: str
    scene: Scene
    T_world_from_scene: np.ndarray
    exact_scene_poses: np.ndarray
    reported_scene_poses: np.ndarray


def scene_setup(item: str, name: str) -> Setup:
    """The :class:`~volec.synth.scene.Setup` that ``SynthConfig.setup`` names for ``item``."""
    if name == "plain":
        return Setup()
    if name == "hard":
        return hard_setup(item)[1]
    if name not in HARD_SETUPS:
        raise ConfigError(f"unknown setup '{name}'; use plain, hard or one of "
                          f"{', '.join(HARD_SETUPS)}")
    return HARD_SETUPS[name]


def plan_capture(item: str, cfg: SynthConfig) -> SynthScene:
    """Build the scene, the exact trajectory and the AR-reported poses for ``item``."""
    if item not in ITEMS:
        raise UnknownNameError(f"unknown food item '{item}'; `volec synth --list` shows the items")
    rng = np.random.default_rng([cfg.seed, stable_seed(item)])
    food = item_mesh(item, cfg.mesh_resolution)
    texture_seed = int(rng.integers(2**31))
    scene = build_scene(food, item, seed=texture_seed, yaw_rad=rng.uniform(0, 2 * np.pi),
                        texture_contrast=cfg.texture_contrast, setup=scene_setup(item, cfg.setup))
    lo, hi = scene.food.bounds
    centre = (lo + hi) / 2
    radius = float(np.linalg.norm(hi - lo) / 2)
    exact = handheld_orbit(cfg.trajectory, centre, radius, rng)
    reported = ar_reported_poses(exact, cfg.drift, rng)
    yaw = rotvec_to_matrix(np.array([0.0, rng.uniform(0, 2 * np.pi), 0.0]))
    offset = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.4, -0.1), rng.uniform(-0.8, -0.2)])
    T_world_from_scene = make_transform(yaw @ WORLD_FROM_SCENE_AXES, offset)
    return SynthScene(item, scene, T_world_from_scene, exact, reported)


class ExactDepth:
    """Exact depth maps of a synthetic capture's scene, for evaluation only: the renderer's
    depth through any camera given in the capture's world frame."""

    def __init__(self, item: str, cfg: SynthConfig) -> None:
        from volec.geometry import invert_rigid

        plan = plan_capture(item, cfg)
        self._renderer = Renderer(plan.scene)
        self._scene_from_world = invert_rigid(plan.T_world_from_scene)

    def __call__(self, K: np.ndarray, width: int, height: int, T_world_from_cam: np.ndarray
                 ) -> np.ndarray:
        """(H, W) z-depth in metres (inf where the ray meets nothing) through ``K``."""
        T_scene_from_cam = self._scene_from_world @ np.asarray(T_world_from_cam, float)
        return self._renderer.depth(K, width, height, T_scene_from_cam)[0]


def _pose_errors(reported: np.ndarray, exact: np.ndarray) -> dict[str, float]:
    pos = np.linalg.norm(reported[:, :3, 3] - exact[:, :3, 3], axis=1)
    rot = np.array(
        [rotation_angle_deg(a[:3, :3], b[:3, :3]) for a, b in zip(reported, exact, strict=True)]
    )
    return {
        "position_error_median_m": float(np.median(pos)),
        "position_error_max_m": float(pos.max()),
        "rotation_error_median_deg": float(np.median(rot)),
        "rotation_error_max_deg": float(rot.max()),
    }


def _capture_of(root: Path, names: list[str], poses: np.ndarray, intr: Intrinsics,
                masks: bool, image_root: Path, metadata: dict[str, Any]) -> Capture:
    frames = tuple(
        Frame(
            name=f"images/{n}.jpg",
            image_path=image_root / "images" / f"{n}.jpg",
            intrinsics=intr,
            T_world_from_cam=poses[i],
            mask_path=(root / "masks" / f"{n}.png") if masks else None,
        )
        for i, n in enumerate(names)
    )
    return Capture(root=root, frames=frames, metadata=metadata, metric=True)


def synth_code() -> dict[str, str]:
    """The volec version and the digest of the generator's source: a capture generated by other
    code is generated again by the experiments (see :func:`is_current`)."""
    from volec.provenance import code_identity

    return code_identity("volec.synth.generate")


def is_current(out: Path, cfg: SynthConfig) -> bool:
    """Whether ``out`` holds a finished capture made with ``cfg`` by the current generator."""
    truth = Path(out) / "ground_truth" / "truth.json"
    if not truth.exists():
        return False
    try:
        recorded = json.loads(truth.read_text())
    except json.JSONDecodeError:
        return False
    return recorded.get("config") == cfg.recorded() and recorded.get("code") == synth_code()


def _noisy_masks(rendered: list[tuple[bytes, bytes, np.ndarray]], cfg: SynthConfig
                 ) -> tuple[list[bytes], list[str]]:
    """What a real segmenter might give for the exact masks (:mod:`volec.synth.masknoise`),
    as PNGs, with what was done to each: the capture's masks with ``mask_noise``, and
    always ``ground_truth/masks_noisy`` for the experiments."""
    from volec.synth.masknoise import MaskNoiseConfig, noisy_masks

    shape = (cfg.height, cfg.width)
    exact = [np.asarray(Image.open(io.BytesIO(png))) > 127 for _, png, _ in rendered]
    shadows = [np.unpackbits(bits)[: shape[0] * shape[1]].reshape(shape).astype(bool)
               for _, _, bits in rendered]
    noisy, notes = noisy_masks(exact, shadows, MaskNoiseConfig(seed=cfg.seed))
    return [_png(m) for m in noisy], notes


def write_synthetic_capture(
    item: str, out: Path, cfg: SynthConfig | None = None, overwrite: bool = False,
    progress: bool = True,
) -> Path:
    """Render ``item`` with ``cfg`` and write ``out/capture`` and ``out/ground_truth``.

    Refuses to replace an existing non-empty ``out`` unless ``overwrite``. Returns ``out``.
    """
    cfg = cfg or PRESETS["default"]
    out = Path(out)
    ensure_writable_output(out, overwrite)  # fail before minutes of rendering, not after
    plan = plan_capture(item, cfg)
    Tws = plan.T_world_from_scene
    exact_world = np.einsum("ij,njk->nik", Tws, plan.exact_scene_poses)
    reported_world = np.einsum("ij,njk->nik", Tws, plan.reported_scene_poses)
    rendered = render_frames(plan.scene, plan.exact_scene_poses, cfg, progress=progress)
    names = [f"frame_{i:05d}" for i in range(len(rendered))]
    noisy_pngs, noise_notes = _noisy_masks(rendered, cfg)
    capture_masks = noisy_pngs if cfg.mask_noise else [png for _, png, _ in rendered]

    def fill(tmp: Path) -> None:
        cap_dir, gt_dir = tmp / "capture", tmp / "ground_truth"
        for d in (cap_dir / "images", gt_dir / "masks", gt_dir / "masks_noisy") + (
                (cap_dir / "masks",) if cfg.masks_in_capture else ()):
            d.mkdir(parents=True)
        for n, (jpg, png, _), given, noisy in zip(names, rendered, capture_masks, noisy_pngs,
                                                  strict=True):
            (cap_dir / "images" / f"{n}.jpg").write_bytes(jpg)
            (gt_dir / "masks" / f"{n}.png").write_bytes(png)
            (gt_dir / "masks_noisy" / f"{n}.png").write_bytes(noisy)
            if cfg.masks_in_capture:
                (cap_dir / "masks" / f"{n}.png").write_bytes(given)
        meta = {"source": "volec synth", "world_up": [0.0, 1.0, 0.0]}
        intr = cfg.intrinsics
        write_transforms_json(
            _capture_of(cap_dir, names, reported_world, intr, cfg.masks_in_capture, cap_dir, meta),
            cap_dir / "transforms.json",
        )
        write_transforms_json(
            _capture_of(gt_dir, names, exact_world, intr, True, cap_dir, {"source": "exact"}),
            gt_dir / "transforms_exact.json",
        )
        food_world = plan.scene.food.copy()
        food_world.apply_transform(Tws)
        write_bytes_atomic(gt_dir / "food_mesh.ply", food_world.export(file_type="ply"))
        truth = {
            "item": item,
            "label": ITEMS[item].label,
            "volume_ml": float(food_world.volume * 1e6),
            "table_volume_ml": float(ITEMS[item].volume_ml),
            "n_frames": len(names),
            "world_up": [0.0, 1.0, 0.0],
            "T_world_from_scene": Tws.tolist(),
            "plate_radius_m": plan.scene.plate_radius_m,
            "setup": asdict(plan.scene.setup),
            "masks_in_capture": "noisy" if cfg.mask_noise else "exact",
            "mask_noise": dict(zip(names, noise_notes, strict=True)),
            "motion_blur": {n: {"length_px": round(smear[0], 2), "angle_deg": round(smear[1], 1)}
                            for i, n in enumerate(names)
                            if (smear := hand_shake(cfg, i)) is not None},
            "ar_pose_error": _pose_errors(reported_world, exact_world),
            "config": cfg.recorded(),
            "code": synth_code(),
        }
        write_json_atomic(gt_dir / "truth.json", truth)

    return fill_folder_atomic(out, fill, overwrite=overwrite)


def write_benchmark(
    root: Path, items: list[str] | None = None, cfg: SynthConfig | None = None,
    overwrite: bool = False, progress: bool = True,
) -> list[Path]:
    """Write one capture per item under ``root/ITEM``; finished items with the same config are
    kept (a re-run only does what is missing). A finished item with another config is an error
    unless ``overwrite``."""
    cfg = cfg or PRESETS["default"]
    items = items or list(ITEMS)
    done: list[Path] = []
    for item in progress_over(items, "benchmark", progress, "items"):
        out = Path(root) / item
        truth = out / "ground_truth" / "truth.json"
        if truth.exists() and not overwrite:
            if not is_current(out, cfg):
                raise OutputExistsError(
                    f"{out} was generated with another config or by another version of the "
                    "generator; pass overwrite=True (--overwrite) to regenerate it, or choose "
                    "another folder"
                )
            log.info("%s: already generated, kept", out)
            done.append(out)
            continue
        done.append(write_synthetic_capture(item, out, cfg, overwrite=overwrite,
                                            progress=progress))
    return done


def render_preview(item: str, size_px: int = 320, seed: int = 0,
                   elevation_deg: float = 35.0, cfg: SynthConfig | None = None) -> np.ndarray:
    """A square 8-bit RGB picture of ``item`` on its plate, for galleries, with the look of
    ``cfg`` (the default preset's)."""
    cfg = cfg or PRESETS["default"]
    food = item_mesh(item)
    scene = build_scene(food, item, seed=seed, yaw_rad=0.6, texture_contrast=cfg.texture_contrast)
    lo, hi = scene.food.bounds
    centre = (lo + hi) / 2
    radius = float(np.linalg.norm(hi - lo) / 2)
    distance = max(radius / np.tan(np.radians(17)), 0.12)
    e = np.radians(elevation_deg)
    eye = centre + distance * np.array([np.cos(e) * np.cos(-0.9), np.cos(e) * np.sin(-0.9),
                                        np.sin(e)])
    T = look_at_opencv(eye, centre, np.array([0.0, 0.0, 1.0]))
    f = size_px / 2 / np.tan(np.radians(20))
    K = np.array([[f, 0, (size_px - 1) / 2], [0, f, (size_px - 1) / 2], [0, 0, 1.0]])
    return to_srgb8(Renderer(scene).render(K, size_px, size_px, T, cfg.look).rgb)


def load_truth(out: Path) -> dict[str, Any]:
    """The ``truth.json`` of a synthetic capture written to ``out``."""
    return json.loads((Path(out) / "ground_truth" / "truth.json").read_text())


def load_ground_truth_mesh(out: Path) -> trimesh.Trimesh:
    """The exact food mesh (world frame, metres) of a synthetic capture written to ``out``."""
    mesh = trimesh.load(Path(out) / "ground_truth" / "food_mesh.ply", process=False)
    if not isinstance(mesh, trimesh.Trimesh):
        raise ValueError(f"{out}: food_mesh.ply is not a single mesh")
    return mesh


__all__ = [
    "PRESETS",
    "SynthConfig",
    "load_ground_truth_mesh",
    "load_truth",
    "plan_capture",
    "render_preview",
    "write_benchmark",
    "write_synthetic_capture",
]
