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
# # 03 · Dense reconstruction and masking
#
# pycolmap's wheel has no CPU multi-view stereo, so volec estimates a depth map per frame itself:
# a plane sweep in torch (at most 512 px on the long side, as the paper's OpenMVS run) that
# compares each frame with four neighbours by normalised cross-correlation, refines the depth
# below the plane spacing, keeps the depths that neighbouring depth maps confirm, and fuses them
# into one coloured cloud. Masking then keeps the points that project inside the food mask in
# every frame that sees them.
#
# Scores against the true food surface: **accuracy** is the distance from the masked points to
# the surface; **completeness** is the fraction of the surface within 2 mm of the cloud, over the
# part the cameras saw (`visible`) and the rest (`unseen`, mostly the bottom, which completion
# has to supply). Runs with the SfM poses (`refined`, the pipeline) and with the exact poses
# (`exact`) separate the stereo's error from the poses'.

# %% tags=["parameters"]
# Parameters (papermill overrides these)
quick = False  # CI-sized run: one item, a 20-frame capture
items = ["apple", "banana", "chocolate_cake"]
shown_item = "banana"

# %%
import numpy as np
import pandas as pd

from volec.capture import read_transforms_json
from volec.dense import load_dense
from volec.experiments import dense_experiment, dense_table, ensure_capture, scenarios
from volec.masking import load_masking
from volec.metrics import distances_to_surface
from volec.paths import experiment_dir, figures_dir
from volec.synth import load_ground_truth_mesh, load_truth
from volec.tables import write_table
from volec.viz import distance_histogram, framed_view, geometry_panels, save_figure

# %% [markdown]
# ## Accuracy, completeness and time
#
# Distances in mm, completeness in percent of the surface, times in seconds (dense: loading,
# depth maps and fusion; mask: the masking stage).

# %%
scenario = scenarios(quick)["quick" if quick else "full_orbit"]
chosen = items[:1] if quick else items
root = experiment_dir(quick)
raw = pd.concat([dense_experiment(root, chosen, scenario, poses)
                 for poses in ("refined", "exact")], ignore_index=True)
table = dense_table(raw)
write_table(table, figures_dir() / "dense_errors", float_digits=2)
table

# %% [markdown]
# ## One item: scene cloud, masked food cloud, true surface
#
# Seen from the first frame's camera's side, framed on the food.

# %%
item = chosen[0] if quick else shown_item
out = ensure_capture(root, item, scenario)
scene = load_dense(out / "work").cloud
food = load_masking(out / "work").cloud
mesh = load_ground_truth_mesh(out)
exact = read_transforms_json(out / "ground_truth" / "transforms_exact.json",
                             check_image_sizes=False)
up = load_truth(out)["world_up"]
eye, target = framed_view(np.vstack([food.xyz, mesh.vertices]),
                          exact.frames[0].camera_centre - mesh.bounds.mean(axis=0), up, (480, 360))
fig = geometry_panels(
    {"scene cloud": scene, "masked food cloud": food, "true surface": mesh},
    eye=eye, target=target, up=up,
)
save_figure(fig, figures_dir() / "dense_masked_cloud.png")

# %%
fig = distance_histogram({
    "refined poses": distances_to_surface(food.xyz, mesh) * 1000,
    "exact poses": distances_to_surface(load_masking(out / "work-exact").cloud.xyz,
                                        mesh) * 1000,
})
save_figure(fig, figures_dir() / "dense_distance_histogram.png")
