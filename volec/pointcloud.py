"""Point clouds: the :class:`PointCloud` that the dense, masking and completion stages pass on.

In: arrays (points in metres, optional uint8 colours and unit normals) or a PLY file.
Out: a :class:`PointCloud`, or a binary PLY that MeshLab, CloudCompare or Blender open
(written atomically through open3d's writer).
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from volec.errors import DataError, VolecError

PREDICTED_RGB = (214, 36, 110)
"""The colour of points a shape prior added (the completion network's): a magenta that no
food has, in ``food_completed.ply``, the pictures and the report."""
PREDICTED_COLOUR = "#{:02x}{:02x}{:02x}".format(*PREDICTED_RGB)
""":data:`PREDICTED_RGB` as a hex colour, for matplotlib, pyvista and the report's page."""
RIM_RGB = (40, 170, 200)
"""The colour of the points the food masks' outlines placed (:mod:`volec.rims`): a cyan."""


@dataclass(frozen=True, eq=False)
class PointCloud:
    """Points with optional per-point colours and normals."""

    xyz: np.ndarray
    """(N, 3) float64 positions, metres."""
    rgb: np.ndarray | None = None
    """(N, 3) uint8 colours, or None."""
    normals: np.ndarray | None = None
    """(N, 3) unit normals, or None."""

    def __post_init__(self) -> None:
        xyz = np.asarray(self.xyz, dtype=float).reshape(-1, 3)
        object.__setattr__(self, "xyz", xyz)
        for name, dtype in (("rgb", np.uint8), ("normals", float)):
            value = getattr(self, name)
            if value is None:
                continue
            value = np.asarray(value, dtype=dtype).reshape(-1, 3)
            if len(value) != len(xyz):
                raise DataError(f"{name} has {len(value)} rows for {len(xyz)} points")
            object.__setattr__(self, name, value)

    def __len__(self) -> int:
        return len(self.xyz)

    def joined(self, other: PointCloud) -> PointCloud:
        """This cloud's points followed by ``other``'s; colours and normals only where both
        have them."""
        def both(a: np.ndarray | None, b: np.ndarray | None) -> np.ndarray | None:
            return None if a is None or b is None else np.concatenate([a, b])

        return PointCloud(np.concatenate([self.xyz, other.xyz]), both(self.rgb, other.rgb),
                          both(self.normals, other.normals))

    def subset(self, keep: np.ndarray) -> PointCloud:
        """The points selected by a boolean mask or an index array."""
        return PointCloud(
            self.xyz[keep],
            None if self.rgb is None else self.rgb[keep],
            None if self.normals is None else self.normals[keep],
        )


def to_open3d(cloud: PointCloud):  # -> open3d.geometry.PointCloud (imported lazily)
    """The cloud as an open3d legacy point cloud."""
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(cloud.xyz))
    if cloud.rgb is not None:
        pcd.colors = o3d.utility.Vector3dVector(cloud.rgb.astype(float) / 255.0)
    if cloud.normals is not None:
        pcd.normals = o3d.utility.Vector3dVector(cloud.normals)
    return pcd


def from_open3d(pcd) -> PointCloud:
    """A :class:`PointCloud` from an open3d legacy point cloud."""
    rgb = (np.round(np.asarray(pcd.colors) * 255).clip(0, 255).astype(np.uint8)
           if pcd.has_colors() else None)
    normals = np.asarray(pcd.normals).copy() if pcd.has_normals() else None
    return PointCloud(np.asarray(pcd.points).copy(), rgb, normals)


def write_ply(cloud: PointCloud, path: Path) -> Path:
    """Write ``cloud`` as a binary PLY at ``path`` atomically (temporary file, then rename)."""
    import open3d as o3d

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=".ply", dir=path.parent)
    os.close(fd)
    try:
        if not o3d.io.write_point_cloud(tmp, to_open3d(cloud), write_ascii=False):
            raise VolecError(f"open3d could not write {path}")
        from volec.io import _file_mode

        os.chmod(tmp, _file_mode())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def read_ply(path: Path) -> PointCloud:
    """Read a point cloud (PLY, PCD, XYZ: what open3d reads); an empty or unreadable file is
    an error naming it."""
    import open3d as o3d

    path = Path(path)
    if not path.is_file():
        raise VolecError(f"{path} does not exist")
    pcd = o3d.io.read_point_cloud(str(path))
    if len(pcd.points) == 0:
        raise VolecError(f"{path} holds no points (or is not a point cloud open3d can read)")
    return from_open3d(pcd)


def write_cloud_record(cloud: PointCloud, record: dict[str, Any], ply_path: Path,
                       json_path: Path) -> Path:
    """A stage's output: the cloud as PLY and its record as JSON, committed together. The old
    record is removed first and the new one written last (atomically), listing the PLY's
    digest under ``files``: an interrupted run never looks finished, and a PLY changed later
    no longer matches its record. ``record`` gets the ``files`` entry."""
    from volec.io import write_json_atomic
    from volec.provenance import file_digest

    ply_path, json_path = Path(ply_path), Path(json_path)
    json_path.unlink(missing_ok=True)
    path = write_ply(cloud, ply_path)
    record["files"] = {ply_path.name: file_digest(ply_path)}
    write_json_atomic(json_path, record)
    return path


def read_cloud_record(ply_path: Path, json_path: Path) -> tuple[PointCloud, dict[str, Any]]:
    """The cloud and record :func:`write_cloud_record` wrote."""
    import json

    return read_ply(ply_path), json.loads(Path(json_path).read_text())
