"""Capture I/O: a phone capture as a typed :class:`Capture`.

In: a folder in nerfstudio's ``transforms.json`` layout (metric, OpenGL camera-to-world,
global or per-frame intrinsics, optional ``mask_path``), or a COLMAP model (text or binary)
with its image folder.
Out: a :class:`Capture` whose frames carry absolute image paths, pinhole + OpenCV-distortion
intrinsics and ``T_world_from_cam`` with OpenCV camera axes (x right, y down, z forward).
The axis conversion (and the half-pixel principal-point shift of nerfstudio and COLMAP files)
happens here, once, at the boundary; nothing else in volec sees OpenGL axes.

Writing goes the other way (:func:`write_transforms_json`) and round-trips every pose exactly.
"""

from __future__ import annotations

import io
import logging
import os
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
from PIL import Image

from volec.errors import CaptureError
from volec.geometry import invert_rigid, opencv_c2w_to_opengl, opengl_c2w_to_opencv, rigid_problem
from volec.io import write_json_atomic

log = logging.getLogger(__name__)

#: Camera models volec reads, with the distortion keys each one uses (nerfstudio naming),
#: in OpenCV order.
DISTORTION_KEYS: dict[str, tuple[str, ...]] = {
    "PINHOLE": (),
    "OPENCV": ("k1", "k2", "p1", "p2"),
    "FULL_OPENCV": ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"),
    "OPENCV_FISHEYE": ("k1", "k2", "k3", "k4"),
}
_INTRINSIC_KEYS = ("fl_x", "fl_y", "cx", "cy", "w", "h")
#: nerfstudio and COLMAP put the centre of the first pixel at (0.5, 0.5); volec (OpenCV) at
#: (0, 0). Files keep their convention; ``Intrinsics`` always holds OpenCV's.
PIXEL_CENTRE_OFFSET = 0.5


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics in pixels plus OpenCV distortion coefficients."""

    width: int
    """Image width in pixels."""
    height: int
    """Image height in pixels."""
    fx: float
    """Focal length along x, pixels."""
    fy: float
    """Focal length along y, pixels."""
    cx: float
    """Principal point x, pixels (OpenCV convention: pixel centres at integers)."""
    cy: float
    """Principal point y, pixels."""
    model: str = "PINHOLE"
    """Camera model name, one of :data:`DISTORTION_KEYS`."""
    distortion: tuple[float, ...] = ()
    """Distortion coefficients in the order :data:`DISTORTION_KEYS` gives for ``model``."""

    @property
    def K(self) -> np.ndarray:
        """3x3 calibration matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def is_undistorted(self) -> bool:
        """True when every distortion coefficient is zero."""
        return not any(self.distortion)

    def project(self, points_cam: np.ndarray) -> np.ndarray:
        """Pixel coordinates (N, 2) of camera-frame points (N, 3), distortion applied; NaN for
        points at or behind the camera."""
        pts = np.asarray(points_cam, float).reshape(-1, 3)
        z = pts[:, 2]
        front = z > 1e-9
        if self.is_undistorted:
            # Column by column, in place (x / z * f + c, as one expression would give): on
            # 500,000 points several times faster than indexing the points in front and
            # building (N, 2) temporaries; carving projects every grid point into 50 views.
            uv = np.empty((len(pts), 2))
            with np.errstate(divide="ignore", invalid="ignore"):
                for axis, (f, c) in enumerate(((self.fx, self.cx), (self.fy, self.cy))):
                    column = uv[:, axis]
                    np.divide(pts[:, axis], z, out=column)
                    column *= f
                    column += c
            uv[~front] = np.nan
            return uv
        uv = np.full((len(pts), 2), np.nan)
        import cv2

        dist = np.asarray(self.distortion, float)
        obj = pts[front].reshape(-1, 1, 3)
        zero = np.zeros(3)
        if self.model == "OPENCV_FISHEYE":
            img, _ = cv2.fisheye.projectPoints(obj, zero, zero, self.K, dist)
        else:
            img, _ = cv2.projectPoints(obj, zero, zero, self.K, dist)
        uv[front] = img.reshape(-1, 2)
        return uv

    def unproject(self, pixels: np.ndarray) -> np.ndarray:
        """Camera-frame ray directions (N, 3), scaled to z = 1, of pixel coordinates (N, 2):
        the inverse of :meth:`project` (distortion removed)."""
        uv = np.asarray(pixels, float).reshape(-1, 2)
        if self.is_undistorted:
            xy = (uv - [self.cx, self.cy]) / [self.fx, self.fy]
        else:
            import cv2

            dist = np.asarray(self.distortion, float)
            if self.model == "OPENCV_FISHEYE":
                xy = cv2.fisheye.undistortPoints(uv.reshape(-1, 1, 2), self.K, dist)
            else:
                xy = cv2.undistortPoints(uv.reshape(-1, 1, 2), self.K, dist)
            xy = xy.reshape(-1, 2)
        return np.column_stack([xy, np.ones(len(xy))])

    def scaled(self, factor: float) -> Intrinsics:
        """Intrinsics for the image resized by ``factor`` (e.g. 0.5 halves each side)."""
        return replace(
            self,
            width=int(round(self.width * factor)),
            height=int(round(self.height * factor)),
            fx=self.fx * factor,
            fy=self.fy * factor,
            cx=(self.cx + 0.5) * factor - 0.5,
            cy=(self.cy + 0.5) * factor - 0.5,
        )


@dataclass(frozen=True, eq=False)
class Frame:
    """One image of a capture with its camera."""

    name: str
    """Image file name relative to the capture root (unique within the capture)."""
    image_path: Path
    """Absolute path to the image."""
    intrinsics: Intrinsics
    """The camera's intrinsics for this image."""
    T_world_from_cam: np.ndarray
    """4x4 camera-to-world transform, OpenCV camera axes, metres."""
    mask_path: Path | None = None
    """Absolute path to a binary food mask (non-zero = food), if the capture has one."""
    content_digest: str = ""
    """Digest of the image file's bytes, when the reader computed it (it decodes every image
    fully, so a capture's identity costs no second read); empty: computed when needed."""
    mask_digest: str = ""
    """Digest of the mask file's bytes, like ``content_digest``."""
    elapsed_share: float | None = None
    """When the frame was taken, as a share of the recording it came from: 0 at its first
    frame, 1 at its last (the reader sets it from the frame's place in the file). A subset of
    the frames (keyframes, a scenario's frames) keeps its frames' shares, so the AR drift
    between two kept frames is the recording's, not that of neighbours. None: its place in the
    capture (:attr:`Capture.elapsed_shares`)."""

    @property
    def camera_centre(self) -> np.ndarray:
        """Camera centre in world coordinates, metres."""
        return self.T_world_from_cam[:3, 3].copy()

    @property
    def T_cam_from_world(self) -> np.ndarray:
        """World-to-camera transform."""
        return invert_rigid(self.T_world_from_cam)


@dataclass(frozen=True, eq=False)
class Capture:
    """A set of posed frames of one food item."""

    root: Path
    """Folder the capture was read from (relative paths are resolved against it)."""
    frames: tuple[Frame, ...]
    """The frames, in capture order."""
    metadata: dict[str, Any] = field(default_factory=dict)
    """Extra top-level keys of the source file, passed through unchanged."""
    metric: bool | None = None
    """Whether the poses are in metres: True or False where the source says (a ``"metric"``
    key in transforms.json; a COLMAP model never is), None where it cannot say (then
    :mod:`volec.scale` judges from the camera distances)."""
    metres_per_unit: float = 1.0
    """The factor the reader multiplied the source's positions by (a scale the user gave)."""

    def __len__(self) -> int:
        return len(self.frames)

    @property
    def camera_centres(self) -> np.ndarray:
        """(N, 3) camera centres, metres."""
        return np.stack([f.camera_centre for f in self.frames]) if self.frames else np.zeros((0, 3))

    @property
    def elapsed_shares(self) -> np.ndarray:
        """(N,) when each frame was taken, as a share of the recording
        (:attr:`Frame.elapsed_share`); a frame without one gets its place in this capture,
        ``i / (N - 1)``."""
        n = len(self.frames)
        place = np.arange(n) / max(n - 1, 1)
        return np.array([place[i] if f.elapsed_share is None else f.elapsed_share
                         for i, f in enumerate(self.frames)], float)

    @property
    def has_masks(self) -> bool:
        """True when every frame has a mask."""
        return bool(self.frames) and all(f.mask_path is not None for f in self.frames)


def read_mask(frame: Frame) -> np.ndarray:
    """The frame's food mask as a bool array at its image's size (grey > 127 = food)."""
    if frame.mask_path is None:
        raise CaptureError(f"frame {frame.name} has no mask")
    try:
        with Image.open(frame.mask_path) as im:
            mask = np.asarray(im.convert("L")) > 127
    except OSError as e:
        raise CaptureError(f"cannot read the mask {frame.mask_path}: {e}") from e
    h, w = frame.intrinsics.height, frame.intrinsics.width
    if mask.shape != (h, w):
        raise CaptureError(
            f"mask {frame.mask_path} is {mask.shape[1]}x{mask.shape[0]} pixels but its image "
            f"is {w}x{h}; masks must match their images"
        )
    return mask


MissingPolicy = Literal["error", "skip"]


# ----------------------------------------------------------------------------- nerfstudio


def _number(source: Path, where: str, key: str, value: Any, positive: bool = False) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise CaptureError(f"{source}: {where}'{key}' is {value!r}, not a number") from None
    if not np.isfinite(x) or (positive and x <= 0):
        kind = "a positive finite number" if positive else "a finite number"
        raise CaptureError(f"{source}: {where}'{key}' is {value!r}, expected {kind}")
    return x


def _intrinsics_from(source: Path, top: dict, fr: dict, index: int) -> Intrinsics:
    def get(key: str, required: bool = True) -> Any:
        if key in fr:
            return fr[key]
        if key in top:
            return top[key]
        if required:
            raise CaptureError(
                f"{source}: frames[{index}] has no '{key}' and there is no global '{key}' "
                "(nerfstudio transforms.json needs fl_x, fl_y, cx, cy, w, h)"
            )
        return None

    where = f"frames[{index}]."
    model = str(get("camera_model", required=False) or "OPENCV")
    if model not in DISTORTION_KEYS:
        raise CaptureError(
            f"{source}: camera_model '{model}' is not supported; "
            f"use one of {sorted(DISTORTION_KEYS)}"
        )
    values = {k: _number(source, where, k, get(k), positive=True) for k in _INTRINSIC_KEYS}
    for k in ("w", "h"):
        if values[k] != int(values[k]):
            raise CaptureError(f"{source}: {where}'{k}' is {values[k]}, expected an integer")
    dist = tuple(
        _number(source, where, k, get(k, required=False) or 0.0) for k in DISTORTION_KEYS[model]
    )
    return Intrinsics(
        width=int(values["w"]),
        height=int(values["h"]),
        fx=values["fl_x"],
        fy=values["fl_y"],
        cx=values["cx"] - PIXEL_CENTRE_OFFSET,
        cy=values["cy"] - PIXEL_CENTRE_OFFSET,
        model=model,
        distortion=dist,
    )


def _pose_from(source: Path, fr: dict, index: int) -> np.ndarray:
    if "transform_matrix" not in fr:
        raise CaptureError(f"{source}: frames[{index}] has no 'transform_matrix'")
    try:
        M = np.array(fr["transform_matrix"], dtype=float)
    except (TypeError, ValueError):
        raise CaptureError(
            f"{source}: frames[{index}].transform_matrix is not a numeric 4x4 matrix"
        ) from None
    if M.shape == (3, 4):
        M = np.vstack([M, [0.0, 0.0, 0.0, 1.0]])
    problem = rigid_problem(M)
    if problem is not None:
        raise CaptureError(
            f"{source}: frames[{index}].transform_matrix {problem}; expected a metric "
            "camera-to-world rigid transform"
        )
    return opengl_c2w_to_opencv(M)


MAX_IMAGE_PIXELS = 150_000_000
"""Images declaring more pixels than this are refused before decoding (a 200-megapixel phone
photo has 2e8; a few-kilobyte file claiming 10^10 pixels is a decompression bomb)."""


def verify_image(path: Path, width: int, height: int, what: str, where: str) -> str:
    """Decode the image at ``path`` fully (a truncated or corrupt file fails here, naming it,
    not minutes later inside a stage), check its size against ``width`` x ``height``, and
    return the digest of its bytes. ``what`` ("image", "mask") and ``where`` (the file and
    frame it is listed in) go into the error messages."""
    from volec.provenance import bytes_digest

    try:
        data = Path(path).read_bytes()
    except OSError as e:
        raise CaptureError(f"{where}: {what} {path} cannot be read: {e.strerror or e}") from e
    try:
        with warnings.catch_warnings():
            # volec's own pixel limit below is stricter than PIL's bomb warning
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(io.BytesIO(data)) as im:
                size = im.size
                if size[0] * size[1] > MAX_IMAGE_PIXELS:
                    raise CaptureError(
                        f"{where}: {what} {path} declares {size[0]}x{size[1]} pixels, more "
                        f"than volec's limit of {MAX_IMAGE_PIXELS:,} (a corrupt file or a "
                        "decompression bomb); use the phone's own frames"
                    )
                if size != (width, height):
                    raise CaptureError(
                        f"{where}: {what} {path} is {size[0]}x{size[1]} but the intrinsics "
                        f"say w={width}, h={height}"
                    )
                im.load()
    except CaptureError:
        raise
    except Image.DecompressionBombError as e:
        raise CaptureError(f"{where}: {what} {path} declares more pixels than can be decoded "
                           f"safely ({e}); use the phone's own frames") from e
    except (OSError, SyntaxError, ValueError) as e:
        # PIL reports truncated files as OSError, some corrupt headers as SyntaxError
        raise CaptureError(f"{where}: {what} {path} is not a readable image ({e}); replace "
                           "it, or remove the frame from the capture") from e
    return bytes_digest(data)


def _verify_frame(source: Path, index: int, frame: Frame) -> Frame:
    """``frame`` with the digests of its image and mask, both decoded and size-checked."""
    where = f"{source}: frames[{index}]"
    w, h = frame.intrinsics.width, frame.intrinsics.height
    image = verify_image(frame.image_path, w, h, "image", where)
    mask = "" if frame.mask_path is None else verify_image(frame.mask_path, w, h, "mask", where)
    return replace(frame, content_digest=image, mask_digest=mask)


def verify_frames(source: Path, frames: list[Frame], indices: list[int]) -> list[Frame]:
    """Every frame decoded and checked (:func:`verify_image`), on two threads (decoding
    releases the GIL); the first bad file raises."""
    with ThreadPoolExecutor(max_workers=min(2, os.cpu_count() or 1)) as pool:
        return list(pool.map(lambda args: _verify_frame(source, *args), zip(indices, frames,
                                                                             strict=True)))


#: Keys of transforms.json that mark files whose positions are not metric: instant-ngp's
#: colmap2nerf rescales scenes to fit its unit cube (``aabb_scale``), nerfstudio's COLMAP
#: conversion keeps COLMAP's arbitrary units (``applied_transform``).
UNSCALED_MARKERS = ("aabb_scale", "applied_transform")


def _metric_flag(source: Path, top: dict[str, Any]) -> bool | None:
    """What ``transforms.json`` says of its units: its ``"metric"`` key, False when it carries
    an unscaled tool's marker, None when it cannot say."""
    if "metric" in top:
        if not isinstance(top["metric"], bool):
            raise CaptureError(f"{source}: 'metric' is {top['metric']!r}; expected true or false")
        return top["metric"]
    if any(k in top for k in UNSCALED_MARKERS):
        return False
    return None


def read_transforms_json(
    path: Path,
    on_missing: MissingPolicy = "error",
    check_image_sizes: bool = True,
) -> Capture:
    """Read a nerfstudio-style capture (a folder holding ``transforms.json``, or the file).

    ``on_missing`` says what to do with frames whose image (or mask) file does not exist:
    ``"error"`` raises with the list, ``"skip"`` drops them with a warning naming each.
    With ``check_image_sizes`` every image and mask is decoded fully and its size compared to
    ``w``/``h`` (:func:`verify_image`); their digests make the capture's identity.
    The capture's ``metric`` is what the file says of its units (:func:`_metric_flag`).
    Each frame's ``elapsed_share`` is its place among the file's frames, skipped ones counted.
    """
    import json

    path = Path(path)
    source = path / "transforms.json" if path.is_dir() else path
    if not source.exists():
        raise CaptureError(f"{source}: no such file; a capture folder holds a transforms.json")
    try:
        top = json.loads(source.read_text())
    except json.JSONDecodeError as e:
        raise CaptureError(f"{source}: not valid JSON ({e})") from e
    if not isinstance(top, dict):
        raise CaptureError(f"{source}: the top level must be a JSON object")
    if "frames" not in top or not isinstance(top["frames"], list):
        raise CaptureError(f"{source}: missing key 'frames' (a list of frames)")
    if not top["frames"]:
        raise CaptureError(f"{source}: 'frames' is empty; a capture needs its frames listed")
    metric = _metric_flag(source, top)
    root = source.parent.resolve()

    frames: list[Frame] = []
    indices: list[int] = []
    missing: list[str] = []
    seen: set[str] = set()
    for i, fr in enumerate(top["frames"]):
        if not isinstance(fr, dict):
            raise CaptureError(f"{source}: frames[{i}] is not a JSON object")
        if "file_path" not in fr:
            raise CaptureError(f"{source}: frames[{i}] has no 'file_path'")
        name = str(fr["file_path"])
        if name in seen:
            raise CaptureError(f"{source}: frames[{i}].file_path '{name}' appears twice")
        seen.add(name)
        intr = _intrinsics_from(source, top, fr, i)
        T = _pose_from(source, fr, i)
        image_path = (root / name).resolve()
        mask_path = (root / str(fr["mask_path"])).resolve() if fr.get("mask_path") else None
        absent = [p for p in (image_path, mask_path) if p is not None and not p.exists()]
        if absent:
            missing.append(f"frames[{i}]: " + ", ".join(str(p) for p in absent))
            continue
        share = i / max(len(top["frames"]) - 1, 1)  # its place in the file, skipped ones too
        frames.append(Frame(name, image_path, intr, T, mask_path, elapsed_share=share))
        indices.append(i)

    if missing:
        listing = "\n  ".join(missing[:20]) + ("\n  ..." if len(missing) > 20 else "")
        if on_missing == "error" or not frames:
            raise CaptureError(
                f"{source}: {len(missing)} of {len(top['frames'])} frames have missing files:\n"
                f"  {listing}\nRestore them, or skip those frames (on_missing='skip', "
                "--skip-missing)."
            )
        log.warning(
            "%s: skipping %d of %d frames with missing files:\n  %s",
            source, len(missing), len(top["frames"]), listing,
        )
    if check_image_sizes:
        frames = verify_frames(source, frames, indices)
    reserved = {"frames", "camera_model", "metric", *_INTRINSIC_KEYS,
                *DISTORTION_KEYS["FULL_OPENCV"]}
    metadata = {k: v for k, v in top.items() if k not in reserved}
    return Capture(root=root, frames=tuple(frames), metadata=metadata, metric=metric)


def _intrinsics_dict(intr: Intrinsics) -> dict[str, Any]:
    d: dict[str, Any] = {
        "camera_model": intr.model,
        "fl_x": intr.fx,
        "fl_y": intr.fy,
        "cx": intr.cx + PIXEL_CENTRE_OFFSET,
        "cy": intr.cy + PIXEL_CENTRE_OFFSET,
        "w": intr.width,
        "h": intr.height,
    }
    d.update(zip(DISTORTION_KEYS[intr.model], intr.distortion, strict=True))
    return d


def _relative(path: Path, folder: Path) -> str:
    return Path(os.path.relpath(Path(path).resolve(), folder.resolve())).as_posix()


def transforms_dict(capture: Capture, folder: Path) -> dict[str, Any]:
    """The ``transforms.json`` content for ``capture``, with paths relative to ``folder``."""
    shared = {f.intrinsics for f in capture.frames}
    out: dict[str, Any] = {}
    if len(shared) == 1:
        out.update(_intrinsics_dict(next(iter(shared))))
    out.update(capture.metadata)
    if capture.metric is not None:
        out["metric"] = capture.metric
    frames = []
    for f in capture.frames:
        fr: dict[str, Any] = {"file_path": _relative(f.image_path, folder)}
        if f.mask_path is not None:
            fr["mask_path"] = _relative(f.mask_path, folder)
        if len(shared) != 1:
            fr.update(_intrinsics_dict(f.intrinsics))
        fr["transform_matrix"] = opencv_c2w_to_opengl(f.T_world_from_cam).tolist()
        frames.append(fr)
    out["frames"] = frames
    return out


def write_transforms_json(capture: Capture, path: Path) -> Path:
    """Write ``capture`` as nerfstudio ``transforms.json`` at ``path`` (a file or a folder).

    Image and mask paths are written relative to the file's folder; the file is replaced
    atomically. Floats are written with full precision, so poses round-trip exactly.
    """
    path = Path(path)
    target = path / "transforms.json" if path.is_dir() else path
    write_json_atomic(target, transforms_dict(capture, target.parent))
    return target


# ----------------------------------------------------------------------------- COLMAP

_COLMAP_TO_OPENCV: dict[str, tuple[str, Any]] = {
    # name: (volec model, function params -> (fx, fy, cx, cy, distortion))
    "SIMPLE_PINHOLE": ("PINHOLE", lambda p: (p[0], p[0], p[1], p[2], ())),
    "PINHOLE": ("PINHOLE", lambda p: (p[0], p[1], p[2], p[3], ())),
    "SIMPLE_RADIAL": ("OPENCV", lambda p: (p[0], p[0], p[1], p[2], (p[3], 0.0, 0.0, 0.0))),
    "RADIAL": ("OPENCV", lambda p: (p[0], p[0], p[1], p[2], (p[3], p[4], 0.0, 0.0))),
    "OPENCV": ("OPENCV", lambda p: (p[0], p[1], p[2], p[3], tuple(p[4:8]))),
    "FULL_OPENCV": ("FULL_OPENCV", lambda p: (p[0], p[1], p[2], p[3], tuple(p[4:12]))),
    "OPENCV_FISHEYE": ("OPENCV_FISHEYE", lambda p: (p[0], p[1], p[2], p[3], tuple(p[4:8]))),
}


def read_colmap_model(
    model_dir: Path,
    images_dir: Path,
    masks_dir: Path | None = None,
    on_missing: MissingPolicy = "error",
) -> Capture:
    """Read a COLMAP sparse model (``cameras/images/points3D`` as .txt or .bin) as a capture.

    Only registered images become frames. COLMAP stores world-to-camera poses with OpenCV
    axes in its own (often unscaled) units; they are inverted here and kept in those units.
    COLMAP's principal point uses pixel-corner coordinates (the centre of the first pixel is
    0.5); volec uses pixel centres at integers, so 0.5 is subtracted from cx, cy.
    ``masks_dir`` (optional) holds ``<image name>.png`` masks.
    """
    import pycolmap  # heavy import, only needed here

    model_dir, images_dir = Path(model_dir), Path(images_dir)
    if not model_dir.is_dir():
        raise CaptureError(f"{model_dir}: not a folder holding a COLMAP model")
    try:
        rec = pycolmap.Reconstruction(str(model_dir))
    except Exception as e:  # pycolmap raises plain RuntimeErrors/ValueErrors
        raise CaptureError(f"{model_dir}: cannot read a COLMAP model: {e}") from e
    if rec.num_reg_images() == 0:
        raise CaptureError(f"{model_dir}: the COLMAP model has no registered images")

    frames: list[Frame] = []
    missing: list[str] = []
    indices: list[int] = []
    for image_id in sorted(rec.reg_image_ids()):
        im = rec.image(image_id)
        cam = rec.camera(im.camera_id)
        model_name = cam.model.name
        if model_name not in _COLMAP_TO_OPENCV:
            raise CaptureError(
                f"{model_dir}: camera {im.camera_id} uses COLMAP model {model_name}, which "
                f"volec does not read; undistort first or use one of {sorted(_COLMAP_TO_OPENCV)}"
            )
        model, convert = _COLMAP_TO_OPENCV[model_name]
        fx, fy, cx, cy, dist = convert([float(x) for x in cam.params])
        intr = Intrinsics(
            int(cam.width), int(cam.height), fx, fy,
            cx - PIXEL_CENTRE_OFFSET, cy - PIXEL_CENTRE_OFFSET,
            model, tuple(float(d) for d in dist),
        )
        T_cam_from_world = np.vstack([im.cam_from_world().matrix(), [0.0, 0.0, 0.0, 1.0]])
        image_path = (images_dir / im.name).resolve()
        mask_path = (masks_dir / f"{im.name}.png").resolve() if masks_dir is not None else None
        absent = [p for p in (image_path, mask_path) if p is not None and not p.exists()]
        if absent:
            missing.append(f"{im.name}: " + ", ".join(str(p) for p in absent))
            continue
        frames.append(Frame(im.name, image_path, intr, invert_rigid(T_cam_from_world), mask_path))
        indices.append(int(image_id))
    if missing:
        listing = "\n  ".join(missing[:20])
        if on_missing == "error" or not frames:
            raise CaptureError(
                f"{model_dir}: {len(missing)} registered images have missing files:\n  {listing}"
            )
        log.warning("%s: skipping %d images with missing files:\n  %s",
                    model_dir, len(missing), listing)
    frames = verify_frames(model_dir, frames, indices)
    # COLMAP's units are arbitrary: the capture is not metric until the user gives a scale
    return Capture(root=images_dir.resolve(), frames=tuple(frames), metadata={"source": "colmap"},
                   metric=False)


def read_capture(path: Path, on_missing: MissingPolicy = "error") -> Capture:
    """Read a capture folder in any layout volec knows.

    A folder with ``transforms.json`` is read as nerfstudio; a folder with ``sparse/0`` (or
    ``sparse``) and ``images`` as a COLMAP project.
    """
    path = Path(path)
    if path.is_file() or (path / "transforms.json").exists():
        return read_transforms_json(path, on_missing=on_missing)
    for sparse in (path / "sparse" / "0", path / "sparse"):
        if (sparse / "images.bin").exists() or (sparse / "images.txt").exists():
            masks = path / "masks" if (path / "masks").is_dir() else None
            return read_colmap_model(sparse, path / "images", masks, on_missing=on_missing)
    raise CaptureError(
        f"{path}: not a capture volec can read; expected a transforms.json (nerfstudio) or "
        "a COLMAP project (sparse/0 and images/)"
    )
