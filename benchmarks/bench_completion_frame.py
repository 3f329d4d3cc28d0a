"""Does the completion network learn better when it knows where the table is? Trains the
``cpu`` recipe twice on the same data, seeds and schedule: with the partials framed by their
own principal axes (``cpu``, the paper's framing) and upright (``cpu_upright``, the shipped
checkpoint's: z along the table's normal,
:func:`volec.completion.preprocess.fit_upright_normalization`), and writes both validation
curves (Chamfer-L1, normalized units: the same in any frame) to
figures/completion_frame.{csv,md}.

Usage: .venv/bin/python benchmarks/bench_completion_frame.py [--steps 4500]
       [--presets cpu cpu_upright]

Each preset takes as long as ``make retrain`` (about 70 minutes for 4500 steps on 2 cores);
the checkpoints go to build/completion_frame/ and are not used by volec unless given as
``--checkpoint`` (a checkpoint records its frame; an upright one needs the support normal,
which ``volec estimate`` passes).
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import pandas as pd

from volec.completion.train import PRESETS, train
from volec.paths import data_dir, figures_dir
from volec.tables import write_table


def validation_curve(preset: str, steps: int, out: Path) -> pd.DataFrame:
    """The validation rows of one training run of ``preset``."""
    result = train(replace(PRESETS[preset], steps=steps), out / f"{preset}.pt",
                   data_dir() / "completion-data")
    log = pd.read_csv(result["log"])
    rows = log.dropna(subset=["val_cd_l1"])
    return pd.DataFrame({"preset": preset, "step": rows["step"],
                         "elapsed_s": rows["elapsed_s"], "val_cd_l1": rows["val_cd_l1"],
                         "val_cd_l1_partial": rows["val_cd_l1_partial"]})


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=PRESETS["cpu"].steps)
    parser.add_argument("--presets", nargs="+", default=["cpu", "cpu_upright"],
                        choices=sorted(PRESETS))
    args = parser.parse_args()
    out = Path("build/completion_frame")
    out.mkdir(parents=True, exist_ok=True)
    table = pd.concat([validation_curve(p, args.steps, out) for p in args.presets])
    write_table(table, figures_dir() / "completion_frame", float_digits=4)
    print(table.pivot(index="step", columns="preset", values="val_cd_l1").to_string())


if __name__ == "__main__":
    main()
