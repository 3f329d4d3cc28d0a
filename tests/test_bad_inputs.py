"""What volec refuses: one table of bad inputs, each run through the command line.

Each case starts from a fresh copy of a small synthetic capture (and an empty output folder),
breaks one thing, runs ``volec``, and checks: the exit status, a message naming the file or
field at fault, that the capture's bytes are unchanged, and that no finished-looking result
appeared in the output folder. The README's table "What volec refuses and what it flags" is
generated from :data:`CASES` (``scripts/refusals_table.py``), not typed twice.
"""

from __future__ import annotations

import errno
import json
import re
import shutil
from collections.abc import Callable
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass, field
from pathlib import Path
from unittest import mock

import numpy as np
import pytest
from PIL import Image

from tests.files import snapshot
from volec.capture import read_transforms_json
from volec.cli import main
from volec.io import folder_lock
from volec.provenance import capture_identity, stage_provenance
from volec.sfm import SfmConfig


@dataclass
class Setup:
    """A case's working copies: the capture folder and the output folder."""

    capture: Path
    out: Path
    argv_tail: list[str] = field(default_factory=list)
    """Extra command-line arguments the case adds."""

    @property
    def transforms(self) -> Path:
        return self.capture / "transforms.json"

    def edit(self, change: Callable[[dict], None]) -> None:
        data = json.loads(self.transforms.read_text())
        change(data)
        self.transforms.write_text(json.dumps(data))

    def frame_file(self, index: int, key: str = "file_path") -> Path:
        data = json.loads(self.transforms.read_text())
        return self.capture / data["frames"][index][key]


@dataclass(frozen=True)
class Case:
    """One bad input and what the user must see."""

    name: str
    given: str
    """What the user gives volec (README column)."""
    answer: str
    """What volec answers (README column)."""
    message: str
    """A regular expression the error message must match (it names the file or field)."""
    prepare: Callable[[Setup], None]
    command: str = "estimate"
    exit_code: int = 2
    around: Callable[[Setup], AbstractContextManager] = lambda s: nullcontext()
    """What is going on while volec runs (another run holding the folder, a full disk)."""


# ----------------------------------------------------------------------------- breakers


def _scale_positions(factor: float) -> Callable[[Setup], None]:
    def change(data: dict) -> None:
        for fr in data["frames"]:
            m = np.array(fr["transform_matrix"])
            m[:3, 3] *= factor
            fr["transform_matrix"] = m.tolist()
    return lambda s: s.edit(change)


def _set_top(key: str, value) -> Callable[[Setup], None]:
    def change(data: dict) -> None:
        if value is None:
            data.pop(key, None)
        else:
            data[key] = value
    return lambda s: s.edit(change)


def _pose_entry(row: int, col: int, value: float) -> Callable[[Setup], None]:
    def change(data: dict) -> None:
        data["frames"][1]["transform_matrix"][row][col] = value
    return lambda s: s.edit(change)


def _truncate_image(s: Setup) -> None:
    path = s.frame_file(3)
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def _garbage_mask(s: Setup) -> None:
    s.frame_file(2, "mask_path").write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(range(200)))


def _decompression_bomb(s: Setup) -> None:
    # a 1-bit PNG of 20000 x 20000 pixels is a few kilobytes on disk
    Image.new("1", (20000, 20000)).save(s.frame_file(0), format="PNG")
    s.edit(lambda d: d["frames"][0].update(w=20000, h=20000))


def _resize_image(s: Setup) -> None:
    path = s.frame_file(4)
    with Image.open(path) as im:
        im.resize((im.width // 2, im.height // 2)).save(path)


def _resize_mask(s: Setup) -> None:
    path = s.frame_file(4, "mask_path")
    with Image.open(path) as im:
        im.resize((im.width + 8, im.height)).save(path)


def _each_mask(change: Callable[[np.ndarray], np.ndarray]) -> Callable[[Setup], None]:
    def prepare(s: Setup) -> None:
        for path in sorted((s.capture / "masks").iterdir()):
            mask = np.asarray(Image.open(path).convert("L")) > 127
            Image.fromarray((change(mask) * 255).astype(np.uint8)).save(path)
    return prepare


def _delete_image(s: Setup) -> None:
    s.frame_file(5).unlink()


def _colmap_project(s: Setup) -> None:
    """Turn the capture into a COLMAP project (sparse/0 + images/) with the same poses."""
    import pycolmap

    capture = read_transforms_json(s.capture)
    intr = capture.frames[0].intrinsics
    rec = pycolmap.Reconstruction()
    cam = pycolmap.Camera.create_from_model_name(1, "PINHOLE", intr.fx, intr.width, intr.height)
    cam.params = [intr.fx, intr.fy, intr.cx + 0.5, intr.cy + 0.5]
    rec.add_camera_with_trivial_rig(cam)
    for i, f in enumerate(capture.frames):
        cfw = np.linalg.inv(f.T_world_from_cam)
        image = pycolmap.Image(name=Path(f.name).name, camera_id=1, image_id=i + 1)
        rec.add_image_with_trivial_frame(
            image, pycolmap.Rigid3d(pycolmap.Rotation3d(cfw[:3, :3]), cfw[:3, 3]))
    (s.capture / "sparse" / "0").mkdir(parents=True)
    rec.write_text(str(s.capture / "sparse" / "0"))
    s.transforms.unlink()
    shutil.rmtree(s.capture / "masks")  # COLMAP projects name masks otherwise


def _fake_record(s: Setup, relative: str, provenance: dict) -> None:
    path = s.out / relative
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"config": provenance["config"], "provenance": provenance,
                                "files": {}}))


def _another_captures_sfm(s: Setup) -> None:
    """The folder holds the SfM stage of a capture with one frame fewer (its record faked, as
    the review that found this did)."""
    capture = read_transforms_json(s.capture)
    from dataclasses import replace

    other = capture_identity(replace(capture, frames=capture.frames[:-1]))
    _fake_record(s, "sfm/summary.json", stage_provenance(other, SfmConfig(), {}, ("volec.sfm",)))


def _sfm_of_all_frames_then_skip_missing(s: Setup) -> None:
    """SfM finished on every frame; then an image is lost and the user skips it."""
    capture = read_transforms_json(s.capture)
    _fake_record(s, "sfm/summary.json",
                 stage_provenance(capture, SfmConfig(), {}, ("volec.sfm",)))
    s.frame_file(5).unlink()
    s.argv_tail.append("--skip-missing")


def _another_captures_result(s: Setup) -> None:
    from dataclasses import replace

    from volec.estimate import MODULES, EstimateConfig

    capture = read_transforms_json(s.capture)
    moved = np.stack([f.T_world_from_cam for f in capture.frames])
    moved[:, 0, 3] += 0.01
    other = replace(capture, frames=tuple(replace(f, T_world_from_cam=T) for f, T in
                                          zip(capture.frames, moved, strict=True)))
    _fake_record(s, "result.json", stage_provenance(other, EstimateConfig(), {}, MODULES))


def _corrupt_result(s: Setup) -> None:
    s.out.mkdir(parents=True)
    (s.out / "result.json").write_text('{"volume_ml": 12')


def _output_is_a_file(s: Setup) -> None:
    s.out.parent.mkdir(parents=True, exist_ok=True)
    s.out.write_text("not a folder")


def _output_inside_capture(s: Setup) -> None:
    s.out = s.capture / "results"


def _add_args(*args: str) -> Callable[[Setup], None]:
    return lambda s: s.argv_tail.extend(args)


def _disk_full(s: Setup) -> AbstractContextManager:
    """The disk fills up as the first stage writes its cloud."""
    error = OSError(errno.ENOSPC, "No space left on device", str(s.out / "scene.ply"))
    return mock.patch("volec.estimate.run_stages", side_effect=error)


CASES = [
    Case("no_such_folder", "a capture folder that does not exist",
         "refused: not a capture volec can read", r"not a capture volec can read",
         lambda s: shutil.rmtree(s.capture)),
    Case("not_json", "a transforms.json that is not JSON", "refused, naming the file",
         r"transforms\.json: not valid JSON", lambda s: s.transforms.write_text("{frames: [")),
    Case("frames_not_a_list", "`frames` that is not a list", "refused, naming the key",
         r"missing key 'frames'", _set_top("frames", {"a": 1})),
    Case("frames_empty", "an empty `frames` list", "refused, naming the key",
         r"'frames' is empty", _set_top("frames", [])),
    Case("frame_not_an_object", "a frame that is not a JSON object", "refused, naming the frame",
         r"frames\[2\] is not a JSON object",
         lambda s: s.edit(lambda d: d["frames"].__setitem__(2, [1, 2]))),
    Case("no_file_path", "a frame without `file_path`", "refused, naming the frame and field",
         r"frames\[0\] has no 'file_path'",
         lambda s: s.edit(lambda d: d["frames"][0].pop("file_path"))),
    Case("duplicated_frame", "the same image listed twice", "refused, naming the file_path",
         r"frames\[1\]\.file_path '.*' appears twice",
         lambda s: s.edit(lambda d: d["frames"][1].update(file_path=d["frames"][0]["file_path"]))),
    Case("missing_image", "a frame whose image file is missing",
         "refused, listing the missing files (or `--skip-missing`)",
         r"frames have missing files:\n  frames\[5\]: .*frame_00005\.jpg", _delete_image),
    Case("truncated_jpeg", "a truncated JPEG", "refused before any work, naming the image",
         r"frames\[3\]: image .*frame_00003\.jpg is not a readable image", _truncate_image),
    Case("corrupt_mask", "a mask file that is not an image", "refused, naming the mask",
         r"frames\[2\]: mask .*frame_00002\.png is not a readable image", _garbage_mask),
    Case("decompression_bomb", "an image declaring 400 megapixels (a decompression bomb)",
         "refused before decoding, naming the image",
         r"frames\[0\]: image .*frame_00000\.jpg declares .*pixels",
         _decompression_bomb),
    Case("mixed_image_sizes", "an image of another size than the intrinsics say",
         "refused, naming the image and both sizes",
         r"frames\[4\]: image .*frame_00004\.jpg is 120x160 but the intrinsics say w=240, h=320",
         _resize_image),
    Case("mask_of_another_size", "a mask of another size than its image",
         "refused, naming the mask", r"frames\[4\]: mask .*frame_00004\.png is 248x320",
         _resize_mask),
    Case("unknown_camera_model", "an unknown `camera_model`", "refused, listing the models read",
         r"camera_model 'KANNALA_BRANDT' is not supported",
         _set_top("camera_model", "KANNALA_BRANDT")),
    Case("missing_focal_length", "no `fl_x` anywhere", "refused, naming the field",
         r"frames\[0\] has no 'fl_x'", _set_top("fl_x", None)),
    Case("negative_focal_length", "a negative focal length", "refused, naming the field",
         r"frames\[0\]\.'fl_y' is -260\.0, expected a positive", _set_top("fl_y", -260.0)),
    Case("non_integer_width", "an image width of 240.5", "refused, naming the field",
         r"'w' is 240\.5, expected an integer", _set_top("w", 240.5)),
    Case("nan_pose", "a NaN in a pose", "refused, naming the frame's matrix",
         r"frames\[1\]\.transform_matrix contains NaN", _pose_entry(0, 3, float("nan"))),
    Case("infinite_pose", "an infinite value in a pose", "refused, naming the frame's matrix",
         r"frames\[1\]\.transform_matrix contains NaN or infinite",
         _pose_entry(1, 3, float("inf"))),
    Case("scaled_rotation", "a pose whose rotation is scaled (not rigid)",
         "refused, naming the frame's matrix",
         r"frames\[1\]\.transform_matrix rotation block is not a proper rotation",
         lambda s: s.edit(lambda d: d["frames"][1].update(transform_matrix=(
             np.diag([2.0, 2.0, 2.0, 1.0]) @ np.array(d["frames"][1]["transform_matrix"])
         ).tolist()))),
    Case("poses_in_centimetres", "poses in centimetres", "refused: the camera distances are not "
         "metres; says how to give the scale",
         r"median \d\d\.?\d* units from the point they look at.*centimetres.*--scale",
         _scale_positions(100.0)),
    Case("poses_in_millimetres", "poses in millimetres", "refused, as for centimetres",
         r"median \d\d\d\.?\d* units .*--scale", _scale_positions(1000.0)),
    Case("instant_ngp_unit_cube", "an instant-ngp transforms.json (`aabb_scale`, rescaled poses)",
         "refused: not metric; says how to give the scale",
         r"not in metres .*aabb_scale.*--scale-from-distance",
         lambda s: s.edit(lambda d: d.update(aabb_scale=16) or d.pop("metric"))),
    Case("says_not_metric", "a transforms.json with `\"metric\": false`",
         "refused: not metric; says how to give the scale", r"not in metres.*--scale",
         _set_top("metric", False)),
    Case("metric_not_a_bool", "`\"metric\": \"yes\"`", "refused, naming the key",
         r"'metric' is 'yes'; expected true or false", _set_top("metric", "yes")),
    Case("colmap_project", "a COLMAP project (arbitrary units)",
         "refused: a COLMAP model has no units; says how to give the scale",
         r"COLMAP model has no units.*--scale", _colmap_project),
    Case("bad_scale", "`--scale -1`", "refused", r"--scale must be a positive number",
         _add_args("--scale", "-1")),
    Case("scale_from_unknown_frame", "`--scale-from-distance` naming a frame not in the capture",
         "refused, naming the frame", r"no frame named 'nope.jpg'",
         _add_args("--scale-from-distance", "nope.jpg", "images/frame_00001.jpg", "0.2")),
    Case("masks_inverted", "every mask inverted (food black)", "refused before any work, "
         "naming the masks", r"12 of 12 food masks are unusable \(.*frame_00000\.png: covers",
         _each_mask(lambda m: ~m)),
    Case("masks_empty", "every mask empty", "refused before any work, naming the masks",
         r"12 of 12 food masks are unusable \(.*frame_00000\.png: empty",
         _each_mask(lambda m: np.zeros_like(m))),
    Case("no_masks_but_given_asked", "`--masks given` for a capture without masks",
         "refused before any work (without `--masks given`, volec segments the food itself)",
         r"12 of 12 frames have no food mask",
         lambda s: (s.edit(lambda d: [fr.pop("mask_path") for fr in d["frames"]]),
                    s.argv_tail.extend(["--masks", "given"]))),
    Case("missing_checkpoint", "`--checkpoint` naming a file that does not exist",
         "refused before any work", r"completion checkpoint not found.*nowhere\.pt",
         _add_args("--checkpoint", "/nowhere.pt")),
    Case("output_inside_capture", "an output folder inside the capture", "refused: volec never "
         "writes into a capture", r"is inside the capture", _output_inside_capture),
    Case("sfm_output_inside_capture", "`volec sfm` into the capture", "refused",
         r"is inside the capture", _output_inside_capture, command="sfm"),
    Case("dense_output_inside_capture", "`volec dense` into the capture", "refused",
         r"is inside the capture", _output_inside_capture, command="dense"),
    Case("output_is_a_file", "an output folder that is a file", "refused, naming it",
         r"output folder .* exists and is a file", _output_is_a_file),
    Case("sfm_of_another_capture", "an output folder holding another capture's SfM",
         "refused before any work, saying the frames differ; `--overwrite` redoes it",
         r"sfm/summary\.json holds a result that is not from this run's inputs: another "
         r"capture: the frames differ \(11 frames recorded, 12 now", _another_captures_sfm),
    Case("skip_missing_other_frames", "`--skip-missing` into a folder made from all the frames",
         "refused: another capture", r"another capture: the frames differ \(12 frames "
         r"recorded, 11 now; not in this capture: images/frame_00005\.jpg",
         _sfm_of_all_frames_then_skip_missing),
    Case("result_of_another_capture", "an output folder holding another capture's result",
         "refused, saying the poses differ", r"result\.json holds a result that is not from "
         r"this run's inputs: the camera poses differ", _another_captures_result),
    Case("corrupt_result", "a damaged `result.json` in the output folder",
         "refused, naming it; `--overwrite` redoes it", r"result\.json is not valid JSON",
         _corrupt_result),
    Case("busy_output", "an output folder another volec run is writing into",
         "refused, naming the other run's process", r"another volec run \(pid \d+\) is writing",
         lambda s: None, around=lambda s: folder_lock(s.out)),
    Case("disk_full", "a disk that fills up", "one line naming the file it could not write",
         r"^volec: error: cannot write or read .*/out/scene\.ply: No space left on device\n$",
         lambda s: None, around=_disk_full),
]


@pytest.fixture
def setup(quick_capture: Path, tmp_path: Path) -> Setup:
    capture = tmp_path / "capture"
    shutil.copytree(quick_capture / "capture", capture)
    return Setup(capture, tmp_path / "out")


FINISHED = ("result.json", "sfm/summary.json", "dense.json", "masking.json", "mesh.ply")


def _finished(out: Path) -> dict[str, tuple[int, int]]:
    return {name: ((out / name).stat().st_size, (out / name).stat().st_mtime_ns)
            for name in FINISHED if out.is_dir() and (out / name).exists()}


def run_case(case: Case, setup: Setup, capsys: pytest.CaptureFixture) -> str:
    """Break the input as ``case`` says, run volec, check everything the case promises and
    return the error message."""
    case.prepare(setup)
    capture_before = snapshot(setup.capture) if setup.capture.exists() else {}
    finished_before = _finished(setup.out)
    argv = [case.command, str(setup.capture), "--out", str(setup.out), *setup.argv_tail]
    if case.command != "sfm":
        argv.append("--quiet")
    with case.around(setup):
        rc = main(argv)
    err = capsys.readouterr().err
    assert rc == case.exit_code, err
    assert re.search(case.message, err, re.S), err
    assert err.startswith("volec: error: ") and "Traceback" not in err
    if setup.capture.exists():
        assert snapshot(setup.capture) == capture_before  # the capture is only read
    assert _finished(setup.out) == finished_before  # no (new) finished-looking result
    return err


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.name)
def test_bad_input_is_refused_with_a_message_naming_it(case, setup, capsys):
    run_case(case, setup, capsys)


def test_the_table_has_every_case_the_issue_lists():
    assert len(CASES) >= 25
    assert len({c.name for c in CASES}) == len(CASES)


def test_an_unexpected_error_is_a_traceback_and_status_1(setup):
    """A bug is not a user error: main() lets it through, so ``python -m volec`` (and the
    ``volec`` script) print its traceback and exit with status 1."""
    with mock.patch("volec.estimate.run_stages", side_effect=ZeroDivisionError("a bug")):
        with pytest.raises(ZeroDivisionError):
            main(["estimate", str(setup.capture), "--out", str(setup.out), "--quiet"])
