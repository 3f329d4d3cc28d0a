"""volec batch: two captures on a local Dask cluster, one failing on purpose."""

from __future__ import annotations

import json
import shutil

import pandas as pd

from tests.files import snapshot
from volec.cli import main


def test_a_batch_estimates_each_capture_records_a_failure_and_skips_finished_work(
        small_capture, small_result, tmp_path, capsys):
    captures = tmp_path / "captures"
    shutil.copytree(small_capture / "capture", captures / "cake")
    broken = captures / "broken"
    shutil.copytree(small_capture / "capture", broken)
    (broken / "transforms.json").write_text("{frames: [")
    out = tmp_path / "out"
    shutil.copytree(small_capture / "work" / "sfm", out / "cake" / "sfm")  # SfM is reused
    before = snapshot(captures)

    assert main(["batch", str(captures), "--out", str(out), "--workers", "2", "--quiet",
                 "--no-completion"]) == 3  # one capture failed
    printed = capsys.readouterr().out
    assert snapshot(captures) == before  # the captures are only read
    table = pd.read_csv(out / "batch.csv").set_index("capture")
    assert list(table.index) == ["broken", "cake"]
    assert table.loc["broken", "status"] == "failed"
    assert "transforms.json: not valid JSON" in table.loc["broken", "error"]
    assert "failed: broken" in printed
    cake = table.loc["cake"]
    result = json.loads((out / "cake" / "result.json").read_text())
    assert cake["status"] == "done" and cake["volume_ml"] == result["volume_ml"]
    assert [cake["low_ml"], cake["high_ml"]] == result["volume_interval_ml"]
    assert not cake["trusted"] and "narrow_orbit" in cake["reasons"]  # 16 frames over 100 deg
    # the batch's page links the report of the capture that has one, and only that
    index = (out / "index.html").read_text()
    assert 'href="cake/report.html"' in index and (out / "cake" / "report.html").exists()
    assert 'href="broken/report.html"' not in index and "transforms.json: not valid" in index

    # a second run finds the cake finished and writes nothing into its folder
    finished = snapshot(out / "cake")
    assert main(["batch", str(captures), "--out", str(out), "--workers", "1", "--quiet",
                 "--no-completion"]) == 3
    assert snapshot(out / "cake") == finished
    again = pd.read_csv(out / "batch.csv").set_index("capture")
    assert again.loc["cake", "volume_ml"] == cake["volume_ml"]
    assert again.loc["cake", "seconds"] < cake["seconds"]


def test_a_batch_into_a_capture_is_refused(small_capture, tmp_path, capsys):
    captures = tmp_path / "captures"
    shutil.copytree(small_capture / "capture", captures / "cake")
    assert main(["batch", str(captures), "--out", str(captures / "cake" / "out")]) == 2
    assert "lie inside one another" in capsys.readouterr().err
    assert main(["batch", str(tmp_path / "nothing"), "--out", str(tmp_path / "o")]) == 2


def test_local_workers_keep_the_adaptive_malloc_threshold(monkeypatch):
    # Dask's nanny would set MALLOC_TRIM_THRESHOLD_=65536 in the workers (and in this
    # process), which made dense stereo 2-2.5 times slower there; volec leaves it unset.
    import os

    from volec.batch import local_cluster

    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "65536")  # as an earlier nanny left it
    client, cluster = local_cluster(1)
    try:
        seen = client.run(lambda: os.environ.get("MALLOC_TRIM_THRESHOLD_"))
        threads = client.run(lambda: os.environ.get("OMP_NUM_THREADS"))
    finally:
        client.close()
        cluster.close()
    assert list(seen.values()) == [None]
    assert list(threads.values()) == ["1"]
    assert "MALLOC_TRIM_THRESHOLD_" not in os.environ
