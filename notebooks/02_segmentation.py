# ---
# jupyter:
#   jupytext:
#     formats: ipynb,py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
#       format_version: '1.3'
#       jupytext_version: 1.19.6
#   kernelspec:
#     display_name: volec (.venv)
#     language: python
#     name: volec
# ---

# %% [markdown]
# # 02 · Food segmentation without masks
#
# No user has a perfect food mask per frame, and volec downloads no weights, so it finds the food
# itself (`volec.segment`): the support plane and the item standing on it from the SfM points
# (a plate so plain that SfM found no point on it is found by stereo round the item, and the
# plane lifted to its top); on 24 evenly spread views, OpenCV's GrabCut seeded by the item's
# points, by stereo heights above the plane (food) and by what lies on it (plate, table,
# shadows); the visual hull of those masks, one disagreeing view outvoted; every frame's hull
# silhouette refined by a colour graph cut in a 4-pixel band.
#
# Scores against the exact masks: IoU and the boundary F-score (boundary pixels within 2 px). The
# full orbits, and the hard setups (one per item: white food on a white plate, a plate the colour
# of the food, the food across the rim, strong shadows, a cup or a fork beside it, dim or bright
# light). Then the default estimate's volume with the automatic masks, and with the noisy masks a
# real segmenter might give (boundaries 1-3 px off, the shadow leaking in on 15 % of the frames,
# a chunk missed or a false blob on 6 %, two empty), estimated with the `tolerant_masks` preset
# that volec documents for imperfect masks: notebook 06 puts them beside the exact-mask volumes
# in Table I.

# %% tags=["parameters"]
# Parameters (papermill overrides these)
quick = False  # CI-sized run: one item, a 20-frame capture
hard_items = ["apple", "orange", "avocado", "lemon", "donut", "durum", "pear",
              "chocolate_cake"]  # one per hard setup
hard_quick_item = "lemon"  # quick: strong shadows
gallery_frames = 6
workers = 2  # captures processed at once (2 cores: measured 1.3x faster than one by one)

# %%
from volec.experiments import (
    scenarios,
    segmentation_experiment,
    segmentation_table,
    worst_frames,
)
from volec.paths import experiment_dir, figures_dir
from volec.synth import item_names
from volec.tables import write_table
from volec.viz import image_grid, save_figure

# %% [markdown]
# ## Full orbits: masks and volumes
#
# IoU and boundary F-score of the automatic masks (median, 10th percentile and worst frame), the
# noisy masks' IoU, the segmentation's time in seconds (two captures at a time, sharing the
# cores), and the volume error (percent) with automatic and with noisy masks.

# %%
scenario = scenarios(quick)["quick" if quick else "full_orbit"]
items = ["apple"] if quick else item_names()
root = experiment_dir(quick)
raw = segmentation_experiment(root, items, scenario, workers=workers)
write_table(raw.drop(columns=["worst_frames", "worst_iou"]),
            figures_dir() / "segmentation_raw", float_digits=4)
table = segmentation_table(raw)
write_table(table, figures_dir() / "segmentation", float_digits=3)
table

# %% [markdown]
# ## The worst frames
#
# Automatic mask outlined green, exact mask red.

# %%
images, titles = worst_frames(root, raw, scenario, gallery_frames)
fig = image_grid(images, titles, ncols=3, size_in=3.2)
save_figure(fig, figures_dir() / "segmentation_worst_frames.png")

# %% [markdown]
# ## Hard setups: masks
#
# One item per setup; masks only (the volumes are for the full orbits above).

# %%
hard_scenario = scenarios(quick)["quick_hard" if quick else "hard"]
hard = segmentation_experiment(root, [hard_quick_item] if quick else hard_items,
                               hard_scenario,
                               volumes=False, workers=workers)
images, titles = worst_frames(root, hard, hard_scenario, gallery_frames)
fig = image_grid(images, titles, ncols=3, size_in=3.2)
save_figure(fig, figures_dir() / "segmentation_hard_worst_frames.png")
hard_table = segmentation_table(hard)
write_table(hard_table, figures_dir() / "segmentation_hard", float_digits=3)
hard_table
