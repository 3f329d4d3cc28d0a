"""Training the completion network.

In: a :class:`TrainConfig` (model preset, data recipe, optimiser, seed). Out: a checkpoint
(model sizes + weights + what it was trained on and its validation score), a CSV log of the
loss and the validation Chamfer distance, both written atomically; the training data is
generated on first use under ``data_dir``.

Run: ``make retrain`` (``python -m volec.completion.train --preset cpu_upright --out
volec/completion/weights/symmcompletion_cpu.pt``; ``--device cuda`` where a GPU is at hand).
Validation shapes are other seeds of the same families, never trained on.
"""

from __future__ import annotations

import argparse
import csv
import io
import logging
import math
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from volec.completion.data import CompletionDataset, ViewConfig, write_dataset
from volec.completion.model import PRESETS as MODEL_PRESETS
from volec.completion.model import ModelConfig, SymmCompletion, chamfer_l1
from volec.io import write_bytes_atomic, write_text_atomic
from volec.progress import Progress
from volec.synth.families import training_shapes

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TrainConfig:
    """Training recipe."""

    model: str = "cpu"
    """Model preset (:data:`volec.completion.model.PRESETS`)."""
    steps: int = 4500
    """Optimiser steps."""
    batch_size: int = 8
    """Pairs per step (paper: 16)."""
    lr: float = 3e-4
    """Adam's peak learning rate (paper: 1e-4); cosine decay to ``lr / 30``."""
    warmup_steps: int = 100
    """Linear warm-up steps."""
    seed: int = 0
    """Seeds torch, the sampling of pairs and the resampling of clouds."""
    train_per_family: int = 4
    """Training shapes per family (30 families: 120 shapes)."""
    val_per_family: int = 1
    """Validation shapes per family (other seeds, never trained on)."""
    val_first_seed: int = 1000
    """First seed of the validation shapes."""
    views_per_shape: int = 26
    """Partial views per shape (paper: 26)."""
    val_every: int = 250
    """Steps between validations (and checkpoint saves)."""
    max_minutes: float = 0.0
    """Stop early after this many minutes of training (0: no limit)."""
    data_workers: int = 2
    """Processes that generate the training data."""
    families: tuple[str, ...] = ()
    """Shape families to use (empty: all of :data:`volec.synth.families.FAMILIES`)."""


PRESETS: dict[str, TrainConfig] = {
    "cpu": TrainConfig(),
    # The cpu recipe with the partials framed upright (benchmarks/bench_completion_frame.py).
    "cpu_upright": TrainConfig(model="cpu_upright"),
    "paper": TrainConfig(model="paper", steps=30000, batch_size=16, lr=1e-4,
                         train_per_family=8, val_every=1000),
    # The test suite's smoke run: two steps on one shape.
    "smoke": TrainConfig(steps=2, batch_size=2, train_per_family=1, val_per_family=1,
                         views_per_shape=2, val_every=1, warmup_steps=1, data_workers=1,
                         families=("egg",)),
}


def learning_rate(cfg: TrainConfig, step: int) -> float:
    """Warm-up, then cosine decay from ``lr`` to ``lr / 30``."""
    if step < cfg.warmup_steps:
        return cfg.lr * (step + 1) / cfg.warmup_steps
    t = (step - cfg.warmup_steps) / max(cfg.steps - cfg.warmup_steps, 1)
    low = cfg.lr / 30
    return low + (cfg.lr - low) * 0.5 * (1 + math.cos(math.pi * min(t, 1.0)))


def evaluate(model: SymmCompletion, data: CompletionDataset, batch_size: int,
             seed: int = 12345) -> dict[str, float]:
    """Mean Chamfer-L1 (normalized units) over ``data``: of the final output and of the
    partial input itself, with fixed resampling, on the model's device."""
    rng = np.random.default_rng(seed)
    device = next(model.parameters()).device
    model.eval()
    out_sum = partial_sum = 0.0
    with torch.no_grad():
        for start in range(0, len(data), batch_size):
            idx = np.arange(start, min(start + batch_size, len(data)))
            partial, complete = (torch.from_numpy(a).to(device) for a in data.batch(idx, rng))
            out_sum += float(chamfer_l1(model(partial)[-1], complete)) * len(idx)
            partial_sum += float(chamfer_l1(partial, complete)) * len(idx)
    model.train()
    return {"cd_l1": out_sum / len(data), "cd_l1_partial": partial_sum / len(data)}


def save_checkpoint(path: Path, model: SymmCompletion, train_cfg: TrainConfig,
                    info: dict[str, Any]) -> Path:
    """Weights (on the CPU, wherever trained), sizes, recipe and scores in one torch file,
    written atomically."""
    buf = io.BytesIO()
    weights = {name: tensor.detach().cpu() for name, tensor in model.state_dict().items()}
    torch.save({"model_config": asdict(model.cfg), "state_dict": weights,
                "train_config": asdict(train_cfg), "info": info}, buf)
    write_bytes_atomic(Path(path), buf.getvalue())
    return Path(path)


def load_checkpoint(path: Path, device: str = "cpu") -> tuple[SymmCompletion, dict[str, Any]]:
    """The model of a checkpoint (in eval mode) and the checkpoint's other entries."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no completion checkpoint at {path}; run `make retrain`")
    ckpt = torch.load(path, map_location=device, weights_only=True)
    cfg = ModelConfig(**{k: tuple(v) if isinstance(v, list) else v
                         for k, v in ckpt["model_config"].items()})
    model = SymmCompletion(cfg).to(device)
    model.load_state_dict(ckpt["state_dict"])
    model.eval()
    return model, {k: v for k, v in ckpt.items() if k != "state_dict"}


def _view_config_tag(view_cfg: ViewConfig) -> str:
    import zlib

    return f"{zlib.crc32(repr(asdict(view_cfg)).encode()):08x}"


def datasets(cfg: TrainConfig, model_cfg: ModelConfig, data_dir: Path,
             view_cfg: ViewConfig | None = None, progress: bool = True
             ) -> tuple[CompletionDataset, CompletionDataset]:
    """(training, validation) datasets, generating missing shape files under ``data_dir``."""
    view_cfg = view_cfg or ViewConfig()
    folder = Path(data_dir) / f"views{cfg.views_per_shape}-{_view_config_tag(view_cfg)}"
    families = list(cfg.families) or None
    train_paths = write_dataset(training_shapes(cfg.train_per_family, 0, families),
                                cfg.views_per_shape, folder, view_cfg, cfg.data_workers, progress)
    val_paths = write_dataset(training_shapes(cfg.val_per_family, cfg.val_first_seed, families),
                              cfg.views_per_shape, folder, view_cfg, cfg.data_workers, progress)
    frame = model_cfg.input_frame
    return (CompletionDataset(train_paths, model_cfg.n_input, model_cfg.n_output, frame),
            CompletionDataset(val_paths, model_cfg.n_input, model_cfg.n_output, frame))


def train(cfg: TrainConfig, checkpoint: Path, data_dir: Path, progress: bool = True,
          device: str = "cpu") -> dict[str, Any]:
    """Train on ``device`` (a torch device name: the recipe is the same on any; the pairs
    are drawn on the CPU from the same seeds), validating and saving the best checkpoint
    every ``val_every`` steps; the log goes next to the checkpoint as ``.csv``. Returns the
    final scores."""
    model_cfg = MODEL_PRESETS[cfg.model]
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    train_data, val_data = datasets(cfg, model_cfg, data_dir, progress=progress)
    log.info("training on %d partial views of %d shapes, validating on %d views",
             len(train_data), len(train_data.completes), len(val_data))
    model = SymmCompletion(model_cfg).to(device)
    optimiser = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    log_rows: list[dict[str, Any]] = []
    log_path = Path(checkpoint).with_suffix(".csv")
    best = float("inf")
    start = time.perf_counter()
    bar = Progress(cfg.steps, "training", "steps", progress)
    for step in range(cfg.steps):
        for group in optimiser.param_groups:
            group["lr"] = learning_rate(cfg, step)
        idx = rng.integers(len(train_data), size=cfg.batch_size)
        partial, complete = (torch.from_numpy(a).to(device)
                             for a in train_data.batch(idx, rng))
        per_stage = [chamfer_l1(o, complete) for o in model(partial)]
        loss = torch.stack(per_stage).sum()  # the paper's loss: every stage's Chamfer-L1
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        row: dict[str, Any] = {"step": step + 1, "loss": float(loss.detach()),
                               "cd_l1_final": float(per_stage[-1].detach()),
                               "lr": learning_rate(cfg, step),
                               "elapsed_s": round(time.perf_counter() - start, 2)}
        last = step + 1 == cfg.steps
        out_of_time = cfg.max_minutes and time.perf_counter() - start > cfg.max_minutes * 60
        if (step + 1) % cfg.val_every == 0 or last or out_of_time:
            row |= {f"val_{k}": v for k, v in evaluate(model, val_data, cfg.batch_size).items()}
            if row["val_cd_l1"] < best:
                best = row["val_cd_l1"]
                save_checkpoint(checkpoint, model, cfg, {
                    "step": step + 1, "val_cd_l1": best,
                    "val_cd_l1_partial": row["val_cd_l1_partial"],
                    "train_views": len(train_data), "val_views": len(val_data),
                    "elapsed_s": row["elapsed_s"], "device": str(device)})
            bar.note(f"loss={loss.item():.4f} val={row['val_cd_l1']:.4f}")
        log_rows.append(row)
        bar.update()
        if (step + 1) % 50 == 0 or last or out_of_time or "val_cd_l1" in row:
            _write_log(log_path, log_rows)
        if out_of_time:
            log.warning("stopping after %.0f minutes (max_minutes) at step %d",
                        cfg.max_minutes, step + 1)
            break
    bar.close()
    return {"best_val_cd_l1": best, "steps": len(log_rows), "log": str(log_path)}


def _write_log(path: Path, rows: list[dict[str, Any]]) -> None:
    fields = ["step", "loss", "cd_l1_final", "lr", "elapsed_s", "val_cd_l1",
              "val_cd_l1_partial"]
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=fields, restval="")
    writer.writeheader()
    writer.writerows(rows)
    write_text_atomic(path, buf.getvalue())


def main(argv: list[str] | None = None) -> int:
    """``python -m volec.completion.train``: train a preset and write its checkpoint."""
    from volec.paths import data_dir

    parser = argparse.ArgumentParser(description="Train the completion network.")
    parser.add_argument("--preset", default="cpu", choices=sorted(PRESETS))
    parser.add_argument("--out", type=Path, required=True, help="checkpoint path (.pt)")
    parser.add_argument("--steps", type=int, help="override the preset's steps")
    parser.add_argument("--max-minutes", type=float, help="stop after this many minutes")
    parser.add_argument("--seed", type=int, help="override the preset's seed")
    parser.add_argument("--data-dir", type=Path, help="training data folder "
                        "(default: data/completion-data)")
    parser.add_argument("--device", default="cpu",
                        help="torch device to train on, e.g. cuda (default: cpu)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    cfg = PRESETS[args.preset]
    changes = {k: v for k, v in (("steps", args.steps), ("max_minutes", args.max_minutes),
                                 ("seed", args.seed)) if v is not None}
    cfg = replace(cfg, **changes)
    result = train(cfg, args.out, args.data_dir or data_dir() / "completion-data",
                   device=args.device)
    print(f"best validation CD-L1 {result['best_val_cd_l1']:.5f} (normalized units); "
          f"checkpoint {args.out}, log {result['log']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
