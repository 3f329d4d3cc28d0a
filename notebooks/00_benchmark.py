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
# # 00 · The built-in benchmark: synthetic FoodKit
#
# Real captures with water-displacement volumes are not shipped, so volec generates them. Each of
# the 21 FoodKit items of the paper's Table I is a procedural, watertight mesh scaled so that its
# exact volume is Table I's ground truth. A capture is what a phone would record walking around
# it: portrait frames, food masks, and AR camera poses that drift a few millimetres, while the
# exact poses and the mesh go to a ground-truth folder the pipeline never reads.

# %% tags=["parameters"]
# Parameters (papermill overrides these)
quick = False  # CI-sized run: smaller pictures, a 12-frame capture
seed = 0
preview_px = 320
sample_item = "apple"

# %%
from volec.paths import benchmark_dir, figures_dir
from volec.synth import PRESETS, load_ground_truth_mesh, load_truth, write_benchmark
from volec.synth.benchmark import (
    ar_error_summary,
    capture_tracks,
    contact_sheet,
    gallery_images,
    items_table,
)
from volec.tables import write_table
from volec.viz import image_grid, save_figure, trajectory_figure

# %% [markdown]
# ## The 21 items
#
# Table I's volume next to the volume measured on each generated mesh (the divergence theorem on
# the closed mesh), with its size.

# %%
table = items_table()
write_table(table, figures_dir() / "benchmark_items")
table

# %%
images, titles = gallery_images(size_px=preview_px // 2 if quick else preview_px)
fig = image_grid(images, titles, ncols=7)
save_figure(fig, figures_dir() / "benchmark_gallery.png")

# %% [markdown]
# ## One capture
#
# A handheld orbit: elevation between 20 and 60 degrees, hand shake, and the AR poses' smooth
# drift (it starts at zero and grows).

# %%
config = PRESETS["quick" if quick else "default"].with_(seed=seed)
outs = write_benchmark(benchmark_dir(quick), [sample_item], config)
images, titles = contact_sheet(outs[0], n_frames=4)
fig = image_grid(images, titles, ncols=4, size_in=2.6)
save_figure(fig, figures_dir() / "benchmark_capture_frames.png")

# %%
truth = load_truth(outs[0])
centre = load_ground_truth_mesh(outs[0]).bounds.mean(axis=0)
fig = trajectory_figure(capture_tracks(outs[0]), up=truth["world_up"], target=centre)
save_figure(fig, figures_dir() / "benchmark_trajectory.png")
ar_error_summary(outs)
