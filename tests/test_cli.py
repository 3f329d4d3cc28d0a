from volec.cli import main
from volec.synth.shapes import ITEMS


def test_synth_list_prints_every_item_with_its_volume(capsys):
    assert main(["synth", "--list"]) == 0
    out = capsys.readouterr().out
    for name, spec in ITEMS.items():
        assert name in out and f"{spec.volume_ml:.1f}" in out


def test_synth_writes_a_capture(tmp_path, capsys):
    rc = main(["synth", "falafel", "--out", str(tmp_path / "f"), "--preset", "quick",
               "--frames", "3", "--seed", "2"])
    assert rc == 0
    assert len(list((tmp_path / "f" / "capture" / "images").iterdir())) == 3
    assert "wrote" in capsys.readouterr().out


def test_bad_input_is_a_clear_error_and_a_nonzero_exit(tmp_path, capsys):
    assert main(["synth", "kiwi", "--out", str(tmp_path)]) == 2
    assert "unknown item 'kiwi'" in capsys.readouterr().err
    assert main(["synth", "apple"]) == 2
    assert "--out" in capsys.readouterr().err


def test_sfm_on_a_folder_that_is_no_capture_is_a_clear_error(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    assert main(["sfm", str(tmp_path / "empty"), "--out", str(tmp_path / "work")]) == 2
    err = capsys.readouterr().err
    assert "not a capture volec can read" in err
    assert not (tmp_path / "work").exists()  # nothing written for bad input
