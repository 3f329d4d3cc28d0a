"""The HTML report: self-contained, the 3D view drawn in a real browser (headless Chromium,
Debian's package, which `make setup` installs), no network request; the batch index sorts."""

from __future__ import annotations

import base64
import hashlib
import json
import re
import shutil
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import trimesh

from volec.pointcloud import PREDICTED_COLOUR, PointCloud
from volec.report import (
    ReportConfig,
    ReportScene,
    report_html,
    write_batch_index,
    write_report_html,
)

ASSETS = Path(__file__).resolve().parents[1] / "volec" / "report_assets"
BACKGROUND = np.array([244, 244, 242])


def _record(trusted: bool = False) -> dict:
    return {
        "volume_ml": 33.51, "trusted": trusted, "completion_used": True,
        "volume_bounds_ml": [30.2, 41.75], "unknown_share": 0.31, "high_open": False,
        "measured_surface_share": 0.574, "volume_interval_ml": [28.41, 44.3],
        "scale_std_pct": 0.3125, "config": {"measured_reach_m": 0.001, "scale_sigmas": 2.0},
        "reasons": [] if trusted else [{"code": "narrow_orbit",
                                        "message": "the cameras span only 150 degrees"}],
        "warnings": [] if trusted else ["the cameras span only 150 degrees <b>"],
        "frames": {"total": 40, "registered": 39}, "orbit_coverage_deg": 150.0,
        "scale": {"source": "transforms.json says metric"}, "masks": {"source": "given"},
        "mesh": {"faces": 1280}, "support_plane": {"normal": [0, 1, 0]},
        "volec_version": "0.1.0", "capture": "/data/apple</script>",
        "stage_seconds": {"sfm_s": 61.2, "dense_s": 30.0, "total_s": 101.0},
    }


def _scene(predicted: int = 300) -> ReportScene:
    """A 20 mm sphere resting on y = 0, its upper half as observed points, and points below
    as the network's."""
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.02)
    mesh.apply_translation([0, 0.02, 0])
    rng = np.random.default_rng(0)
    directions = rng.normal(size=(4000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    top = directions[directions[:, 1] > 0][:1500]
    bottom = directions[directions[:, 1] <= 0][:predicted]
    observed = PointCloud(top * 0.02 + [0, 0.02, 0],
                          rgb=np.tile(np.array([[200, 40, 30]], np.uint8), (len(top), 1)))
    return ReportScene(mesh, observed, bottom * 0.02 + [0, 0.02, 0], np.array([0, 1.0, 0]))


def _viewer_data(page: str) -> dict:
    match = re.search(r'<script type="application/json" id="volec-data">(.*?)</script>', page,
                      re.S)
    assert match is not None
    return json.loads(match.group(1).replace("<\\/", "</"))


def test_the_viewer_bundle_was_made_from_the_current_source():
    header = (ASSETS / "viewer.min.js").read_text()[:300]
    source = hashlib.sha256((ASSETS / "viewer_src.js").read_bytes()).hexdigest()
    assert f"sha256 {source}" in header, "viewer_src.js changed: run scripts/vendor_viewer.sh"
    assert "three.js authors" in (ASSETS / "LICENSE-three.txt").read_text()


def test_the_report_holds_the_geometry_and_names_no_outside_resource():
    scene = _scene()
    page = report_html(_record(), scene, {"masks": b"\x89PNG fake"})
    # nothing to fetch: no src/href but data: URIs, and a policy that forbids every request
    assert not re.findall(r'(?:src|href)="(?!data:)[^"]*"', page)
    assert "default-src 'none'" in page
    assert "@import" not in page and "url(" not in page.split("<script>")[0]
    data = _viewer_data(page)
    positions = np.frombuffer(base64.b64decode(data["mesh"]["positions"]), np.float32)
    np.testing.assert_allclose(positions.reshape(-1, 3), scene.mesh.vertices, atol=1e-7)
    faces = np.frombuffer(base64.b64decode(data["mesh"]["indices"]), np.uint32)
    np.testing.assert_array_equal(faces.reshape(-1, 3), scene.mesh.faces)
    layers = {layer["name"]: layer for layer in data["layers"]}
    assert layers["predicted"]["color"] == PREDICTED_COLOUR and layers["predicted"]["count"] == 300
    assert layers["observed"]["count"] == len(scene.observed)
    # what the record says reaches the page, escaped
    assert "33.5 mL" in page and "narrow_orbit" in page
    assert "Between 30.2 and 41.8 mL" in page and "31 %" in page
    assert "57 % of the mesh" in page and "within 1 mm of a measured point" in page
    assert "2 standard deviations of 0.31 % in length" in page
    assert "between 28.4 and 44.3 mL" in page
    assert "&lt;b&gt;" in page and "/data/apple&lt;/script&gt;" in page


def test_the_bounds_say_when_the_scales_uncertainty_is_not_in_them():
    from volec.report import bounds_sentence

    record = {**_record(), "scale_std_pct": None, "volume_interval_ml": [30.2, 41.75]}
    assert "uncertainty is not known" in bounds_sentence(record)
    # cameras in one place bound no scale: result.json holds null, and the page says so
    unbounded = {**_record(), "scale_std_pct": None, "volume_interval_ml": [0.0, None]}
    assert "uncertainty is not known" in bounds_sentence(unbounded)
    # a record made before volec reported the interval says only what it holds
    old = {k: v for k, v in _record().items() if k not in ("scale_std_pct",
                                                          "volume_interval_ml")}
    assert "scale" not in bounds_sentence(old)


def test_large_clouds_and_meshes_are_sampled_for_the_view_only():
    scene = _scene(predicted=1000)
    page = report_html(_record(True), scene, {}, ReportConfig(max_points=500, max_faces=400))
    data = _viewer_data(page)
    layers = {layer["name"]: layer for layer in data["layers"]}
    assert (layers["observed"]["count"], layers["observed"]["of"]) == (500, 1500)
    assert layers["predicted"]["count"] == 500
    assert 0 < data["mesh"]["faces"] <= 400
    assert "Trusted" in page and "(500 of 1500)" in page


def test_without_completion_there_is_no_predicted_layer():
    scene = _scene(predicted=0)
    data = _viewer_data(report_html(_record(), scene, {}))
    assert [layer["name"] for layer in data["layers"]] == ["observed"]


def _chromium() -> str:
    path = shutil.which("chromium") or shutil.which("chromium-browser")
    if path is None:
        pytest.skip("Chromium is not installed (make setup installs Debian's chromium as root)")
    pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
    return path


@pytest.fixture(scope="module")
def browser():
    executable = _chromium()
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        # WebGL in a headless browser without a GPU: ANGLE on SwiftShader (software)
        b = p.chromium.launch(executable_path=executable, headless=True,
                              args=["--use-angle=swiftshader", "--enable-unsafe-swiftshader"])
        yield b
        b.close()


def _open(browser, path: Path):
    page = browser.new_page(viewport={"width": 1200, "height": 1400})
    requests: list[str] = []
    page.on("request", lambda r: requests.append(r.url))
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(path.as_uri())
    return page, requests, errors


def _wait_for_frames(page, more_than: int, timeout_s: float = 60.0) -> None:
    """Wait until the viewer has drawn more than ``more_than`` frames (polled from here:
    the page's policy forbids the eval that Playwright's own waiting uses)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if page.evaluate("window.volecViewerState ? window.volecViewerState.frames : -1") \
                > more_than:
            return
        page.wait_for_timeout(100)
    raise AssertionError(f"the viewer drew no more than {more_than} frames in {timeout_s} s")


def _viewer_pixels(page, path: Path) -> np.ndarray:
    from PIL import Image

    page.locator("#volec-viewer").screenshot(path=str(path))
    with Image.open(path) as im:
        return np.asarray(im.convert("RGB")).astype(int)


def test_the_report_draws_the_mesh_in_chromium_without_any_request(browser, tmp_path):
    report = write_report_html(tmp_path / "report.html", _record(), _scene(), {})
    page, requests, errors = _open(browser, report)
    _wait_for_frames(page, 10)
    assert page.evaluate("window.volecViewerState.error") is None
    pixels = _viewer_pixels(page, tmp_path / "viewer.png")
    drawn = np.abs(pixels - BACKGROUND).sum(axis=2) > 30
    # the sphere fills a good part of the canvas: framed on it, not a speck or nothing
    assert 0.05 < drawn.mean() < 0.9, f"{drawn.mean():.3f} of the canvas drawn"
    mesh_colour = np.array([216, 178, 122])
    lit = (np.abs(pixels - mesh_colour).sum(axis=2) < 120) & drawn
    assert lit.mean() > 0.03  # shaded in the mesh's colour
    # the network's points appear in their own colour when switched on (mesh hidden)
    page.locator('input[data-layer="mesh"]').uncheck()
    page.locator('input[data-layer="predicted"]').check()
    page.locator("#volec-rotate").uncheck()
    frames = page.evaluate("window.volecViewerState.frames")
    _wait_for_frames(page, frames + 5)
    pixels = _viewer_pixels(page, tmp_path / "predicted.png")
    magenta = np.array([0xd6, 0x24, 0x6e])
    assert (np.abs(pixels - magenta).sum(axis=2) < 90).sum() > 50
    assert errors == []
    assert requests == [report.as_uri()], f"the page asked for {requests}"
    page.close()


def test_the_batch_index_links_each_report_and_sorts_in_chromium(browser, tmp_path):
    table = pd.DataFrame({"capture": ["banana", "apple", "kiwi"],
                          "volume_ml": [120.5, 9.25, 80.0], "status": ["ok", "ok", "failed"]})
    index = write_batch_index(tmp_path / "index.html", table,
                              {"banana": "banana/report.html", "apple": "apple/report.html"})
    page, requests, errors = _open(browser, index)
    assert page.locator('a[href="banana/report.html"]').inner_text() == "banana"
    assert page.locator("a").count() == 2  # the failed capture has no report
    page.locator("th", has_text="volume_ml").click()
    column = page.locator("#batch tbody td:nth-child(2)").all_inner_texts()
    assert column == ["9.25", "80.0", "120.5"]  # numerically, not as text
    page.locator("th", has_text="volume_ml").click()
    assert page.locator("#batch tbody td:nth-child(1)").all_inner_texts() == \
        ["banana", "kiwi", "apple"]
    assert errors == [] and requests == [index.as_uri()]
    page.close()
