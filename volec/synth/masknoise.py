"""Masks as a real segmenter would give them, from the exact ones.

In: a capture's exact food masks (bool, in frame order), the shadow each frame shows
(from the renderer) and a :class:`MaskNoiseConfig`. Out: the same number of masks, each with
its boundary a few pixels off (grown or shrunk, and wobbling), and on some frames worse: the
food's shadow leaked in, a chunk of the food missed, a false blob beside it, or nothing at all;
with the list of what was done to which frame, for the ground truth. Seeded: the same config
gives the same masks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage


@dataclass(frozen=True)
class MaskNoiseConfig:
    """How wrong the masks are."""

    boundary_px: tuple[int, int] = (1, 3)
    """Every mask's boundary moves in or out by this many pixels (drawn per frame)..."""
    wobble_px: float = 1.5
    """... and wobbles by up to this much along its length."""
    shadow_share: float = 0.15
    """Share of the frames where the shadow beside the food leaks into the mask."""
    chunk_share: float = 0.06
    """Share of the frames where a chunk of the food is missed..."""
    chunk_fraction: float = 0.25
    """... this share of the food's pixels."""
    blob_share: float = 0.06
    """Share of the frames with a false blob beside the food..."""
    blob_fraction: float = 0.15
    """... this share of the food's area."""
    empty_frames: int = 2
    """Frames whose mask is empty."""
    seed: int = 0


def _wobbly_boundary(mask: np.ndarray, offset_px: int, wobble_px: float,
                     rng: np.random.Generator) -> np.ndarray:
    """``mask`` grown (``offset_px`` > 0) or shrunk, by an amount that wobbles smoothly by up
    to ``wobble_px`` along the boundary."""
    inside = ndimage.distance_transform_edt(mask)
    outside = ndimage.distance_transform_edt(~mask)
    signed = outside - inside  # > 0 outside
    wobble = ndimage.gaussian_filter(rng.normal(size=mask.shape), 6.0)
    wobble *= wobble_px / (np.abs(wobble).max() + 1e-9)
    return signed < offset_px + wobble + 0.5


def _chunk(mask: np.ndarray, fraction: float, rng: np.random.Generator) -> np.ndarray:
    """The pixels of a round chunk of ``mask`` holding about ``fraction`` of it, at its edge."""
    ys, xs = np.nonzero(mask)
    edge = mask & ~ndimage.binary_erosion(mask)
    ey, ex = np.nonzero(edge)
    k = rng.integers(len(ey))
    radius = np.sqrt(fraction * len(ys) / np.pi) * 1.4
    yy, xx = np.ogrid[:mask.shape[0], :mask.shape[1]]
    return mask & ((yy - ey[k]) ** 2 + (xx - ex[k]) ** 2 <= radius**2)


def _blob(mask: np.ndarray, fraction: float, rng: np.random.Generator) -> np.ndarray:
    """A false blob of about ``fraction`` of the mask's area, touching it from outside."""
    area = mask.sum()
    radius = max(2.0, np.sqrt(fraction * area / np.pi))
    edge = mask & ~ndimage.binary_erosion(mask)
    ey, ex = np.nonzero(edge)
    k = rng.integers(len(ey))
    cy, cx = ndimage.center_of_mass(mask)
    direction = np.array([ey[k] - cy, ex[k] - cx])
    direction /= np.linalg.norm(direction) + 1e-9
    centre = np.array([ey[k], ex[k]]) + 0.8 * radius * direction
    yy, xx = np.ogrid[:mask.shape[0], :mask.shape[1]]
    return (yy - centre[0]) ** 2 + (xx - centre[1]) ** 2 <= radius**2


def noisy_masks(masks: list[np.ndarray], shadows: list[np.ndarray],
                cfg: MaskNoiseConfig | None = None) -> tuple[list[np.ndarray], list[str]]:
    """The masks a segmenter might give for ``masks`` (exact, bool), and per frame what was
    done to it (``boundary +2 px``, ``... + shadow``, ``empty`` ...)."""
    cfg = cfg or MaskNoiseConfig()
    rng = np.random.default_rng(cfg.seed)
    n = len(masks)
    kinds = np.array(["boundary"] * n, dtype=object)
    order = rng.permutation(n)
    counts = [("empty", cfg.empty_frames), ("shadow", round(cfg.shadow_share * n)),
              ("chunk", round(cfg.chunk_share * n)), ("blob", round(cfg.blob_share * n))]
    start = 0
    for kind, count in counts:
        kinds[order[start:start + count]] = kind
        start += count
    out, notes = [], []
    for mask, shadow, kind in zip(masks, shadows, kinds, strict=True):
        if kind == "empty" or not mask.any():
            out.append(np.zeros_like(mask))
            notes.append("empty")
            continue
        offset = int(rng.integers(cfg.boundary_px[0], cfg.boundary_px[1] + 1)) * (
            1 if rng.random() < 0.5 else -1)
        noisy = _wobbly_boundary(mask, offset, cfg.wobble_px, rng)
        note = f"boundary {offset:+d} px"
        if kind == "shadow":
            noisy |= shadow & ndimage.binary_dilation(mask, iterations=25)
            note += ", shadow leaked in"
        elif kind == "chunk":
            noisy &= ~_chunk(mask, cfg.chunk_fraction, rng)
            note += ", a chunk missed"
        elif kind == "blob":
            noisy |= _blob(mask, cfg.blob_fraction, rng)
            note += ", a false blob"
        out.append(noisy)
        notes.append(note)
    return out, notes
