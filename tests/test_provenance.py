"""Provenance: source digests follow the code a result depends on; capture identities say
what differs."""

from __future__ import annotations

import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import volec.provenance as provenance
from volec.capture import read_transforms_json
from volec.experiments import cached_row, row_key
from volec.provenance import capture_identity, differences, stage_provenance
from volec.sfm import SfmConfig


@pytest.fixture
def fake_package(tmp_path, monkeypatch) -> Path:
    """A package laid out like volec: ``a`` imports ``b`` (lazily, inside a function), ``b``
    imports ``sub.c``; ``d`` stands alone."""
    root = tmp_path / "volec"
    (root / "sub").mkdir(parents=True)
    (root / "__init__.py").write_text("__version__ = '0'\n")
    (root / "sub" / "__init__.py").write_text("")
    (root / "a.py").write_text("def f():\n    from volec.b import g\n    return g()\n")
    (root / "b.py").write_text("from volec.sub import c\n\ndef g():\n    return c.K\n")
    (root / "sub" / "c.py").write_text("K = 1\n")
    (root / "d.py").write_text("import numpy\n")
    monkeypatch.setattr(provenance, "_PACKAGE_ROOT", root)
    provenance.module_closure.cache_clear()
    provenance.source_digest.cache_clear()
    yield root
    provenance.module_closure.cache_clear()
    provenance.source_digest.cache_clear()


def _digest_after(root: Path, relative: str, text: str, module: str) -> str:
    (root / relative).write_text(text)
    provenance.module_closure.cache_clear()
    provenance.source_digest.cache_clear()
    return provenance.source_digest(module)


def test_source_digest_covers_what_a_module_imports_and_nothing_else(fake_package):
    assert provenance.module_closure("volec.a") == (
        "volec", "volec.a", "volec.b", "volec.sub", "volec.sub.c")
    before = provenance.source_digest("volec.a")
    # a module it does not import: unchanged
    assert _digest_after(fake_package, "d.py", "import os\n", "volec.a") == before
    # a module two imports away: changed
    changed = _digest_after(fake_package, "sub/c.py", "K = 2\n", "volec.a")
    assert changed != before
    assert _digest_after(fake_package, "sub/c.py", "K = 1\n", "volec.a") == before
    # prose is not code: a docstring or a comment changes nothing
    prose = '"""Constants."""\n\nK = 1  # the constant\n'
    assert _digest_after(fake_package, "sub/c.py", prose, "volec.a") == before
    # a field's docstring (under it, as in the configs) is prose too; an f-string is not
    field = '"""Constants."""\n\nK = 1  # the constant\n"""What K is."""\nif K:\n    """x"""\n'
    with_if = _digest_after(fake_package, "sub/c.py", "K = 1\nif K:\n    pass\n", "volec.a")
    assert _digest_after(fake_package, "sub/c.py", field, "volec.a") == with_if != before
    assert _digest_after(fake_package, "sub/c.py", 'K = 1\nf"{K}"\n', "volec.a") != before


def test_the_real_stages_depend_on_their_own_modules():
    sfm = provenance.module_closure("volec.sfm")
    assert "volec.sfm" in sfm and "volec.capture" in sfm and "volec.dense" not in sfm
    estimate = provenance.module_closure("volec.estimate")
    for stage in ("volec.sfm", "volec.dense", "volec.masking", "volec.meshing", "volec.trust",
                  "volec.completion.complete", "volec.completion.model"):
        assert stage in estimate


def test_a_capture_is_itself_wherever_it_lies_and_changes_are_named(quick_capture, tmp_path):
    capture = read_transforms_json(quick_capture / "capture")
    moved = tmp_path / "moved"
    shutil.copytree(quick_capture / "capture", moved)
    assert capture_identity(read_transforms_json(moved))["digest"] == \
        capture_identity(capture)["digest"]

    wanted = stage_provenance(capture, SfmConfig(), {}, ("volec.sfm",))
    assert differences(wanted, wanted) == []
    # one image's bytes change
    image = moved / capture.frames[3].name
    image.write_bytes(image.read_bytes() + b"\0")
    edited = stage_provenance(read_transforms_json(moved), SfmConfig(), {}, ("volec.sfm",))
    name = capture.frames[3].name
    assert differences(wanted, edited) == [f"the images of 1 frames differ ({name})"]
    # the poses move, the frames are reordered
    poses = np.stack([f.T_world_from_cam for f in capture.frames])
    poses[:, 1, 3] += 1e-4
    shifted = replace(capture, frames=tuple(replace(f, T_world_from_cam=T)
                                            for f, T in zip(capture.frames, poses, strict=True)))
    assert "the camera poses differ" in differences(
        wanted, stage_provenance(shifted, SfmConfig(), {}, ("volec.sfm",)))
    # the same frames, timed as a recording of their own
    retimed = replace(capture, frames=tuple(replace(f, elapsed_share=0.5 * i / (len(capture) - 1))
                                            for i, f in enumerate(capture.frames)))
    assert differences(wanted, stage_provenance(retimed, SfmConfig(), {}, ("volec.sfm",))) == \
        ["the frames' times in the recording differ"]
    reordered = replace(capture, frames=capture.frames[::-1])
    assert "the same frames in another order" in differences(
        wanted, stage_provenance(reordered, SfmConfig(), {}, ("volec.sfm",)))[0]
    assert differences(None, wanted) == ["it records no provenance (made by an older volec)"]


def test_an_experiment_row_is_recomputed_when_its_code_changes(tmp_path, monkeypatch):
    import volec.experiments as experiments

    calls = []

    def compute() -> dict:
        calls.append(1)
        return {"value": len(calls)}

    cache = tmp_path / "volume_eval.json"
    key = row_key({"cfg": 1}, "volec.sfm")
    assert key["code"]["source_digest"] == provenance.source_digest("volec.sfm")
    assert cached_row(cache, key, compute) == {"value": 1}
    assert cached_row(cache, row_key({"cfg": 1}, "volec.sfm"), compute) == {"value": 1}
    # the same config, but the SfM code (or anything it imports) changed
    monkeypatch.setattr(experiments, "code_identity",
                        lambda *m: {"volec_version": "0.1.0", "source_digest": "changed"})
    assert cached_row(cache, row_key({"cfg": 1}, "volec.sfm"), compute) == {"value": 2}
    assert len(calls) == 2


def test_a_synthetic_capture_made_by_other_generator_code_is_not_current(quick_capture,
                                                                         monkeypatch):
    import volec.synth.generate as generate

    assert generate.is_current(quick_capture, generate.PRESETS["quick"])
    assert not generate.is_current(quick_capture, generate.PRESETS["default"])
    monkeypatch.setattr(generate, "synth_code",
                        lambda: {"volec_version": "0.1.0", "source_digest": "other"})
    assert not generate.is_current(quick_capture, generate.PRESETS["quick"])
