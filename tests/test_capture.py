import json
import logging
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from volec.capture import (
    Capture,
    Frame,
    Intrinsics,
    read_capture,
    read_colmap_model,
    read_transforms_json,
    write_transforms_json,
)
from volec.errors import CaptureError
from volec.geometry import invert_rigid, rotvec_to_matrix, transform_points


def _image(path: Path, width: int, height: int) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.new("RGB", (width, height), (120, 80, 40)).save(path)


def _capture_dir(tmp_path: Path, frames: list[dict], **top) -> Path:
    """A capture folder with a transforms.json and real images of the right size."""
    content = {"camera_model": "OPENCV", "fl_x": 500.0, "fl_y": 510.0, "cx": 320.0,
               "cy": 240.0, "w": 64, "h": 48, **top, "frames": frames}
    for fr in frames:
        w = fr.get("w", content.get("w", 64))
        h = fr.get("h", content.get("h", 48))
        _image(tmp_path / fr["file_path"], int(w), int(h))
    (tmp_path / "transforms.json").write_text(json.dumps(content))
    return tmp_path


def _frame(name: str, matrix) -> dict:
    return {"file_path": f"images/{name}.png", "transform_matrix": np.asarray(matrix).tolist()}


def test_hand_made_camera_axes_survive_the_conversion(tmp_path):
    # An OpenGL camera 1 m above the origin, identity rotation: it looks straight down the
    # world -z axis, image up = world +y, image right = world +x.
    c2w_gl = np.eye(4)
    c2w_gl[2, 3] = 1.0
    cap = read_transforms_json(_capture_dir(tmp_path, [_frame("a", c2w_gl)]))
    f = cap.frames[0]
    K = f.intrinsics.K

    def project(p):
        q = transform_points(f.T_cam_from_world, np.asarray([p], float))[0]
        assert q[2] > 0, "point must be in front of the camera"
        uv = K @ (q / q[2])
        return uv[:2]

    u0, v0 = project([0, 0, 0])
    assert (u0, v0) == pytest.approx((f.intrinsics.cx, f.intrinsics.cy))
    u_right, _ = project([0.1, 0, 0])
    _, v_up = project([0, 0.1, 0])
    assert u_right > u0  # world +x is image right
    assert v_up < v0  # world +y is image up (smaller row)
    np.testing.assert_allclose(f.camera_centre, [0, 0, 1])


def test_principal_point_moves_to_pixel_centre_convention(tmp_path):
    cap = read_transforms_json(_capture_dir(tmp_path, [_frame("a", np.eye(4))]))
    intr = cap.frames[0].intrinsics
    # nerfstudio's cx=320 (first pixel centre at 0.5) is OpenCV's 319.5.
    assert (intr.cx, intr.cy) == (319.5, 239.5)
    assert (intr.fx, intr.fy, intr.width, intr.height) == (500.0, 510.0, 64, 48)


def _random_capture(root: Path, n: int, per_frame_intrinsics: bool, seed: int = 0) -> Capture:
    rng = np.random.default_rng(seed)
    frames = []
    for i in range(n):
        T = np.eye(4)
        T[:3, :3] = rotvec_to_matrix(rng.normal(size=3))
        T[:3, 3] = rng.normal(scale=0.3, size=3)
        intr = Intrinsics(64, 48, 50.0 + (i if per_frame_intrinsics else 0), 51.0, 31.7, 23.2,
                          "OPENCV", (0.01, -0.002, 1e-4, 2e-4))
        img = root / "images" / f"f{i}.png"
        mask = root / "masks" / f"f{i}.png"
        _image(img, 64, 48)
        _image(mask, 64, 48)
        frames.append(Frame(f"images/f{i}.png", img, intr, T, mask))
    return Capture(root, tuple(frames), {"note": "kept"})


@pytest.mark.parametrize("per_frame", [False, True])
def test_write_read_round_trip_preserves_every_pose(tmp_path, per_frame):
    cap = _random_capture(tmp_path, 7, per_frame)
    write_transforms_json(cap, tmp_path / "transforms.json")
    back = read_transforms_json(tmp_path)
    assert len(back) == 7
    assert back.metadata == {"note": "kept"}
    for a, b in zip(cap.frames, back.frames, strict=True):
        np.testing.assert_allclose(b.T_world_from_cam, a.T_world_from_cam, atol=1e-9, rtol=0)
        # the half-pixel shift of the file convention may cost one ulp
        np.testing.assert_allclose(b.intrinsics.K, a.intrinsics.K, atol=1e-12, rtol=0)
        assert b.intrinsics.distortion == a.intrinsics.distortion
        assert b.intrinsics.width == a.intrinsics.width
        assert b.intrinsics.height == a.intrinsics.height
        assert b.image_path == a.image_path.resolve()
        assert b.mask_path == a.mask_path.resolve()
    if per_frame:
        assert "fl_x" in json.loads((tmp_path / "transforms.json").read_text())["frames"][0]


def test_three_by_four_matrices_are_accepted(tmp_path):
    cap = read_transforms_json(_capture_dir(tmp_path, [_frame("a", np.eye(4)[:3])]))
    np.testing.assert_allclose(cap.frames[0].T_world_from_cam, np.diag([1.0, -1, -1, 1]))


@pytest.mark.parametrize(
    "mutate, words",
    [
        (lambda c: c.pop("frames"), "missing key 'frames'"),
        (lambda c: c.pop("fl_x"), "'fl_x'"),
        (lambda c: c.update(cx="left"), "'cx' is 'left'"),
        (lambda c: c.update(w=-5), "'w' is -5"),
        (lambda c: c.update(camera_model="KANNALA"), "camera_model 'KANNALA'"),
        (lambda c: c["frames"][1].pop("transform_matrix"), "frames[1] has no 'transform_matrix'"),
        (lambda c: c["frames"][1].pop("file_path"), "frames[1] has no 'file_path'"),
        (lambda c: c["frames"][0].update(transform_matrix=[[float("nan")] * 4] * 4),
         "frames[0].transform_matrix contains NaN"),
        (lambda c: c["frames"][0].update(transform_matrix=np.diag([0.0, 0, 0, 1]).tolist()),
         "frames[0].transform_matrix rotation block is singular"),
        (lambda c: c["frames"][1].update(transform_matrix=np.diag([3.0, 3, 3, 1]).tolist()),
         "frames[1].transform_matrix rotation block is not a proper rotation"),
        (lambda c: c["frames"][0].update(transform_matrix=[[1, 2], [3, 4]]),
         "frames[0].transform_matrix shape"),
        (lambda c: c.update(w=100), "is 64x48 but the intrinsics say w=100"),
    ],
)
def test_malformed_files_name_the_file_and_field(tmp_path, mutate, words):
    root = _capture_dir(tmp_path, [_frame("a", np.eye(4)), _frame("b", np.eye(4))])
    content = json.loads((root / "transforms.json").read_text())
    mutate(content)
    (root / "transforms.json").write_text(json.dumps(content))
    with pytest.raises(CaptureError) as err:
        read_transforms_json(root)
    assert str(root / "transforms.json") in str(err.value)
    assert words in str(err.value)


def test_invalid_json_and_missing_file(tmp_path):
    (tmp_path / "transforms.json").write_text("{not json")
    with pytest.raises(CaptureError, match="not valid JSON"):
        read_transforms_json(tmp_path)
    with pytest.raises(CaptureError, match="no such file"):
        read_transforms_json(tmp_path / "elsewhere")


def test_missing_images_are_listed_or_skipped_with_a_warning(tmp_path, caplog):
    root = _capture_dir(tmp_path, [_frame(n, np.eye(4)) for n in "abc"])
    (root / "images" / "b.png").unlink()
    with pytest.raises(CaptureError, match=r"1 of 3 frames have missing files:\n.*b\.png"):
        read_transforms_json(root)
    with caplog.at_level(logging.WARNING):
        cap = read_transforms_json(root, on_missing="skip")
    assert [f.name for f in cap.frames] == ["images/a.png", "images/c.png"]
    assert "b.png" in caplog.text
    # the frames keep their times in the recording: the skipped one is counted
    np.testing.assert_array_equal(cap.elapsed_shares, [0.0, 1.0])


def test_frames_keep_their_time_in_the_recording_in_a_subset(tmp_path):
    root = _capture_dir(tmp_path, [_frame(n, np.eye(4)) for n in "abcde"])
    cap = read_transforms_json(root)
    np.testing.assert_array_equal(cap.elapsed_shares, [0, 0.25, 0.5, 0.75, 1])
    subset = replace(cap, frames=cap.frames[1::2])
    np.testing.assert_array_equal(subset.elapsed_shares, [0.25, 0.75])
    # frames made by hand carry none: their place in the capture stands in
    untimed = replace(cap, frames=tuple(replace(f, elapsed_share=None) for f in subset.frames))
    np.testing.assert_array_equal(untimed.elapsed_shares, [0.0, 1.0])


def test_mask_of_the_wrong_size_is_an_error(tmp_path):
    fr = _frame("a", np.eye(4)) | {"mask_path": "masks/a.png"}
    root = _capture_dir(tmp_path, [fr])
    _image(root / "masks" / "a.png", 10, 10)
    with pytest.raises(CaptureError, match="mask .* is 10x10"):
        read_transforms_json(root)


@pytest.mark.parametrize("binary", [False, True])
def test_colmap_model_reads_as_a_capture(tmp_path, binary):
    pycolmap = pytest.importorskip("pycolmap")
    rec = pycolmap.Reconstruction()
    cam = pycolmap.Camera.create_from_model_name(1, "PINHOLE", 500.0, 64, 48)
    cam.params = [500.0, 505.0, 32.0, 24.0]
    rec.add_camera_with_trivial_rig(cam)
    rng = np.random.default_rng(3)
    T_world_from_cam = []
    for i in range(3):
        T = np.eye(4)
        T[:3, :3] = rotvec_to_matrix(rng.normal(size=3))
        T[:3, 3] = rng.normal(size=3)
        T_world_from_cam.append(T)
        cfw = invert_rigid(T)
        image = pycolmap.Image(name=f"im{i}.png", camera_id=1, image_id=i + 1)
        rec.add_image_with_trivial_frame(
            image, pycolmap.Rigid3d(pycolmap.Rotation3d(cfw[:3, :3]), cfw[:3, 3])
        )
        _image(tmp_path / "images" / f"im{i}.png", 64, 48)
    model = tmp_path / "sparse" / "0"
    model.mkdir(parents=True)
    (rec.write_binary if binary else rec.write_text)(str(model))
    cap = read_capture(tmp_path)
    assert len(cap) == 3
    for f, T in zip(cap.frames, T_world_from_cam, strict=True):
        np.testing.assert_allclose(f.T_world_from_cam, T, atol=1e-9)
        assert (f.intrinsics.fx, f.intrinsics.fy) == (500.0, 505.0)
        assert (f.intrinsics.cx, f.intrinsics.cy) == (31.5, 23.5)
    with pytest.raises(CaptureError, match="missing files"):
        read_colmap_model(model, tmp_path / "nowhere")


def test_unknown_layout_is_explained(tmp_path):
    with pytest.raises(CaptureError, match="transforms.json .* COLMAP"):
        read_capture(tmp_path)


def test_intrinsics_scaling_keeps_pixel_centres():
    intr = Intrinsics(640, 480, 500.0, 500.0, 319.5, 239.5)
    half = intr.scaled(0.5)
    assert (half.width, half.height, half.fx) == (320, 240, 250.0)
    assert (half.cx, half.cy) == (159.5, 119.5)


def test_projection_with_distortion_inverts_opencv_undistortion():
    import cv2

    from volec.capture import Intrinsics

    intr = Intrinsics(640, 480, 500.0, 505.0, 319.0, 241.0, "OPENCV", (0.1, -0.05, 0.001, 0.002))
    rng = np.random.default_rng(0)
    cam = np.c_[rng.uniform(-0.2, 0.2, (50, 2)), rng.uniform(0.5, 1.0, 50)]
    uv = intr.project(cam)
    undone = cv2.undistortPoints(uv.reshape(-1, 1, 2), intr.K, np.array(intr.distortion))
    np.testing.assert_allclose(undone.reshape(-1, 2), cam[:, :2] / cam[:, 2:], atol=1e-6)
    pinhole = Intrinsics(640, 480, 500.0, 505.0, 319.0, 241.0)
    expected = cam[:, :2] / cam[:, 2:] * [500.0, 505.0] + [319.0, 241.0]
    np.testing.assert_allclose(pinhole.project(cam), expected, atol=1e-12)
    assert np.isnan(pinhole.project(np.array([[0.0, 0.0, -1.0]]))).all()
    # unproject gives back each point's ray (z = 1), with and without distortion
    for camera in (intr, pinhole):
        np.testing.assert_allclose(camera.unproject(camera.project(cam)), cam / cam[:, 2:],
                                   atol=1e-6)


def test_a_mask_of_the_wrong_size_is_a_clear_error(tmp_path):
    from PIL import Image

    from volec.capture import Frame, Intrinsics, read_mask
    from volec.errors import CaptureError

    Image.fromarray(np.zeros((10, 12), np.uint8)).save(tmp_path / "m.png")
    frame = Frame("f", tmp_path / "f.png", Intrinsics(24, 20, 10.0, 10.0, 11.5, 9.5),
                  np.eye(4), mask_path=tmp_path / "m.png")
    with pytest.raises(CaptureError, match="must match"):
        read_mask(frame)


def test_images_are_decoded_in_full_and_size_limited(tmp_path, monkeypatch):
    import volec.capture

    path = tmp_path / "a.png"
    _image(path, 40, 30)
    digest = volec.capture.verify_image(path, 40, 30, "image", "here")
    assert len(digest) == 16
    monkeypatch.setattr(volec.capture, "MAX_IMAGE_PIXELS", 1000)
    with pytest.raises(CaptureError, match="here: image .*a.png declares 40x30 pixels, more than"):
        volec.capture.verify_image(path, 40, 30, "image", "here")


def test_a_capture_says_whether_it_is_metric(tmp_path):
    fr = _frame("a", np.eye(4).tolist())
    root = _capture_dir(tmp_path / "plain", [fr])
    assert read_transforms_json(root).metric is None
    root = _capture_dir(tmp_path / "metric", [fr], metric=True)
    capture = read_transforms_json(root)
    assert capture.metric is True
    write_transforms_json(capture, tmp_path / "copy.json")  # round trip keeps it
    assert json.loads((tmp_path / "copy.json").read_text())["metric"] is True
    root = _capture_dir(tmp_path / "ngp", [fr], aabb_scale=16)
    assert read_transforms_json(root).metric is False
