"""SymmCompletion in plain torch: LSTNet (local symmetry transforms) + SGFormer (refinement).

In: a batch of normalized partial clouds (B, N, 3). Out: the list of every stage's cloud, from
the initial (key points plus their symmetric images) to the final, densest one; the loss is the
Chamfer distance of each against the complete shape.

- LSTNet: key points by farthest point sampling; each key point's local feature from its kNN
  neighbourhood in the input through point-transformer (vector) attention; a global feature by
  max pooling; per key point an affine 3x3 matrix A and a translation T, predicted from the
  local and global features, map the key point into the missing region (x' = A x + T). Key
  points plus mapped points are the initial cloud.
- SGFormer: each stage embeds the current points, attends by cross-attention to two guidance
  sets (the partial input's key-point features and the symmetric points' features), then by
  self-attention to itself, and predicts ``up`` offsets per point, multiplying the count.

No custom CUDA ops: kNN is ``torch.cdist`` + ``topk``, FPS a loop of tensor ops; the same code
runs on the CPU and on a GPU.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import nn


@dataclass(frozen=True)
class ModelConfig:
    """Network sizes. The output has ``2 * n_keypoints * prod(upsample)`` points."""

    n_input: int = 2048
    """Points of the (resampled) partial input."""
    n_keypoints: int = 512
    """Key points sampled from the input by FPS."""
    knn: int = 16
    """Neighbours per key point in the local (point-transformer) attention."""
    width: int = 256
    """Feature width."""
    heads: int = 4
    """Attention heads in SGFormer."""
    upsample: tuple[int, ...] = (2, 4)
    """Per refinement stage, how many children each point gets (one stage per entry)."""
    input_frame: str = "pca"
    """How the partial is framed before the network sees it
    (:data:`volec.completion.preprocess.FRAMES`): ``pca``, its own principal axes (the
    paper's; checkpoints that do not say are framed so), or ``upright``, z along the support
    plane's normal (the network then knows which side the table is on)."""

    @property
    def n_output(self) -> int:
        """Points of the final stage's cloud."""
        return 2 * self.n_keypoints * math.prod(self.upsample)


PRESETS: dict[str, ModelConfig] = {
    # The published sizes (2048 in, 512 key points, kNN 16, width 256, two stages).
    "paper": ModelConfig(),
    # Trains on a 2-core CPU in about an hour.
    "cpu": ModelConfig(n_input=1024, n_keypoints=128, knn=16, width=96, heads=4,
                       upsample=(2, 4)),
    # The cpu sizes with the partial framed upright (benchmarks/bench_completion_frame.py).
    "cpu_upright": ModelConfig(n_input=1024, n_keypoints=128, knn=16, width=96, heads=4,
                               upsample=(2, 4), input_frame="upright"),
}


def farthest_point_sample(xyz: torch.Tensor, m: int) -> torch.Tensor:
    """Indices (B, m) of ``m`` farthest-point samples of ``xyz`` (B, N, 3), starting at
    index 0 (deterministic)."""
    B, N, _ = xyz.shape
    idx = torch.zeros(B, m, dtype=torch.long, device=xyz.device)
    dist = torch.full((B, N), float("inf"), device=xyz.device)
    last = torch.zeros(B, dtype=torch.long, device=xyz.device)
    batch = torch.arange(B, device=xyz.device)
    for i in range(m):
        idx[:, i] = last
        d = ((xyz - xyz[batch, last][:, None]) ** 2).sum(-1)
        dist = torch.minimum(dist, d)
        last = dist.argmax(dim=1)
    return idx


def gather(x: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
    """``x`` (B, N, C) at ``idx`` (B, ...) -> (B, ..., C)."""
    B = x.shape[0]
    flat = idx.reshape(B, -1)
    out = torch.gather(x, 1, flat[..., None].expand(-1, -1, x.shape[-1]))
    return out.reshape(*idx.shape, x.shape[-1])


def knn_indices(query: torch.Tensor, points: torch.Tensor, k: int) -> torch.Tensor:
    """(B, M, k) indices of each query's ``k`` nearest ``points``."""
    return torch.cdist(query, points).topk(k, dim=-1, largest=False).indices


def mlp(*sizes: int) -> nn.Sequential:
    """Linear layers with GELU between them."""
    layers: list[nn.Module] = []
    for i in range(len(sizes) - 1):
        layers.append(nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2:
            layers.append(nn.GELU())
    return nn.Sequential(*layers)


class PointTransformer(nn.Module):
    """Vector attention of each query point over its kNN neighbourhood (Zhao et al. 2021)."""

    def __init__(self, width: int) -> None:
        super().__init__()
        self.q, self.k, self.v = (nn.Linear(width, width) for _ in range(3))
        self.pos = mlp(3, width, width)
        self.weight = mlp(width, width, width)
        self.out = nn.Linear(width, width)
        self.norm = nn.LayerNorm(width)

    def forward(self, q_xyz, q_feat, n_xyz, n_feat, idx):
        """Queries (B, M, 3)/(B, M, C) over neighbours ``idx`` (B, M, k) of (B, N, 3)/(B, N, C)."""
        nb_xyz, nb_feat = gather(n_xyz, idx), gather(n_feat, idx)  # (B, M, k, .)
        delta = self.pos(q_xyz[:, :, None] - nb_xyz)
        logits = self.weight(self.q(q_feat)[:, :, None] - self.k(nb_feat) + delta)
        attn = torch.softmax(logits, dim=2)
        agg = (attn * (self.v(nb_feat) + delta)).sum(dim=2)
        return self.norm(q_feat + self.out(agg))


class LSTNet(nn.Module):
    """Key points, local and global features, per-key-point symmetry transforms."""

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        w = cfg.width
        self.cfg = cfg
        self.point_embed = mlp(3, w // 2, w)
        self.local1 = PointTransformer(w)
        self.local2 = PointTransformer(w)
        self.global_mlp = mlp(w, w, w)
        self.transform_head = mlp(2 * w, w, 12)
        self.symm_embed = mlp(w + 12, w, w)
        # Start from the identity map (mapped point = key point) so training starts stable.
        nn.init.zeros_(self.transform_head[-1].weight)
        nn.init.zeros_(self.transform_head[-1].bias)

    def forward(self, partial: torch.Tensor):
        cfg = self.cfg
        key_idx = farthest_point_sample(partial, cfg.n_keypoints)
        keys = gather(partial, key_idx)  # (B, M, 3)
        feats = self.point_embed(partial)  # (B, N, C)
        idx = knn_indices(keys, partial, cfg.knn)
        f = self.local1(keys, gather(feats, key_idx), partial, feats, idx)
        idx_keys = knn_indices(keys, keys, min(cfg.knn, cfg.n_keypoints))
        f = self.local2(keys, f, keys, f, idx_keys)
        g = self.global_mlp(f).max(dim=1).values  # (B, C)
        params = self.transform_head(torch.cat([f, g[:, None].expand_as(f)], dim=-1))
        A = torch.eye(3, device=partial.device) + params[..., :9].reshape(*keys.shape[:2], 3, 3)
        T = params[..., 9:]
        mapped = (A @ keys[..., None])[..., 0] + T
        f_sym = self.symm_embed(torch.cat([f, params], dim=-1))
        return keys, f, mapped, f_sym, g


class SGFormerStage(nn.Module):
    """Cross-attention to the partial and symmetric guidance, self-attention, upsampling."""

    def __init__(self, cfg: ModelConfig, up: int, step_scale: float) -> None:
        super().__init__()
        w = cfg.width
        self.up, self.step_scale = up, step_scale
        self.pos = mlp(3, w, w)
        self.norms = nn.ModuleList(nn.LayerNorm(w) for _ in range(4))
        self.cross_partial = nn.MultiheadAttention(w, cfg.heads, batch_first=True)
        self.cross_symm = nn.MultiheadAttention(w, cfg.heads, batch_first=True)
        self.self_attn = nn.MultiheadAttention(w, cfg.heads, batch_first=True)
        self.ffn = mlp(w, 2 * w, w)
        self.child = nn.Linear(w, up * w)
        self.offset = mlp(w, w // 2, 3)

    def forward(self, xyz, feat, partial_tokens, symm_tokens):
        h = feat + self.pos(xyz)
        q = self.norms[0](h)
        h = h + self.cross_partial(q, partial_tokens, partial_tokens, need_weights=False)[0]
        q = self.norms[1](h)
        h = h + self.cross_symm(q, symm_tokens, symm_tokens, need_weights=False)[0]
        q = self.norms[2](h)
        h = h + self.self_attn(q, q, q, need_weights=False)[0]
        h = h + self.ffn(self.norms[3](h))
        B, N, C = h.shape
        children = self.child(h).reshape(B, N * self.up, C)
        offsets = torch.tanh(self.offset(children)) * self.step_scale
        xyz_up = xyz.repeat_interleave(self.up, dim=1) + offsets
        return xyz_up, children


class SymmCompletion(nn.Module):
    """LSTNet followed by one SGFormer stage per ``cfg.upsample`` entry."""

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        self.cfg = cfg
        w = cfg.width
        self.lst = LSTNet(cfg)
        self.key_pos = mlp(3, w, w)
        self.init_feat = mlp(2 * w, w, w)
        # Offsets shrink stage by stage, as the points get denser.
        self.stages = nn.ModuleList(
            SGFormerStage(cfg, up, 0.2 / (2**i)) for i, up in enumerate(cfg.upsample)
        )

    def forward(self, partial: torch.Tensor) -> list[torch.Tensor]:
        """Every stage's cloud, coarse to fine: (B, 2M, 3), then one per SGFormer stage."""
        if partial.ndim != 3 or partial.shape[-1] != 3:
            raise ValueError(f"expected a (B, N, 3) batch, got {tuple(partial.shape)}")
        keys, f, mapped, f_sym, g = self.lst(partial)
        partial_tokens = f + self.key_pos(keys)
        symm_tokens = f_sym + self.key_pos(mapped)
        xyz = torch.cat([keys, mapped], dim=1)
        gg = g[:, None].expand_as(f)
        feat = torch.cat([self.init_feat(torch.cat([f, gg], -1)),
                          self.init_feat(torch.cat([f_sym, gg], -1))], dim=1)
        outputs = [xyz]
        for stage in self.stages:
            xyz, feat = stage(xyz, feat, partial_tokens, symm_tokens)
            outputs.append(xyz)
        return outputs


def _nearest(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """(B, N) index of each ``a`` point's nearest ``b`` point: the argmin over j of
    |b_j|^2 - 2 a.b_j (|a|^2 does not change the order), one fused batched product."""
    bb = (b * b).sum(-1)[:, None, :]
    return torch.baddbmm(bb, a, b.transpose(1, 2), alpha=-2.0).argmin(dim=2)


def chamfer_l1(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Batch mean of the symmetric Chamfer-L1 distance (mean nearest-neighbour Euclidean
    distance, averaged over both directions) between (B, N, 3) and (B, M, 3).

    The nearest neighbours are found without autograd and the distances recomputed for those
    pairs only: the same value and gradient as differentiating through ``cdist``'s minima,
    at a fraction of the cost (``cdist``'s backward was half the CPU training step).
    """
    with torch.no_grad():
        to_target = _nearest(pred, target)
        to_pred = _nearest(target, pred)
    forward = (pred - gather(target, to_target)).norm(dim=-1).mean(dim=1)
    backward = (target - gather(pred, to_pred)).norm(dim=-1).mean(dim=1)
    return (forward + backward).mean() / 2


def completion_loss(outputs: list[torch.Tensor], target: torch.Tensor) -> torch.Tensor:
    """Sum of every stage's Chamfer-L1 distance to the complete shape."""
    return sum((chamfer_l1(o, target) for o in outputs), torch.zeros((), device=target.device))
