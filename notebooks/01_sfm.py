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
# # 01 · Metric camera poses: SfM aligned to the AR poses
#
# The phone's AR poses are metric but drift; COLMAP's are consistent but unscaled. volec runs
# pycolmap SfM (SIFT, pairs chosen from the AR poses, points triangulated from the AR poses,
# then bundle adjustment) and maps the model into the AR world: the rotation from the AR
# orientations, the scale from short-baseline AR displacements (drift cancels there) or from a
# Sim(3) fit to all camera centres. The table compares both against the exact poses of
# synthetic captures: full orbits, half orbits, and 1 cm of AR drift. Captures not cached yet
# run two at a time (`workers`), so their `wall_s` is that of two runs sharing the 2 cores
# (`benchmarks/bench_sfm.py` times one alone).

# %% tags=["parameters"]
# Parameters (papermill overrides these)
quick = False  # CI-sized run: one item, a 20-frame capture
items = ["apple", "banana", "chocolate_cake"]
trajectory_item = "banana"
conditions_shown = ["full_orbit", "half_orbit", "drift_1cm"]  # quick: its one capture
workers = 2  # captures processed at once (2 cores: measured 1.3x faster than one by one)

# %%
from volec.capture import read_transforms_json
from volec.experiments import ensure_capture, scenarios, sfm_error_table, sfm_experiment
from volec.paths import experiment_dir, figures_dir
from volec.sfm import load_sfm
from volec.synth import load_ground_truth_mesh, load_truth
from volec.tables import write_table
from volec.viz import save_figure, trajectory_figure

# %% [markdown]
# ## Errors against the exact poses
#
# Centre errors in mm, rotation errors in degrees, scale errors in percent; `ar_*` columns are
# the AR poses' own errors.

# %%
conditions = [scenarios(quick)[n] for n in (["quick"] if quick else conditions_shown)]
chosen = items[:1] if quick else items
raw = sfm_experiment(experiment_dir(quick), chosen, conditions, workers=workers)
table = sfm_error_table(raw)
write_table(table, figures_dir() / "sfm_errors", float_digits=3)
table

# %% [markdown]
# ## AR, refined and exact camera centres

# %%
shown_item = chosen[0] if quick else trajectory_item
out = ensure_capture(experiment_dir(quick), shown_item, conditions[-1])
reported = read_transforms_json(out / "capture")
exact = read_transforms_json(out / "ground_truth" / "transforms_exact.json")
refined = load_sfm(out / "work")
tracks = {"AR reported": reported.camera_centres,
          "SfM refined": refined.T_world_from_cam[:, :3, 3],
          "exact": exact.camera_centres}
centre = load_ground_truth_mesh(out).bounds.mean(axis=0)
fig = trajectory_figure(tracks, up=load_truth(out)["world_up"], target=centre)
save_figure(fig, figures_dir() / "sfm_trajectory.png")
