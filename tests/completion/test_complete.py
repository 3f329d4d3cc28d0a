"""Completing a metric cloud: the exact inverse transform, and `volec complete`."""


import numpy as np
import pytest
import torch

from volec.cli import main
from volec.completion.complete import CompletionConfig, complete_cloud
from volec.completion.model import ModelConfig
from volec.geometry import rotvec_to_matrix
from volec.pointcloud import PointCloud, read_ply, write_ply


class _Identity(torch.nn.Module):
    """Returns its input as the final stage: the completed points must be the partial's."""

    def __init__(self, cfg: ModelConfig | None = None) -> None:
        super().__init__()
        self.cfg = cfg or ModelConfig(n_input=256)
        self.dummy = torch.nn.Parameter(torch.zeros(1))

    def forward(self, x):
        return [x]


def _cap(seed: int = 0, n: int = 3000) -> np.ndarray:
    """The upper part of a 4 cm sphere, rotated and moved somewhere in a room."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d = d[d[:, 2] > -0.3] * 0.04
    return d @ rotvec_to_matrix(np.array([0.2, -0.4, 1.0])).T + [0.5, -0.3, 1.2]


def test_the_prediction_returns_to_the_input_frame_exactly():
    partial = _cap()
    result = complete_cloud(PointCloud(partial), _Identity(), CompletionConfig())
    # every predicted point is a partial point, mapped there and back (float32 in between)
    from scipy.spatial import cKDTree

    d, _ = cKDTree(partial).query(result.predicted_xyz)
    assert d.max() < 1e-7 and len(result.predicted_xyz) > 200
    assert len(result.cloud) == len(partial) + len(result.predicted_xyz)
    np.testing.assert_array_equal(result.cloud.xyz[: len(partial)], partial)


def test_volec_complete_writes_a_cloud_in_the_input_frame(tmp_path, smoke_checkpoint, capsys):
    partial = _cap()
    source = write_ply(PointCloud(partial), tmp_path / "partial.ply")
    out = tmp_path / "done.ply"
    args = ["complete", str(source), "--out", str(out), "--checkpoint", str(smoke_checkpoint)]
    assert main(args) == 0
    done = read_ply(out)
    assert len(done) > len(partial)
    np.testing.assert_allclose(done.xyz[: len(partial)], partial, atol=1e-12)
    # predictions lie around the item, not somewhere else: within three of its radii
    centre = partial.mean(axis=0)
    assert np.linalg.norm(done.xyz - centre, axis=1).max() < 3 * 0.04 * 2
    # an existing output is kept unless --overwrite; the input is never the output
    assert main(args) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert main(args + ["--overwrite"]) == 0
    assert main(["complete", str(source), "--out", str(source), "--overwrite"]) == 2


def test_volec_complete_errors_are_clear(tmp_path, capsys):
    few = write_ply(PointCloud(_cap(n=40)), tmp_path / "few.ply")
    missing = tmp_path / "none.pt"
    assert main(["complete", str(few), "--out", str(tmp_path / "o.ply"),
                 "--checkpoint", str(missing)]) == 2
    assert "make retrain" in capsys.readouterr().err
    assert main(["complete", str(tmp_path / "absent.ply"), "--out", str(tmp_path / "o.ply")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert not (tmp_path / "o.ply").exists()


class _CopyAndShift(torch.nn.Module):
    """Predicts the input twice: as it is, and shifted 3 units (normalized frame) away."""

    def __init__(self) -> None:
        super().__init__()
        self.cfg = ModelConfig(n_input=256)
        self.dummy = torch.nn.Parameter(torch.zeros(1))

    def forward(self, x):
        return [torch.cat([x, x + torch.tensor([0.0, 0.0, 3.0])], dim=1)]


def test_missing_only_keeps_the_predicted_points_away_from_the_partial():
    partial = _cap()
    normals = np.tile([0.0, 0.0, 1.0], (len(partial), 1))
    result = complete_cloud(PointCloud(partial, None, normals), _CopyAndShift(),
                            CompletionConfig(missing_only_gap_m=0.01))
    from scipy.spatial import cKDTree

    gap, _ = cKDTree(partial).query(result.predicted_xyz)
    # the copies (on the partial) are gone, the shifted points (metres away) all stay
    assert gap.min() > 0.01 and len(result.predicted_xyz) > 200
    n = len(partial)
    np.testing.assert_array_equal(result.cloud.normals[:n], normals)
    assert np.isnan(result.cloud.normals[n:]).all()


def test_a_model_trained_upright_is_framed_about_the_given_up_and_refuses_without_it():
    from volec.errors import DataError

    partial = np.random.default_rng(4).normal(size=(600, 3)) * [0.02, 0.01, 0.03]
    model = _Identity()
    model.cfg = ModelConfig(n_input=256, input_frame="upright")
    up = np.array([0.0, 0.6, 0.8])
    result = complete_cloud(PointCloud(partial), model, CompletionConfig(), up)
    np.testing.assert_allclose(result.normalization.rotation[2], up, atol=1e-12)
    with pytest.raises(DataError, match="upright"):
        complete_cloud(PointCloud(partial), model, CompletionConfig())


def test_volec_complete_with_the_shipped_upright_checkpoint_needs_up(tmp_path, capsys):
    from volec.completion.complete import SHIPPED_CHECKPOINT
    from volec.completion.train import load_checkpoint

    assert load_checkpoint(SHIPPED_CHECKPOINT)[0].cfg.input_frame == "upright"
    source = write_ply(PointCloud(_cap(n=2000)), tmp_path / "cap.ply")
    out = tmp_path / "done.ply"
    assert main(["complete", str(source), "--out", str(out)]) == 2
    assert "--up" in capsys.readouterr().err and not out.exists()
    assert main(["complete", str(source), "--out", str(out), "--up", "0", "0", "1"]) == 0
    assert len(read_ply(out)) > 2000


def test_resamplings_pool_predictions_from_other_subsets_of_the_partial():
    from scipy.spatial import cKDTree

    from volec.errors import ConfigError

    partial = PointCloud(_cap())
    one = complete_cloud(partial, _Identity(), CompletionConfig())
    again = complete_cloud(partial, _Identity(), CompletionConfig(resamplings=1))
    np.testing.assert_array_equal(one.predicted_xyz, again.predicted_xyz)
    four = complete_cloud(partial, _Identity(), CompletionConfig(resamplings=4))
    # the meshing gets as many predicted points as from one prediction ...
    assert four.summary["predicted_points"] == one.summary["predicted_points"] == 256
    # ... every one a partial point (the identity), and most from the other three subsets
    assert cKDTree(partial.xyz).query(four.predicted_xyz)[0].max() < 1e-7
    from_first = cKDTree(one.predicted_xyz).query(four.predicted_xyz)[0] < 1e-9
    assert 0.1 < from_first.mean() < 0.5
    with pytest.raises(ConfigError, match="resamplings"):
        complete_cloud(partial, _Identity(), CompletionConfig(resamplings=0))


def test_the_network_can_be_shown_the_rim_points_without_meshing_them_twice():
    model = _Identity(ModelConfig(n_input=512, input_frame="upright"))
    rng = np.random.default_rng(3)
    top = PointCloud(rng.normal(size=(2000, 3)) * [0.02, 0.02, 0.01] + [0, 0, 0.06])
    rims = PointCloud(rng.normal(size=(600, 3)) * [0.02, 0.02, 0.002])
    up, cfg = np.array([0.0, 0.0, 1.0]), CompletionConfig()
    alone = complete_cloud(top, model, cfg, up)
    shown = complete_cloud(top, model, cfg, up, rims)
    assert alone.predicted_xyz[:, 2].min() > 0.01  # only the top was shown
    low = shown.predicted_xyz[:, 2] < 0.01  # the rim points, shown and so predicted
    assert 0.1 < low.mean() < 0.4
    # the completed cloud is the partial and the predictions: no rim point is merged in
    np.testing.assert_array_equal(shown.cloud.xyz[:len(top)], top.xyz)
    assert len(shown.cloud) == len(top) + len(shown.predicted_xyz)
