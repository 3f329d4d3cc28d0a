"""Experiments: the per-item runner and the cache its rows go through."""

from __future__ import annotations

from volec.experiments import cached_row, map_items


def test_map_items_in_parallel_returns_the_rows_in_job_order():
    jobs = [([("n", n), ("square", n * n)],) for n in range(5)]
    labels = [f"job {n}" for n in range(5)]
    expected = [{"n": n, "square": n * n} for n in range(5)]
    assert map_items(dict, jobs, labels, workers=2, progress=False) == expected
    assert map_items(dict, jobs, labels, workers=1, progress=False) == expected


def test_cached_row_recomputes_only_when_the_key_changes(tmp_path):
    calls = []

    def compute() -> dict:
        calls.append(1)
        return {"value": len(calls)}

    cache = tmp_path / "eval.json"
    assert cached_row(cache, {"cfg": 1}, compute) == {"value": 1}
    assert cached_row(cache, {"cfg": 1}, compute) == {"value": 1}  # read back, not computed
    assert cached_row(cache, {"cfg": 2}, compute) == {"value": 2}
    assert len(calls) == 2
