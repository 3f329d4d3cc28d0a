"""Many captures at once: ``volec estimate`` over every capture in a folder, on Dask.

In: a folder of captures (each a subfolder ``volec`` can read), an output folder, the estimate's
settings and where to run (a local Dask cluster by default: one capture per worker process,
its threads limited so the workers do not oversubscribe the cores; or an existing cluster's
scheduler address). Out: ``OUT/CAPTURE/`` holding each capture's result folder (what
``volec estimate`` writes), and ``OUT/batch.csv``: one row per capture (volume, how low and
high it may be (``volume_interval_ml``), trusted, the reasons' codes, warnings, seconds, and
the error of a capture that failed), and ``OUT/index.html``: that table as a sortable page
linking each capture's ``report.html``; both written atomically after every capture that
finishes, so an interrupted batch keeps what it finished. A capture's
failure is recorded and does not stop the others; a re-run finds the finished captures finished
(their ``result.json`` is current) and skips their work.
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from volec.errors import VolecError
from volec.progress import Progress

log = logging.getLogger(__name__)

TABLE = "batch.csv"
INDEX = "index.html"
COLUMNS = ["capture", "status", "volume_ml", "low_ml", "high_ml", "trusted", "reasons",
           "warnings", "seconds", "masks", "error", "result"]


@dataclass(frozen=True)
class BatchConfig:
    """Where and how the captures run."""

    preset: str = "default"
    """The estimate preset (``volec.estimate.PRESETS``)."""
    masks: str = "default"
    """``default``, ``given`` or ``auto`` (see ``EstimateConfig.masks``)."""
    use_completion: bool = True
    max_frames: int = 100
    """Keyframes reconstructed per capture, at most (see :mod:`volec.keyframes`)."""
    workers: int = 0
    """Worker processes of the local cluster (0: half the cores, at least one)."""
    threads_per_worker: int = 0
    """Threads each worker's numerical libraries may use (0: the cores divided among the
    workers)."""
    scheduler: str = ""
    """An existing Dask scheduler's address (``tcp://host:8786``); empty: a local cluster."""


def find_captures(folder: Path) -> list[Path]:
    """The subfolders of ``folder`` that hold a capture (a ``transforms.json``, or a COLMAP
    project's ``sparse/``), sorted by name. A folder holding none is an error."""
    folder = Path(folder)
    if not folder.is_dir():
        raise VolecError(f"{folder} is not a folder of captures")
    found = sorted(p for p in folder.iterdir() if p.is_dir() and (
        (p / "transforms.json").exists() or (p / "sparse").is_dir()
        or (p / "capture" / "transforms.json").exists()))
    if not found:
        raise VolecError(f"{folder} holds no capture (subfolders with a transforms.json or a "
                         "COLMAP project's sparse/)")
    return found


def _capture_root(path: Path) -> Path:
    """A synthetic benchmark item's folder holds its capture in ``capture/``."""
    return path / "capture" if (path / "capture" / "transforms.json").exists() else path


#: The limit :func:`limit_threads` set in this process (None: no limit set).
_THREAD_LIMIT: int | None = None


def thread_limit() -> int:
    """How many threads this process may use: what :func:`limit_threads` set in it, else the
    machine's cores."""
    return _THREAD_LIMIT or os.cpu_count() or 1


def limit_threads(threads: int) -> None:
    """In a worker: let the numerical libraries (BLAS, torch, OpenCV) use at most ``threads``
    threads (and volec's own process pools, :func:`thread_limit`)."""
    global _THREAD_LIMIT
    _THREAD_LIMIT = threads
    for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[name] = str(threads)
    import cv2
    import torch

    torch.set_num_threads(threads)
    cv2.setNumThreads(threads)


def estimate_one(capture_path: str, out_dir: str, cfg: BatchConfig, threads: int
                 ) -> dict[str, Any]:
    """One capture of a batch (runs in a worker): its row of the table. Errors volec raises
    on purpose, and any other, are caught and recorded; nothing is raised."""
    from dataclasses import replace

    from volec.capture import read_capture
    from volec.estimate import PRESETS, run_estimate

    limit_threads(threads)
    name = Path(capture_path).name
    start = time.perf_counter()
    row: dict[str, Any] = {"capture": name, "result": str(Path(out_dir) / "result.json")}
    try:
        capture = read_capture(_capture_root(Path(capture_path)))
        base = PRESETS[cfg.preset]
        est_cfg = replace(base, masks=cfg.masks, use_completion=cfg.use_completion,
                          keyframes=replace(base.keyframes, max_frames=cfg.max_frames))
        result = run_estimate(capture, Path(out_dir), est_cfg, progress=False)
        low_ml, high_ml = result["volume_interval_ml"]
        row |= {"status": "done", "volume_ml": result["volume_ml"], "low_ml": low_ml,
                "high_ml": high_ml, "trusted": result["trusted"],
                "reasons": ",".join(r["code"] for r in result["reasons"]),
                "warnings": len(result["warnings"]), "masks": result["masks"]["source"]}
    except VolecError as e:
        row |= {"status": "failed", "error": str(e)}
    except Exception as e:  # a bug: recorded with its type, so the batch goes on
        log.exception("capture %s failed", name)
        row |= {"status": "failed", "error": f"{type(e).__name__}: {e}"}
    row["seconds"] = round(time.perf_counter() - start, 1)
    return row


_DASK_TRIM_THRESHOLD = 65536
"""The ``MALLOC_TRIM_THRESHOLD_`` Dask's nanny sets by default (see :func:`local_cluster`)."""


def local_cluster(workers: int):  # -> (dask.distributed.Client, LocalCluster)
    """A local Dask cluster of ``workers`` spawned processes, each running one task at a
    time (torch, open3d and COLMAP hold thread pools that a fork would copy half-made). The
    workers are not daemons, so that a task may start processes of its own (rendering a
    capture does).

    Dask's nanny would start each worker with ``MALLOC_TRIM_THRESHOLD_=65536`` (and write it
    into this process's environment too, for every process started later): a fixed threshold
    turns off glibc's adaptive one, so each of dense stereo's large temporary arrays is
    mapped and unmapped afresh. It made the depth maps of one capture 2-2.5 times slower in a
    worker (banana and pear: 61-69 s against 24-28 s in a plain process under the same load),
    so it is left unset here."""
    import dask
    from dask.distributed import Client, LocalCluster

    if os.environ.get("MALLOC_TRIM_THRESHOLD_") == str(_DASK_TRIM_THRESHOLD):
        del os.environ["MALLOC_TRIM_THRESHOLD_"]  # put there by an earlier cluster's nanny
    with dask.config.set({"distributed.worker.daemon": False,
                          "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}):
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=None, silence_logs=logging.WARNING)
    return Client(cluster), cluster


def _cluster(cfg: BatchConfig):  # -> (Client, LocalCluster or None, threads per worker)
    """A client of the scheduler ``cfg`` names, or of a new local cluster: one task at a time
    per worker process, each worker's libraries limited to its share of the cores."""
    from dask.distributed import Client

    cores = os.cpu_count() or 1
    if cfg.scheduler:
        return Client(cfg.scheduler), None, max(1, cfg.threads_per_worker or 1)
    workers = cfg.workers or max(1, cores // 2)
    threads = cfg.threads_per_worker or max(1, cores // workers)
    client, cluster = local_cluster(workers)
    return client, cluster, threads


def write_table(rows: list[dict[str, Any]], out_dir: Path) -> Path:
    """``OUT/batch.csv`` and ``OUT/index.html`` from the rows so far (atomically); the page
    links the report of every capture that has one."""
    from volec.io import write_text_atomic
    from volec.report import write_batch_index

    table = pd.DataFrame(rows, columns=COLUMNS).sort_values("capture")
    path = Path(out_dir) / TABLE
    write_text_atomic(path, table.to_csv(index=False))
    reports = {name: f"{name}/report.html" for name in table["capture"]
               if (Path(out_dir) / name / "report.html").exists()}
    write_batch_index(Path(out_dir) / INDEX, table.drop(columns=["result"]), reports)
    return path


def run_batch(captures_dir: Path, out_dir: Path, cfg: BatchConfig | None = None,
              progress: bool = True) -> pd.DataFrame:
    """Estimate every capture of ``captures_dir`` into ``out_dir`` (see the module docstring)
    and return the table."""
    from dask.distributed import as_completed

    cfg = cfg or BatchConfig()
    captures = find_captures(captures_dir)
    out_dir = Path(out_dir)
    inside = [c for c in captures if out_dir.resolve() in (c.resolve(), *c.resolve().parents)
              or c.resolve() in out_dir.resolve().parents]
    if inside:
        raise VolecError(f"the output folder {out_dir} and the capture {inside[0]} lie inside "
                         "one another; choose an output folder outside the captures")
    out_dir.mkdir(parents=True, exist_ok=True)
    client, cluster, threads = _cluster(cfg)
    rows: list[dict[str, Any]] = []
    try:
        futures = [client.submit(estimate_one, str(c), str(out_dir / c.name), cfg, threads,
                                 key=f"estimate-{c.name}", pure=False) for c in captures]
        with Progress(len(futures), "batch", "captures", progress) as bar:
            for future in as_completed(futures):
                rows.append(future.result())
                write_table(rows, out_dir)
                bar.update()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return pd.read_csv(out_dir / TABLE)
