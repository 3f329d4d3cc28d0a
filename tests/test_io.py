import json

import pytest

from volec.errors import OutputExistsError
from volec.io import atomic_folder, fill_folder_atomic, write_json_atomic


def test_failed_fill_leaves_no_output_and_no_temporary(tmp_path):
    final = tmp_path / "out"
    with pytest.raises(RuntimeError):
        with atomic_folder(final) as tmp:
            (tmp / "half.txt").write_text("partial")
            raise RuntimeError("boom")
    assert not final.exists()
    assert list(tmp_path.iterdir()) == []


def test_existing_result_is_kept_unless_overwrite(tmp_path):
    final = tmp_path / "out"
    fill_folder_atomic(final, lambda d: (d / "a.txt").write_text("first"))
    with pytest.raises(OutputExistsError, match="--overwrite"):
        fill_folder_atomic(final, lambda d: (d / "a.txt").write_text("second"))
    assert (final / "a.txt").read_text() == "first"
    fill_folder_atomic(final, lambda d: (d / "b.txt").write_text("second"), overwrite=True)
    assert sorted(p.name for p in final.iterdir()) == ["b.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_failed_overwrite_keeps_the_earlier_result(tmp_path):
    final = tmp_path / "out"
    fill_folder_atomic(final, lambda d: (d / "a.txt").write_text("first"))

    def broken(d):
        (d / "a.txt").write_text("second")
        raise ValueError("bad input")

    with pytest.raises(ValueError):
        fill_folder_atomic(final, broken, overwrite=True)
    assert (final / "a.txt").read_text() == "first"


def test_write_json_atomic_round_trips(tmp_path):
    data = {"volume_ml": 175.25, "items": [1, 2]}
    write_json_atomic(tmp_path / "x" / "r.json", data)
    assert json.loads((tmp_path / "x" / "r.json").read_text()) == data


def test_a_folder_lock_refuses_a_second_holder_and_is_released(tmp_path):
    from volec.errors import BusyError
    from volec.io import folder_lock

    with folder_lock(tmp_path / "out"):
        with pytest.raises(BusyError, match=r"another volec run \(pid \d+\)"):
            with folder_lock(tmp_path / "out"):
                pass
    with folder_lock(tmp_path / "out"):  # released when the first run ended
        pass
