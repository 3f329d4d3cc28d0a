"""Stage reuse, and `volec dense` end to end on a small synthetic capture."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace

import numpy as np
import pytest

from tests.files import snapshot
from volec.capture import read_transforms_json
from volec.cli import main
from volec.dense import DenseConfig
from volec.metrics import distances_to_surface
from volec.pipeline import config_record, stale_reasons
from volec.pointcloud import read_ply
from volec.provenance import capture_identity, file_digest, stage_provenance
from volec.synth import PRESETS, load_ground_truth_mesh, write_synthetic_capture


def test_a_stage_is_reused_only_when_made_from_the_same_inputs(quick_capture, tmp_path):
    capture = read_transforms_json(quick_capture / "capture")
    wanted = stage_provenance(capture, DenseConfig(), {"sfm": "0123"}, ("volec.dense",))
    (tmp_path / "scene.ply").write_bytes(b"points")
    record = {"provenance": wanted, "files": {"scene.ply": file_digest(tmp_path / "scene.ply")}}
    assert stale_reasons(record, wanted, tmp_path, "dense.json") == []

    def reasons(**changes) -> str:
        other = {**wanted, **changes}
        return "; ".join(stale_reasons({**record, "provenance": other}, wanted, tmp_path,
                                       "dense.json"))

    assert "n_depth_planes" in reasons(config=config_record(DenseConfig(n_depth_planes=32)))
    assert "another SfM result" in reasons(upstream={"sfm": "4567"})
    assert "code has changed" in reasons(source_digest="ffff")
    assert "another volec version" in reasons(volec_version="0.0.1")
    fewer = capture_identity(replace(capture, frames=capture.frames[:-1]))
    assert "another capture" in reasons(capture=fewer)
    (tmp_path / "scene.ply").write_bytes(b"other points")
    assert "scene.ply was changed" in "; ".join(
        stale_reasons(record, wanted, tmp_path, "dense.json"))


def test_volec_dense_end_to_end(small_capture, small_result, tmp_path, capsys):
    work = tmp_path / "work"
    shutil.copytree(small_capture / "work" / "sfm", work / "sfm")  # SfM is reused
    capture = small_capture / "capture"
    before = snapshot(capture)
    assert main(["dense", str(capture), "--out", str(work), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "food_masked.ply" in out
    assert snapshot(capture) == before  # the capture is only read

    scene, food = read_ply(work / "scene.ply"), read_ply(work / "food_masked.ply")
    report = json.loads((work / "masking.json").read_text())
    assert report["kept"] == len(food) and report["input_points"] == len(scene)
    assert scene.normals is not None and scene.rgb is not None
    # every other registered frame gets a depth map (DenseConfig.reference_stride = 2)
    registered = int(small_result[0].registered.sum())
    assert json.loads((work / "dense.json").read_text())["reference_views"] == (registered + 1) // 2
    mesh = load_ground_truth_mesh(small_capture)
    d_food = distances_to_surface(food.xyz, mesh)
    d_scene = distances_to_surface(scene.xyz, mesh)
    # metric, in the capture's world frame, on the true surface
    assert np.median(d_food) < 0.0015
    assert np.percentile(d_food, 90) < 0.004
    # what masking removed was mostly not food
    removed = d_scene > 0.004
    assert removed.sum() > 0 and (d_food > 0.004).mean() < 0.25 * removed.mean()

    # a second run reuses every stage; other settings are refused, nothing is touched
    stages = snapshot(work)
    assert main(["dense", str(capture), "--out", str(work), "--quiet"]) == 0
    assert snapshot(work) == stages
    assert main(["dense", str(capture), "--out", str(work), "--preset", "thorough", "--quiet"]) == 2
    assert "other settings" in capsys.readouterr().err
    assert snapshot(work) == stages


def test_volec_dense_with_given_masks_refuses_a_capture_without_masks(tmp_path, capsys):
    out = write_synthetic_capture("apple", tmp_path / "apple",
                                  PRESETS["quick"].with_(n_frames=3, masks_in_capture=False),
                                  progress=False)
    assert main(["dense", str(out / "capture"), "--out", str(tmp_path / "work"),
                 "--masks", "given"]) == 2
    assert "no food mask" in capsys.readouterr().err
    assert not (tmp_path / "work").exists()


def test_masks_handed_in_are_named_by_their_content(quick_capture):
    from volec.pipeline import masks_digest, masks_source
    from volec.segment import MaskSet, given_masks

    capture = read_transforms_json(quick_capture / "capture")
    given = given_masks(capture)
    assert masks_source(capture, "default") == "given" and masks_digest(given) == "given"
    handed = MaskSet(given.names, given.masks, "noisy")
    assert masks_source(capture, handed) == "handed"
    changed = MaskSet(given.names, (~given.masks[0],) + given.masks[1:], "noisy")
    assert masks_digest(handed) != masks_digest(changed)
    assert masks_digest(handed) == masks_digest(MaskSet(given.names, given.masks, "noisy"))
    with pytest.raises(Exception, match="not for this capture"):
        masks_source(capture, MaskSet(given.names[:-1], given.masks[:-1], "noisy"))
