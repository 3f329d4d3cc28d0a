"""Progress: a bar on a terminal, a few plain log lines anywhere else, nothing when off."""

from __future__ import annotations

import logging

from volec.progress import Progress, progress_over, step


def test_off_a_terminal_progress_is_a_few_log_lines(caplog, capsys):
    caplog.set_level(logging.INFO, logger="volec.progress")
    assert list(progress_over(range(100), "dense: depth maps", unit="views")) == list(range(100))
    lines = [r.getMessage() for r in caplog.records]
    # the start, each quarter and the end: not a line per step, and no bar characters
    assert lines[0] == "dense: depth maps: 100 views to do"
    assert [line.split(",")[0] for line in lines[1:4]] == [
        "dense: depth maps: 25 of 100 views", "dense: depth maps: 50 of 100 views",
        "dense: depth maps: 75 of 100 views"]
    assert lines[4].startswith("dense: depth maps: 100 of 100 views done in")
    assert len(lines) == 5
    assert capsys.readouterr().err == ""  # pytest's stderr is not a terminal: no bar


def test_a_bar_when_asked_and_nothing_when_disabled(caplog, capsys):
    caplog.set_level(logging.INFO, logger="volec.progress")
    with Progress(4, "render", "frames", bar=True) as bar:
        for _ in range(4):
            bar.update()
        bar.note("loss=0.1")
    err = capsys.readouterr().err
    assert "render" in err and "4/4" in err and not caplog.records
    for _ in progress_over([1, 2, 3], "quiet", enabled=False):
        pass
    step(False, "not said")
    assert not caplog.records and capsys.readouterr().err == ""
    step(True, "dense stereo")
    assert capsys.readouterr().err == "volec: dense stereo\n"
