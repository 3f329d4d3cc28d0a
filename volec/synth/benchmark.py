"""The benchmark at a glance: the item table, the gallery, one capture's trajectories.

In: item names (default: all 21) and the folder of generated captures. Out: a pandas table of
the items (Table I volume next to the volume measured on the generated mesh, sizes, faces),
preview pictures, and the AR-reported vs exact camera tracks of a capture.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from volec.capture import read_transforms_json
from volec.synth.generate import load_truth, render_preview
from volec.synth.shapes import ITEMS, item_mesh


def items_table(names: list[str] | None = None) -> pd.DataFrame:
    """One row per item: Table I volume, the generated mesh's volume and size."""
    rows = []
    for name in names or list(ITEMS):
        mesh = item_mesh(name)
        ext = np.sort(mesh.extents)[::-1] * 100
        rows.append({
            "item": name,
            "label": ITEMS[name].label,
            "table_I_ml": float(ITEMS[name].volume_ml),
            "mesh_ml": float(mesh.volume * 1e6),
            "size_cm": f"{ext[0]:.1f} x {ext[1]:.1f} x {ext[2]:.1f}",
            "faces": len(mesh.faces),
            "watertight": bool(mesh.is_watertight),
        })
    return pd.DataFrame(rows)


def gallery_images(
    names: list[str] | None = None, size_px: int = 320
) -> tuple[list[np.ndarray], list[str]]:
    """Preview pictures of the items and their titles ("Label, V mL")."""
    names = names or list(ITEMS)
    images = [render_preview(n, size_px) for n in names]
    titles = [f"{ITEMS[n].label}, {ITEMS[n].volume_ml:g} mL" for n in names]
    return images, titles


def capture_tracks(out: Path) -> dict[str, np.ndarray]:
    """Camera centres of a generated capture: the AR-reported ones and the exact ones."""
    out = Path(out)
    reported = read_transforms_json(out / "capture", check_image_sizes=False)
    exact = read_transforms_json(out / "ground_truth" / "transforms_exact.json",
                                 check_image_sizes=False)
    return {"AR reported": reported.camera_centres, "exact": exact.camera_centres}


def ar_error_summary(outs: list[Path]) -> pd.DataFrame:
    """The AR pose error recorded for each generated capture, in mm and degrees."""
    rows = []
    for out in outs:
        t = load_truth(out)
        e = t["ar_pose_error"]
        rows.append({
            "item": t["item"],
            "frames": t["n_frames"],
            "ar_centre_err_median_mm": e["position_error_median_m"] * 1000,
            "ar_centre_err_max_mm": e["position_error_max_m"] * 1000,
            "ar_rot_err_median_deg": e["rotation_error_median_deg"],
            "ar_rot_err_max_deg": e["rotation_error_max_deg"],
        })
    return pd.DataFrame(rows)


def contact_sheet(out: Path, n_frames: int = 4) -> tuple[list[np.ndarray], list[str]]:
    """``n_frames`` evenly spaced frames of a generated capture, each followed by its mask
    overlaid in red, with titles."""
    from PIL import Image

    cap = read_transforms_json(Path(out) / "capture", check_image_sizes=False)
    picks = np.linspace(0, len(cap) - 1, n_frames).round().astype(int)
    images, titles = [], []
    for i in picks:
        frame = cap.frames[i]
        rgb = np.asarray(Image.open(frame.image_path).convert("RGB"))
        images.append(rgb)
        titles.append(f"frame {i}")
        if frame.mask_path is not None:
            mask = np.asarray(Image.open(frame.mask_path)) > 0
            overlay = rgb.copy()
            overlay[mask] = (0.5 * overlay[mask] + [127, 0, 0]).astype(np.uint8)
            images.append(overlay)
            titles.append(f"frame {i}, mask")
    return images, titles
