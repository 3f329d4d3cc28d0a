"""The built-in benchmark: synthetic FoodKit captures with exact ground truth.

:mod:`~volec.synth.shapes` (21 items of known volume), :mod:`~volec.synth.scene` (plate, table,
textures), :mod:`~volec.synth.trajectory` (handheld orbit, AR drift),
:mod:`~volec.synth.render` (CPU ray casting) and :mod:`~volec.synth.generate` (the folders).
"""

from volec.synth.generate import (
    PRESETS,
    SynthConfig,
    load_ground_truth_mesh,
    load_truth,
    render_preview,
    write_benchmark,
    write_synthetic_capture,
)
from volec.synth.shapes import ITEMS, item_mesh, item_names

__all__ = [
    "ITEMS",
    "PRESETS",
    "SynthConfig",
    "item_mesh",
    "item_names",
    "load_ground_truth_mesh",
    "load_truth",
    "render_preview",
    "write_benchmark",
    "write_synthetic_capture",
]
