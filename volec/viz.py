"""Figures: matplotlib pictures of captures, clouds and meshes for notebooks and reports.

In: images, poses and tables as numpy arrays, point clouds and meshes. Out:
``matplotlib.figure.Figure`` objects or rendered images (pyvista, off-screen);
:func:`save_figure` writes a figure to PNG atomically. Nothing here touches volec's data files.
"""

from __future__ import annotations

import io
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import trimesh
from matplotlib.figure import Figure

from volec.io import write_bytes_atomic
from volec.pointcloud import PREDICTED_COLOUR, PointCloud


def mask_outline_strip(images: Sequence[np.ndarray], masks: Sequence[np.ndarray],
                       titles: Sequence[str], colour: tuple[int, int, int] = (40, 220, 40),
                       width_px: int = 2) -> Figure:
    """A strip of frames with their food masks' outlines drawn on them."""
    from scipy import ndimage

    drawn = []
    for image, mask in zip(images, masks, strict=True):
        out = np.asarray(image).copy()
        out[mask & ~ndimage.binary_erosion(mask, iterations=width_px)] = colour
        drawn.append(out)
    return image_grid(drawn, titles, ncols=len(drawn), size_in=2.4)


def image_grid(
    images: Sequence[np.ndarray], titles: Sequence[str], ncols: int = 7, size_in: float = 2.2
) -> Figure:
    """A grid of images with a title under each."""
    n = len(images)
    nrows = int(np.ceil(n / ncols))
    fig, axes = plt.subplots(nrows, ncols, figsize=(ncols * size_in, nrows * (size_in + 0.3)))
    for ax in np.atleast_1d(axes).ravel():
        ax.axis("off")
    for ax, img, title in zip(np.atleast_1d(axes).ravel(), images, titles, strict=False):
        ax.imshow(img)
        ax.set_title(title, fontsize=9)
    fig.tight_layout()
    return fig


def trajectory_figure(
    tracks: dict[str, np.ndarray],
    up: np.ndarray,
    target: np.ndarray,
    reference: str = "exact",
) -> Figure:
    """Camera-centre tracks (name -> (N, 3) metres): a top view, the height above ``target``
    per frame, and each track's distance to the ``reference`` track per frame, in mm."""
    up = np.asarray(up, float) / np.linalg.norm(up)
    helper = np.array([1.0, 0, 0]) if abs(up[0]) < 0.9 else np.array([0, 0, 1.0])
    e1 = np.cross(up, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(up, e1)
    target = np.asarray(target, float)
    fig, (top, side, err) = plt.subplots(1, 3, figsize=(14, 4.2))
    for name, c in tracks.items():
        d = (np.asarray(c) - target) * 100
        top.plot(d @ e1, d @ e2, ".-", ms=3, lw=0.8, label=name)
        side.plot(np.arange(len(d)), d @ up, ".-", ms=3, lw=0.8, label=name)
        if name != reference and reference in tracks:
            mm = np.linalg.norm(np.asarray(c) - tracks[reference], axis=1) * 1000
            err.plot(np.arange(len(mm)), mm, ".-", ms=3, lw=0.8, label=name)
    top.plot(0, 0, "k+", ms=10, label="object")
    top.set_aspect("equal")
    top.set(xlabel="cm", ylabel="cm", title="camera centres, seen from above")
    side.set(xlabel="frame", ylabel="cm", title="camera height above the object centre")
    err.set(xlabel="frame", ylabel="mm", title=f"camera-centre distance to the {reference} one")
    top.legend(fontsize=8)
    err.legend(fontsize=8)
    fig.tight_layout()
    return fig


VIEW_ANGLE_DEG = 30.0
"""Vertical field of view of every rendered picture."""


@dataclass(frozen=True, eq=False)
class Highlighted:
    """A cloud with points of another kind drawn over it, larger and in one colour: the
    completion network's points over the observed ones."""

    cloud: PointCloud
    extra_xyz: np.ndarray
    """(M, 3) the points drawn over ``cloud``, metres."""
    colour: str = PREDICTED_COLOUR

    def xyz(self) -> np.ndarray:
        """Every point, metres."""
        return np.vstack([self.cloud.xyz, np.asarray(self.extra_xyz, float).reshape(-1, 3)])


Geometry = PointCloud | trimesh.Trimesh | Highlighted
"""What a picture shows."""


def geometry_points(geometry: Geometry) -> np.ndarray:
    """(N, 3) the points or vertices of ``geometry``."""
    if isinstance(geometry, Highlighted):
        return geometry.xyz()
    return geometry.xyz if isinstance(geometry, PointCloud) else np.asarray(geometry.vertices)


def framed_view(points: np.ndarray, direction: np.ndarray, up: np.ndarray,
                size_px: tuple[int, int], fill: float = 0.9) -> tuple[np.ndarray, np.ndarray]:
    """(eye, target) of a camera looking along ``-direction`` (``direction`` points from the
    object to the eye) with ``up`` upwards and a vertical field of view of
    :data:`VIEW_ANGLE_DEG`, placed so that ``points`` fill ``fill`` of the picture's width or
    height (whichever they reach first): every point p at depth d from the eye must have
    |lateral offset| <= fill * tan(half angle) * d."""
    direction = np.asarray(direction, float) / np.linalg.norm(direction)
    right = np.cross(direction, up)
    right /= np.linalg.norm(right)
    upward = np.cross(right, direction)
    points = np.asarray(points, float)
    x, y = points @ right, points @ upward
    target = (right * (x.min() + x.max()) / 2 + upward * (y.min() + y.max()) / 2
              + direction * float(np.median(points @ direction)))
    offsets = points - target
    along, x, y = offsets @ direction, offsets @ right, offsets @ upward
    tan_v = fill * np.tan(np.radians(VIEW_ANGLE_DEG / 2))
    tan_h = tan_v * size_px[0] / size_px[1]
    distance = float(np.max(along + np.maximum(np.abs(x) / tan_h, np.abs(y) / tan_v)))
    return target + max(distance, 1e-6) * direction, target


def render_geometry(
    geometry: Geometry,
    eye: np.ndarray,
    target: np.ndarray,
    up: np.ndarray,
    size_px: tuple[int, int] = (480, 360),
    point_size_px: float = 2.0,
) -> np.ndarray:
    """An off-screen pyvista picture (H, W, 3 uint8) of a coloured cloud or a mesh, seen from
    ``eye`` towards ``target`` (metres, world frame) with ``up`` upwards."""
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista as pv

    plotter = pv.Plotter(off_screen=True, window_size=size_px)
    plotter.set_background("white")
    if isinstance(geometry, Highlighted):
        extra = np.asarray(geometry.extra_xyz, float).reshape(-1, 3)
        if len(extra):
            plotter.add_mesh(pv.PolyData(extra), color=geometry.colour,
                             point_size=2.5 * point_size_px, render_points_as_spheres=True)
        geometry = geometry.cloud
    if isinstance(geometry, PointCloud):
        data = pv.PolyData(geometry.xyz)
        if geometry.rgb is not None:
            data["rgb"] = geometry.rgb
            plotter.add_mesh(data, scalars="rgb", rgb=True, point_size=point_size_px,
                             render_points_as_spheres=False)
        else:
            plotter.add_mesh(data, color="#4477aa", point_size=point_size_px)
    else:
        faces = np.c_[np.full(len(geometry.faces), 3), geometry.faces].ravel()
        plotter.add_mesh(pv.PolyData(np.asarray(geometry.vertices), faces), color="#d9b38c",
                         smooth_shading=True)
    return _screenshot(plotter, eye, target, up)


def _screenshot(plotter, eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    """The picture (H, W, 3 uint8) of a pyvista plotter's scene seen from ``eye`` towards
    ``target``; the plotter is closed."""
    plotter.camera.position = tuple(np.asarray(eye, float))
    plotter.camera.focal_point = tuple(np.asarray(target, float))
    plotter.camera.up = tuple(np.asarray(up, float))
    plotter.camera.view_angle = VIEW_ANGLE_DEG
    image = plotter.screenshot(return_img=True)
    plotter.close()
    return np.asarray(image)


def render_scalar_mesh(mesh: trimesh.Trimesh, values: np.ndarray, eye: np.ndarray,
                       target: np.ndarray, up: np.ndarray, limit: float, cmap: str = "RdBu_r",
                       size_px: tuple[int, int] = (420, 360)) -> np.ndarray:
    """An off-screen picture (H, W, 3 uint8) of ``mesh`` coloured by a per-vertex value, on a
    diverging colour map from -``limit`` to ``limit``."""
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista as pv

    plotter = pv.Plotter(off_screen=True, window_size=size_px)
    plotter.set_background("white")
    faces = np.c_[np.full(len(mesh.faces), 3), mesh.faces].ravel()
    data = pv.PolyData(np.asarray(mesh.vertices), faces)
    data["value"] = np.asarray(values, float)
    plotter.add_mesh(data, scalars="value", cmap=cmap, clim=(-limit, limit),
                     smooth_shading=True, show_scalar_bar=False)
    return _screenshot(plotter, eye, target, up)


def signed_distance_figure(surfaces: dict[str, tuple[trimesh.Trimesh, np.ndarray]],
                           up: np.ndarray, limit_mm: float = 1.0) -> Figure:
    """Each named mesh coloured by its signed distance to the true surface (per vertex,
    metres; red outside, blue inside), seen from above and from below the table's level,
    with one colour bar in mm."""
    from volec.geometry import horizontal_axes

    up = np.asarray(up, float) / np.linalg.norm(up)
    side, _ = horizontal_axes(up)
    fig, axes = plt.subplots(2, len(surfaces), figsize=(3.4 * len(surfaces), 6.2),
                             squeeze=False)
    for col, (name, (mesh, signed_m)) in enumerate(surfaces.items()):
        for row, elevation in enumerate((40.0, -35.0)):
            el = np.radians(elevation)
            eye, target = framed_view(mesh.vertices, np.cos(el) * side + np.sin(el) * up, up,
                                      (420, 360))
            image = render_scalar_mesh(mesh, 1000 * np.asarray(signed_m), eye, target, up,
                                       limit_mm)
            axes[row, col].imshow(image)
            axes[row, col].axis("off")
            where = "above" if elevation > 0 else "below"
            axes[row, col].set_title(f"{name}, from {where}\nmedian "
                                     f"{1000 * np.median(signed_m):+.2f} mm", fontsize=9)
    fig.suptitle("signed distance of each mesh to the true surface, after a rigid alignment",
                 fontsize=10)
    mappable = matplotlib.cm.ScalarMappable(
        norm=matplotlib.colors.Normalize(-limit_mm, limit_mm), cmap="RdBu_r")
    fig.colorbar(mappable, ax=axes, shrink=0.6, label="signed distance to the true surface, "
                 "mm (+ outside)")
    return fig


def geometry_panels(
    panels: dict[str, Geometry],
    eye: np.ndarray,
    target: np.ndarray,
    up: np.ndarray,
    size_px: tuple[int, int] = (480, 360),
) -> Figure:
    """One :func:`render_geometry` picture per named cloud or mesh, side by side, all from
    the same viewpoint."""
    images = [render_geometry(g, eye, target, up, size_px) for g in panels.values()]
    return image_grid(images, list(panels), ncols=len(images), size_in=4.0)


def panels_around(
    panels: dict[str, Geometry],
    up: np.ndarray,
    elevation_deg: float,
    size_px: tuple[int, int] = (480, 360),
) -> Figure:
    """:func:`geometry_panels` seen from ``elevation_deg`` above the horizontal plane (``up``
    is the world's up), one viewpoint for all, framed so that together they fill the
    picture (:func:`framed_view`)."""
    from volec.geometry import horizontal_axes

    up = np.asarray(up, float) / np.linalg.norm(up)
    side, _ = horizontal_axes(up)
    el = np.radians(elevation_deg)
    points = np.vstack([geometry_points(g) for g in panels.values()])
    eye, target = framed_view(points, np.cos(el) * side + np.sin(el) * up, up, size_px)
    return geometry_panels(panels, eye, target, up, size_px)


def cloud_grid(rows: dict[str, dict[str, np.ndarray]], elevation_deg: float = -20.0,
               size_px: tuple[int, int] = (300, 240)) -> Figure:
    """A grid of point-cloud pictures: one row per entry of ``rows`` (name -> column name ->
    (N, 3) points, z up), each cloud seen from the same side, ``elevation_deg`` above the
    horizon (negative: from below, where completion has to fill in)."""
    colours = ["#4477aa", "#ee6677", "#228833", "#999999", "#ccbb44"]
    images, titles = [], []
    e = np.radians(elevation_deg)
    direction = np.array([np.cos(e), -0.3 * np.cos(e), np.sin(e)])
    for name, columns in rows.items():
        # one framing per row, on all its clouds, so they compare at one scale
        eye, centre = framed_view(np.vstack(list(columns.values())), direction, [0, 0, 1],
                                  size_px)
        for k, (column, xyz) in enumerate(columns.items()):
            rgb = np.tile(np.array(matplotlib.colors.to_rgb(colours[k % len(colours)])) * 255,
                          (len(xyz), 1)).astype(np.uint8)
            images.append(render_geometry(PointCloud(xyz, rgb), eye, centre, [0, 0, 1], size_px))
            titles.append(f"{name}: {column}")
    ncols = len(next(iter(rows.values())))
    return image_grid(images, titles, ncols=ncols, size_in=2.8)


def loss_curves(log: pd.DataFrame) -> Figure:
    """Training loss (sum over stages) and the final stage's Chamfer-L1 per step, smoothed,
    with the validation Chamfer-L1 of the network and of the partial inputs."""
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 3.6))
    window = max(1, len(log) // 100)
    left.plot(log["step"], log["loss"].rolling(window, min_periods=1).mean(), lw=1)
    left.set(xlabel="step", ylabel="loss (sum of stage CD-L1)", yscale="log",
             title="training loss")
    right.plot(log["step"], log["cd_l1_final"].rolling(window, min_periods=1).mean(), lw=1,
               label="training batch, final stage")
    val = log.dropna(subset=["val_cd_l1"])
    right.plot(val["step"], val["val_cd_l1"], "o-", ms=3, label="validation, network")
    right.plot(val["step"], val["val_cd_l1_partial"], "--", label="validation, partial input")
    right.set(xlabel="step", ylabel="CD-L1 (normalized units)", yscale="log",
              title="Chamfer distance")
    right.legend(fontsize=8)
    fig.tight_layout()
    return fig


def distance_histogram(distances_mm: dict[str, np.ndarray], limit_mm: float = 5.0) -> Figure:
    """Histograms of point-to-surface distances (name -> (N,) mm), with their medians."""
    fig, ax = plt.subplots(figsize=(7, 3.2))
    bins = np.linspace(0, limit_mm, 51)
    for name, d in distances_mm.items():
        d = np.asarray(d)
        ax.hist(np.clip(d, 0, limit_mm), bins=bins, histtype="step", density=True,
                label=f"{name} (median {np.median(d):.2f} mm)")
    ax.set(xlabel=f"distance to the true surface, mm (clipped at {limit_mm:g})",
           ylabel="density")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def save_figure(fig: Figure, path: Path, dpi: int = 120) -> Path:
    """Write ``fig`` as PNG to ``path`` atomically and return the path. The PNG's metadata
    names the volec version and source digest that made it."""
    from volec.tables import made_by

    origin = made_by()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight",
                metadata={"Software": f"volec {origin['volec_version']} (source "
                                      f"{origin['source_digest']})"})
    write_bytes_atomic(Path(path), buf.getvalue())
    return Path(path)
