"""The network's output shapes, its Chamfer loss, and a two-step training run."""

import numpy as np
import pytest
import torch

from volec.completion.model import (
    PRESETS,
    SymmCompletion,
    chamfer_l1,
    farthest_point_sample,
)


@pytest.mark.parametrize("preset", ["cpu", "paper"])
def test_forward_shapes(preset):
    cfg = PRESETS[preset]
    torch.manual_seed(0)
    model = SymmCompletion(cfg).eval()
    with torch.no_grad():
        outs = model(torch.randn(2, cfg.n_input, 3) * 0.3)
    sizes = [2 * cfg.n_keypoints]
    for up in cfg.upsample:
        sizes.append(sizes[-1] * up)
    assert [tuple(o.shape) for o in outs] == [(2, n, 3) for n in sizes]
    assert sizes[-1] == cfg.n_output
    assert all(torch.isfinite(o).all() for o in outs)


def test_paper_preset_has_the_published_sizes():
    cfg = PRESETS["paper"]
    assert (cfg.n_input, cfg.n_keypoints, cfg.knn, cfg.width, len(cfg.upsample)) == (
        2048, 512, 16, 256, 2)


def test_chamfer_matches_a_direct_computation_and_its_gradient():
    rng = np.random.default_rng(0)
    a = torch.tensor(rng.normal(size=(2, 50, 3)), requires_grad=True)
    b = torch.tensor(rng.normal(size=(2, 70, 3)))
    d = torch.cdist(a, b)
    direct = (d.min(2).values.mean(1) + d.min(1).values.mean(1)).mean() / 2
    (g_direct,) = torch.autograd.grad(direct, a)
    ours = chamfer_l1(a, b)
    (g_ours,) = torch.autograd.grad(ours, a)
    assert float(ours.detach()) == pytest.approx(float(direct.detach()), rel=1e-10)
    torch.testing.assert_close(g_ours, g_direct)
    assert float(chamfer_l1(b, b)) == 0.0


def test_farthest_point_sampling_spreads_out():
    line = torch.linspace(0, 1, 101)[None, :, None].expand(1, 101, 3).contiguous()
    idx = farthest_point_sample(line, 3)[0].tolist()
    assert idx == [0, 100, 50]


def test_two_step_cpu_training_smoke(smoke_checkpoint):
    from volec.completion.train import load_checkpoint

    lines = smoke_checkpoint.with_suffix(".csv").read_text().splitlines()
    assert lines[0].startswith("step,loss") and len(lines) == 3
    rows = [line.split(",") for line in lines[1:]]
    assert all(np.isfinite(float(r[1])) for r in rows)
    model, meta = load_checkpoint(smoke_checkpoint)
    assert meta["info"]["step"] in (1, 2) and np.isfinite(meta["info"]["val_cd_l1"])
    assert model.cfg == PRESETS["cpu"]
    assert meta["train_config"]["steps"] == 2
    assert meta["info"]["device"] == "cpu"
    assert all(t.device.type == "cpu" for t in model.state_dict().values())
