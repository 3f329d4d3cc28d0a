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
# # 07 · Partial captures: the paper's Table II, Table III and Fig. 1
#
# Phone captures are incomplete, and that is where completion has to earn its place. Each
# scenario takes its frames from the same 100-frame full-orbit rendering of each item, so the
# scenarios compare directly and nothing is rendered twice:
#
# - `full_orbit`: all 100 frames, 360 degrees;
# - `half_orbit`: the frames whose camera lies within the first 180 degrees the phone went
#   round (about 50; one side is never seen);
# - `sparse`: 30 evenly spaced frames.
#
# Two more are rendered on their own, on ten of the items:
#
# - `low`: 60 frames from 10-25 degrees of elevation (the top seen obliquely, more of the item
#   hidden by itself);
# - `smooth`: the full orbit with skins as faint as a peach's or a plum's, where dense stereo
#   finds little to match; a surface that was seen but not reconstructed is unknown space too.
#
# Each runs the whole pipeline on its own frames only (SfM, dense, masking: cached per
# scenario in `ITEM-full_orbit/work-SCENARIO/`, or in `ITEM-SCENARIO/work/` for the rendered
# ones), then every method on the same stage results:
#
# - **visual hull (AR poses)**: the food masks' visual hull from the phone's own poses, cut at
#   the support plane; no SfM, no depth;
# - **VolE-style**: the masked dense cloud closed by Poisson, the support plane and the masks'
#   hull, no completion;
# - **mirror completion**: the masked cloud plus its reflection in its best mirror plane, and
#   the views reflected in its best vertical mirror plane carving where no camera showed food;
# - **rotation completion**: the masked cloud plus its half-turn about its best vertical axis,
#   kept only where no camera constrained the space (the far side of a half orbit);
# - **network completion**: the masked cloud plus the SymmCompletion network's points where
#   nothing was observed;
# - **volec's default**: the half-turn where the masked cloud is symmetric under it, then the
#   network for what is still missing (the network alone where it is not); where the cloud is
#   symmetric about a vertical plane, the views reflected in it carve the space no camera
#   showed to be food; where it is symmetric about a horizontal plane, its top reflected below
#   that plane fills the wedge above the plate that no camera reached (`volec.underside`).
#   Every method but the visual hull meshes the rim points the masks' outlines place
#   (`volec.rims`) with the masked cloud.
#
# Volumes are scored against the true volume (APE: absolute percentage error) and each mesh by
# its Chamfer-L1 distance to the true surface. The ground truth is read only to score.

# %% tags=["parameters"]
# Parameters (papermill overrides these)
quick = False  # CI-sized run: one item, the 20-frame quick capture
scenario_names = ["full_orbit", "half_orbit", "sparse"]
rendered_names = ["low", "smooth"]  # rendered scenarios, on rendered_items only
rendered_items = ["apple", "orange", "lemon", "pear", "banana", "chocolate_croissant",
                  "empanadilla", "donut", "capsicum", "french_bread"]
figure_items = ["apple", "pear", "banana"]
figure_scenario = "half_orbit"
workers = 2  # captures processed at once

# %%
import pandas as pd

from volec.experiments import (
    bounds_summary,
    completion_clouds,
    dense_experiment,
    dense_table,
    method_table,
    method_tests,
    pose_scale_errors,
    scenarios,
    volume_experiment,
)
from volec.paths import experiment_dir, figures_dir
from volec.synth import item_names
from volec.tables import write_table
from volec.viz import cloud_grid, save_figure

root = experiment_dir(quick)
chosen = ["quick"] if quick else scenario_names + rendered_names
items = ["apple"] if quick else item_names()
raws = {name: volume_experiment(root, rendered_items if name in rendered_names else items,
                                scenarios(quick)[name], workers=workers)
        for name in chosen}

# %% [markdown]
# ## Table II: the methods side by side, per scenario
#
# Per item the volume (mL), its APE (%) and the mesh's Chamfer-L1 distance to the true surface
# (mm); the last two rows are the mean and the standard deviation over the items (an item
# whose SfM failed is left out; `volume_raw_SCENARIO` records why).

# %%
tables = {}
for name, raw in raws.items():
    write_table(raw, figures_dir() / f"volume_raw_{name}", float_digits=3)
    tables[name] = method_table(raw)
    write_table(tables[name], figures_dir() / f"table2_{name}", float_digits=2)
pd.concat({name: table.tail(2).set_index("item") for name, table in tables.items()})

# %% [markdown]
# ## Table III: does the default beat each other method?
#
# Paired t-tests over the items of each scenario, the default (`auto` completion) against
# each other method, on the volume's APE and on the Chamfer distance. `mean_without` is the
# other method's mean, `mean_with` the default's; a positive `mean_difference` favours the
# default.

# %%
table3 = method_tests(raws)
write_table(table3, figures_dir() / "table3_methods", float_digits=4)
table3

# %% [markdown]
# ## How far the default's volumes can be trusted
#
# Per scenario, for volec's default: how many items were trusted, and how many of those were
# more than 2 % off; the mean share of the estimate in space no camera constrained; on how
# many items the bounds from the space alone (`volume_bounds_ml`) and the interval that adds
# the metric scale's uncertainty (`volume_interval_ml`, two standard deviations) hold the
# true volume, and their mean widths (% of the truth). The scale's standard deviation comes
# from the AR drift model SfM fits (`volec.scale_uncertainty`); its true error, from the
# exact poses (scoring only), over that deviation should have a root mean square near 1 and
# lie within two deviations on about 95 % of the items.

# %%
trust = pd.concat([bounds_summary(raw, scale_err_pct=pose_scale_errors(
    root, rendered_items if name in rendered_names else items, scenarios(quick)[name]))
    for name, raw in raws.items()], ignore_index=True)
write_table(trust, figures_dir() / "bounds_trust", float_digits=3)
trust

# %% [markdown]
# ## Faint skins: how much of the seen surface dense stereo covers
#
# Per item, the share of the true surface that at least two cameras see which has a masked
# dense point within 2 mm (`completeness_visible_pct`), on the full orbit and on the same
# orbit with faint skins (`smooth`), and the masked cloud's median signed distance (mm).

# %%
coverage_names = ["quick"] if quick else ["full_orbit", "smooth"]
coverage_items = items if quick else rendered_items
coverage = pd.concat([dense_experiment(root, coverage_items, scenarios(quick)[name])
                      for name in coverage_names])
coverage = dense_table(coverage)
write_table(coverage, figures_dir() / "dense_coverage_smooth", float_digits=2)
coverage

# %% [markdown]
# ## Fig. 1: incomplete and completed clouds
#
# The observed (masked) cloud, the cloud completed by the network and the true surface, seen
# from below the plate's level, where nothing was observed.

# %%
shown_scenario = chosen[0] if quick else figure_scenario
shown_items = items if quick else figure_items
clouds = completion_clouds(root, shown_items, scenarios(quick)[shown_scenario])
fig = cloud_grid(clouds, elevation_deg=-20.0)
save_figure(fig, figures_dir() / f"fig1_completion_{shown_scenario}.png")
