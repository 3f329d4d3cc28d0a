"""Does the completion network learn better when it knows where the table is? Trains the
``cpu`` preset on the same data, seeds and schedule with the partials framed two ways: by
their own principal axes (``pca``, the paper's and the shipped checkpoint's) and upright (z
along the table's normal, :func:`volec.completion.preprocess.fit_upright_normalization`),
and writes both validation curves (Chamfer-L1, normalized units) to
figures/completion_frame.{csv,md}.

Usage: .venv/bin/python benchmarks/bench_completion_frame.py [--steps 4500]
       [--frames pca upright]

Each frame takes as long as ``make retrain`` (about 70 minutes for 4500 steps on 2 cores);
the checkpoints go to build/completion_frame/ and are not used by volec. The training data
rests on the table at z = 0, so its up is +z. Framing is not a training option of volec yet:
this script swaps the dataset's normalization for the run, and inference
(:func:`volec.completion.complete.complete_cloud`) still frames by PCA.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

import volec.completion.data as completion_data
from volec.completion.preprocess import fit_normalization, fit_upright_normalization
from volec.completion.train import PRESETS, train
from volec.paths import data_dir, figures_dir
from volec.tables import write_table

TABLE_UP = np.array([0.0, 0.0, 1.0])
FRAMES = {"pca": fit_normalization,
          "upright": lambda xyz: fit_upright_normalization(xyz, TABLE_UP)}


def validation_curve(frame: str, steps: int, out: Path) -> pd.DataFrame:
    """The validation rows of one training run with the partials framed by ``frame``."""
    completion_data.fit_normalization = FRAMES[frame]
    try:
        result = train(replace(PRESETS["cpu"], steps=steps), out / f"{frame}.pt",
                       data_dir() / "completion-data")
    finally:
        completion_data.fit_normalization = fit_normalization
    log = pd.read_csv(result["log"])
    rows = log.dropna(subset=["val_cd_l1"])
    return pd.DataFrame({"frame": frame, "step": rows["step"], "elapsed_s": rows["elapsed_s"],
                         "val_cd_l1": rows["val_cd_l1"],
                         "val_cd_l1_partial": rows["val_cd_l1_partial"]})


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=PRESETS["cpu"].steps)
    parser.add_argument("--frames", nargs="+", default=list(FRAMES), choices=list(FRAMES))
    args = parser.parse_args()
    out = Path("build/completion_frame")
    out.mkdir(parents=True, exist_ok=True)
    table = pd.concat([validation_curve(f, args.steps, out) for f in args.frames])
    write_table(table, figures_dir() / "completion_frame", float_digits=4)
    print(table.pivot(index="step", columns="frame", values="val_cd_l1").to_string())


if __name__ == "__main__":
    main()
