"""Measure `volec estimate` on a 1000-frame phone video (30 s at 30 fps, a quarter of the
frames smeared by hand motion) beside the 100-frame capture of the same item.

Usage: .venv/bin/python benchmarks/bench_long_capture.py [--items banana ...]

The video capture is made by ``volec synth ITEM --preset video`` into
data/bench-video/ITEM when missing or made by older generator code (about 10 minutes of
rendering on two cores); the 100-frame capture is the volume benchmark's
(data/bench-sfm/ITEM-full_orbit). Each is estimated from scratch, one after the other, by
``volec estimate`` in a child process (``benchmarks/bench_estimate.py``'s runner): wall time,
stage times, peak memory, volume error. For the video it also reports how many frames the
keyframe stage kept and dropped, and how the dropped blurred frames compare with the frames
the renderer smeared (from ``ground_truth/truth.json``; the pipeline never reads it).
Written to figures/long_capture.{csv,md}.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import pandas as pd

from volec.experiments import ensure_capture, scenarios
from volec.paths import data_dir, experiment_dir, figures_dir
from volec.synth import PRESETS, write_synthetic_capture
from volec.synth.generate import is_current
from volec.tables import write_table

sys.path.insert(0, str(Path(__file__).parent))
from bench_estimate import estimate_run  # noqa: E402


def video_capture(item: str) -> Path:
    """The item's 1000-frame video capture, rendered if missing or stale."""
    out = data_dir() / "bench-video" / item
    if not is_current(out, PRESETS["video"]):
        write_synthetic_capture(item, out, PRESETS["video"], overwrite=True)
    return out


def blur_detection(out: Path, result: dict) -> dict[str, float]:
    """How the frames dropped as blurred compare with the frames the renderer smeared."""
    truth = json.loads((out / "ground_truth" / "truth.json").read_text())
    smeared = {f"images/{name}.jpg" for name, blur in truth["motion_blur"].items()
               if blur["length_px"] >= 3.0}
    dropped = result["keyframes"]["dropped"]
    blurred = {name for name, why in dropped.items() if why.startswith("blurred")}
    return {"smeared_3px_or_more": len(smeared), "dropped_as_blurred": len(blurred),
            "dropped_as_blurred_and_smeared": len(blurred & smeared),
            "kept_and_smeared": len(smeared - set(dropped))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--items", nargs="+", default=["banana"])
    args = parser.parse_args()
    rows = []
    for item in args.items:
        video = video_capture(item)
        run = estimate_run(video, keep_result=True)
        result = run.pop("result")
        rows.append({"item": item, "capture": "video_1000", **run,
                     "frames_in": result["keyframes"]["frames_in"],
                     "frames_kept": result["keyframes"]["frames_kept"],
                     **blur_detection(video, result)})
        print(rows[-1], flush=True)
        orbit = ensure_capture(experiment_dir(False), item, scenarios(False)["full_orbit"])
        run = estimate_run(orbit)
        rows.append({"item": item, "capture": "orbit_100", **run})
        print(rows[-1], flush=True)
    table = pd.DataFrame(rows)
    write_table(table, figures_dir() / "long_capture", float_digits=2)
    print(table.to_string(index=False, float_format=lambda x: f"{x:.2f}"))


if __name__ == "__main__":
    main()
