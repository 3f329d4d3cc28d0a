"""Scale: whether a capture's poses are in metres, and giving them metres when they are not.

In: a :class:`~volec.capture.Capture` and, optionally, a scale the user gives (metres per unit,
or the distance in metres between two named frames' cameras). Out: the capture in metres
(:func:`with_scale`) and a :class:`ScaleCheck` saying why volec takes its poses as metres;
or a :class:`~volec.errors.ScaleError` that says how to give the scale.

Millilitres need metres. A phone's AR tracking is metric, but many ``transforms.json`` files are
not (instant-ngp fits scenes into a unit cube, nerfstudio's COLMAP path keeps COLMAP's arbitrary
units) and a COLMAP project never is. Where the file says (:attr:`Capture.metric`), volec
believes it if the cameras stand at a plausible distance from what they look at; where it
cannot say, that distance decides: a phone filming food is a few decimetres away, not a few
centimetres or tens of metres. The volume itself is judged again later (:mod:`volec.trust`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from volec.capture import Capture
from volec.errors import ScaleError

HOW_TO_GIVE_SCALE = (
    "give the scale: --scale METRES_PER_UNIT (e.g. 0.01 for centimetres), or "
    "--scale-from-distance FRAME_A FRAME_B METRES (how far apart two frames' cameras were), "
    "or record the capture with an app that saves metric AR poses (transforms.json "
    "with \"metric\": true)"
)


@dataclass(frozen=True)
class ScaleConfig:
    """What volec accepts as a phone capture of food, in metres."""

    min_camera_distance_m: float = 0.08
    """Cameras closer than this (median) to the point they look at are not a phone filming
    food (phones do not focus much closer)."""
    max_camera_distance_m: float = 2.0
    """Cameras farther than this (median) are not filming one food item."""


@dataclass(frozen=True)
class ScaleCheck:
    """Why the capture's poses are taken as metres."""

    source: str
    """``file`` (the capture says it is metric), ``user`` (a scale was given) or
    ``plausibility`` (the capture cannot say; the camera distances look metric)."""
    camera_distance_m: float
    """Median distance from the cameras to the point they look at, metres."""
    metres_per_unit: float
    """The factor the capture's positions were multiplied by (1: none)."""
    warning: str | None
    """A note for people when the scale was only judged plausible."""

    def record(self) -> dict[str, object]:
        """JSON-able description."""
        return {"source": self.source, "camera_distance_m": round(self.camera_distance_m, 4),
                "metres_per_unit": self.metres_per_unit}


def fixation_point(capture: Capture) -> np.ndarray:
    """The point nearest to all of ``capture``'s optical axes (:func:`fixation_of_poses`)."""
    return fixation_of_poses(np.stack([f.T_world_from_cam for f in capture.frames]))


def fixation_of_poses(T_world_from_cam: np.ndarray) -> np.ndarray:
    """The point nearest to the optical axes of the cameras (N, 4, 4) in the least-squares
    sense (what an orbit looks at). Where the axes are (nearly) parallel there is none: then
    the point as far in front of the mean camera as the cameras are spread."""
    centres = T_world_from_cam[:, :3, 3]
    axes = T_world_from_cam[:, :3, 2]
    projectors = np.eye(3)[None] - axes[:, :, None] * axes[:, None, :]
    A = projectors.sum(axis=0)
    b = np.einsum("nij,nj->i", projectors, centres)
    if np.linalg.cond(A) < 1e6:
        return np.linalg.solve(A, b)
    spacing = float(np.linalg.norm(centres - centres.mean(axis=0), axis=1).mean()) or 1.0
    return centres.mean(axis=0) + spacing * axes.mean(axis=0)


def camera_distance(capture: Capture) -> float:
    """Median distance (the capture's units) from the cameras to :func:`fixation_point`."""
    return float(np.median(np.linalg.norm(capture.camera_centres - fixation_point(capture),
                                           axis=1)))


def with_scale(capture: Capture, metres_per_unit: float) -> Capture:
    """``capture`` with every camera position multiplied by ``metres_per_unit``: metric."""
    if not np.isfinite(metres_per_unit) or metres_per_unit <= 0:
        raise ScaleError(f"--scale must be a positive number of metres per unit, not "
                         f"{metres_per_unit}")
    frames = []
    for f in capture.frames:
        T = f.T_world_from_cam.copy()
        T[:3, 3] *= metres_per_unit
        frames.append(replace(f, T_world_from_cam=T))
    return replace(capture, frames=tuple(frames), metric=True,
                   metres_per_unit=capture.metres_per_unit * metres_per_unit)


def scale_from_distance(capture: Capture, frame_a: str, frame_b: str, distance_m: float
                        ) -> float:
    """Metres per unit such that the cameras of the frames named ``frame_a`` and ``frame_b``
    are ``distance_m`` apart."""
    names = {f.name: f for f in capture.frames}
    for name in (frame_a, frame_b):
        if name not in names:
            raise ScaleError(f"--scale-from-distance: no frame named '{name}' in "
                             f"{capture.root} (frame names look like '{capture.frames[0].name}')")
    gap = float(np.linalg.norm(names[frame_a].camera_centre - names[frame_b].camera_centre))
    if gap == 0.0 or not np.isfinite(distance_m) or distance_m <= 0:
        raise ScaleError("--scale-from-distance needs two frames whose cameras are apart and a "
                         "positive distance in metres")
    return distance_m / gap


def require_metric(capture: Capture, cfg: ScaleConfig | None = None,
                   user_scale: bool = False) -> ScaleCheck:
    """Why ``capture`` can be measured in millilitres; raises :class:`ScaleError` (naming the
    capture and how to give the scale) when it is not metric or its distances are not
    plausible as metres. ``user_scale``: the scale was given by the user."""
    cfg = cfg or ScaleConfig()
    where = str(capture.root)
    if capture.metric is False:
        source = capture.metadata.get("source")
        why = ("a COLMAP model has no units" if source == "colmap"
               else "its transforms.json says it is not metric, or was written by a tool that "
               "rescales poses (aabb_scale, applied_transform)")
        raise ScaleError(f"{where}: the poses are not in metres ({why}), so a volume in "
                         f"millilitres would be a guess; {HOW_TO_GIVE_SCALE}")
    distance = camera_distance(capture)
    if not cfg.min_camera_distance_m <= distance <= cfg.max_camera_distance_m:
        guess = ("Are the poses in centimetres (--scale 0.01) or millimetres (--scale 0.001)?"
                 if distance > cfg.max_camera_distance_m else "Are the poses in another unit?")
        raise ScaleError(
            f"{where}: the cameras are a median {distance:.3g} units from the point they look "
            f"at; as metres that is not a phone filming food (expected "
            f"{cfg.min_camera_distance_m}-{cfg.max_camera_distance_m} m). {guess} "
            f"{HOW_TO_GIVE_SCALE[0].upper()}{HOW_TO_GIVE_SCALE[1:]}"
        )
    if user_scale:
        return ScaleCheck("user", distance, capture.metres_per_unit, None)
    if capture.metric:
        return ScaleCheck("file", distance, capture.metres_per_unit, None)
    return ScaleCheck("plausibility", distance, capture.metres_per_unit,
                      f"the capture does not say its poses are metric (no \"metric\" key in "
                      f"transforms.json); taken as metres because the cameras are a plausible "
                      f"{distance:.2f} m from the food")
