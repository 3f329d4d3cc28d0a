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
# # 06 · The paper's tables
#
# Table I (volumes and errors per item, without and with completion), Table III (paired t-tests),
# the runtime per stage and qualitative pictures (as the paper's Fig. 3), from the per-item
# results of notebooks 02 and 05 (cached, so this notebook only reads them). Every number here
# comes from that run.

# %% tags=["parameters"]
# Parameters (papermill overrides these)
quick = False  # CI-sized run: the one item of notebook 05's quick mode
shown = ["apple", "banana", "chocolate_croissant", "capsicum"]
offset_items = ["pear", "banana", "chocolate_croissant"]

# %%
from volec.experiments import (
    paired_tests,
    pose_scale_errors,
    qualitative_panels,
    runtime_table,
    scenarios,
    segmentation_experiment,
    signed_surfaces,
    surface_bands,
    surface_offset_table,
    volume_experiment,
    volume_table,
)
from volec.paths import experiment_dir, figures_dir
from volec.synth import item_names, load_truth
from volec.tables import write_table
from volec.viz import panels_around, save_figure, signed_distance_figure

scenario = scenarios(quick)["quick" if quick else "full_orbit"]
items = ["apple"] if quick else item_names()
root = experiment_dir(quick)
raw = volume_experiment(root, items, scenario, progress=False)

# %% [markdown]
# ## Table I: volume per item
#
# APE: absolute percentage error; accuracy = 100 - APE. With exact masks, without and with
# completion; then the default (with completion) with volec's automatic masks, and the
# `tolerant_masks` preset with noisy masks (notebook 02). The last row is the mean (MAPE).

# %%
masks = segmentation_experiment(root, items, scenario, progress=False)
table1 = volume_table(raw, masks)
write_table(table1, figures_dir() / "table1_volume", float_digits=2)
table1

# %% [markdown]
# ## Table III: does completion help?
#
# Paired t-tests over the items, without against with completion (a positive mean difference:
# completion lowers it).

# %%
table3 = paired_tests(raw)
write_table(table3, figures_dir() / "table3_ttests", float_digits=4)
table3

# %% [markdown]
# ## Where the surface lies
#
# Signed distances to the true surface, in mm (+ outside, - inside): median, 10th and 90th
# percentile of the masked cloud's points and of the final mesh (area-uniform samples), and the
# volume the mesh's offset implies (mean signed distance times area, in percent of the true
# volume) beside the volume error; then how far the poses misplaced the mesh and its signed
# distances once rigidly aligned to the truth (the shape's own offset; the misplacement moves the
# whole mesh and does not change its volume). A systematic offset of a fraction of a millimetre
# is a few percent of volume. Last, the error of the metric scale SfM took from the AR poses
# (against the exact poses; the AR drift leaves it) and the volume error the estimate would
# have at the exact scale: what the shape alone gets wrong. The figure shows the aligned meshes.

# %%
offsets = surface_offset_table(raw, scale_err_pct=pose_scale_errors(root, items, scenario))
write_table(offsets, figures_dir() / "surface_offset", float_digits=3)
offsets

# %%
shown_offsets = items if quick else offset_items
surfaces = signed_surfaces(root, shown_offsets, scenario)
up = load_truth(root / f"{shown_offsets[0]}-{scenario.name}")["world_up"]
fig = signed_distance_figure(surfaces, up)
save_figure(fig, figures_dir() / "surface_signed_distance.png")

# %% [markdown]
# ## Where on the item the offset lies, by height
#
# Each item's height above its lowest point cut into bands (fractions of its true height): the
# share of the true surface in each band, how much of it the masked cloud covers (within 1.5 mm),
# and the final mesh's median signed distance (mm) and the volume its offset there implies (% of
# the true volume; the bands add up to the mesh's whole offset). On an orbit the lower bands are
# seen only obliquely, stereo drops what it sees at grazing angles, and there the mesh is what
# the visual hull and the shape prior make of the gap. The last rows are the means over the items.

# %%
bands = surface_bands(root, items, scenario)
write_table(bands, figures_dir() / "surface_bands", float_digits=3)
bands[bands["item"] == "mean"]

# %% [markdown]
# ## Runtime per stage
#
# Wall time in seconds per 100-frame capture on this machine (SfM and dense as measured when they
# ran). Items that ran two at a time (column `workers` of `volume_raw`) shared the 2 cores, so
# these times are longer than those of a capture processed alone, which
# `benchmarks/bench_estimate.py` measures.

# %%
runtime = runtime_table(raw)
write_table(runtime, figures_dir() / "runtime_stages", float_digits=1)
runtime

# %% [markdown]
# ## Qualitative results (Fig. 3)
#
# Masked cloud, completed cloud, mesh and the true surface, seen from slightly below the plate's
# level.

# %%
for item in (items if quick else shown):
    panels = qualitative_panels(root, item, scenario)
    up = load_truth(root / f"{item}-{scenario.name}")["world_up"]
    fig = panels_around(panels, up, elevation_deg=-8.0)
    save_figure(fig, figures_dir() / f"qualitative_{item}.png")
