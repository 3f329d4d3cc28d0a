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
# # 05 · Meshing and volume: the whole pipeline on the benchmark
#
# Each item's capture goes through SfM, dense stereo and masking (reused from notebooks 01-03
# where they ran), then twice through meshing: once with the masked cloud as it is (the
# VolE-style baseline: the support plane, Poisson and the masks close the unseen underside) and
# once completed by the network. Meshing is screened Poisson, a ray-cast signed distance cut at
# the support plane (the plate top, found by RANSAC in the scene cloud) and intersected with the
# visual hull of the food masks, then marching cubes, so every mesh is watertight before its
# volume is taken.
#
# Each estimate is what `volec estimate` computes (the same core,
# `volec.estimate.estimate_from_stages`), with its trust flag and the reasons' codes; the ground
# truth is read only to score it. Results are cached per item (`work/volume_eval.json`), keyed by
# the config, the checkpoint and the code: a re-run only redoes what changed. Items not cached
# yet run two at a time (`workers`); the first full run of this notebook took 37 minutes on 2
# cores.

# %% tags=["parameters"]
# Parameters (papermill overrides these)
quick = False  # CI-sized run: one item, a 20-frame capture
shown_item = "apple"
attribution_items = ["pear", "banana", "chocolate_croissant"]
workers = 2  # captures processed at once (2 cores: measured 1.3x faster than one by one)

# %%
from volec.experiments import (
    attribution_experiment,
    attribution_table,
    qualitative_panels,
    scenarios,
    volume_experiment,
)
from volec.paths import experiment_dir, figures_dir
from volec.synth import item_names, load_truth
from volec.tables import write_table
from volec.viz import panels_around, save_figure

# %%
scenario = scenarios(quick)["quick" if quick else "full_orbit"]
items = ["apple"] if quick else item_names()
root = experiment_dir(quick)
raw = volume_experiment(root, items, scenario, workers=workers)
write_table(raw, figures_dir() / "volume_raw", float_digits=3)
raw[["item", "gt_ml", "no_completion_ml", "completion_ml", "no_completion_chamfer_mm",
     "completion_chamfer_mm", "completion_trusted", "completion_reasons"]]

# %% [markdown]
# ## One item, stage by stage
#
# Seen from slightly below the plate's level: the completed cloud's magenta points (drawn
# larger) are the network's.

# %%
item = items[0] if quick else shown_item
panels = qualitative_panels(root, item, scenario)
up = load_truth(root / f"{item}-{scenario.name}")["world_up"]
fig = panels_around(panels, up, elevation_deg=-8.0)
save_figure(fig, figures_dir() / "volume_stages.png")

# %% [markdown]
# ## Where the surface offset comes from
#
# The same items again, with each source of error taken away in turn: the exact camera poses
# instead of SfM's, then stereo at the full image resolution, then the renderer's exact depth
# maps instead of stereo (through the same fusion, masking, completion and meshing). Signed
# distances to the true surface in mm (+ outside); what remains with exact depth is the share of
# fusion, masking and meshing. The last two columns are the same without completion: the
# network's points move the volume on their own, and can hide or add to the surface's offset.

# %%
chosen = items if quick else attribution_items
attribution = attribution_table(attribution_experiment(root, chosen, scenario,
                                                       workers=workers))
write_table(attribution, figures_dir() / "surface_attribution", float_digits=3)
attribution
