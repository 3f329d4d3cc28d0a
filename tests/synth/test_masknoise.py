"""Masks as a segmenter would give them: each kind of mistake, as often as configured."""

import numpy as np

from volec.synth.masknoise import MaskNoiseConfig, noisy_masks


def _disc(n: int = 80, r: float = 20.0) -> np.ndarray:
    yy, xx = np.mgrid[:n, :n]
    return (yy - n / 2) ** 2 + (xx - n / 2) ** 2 <= r**2


def test_every_kind_of_mistake_as_often_as_configured():
    masks = [_disc()] * 50
    shadow = np.zeros_like(masks[0])
    shadow[55:75, 20:60] = True  # a shadow on the plate below the food
    cfg = MaskNoiseConfig(seed=4)
    noisy, notes = noisy_masks(masks, [shadow] * 50, cfg)
    assert sum(n == "empty" for n in notes) == 2
    assert sum("shadow" in n for n in notes) == round(0.15 * 50)
    assert sum("chunk" in n for n in notes) == round(0.06 * 50)
    assert sum("blob" in n for n in notes) == round(0.06 * 50)
    area = masks[0].sum()
    for mask, note in zip(noisy, notes, strict=True):
        if note == "empty":
            assert not mask.any()
            continue
        iou = (mask & masks[0]).sum() / (mask | masks[0]).sum()
        if note.startswith("boundary") and "," not in note:
            # 1-3 px of a 20 px radius disc, with its wobble
            assert 0.6 < iou < 0.995 and abs(mask.sum() - area) < 0.45 * area
        if "shadow" in note:
            assert (mask & shadow).sum() > 0.5 * (shadow & ~masks[0]).sum()
        if "chunk" in note:
            assert (masks[0] & ~mask).sum() > 0.1 * area
    again, _ = noisy_masks(masks, [shadow] * 50, cfg)  # seeded
    assert all(np.array_equal(a, b) for a, b in zip(noisy, again, strict=True))
