"""Writes the notebooks in notebooks/ from code, so their source is reviewable and consistent.

Run: .venv/bin/python scripts/make_notebooks.py   (then commit the .ipynb files, no outputs)
"""

import nbformat as nbf

md, code = nbf.v4.new_markdown_cell, nbf.v4.new_code_cell


def parameters(text: str) -> nbf.NotebookNode:
    cell = code("# Parameters (papermill overrides these)\n" + text)
    cell.metadata["tags"] = ["parameters"]
    return cell


def write(cells: list, path: str) -> None:
    nb = nbf.v4.new_notebook()
    # Stable cell ids, so regenerating an unchanged notebook changes nothing.
    for i, cell in enumerate(cells):
        cell.id = f"cell-{i:02d}"
    nb.cells = cells
    nb.metadata["kernelspec"] = {"name": "volec", "display_name": "volec (.venv)",
                                 "language": "python"}
    nbf.write(nb, path)


params = parameters(
    "quick = False  # CI-sized run: smaller pictures, a 12-frame capture\n"
    "seed = 0\n"
    "preview_px = 320\n"
    'sample_item = "apple"'
)
write([
    md(
        "# 00 · The built-in benchmark: synthetic FoodKit\n\n"
        "Real captures with water-displacement volumes are not shipped, so volec generates "
        "them. Each of the 21 FoodKit items of the paper's Table I is a procedural, watertight "
        "mesh scaled so that its exact volume is Table I's ground truth. A capture is what a "
        "phone would record walking around it: portrait frames, food masks, and AR camera "
        "poses that drift a few millimetres, while the exact poses and the mesh go to a "
        "ground-truth folder the pipeline never reads."
    ),
    params,
    code(
        "from volec.paths import benchmark_dir, figures_dir\n"
        "from volec.synth import PRESETS, load_ground_truth_mesh, load_truth, write_benchmark\n"
        "from volec.synth.benchmark import (\n"
        "    ar_error_summary,\n"
        "    capture_tracks,\n"
        "    contact_sheet,\n"
        "    gallery_images,\n"
        "    items_table,\n"
        ")\n"
        "from volec.tables import write_table\n"
        "from volec.viz import image_grid, save_figure, trajectory_figure"
    ),
    md("## The 21 items\n\nTable I's volume next to the volume measured on each generated mesh "
       "(the divergence theorem on the closed mesh), with its size."),
    code(
        "table = items_table()\n"
        'write_table(table, figures_dir() / "benchmark_items")\n'
        "table"
    ),
    code(
        "images, titles = gallery_images(size_px=preview_px // 2 if quick else preview_px)\n"
        "fig = image_grid(images, titles, ncols=7)\n"
        'save_figure(fig, figures_dir() / "benchmark_gallery.png")'
    ),
    md("## One capture\n\nA handheld orbit: elevation between 20 and 60 degrees, hand shake, "
       "and the AR poses' smooth drift (it starts at zero and grows)."),
    code(
        'config = PRESETS["quick" if quick else "default"].with_(seed=seed)\n'
        "outs = write_benchmark(benchmark_dir(quick), [sample_item], config)\n"
        "images, titles = contact_sheet(outs[0], n_frames=4)\n"
        "fig = image_grid(images, titles, ncols=4, size_in=2.6)\n"
        'save_figure(fig, figures_dir() / "benchmark_capture_frames.png")'
    ),
    code(
        'truth = load_truth(outs[0])\n'
        "centre = load_ground_truth_mesh(outs[0]).bounds.mean(axis=0)\n"
        'fig = trajectory_figure(capture_tracks(outs[0]), up=truth["world_up"], target=centre)\n'
        'save_figure(fig, figures_dir() / "benchmark_trajectory.png")\n'
        "ar_error_summary(outs)"
    ),
], "notebooks/00_benchmark.ipynb")

write([
    md(
        "# 01 · Metric camera poses: SfM aligned to the AR poses\n\n"
        "The phone's AR poses are metric but drift; COLMAP's are consistent but unscaled. "
        "volec runs pycolmap SfM (SIFT, pairs chosen from the AR poses, incremental mapping) and "
        "maps the model into the AR world: the rotation from the AR orientations, the scale "
        "from short-baseline AR displacements (drift cancels there) or from a Sim(3) fit to all "
        "camera centres. The table compares both against the exact poses of synthetic "
        "captures: full orbits, half orbits, and 1 cm of AR drift. Captures not cached yet run "
        "two at a time (`workers`), so their `wall_s` is that of two runs sharing the 2 cores "
        "(`benchmarks/bench_sfm.py` times one alone)."
    ),
    parameters(
        "quick = False  # CI-sized run: one item, a 20-frame capture\n"
        'items = ["apple", "banana", "chocolate_cake"]\n'
        'trajectory_item = "banana"\n'
        'conditions_shown = ["full_orbit", "half_orbit", "drift_1cm"]  # quick: its one capture\n'
        "workers = 2  # captures processed at once (2 cores: measured 1.3x faster than one by one)"
    ),
    code(
        "from volec.capture import read_transforms_json\n"
        "from volec.experiments import ensure_capture, scenarios, sfm_error_table, sfm_experiment\n"
        "from volec.paths import experiment_dir, figures_dir\n"
        "from volec.sfm import load_sfm\n"
        "from volec.synth import load_ground_truth_mesh, load_truth\n"
        "from volec.tables import write_table\n"
        "from volec.viz import save_figure, trajectory_figure"
    ),
    md("## Errors against the exact poses\n\nCentre errors in mm, rotation errors in degrees, "
       "scale errors in percent; `ar_*` columns are the AR poses' own errors."),
    code(
        'conditions = [scenarios(quick)[n] for n in (["quick"] if quick else conditions_shown)]\n'
        "chosen = items[:1] if quick else items\n"
        "raw = sfm_experiment(experiment_dir(quick), chosen, conditions, workers=workers)\n"
        "table = sfm_error_table(raw)\n"
        'write_table(table, figures_dir() / "sfm_errors", float_digits=3)\n'
        "table"
    ),
    md("## AR, refined and exact camera centres"),
    code(
        "shown_item = chosen[0] if quick else trajectory_item\n"
        "out = ensure_capture(experiment_dir(quick), shown_item, conditions[-1])\n"
        'reported = read_transforms_json(out / "capture")\n'
        'exact = read_transforms_json(out / "ground_truth" / "transforms_exact.json")\n'
        'refined = load_sfm(out / "work")\n'
        'tracks = {"AR reported": reported.camera_centres,\n'
        '          "SfM refined": refined.T_world_from_cam[:, :3, 3],\n'
        '          "exact": exact.camera_centres}\n'
        "centre = load_ground_truth_mesh(out).bounds.mean(axis=0)\n"
        'fig = trajectory_figure(tracks, up=load_truth(out)["world_up"], target=centre)\n'
        'save_figure(fig, figures_dir() / "sfm_trajectory.png")'
    ),
], "notebooks/01_sfm.ipynb")

write([
    md(
        "# 02 · Food segmentation without masks\n\n"
        "No user has a perfect food mask per frame, and volec downloads no weights, so it finds "
        "the food itself (`volec.segment`): the support plane and the item standing on it from "
        "the SfM points; on 24 evenly spread views, OpenCV's GrabCut seeded by the item's "
        "points, by stereo heights above the plane (food) and by what lies on it (plate, table, "
        "shadows); the visual hull of those masks, one disagreeing view outvoted; every "
        "frame's hull silhouette refined by a colour graph cut in a 4-pixel band.\n\n"
        "Scores against the exact masks: IoU and the boundary F-score (boundary pixels within "
        "2 px). The full orbits, and the hard setups (one per item: white food on a white "
        "plate, a plate the colour of the food, the food across the rim, strong shadows, a cup "
        "or a fork beside it, dim or bright light). Then the default estimate's volume with the "
        "automatic masks, and with the noisy masks a real segmenter might give (boundaries 1-3 "
        "px off, the shadow leaking in on 15 % of the frames, a chunk missed or a false blob on "
        "6 %, two empty): notebook 06 puts them beside the exact-mask volumes in Table I."
    ),
    parameters(
        "quick = False  # CI-sized run: one item, a 20-frame capture\n"
        'hard_items = ["apple", "orange", "avocado", "lemon", "donut", "durum", "pear",\n'
        '              "chocolate_cake"]  # one per hard setup\n'
        'hard_quick_item = "lemon"  # quick: strong shadows\n'
        "gallery_frames = 6\n"
        "workers = 2  # captures processed at once (2 cores: measured 1.3x faster than one by one)"
    ),
    code(
        "from volec.experiments import (\n"
        "    scenarios,\n"
        "    segmentation_experiment,\n"
        "    segmentation_table,\n"
        "    worst_frames,\n"
        ")\n"
        "from volec.paths import experiment_dir, figures_dir\n"
        "from volec.synth import item_names\n"
        "from volec.tables import write_table\n"
        "from volec.viz import image_grid, save_figure"
    ),
    md("## Full orbits: masks and volumes\n\nIoU and boundary F-score of the automatic masks "
       "(median, 10th percentile and worst frame), the noisy masks' IoU, the segmentation's "
       "time in seconds (two captures at a time, sharing the cores), and the volume error "
       "(percent) with automatic and with noisy masks."),
    code(
        'scenario = scenarios(quick)["quick" if quick else "full_orbit"]\n'
        'items = ["apple"] if quick else item_names()\n'
        "root = experiment_dir(quick)\n"
        "raw = segmentation_experiment(root, items, scenario, workers=workers)\n"
        'write_table(raw.drop(columns=["worst_frames", "worst_iou"]),\n'
        '            figures_dir() / "segmentation_raw", float_digits=4)\n'
        "table = segmentation_table(raw)\n"
        'write_table(table, figures_dir() / "segmentation", float_digits=3)\n'
        "table"
    ),
    md("## The worst frames\n\nAutomatic mask outlined green, exact mask red."),
    code(
        "images, titles = worst_frames(root, raw, scenario, gallery_frames)\n"
        "fig = image_grid(images, titles, ncols=3, size_in=3.2)\n"
        'save_figure(fig, figures_dir() / "segmentation_worst_frames.png")'
    ),
    md("## Hard setups: masks\n\nOne item per setup; masks only (the volumes are for the "
       "full orbits above)."),
    code(
        'hard_scenario = scenarios(quick)["quick_hard" if quick else "hard"]\n'
        "hard = segmentation_experiment(root, [hard_quick_item] if quick else hard_items,\n"
        "                               hard_scenario,\n"
        "                               volumes=False, workers=workers)\n"
        "images, titles = worst_frames(root, hard, hard_scenario, gallery_frames)\n"
        "fig = image_grid(images, titles, ncols=3, size_in=3.2)\n"
        'save_figure(fig, figures_dir() / "segmentation_hard_worst_frames.png")\n'
        "hard_table = segmentation_table(hard)\n"
        'write_table(hard_table, figures_dir() / "segmentation_hard", float_digits=3)\n'
        "hard_table"
    ),
], "notebooks/02_segmentation.ipynb")

write([
    md(
        "# 03 · Dense reconstruction and masking\n\n"
        "pycolmap's wheel has no CPU multi-view stereo, so volec estimates a depth map per "
        "frame itself: a plane sweep in torch (at most 512 px on the long side, as the "
        "paper's OpenMVS run) that compares each frame with four neighbours by normalised "
        "cross-correlation, refines the depth below the plane spacing, keeps the depths that "
        "neighbouring depth maps confirm, and fuses them into one coloured cloud. Masking "
        "then keeps the points that project inside the food mask in every frame that sees "
        "them.\n\n"
        "Scores against the true food surface: **accuracy** is the distance from the masked "
        "points to the surface; **completeness** is the fraction of the surface within 2 mm "
        "of the cloud, over the part the cameras saw (`visible`) and the rest (`unseen`, "
        "mostly the bottom, which completion has to supply). Runs with the SfM poses "
        "(`refined`, the pipeline) and with the exact poses (`exact`) separate the stereo's "
        "error from the poses'."
    ),
    parameters(
        "quick = False  # CI-sized run: one item, a 20-frame capture\n"
        'items = ["apple", "banana", "chocolate_cake"]\n'
        'shown_item = "banana"'
    ),
    code(
        "import pandas as pd\n\n"
        "from volec.capture import read_transforms_json\n"
        "from volec.dense import load_dense\n"
        "from volec.experiments import dense_experiment, dense_table, ensure_capture, scenarios\n"
        "from volec.masking import load_masking\n"
        "from volec.metrics import distances_to_surface\n"
        "from volec.paths import experiment_dir, figures_dir\n"
        "from volec.synth import load_ground_truth_mesh, load_truth\n"
        "from volec.tables import write_table\n"
        "from volec.viz import distance_histogram, geometry_panels, save_figure"
    ),
    md("## Accuracy, completeness and time\n\nDistances in mm, completeness in percent of "
       "the surface, times in seconds (dense: loading, depth maps and fusion; mask: the "
       "masking stage)."),
    code(
        'scenario = scenarios(quick)["quick" if quick else "full_orbit"]\n'
        "chosen = items[:1] if quick else items\n"
        "root = experiment_dir(quick)\n"
        "raw = pd.concat([dense_experiment(root, chosen, scenario, poses)\n"
        '                 for poses in ("refined", "exact")], ignore_index=True)\n'
        "table = dense_table(raw)\n"
        'write_table(table, figures_dir() / "dense_errors", float_digits=2)\n'
        "table"
    ),
    md("## One item: scene cloud, masked food cloud, true surface\n\nSeen from the first "
       "frame's camera."),
    code(
        "item = chosen[0] if quick else shown_item\n"
        "out = ensure_capture(root, item, scenario)\n"
        'scene = load_dense(out / "work").cloud\n'
        'food = load_masking(out / "work").cloud\n'
        "mesh = load_ground_truth_mesh(out)\n"
        'exact = read_transforms_json(out / "ground_truth" / "transforms_exact.json",\n'
        "                             check_image_sizes=False)\n"
        "fig = geometry_panels(\n"
        '    {"scene cloud": scene, "masked food cloud": food, "true surface": mesh},\n'
        "    eye=exact.frames[0].camera_centre, target=mesh.bounds.mean(axis=0),\n"
        '    up=load_truth(out)["world_up"],\n'
        ")\n"
        'save_figure(fig, figures_dir() / "dense_masked_cloud.png")'
    ),
    code(
        "fig = distance_histogram({\n"
        '    "refined poses": distances_to_surface(food.xyz, mesh) * 1000,\n'
        '    "exact poses": distances_to_surface(load_masking(out / "work-exact").cloud.xyz,\n'
        "                                        mesh) * 1000,\n"
        "})\n"
        'save_figure(fig, figures_dir() / "dense_distance_histogram.png")'
    ),
], "notebooks/03_dense_masking.ipynb")

write([
    md(
        "# 04 · Symmetry-guided completion: training, scores, pictures\n\n"
        "A phone orbit never sees the bottom of the food, and sometimes misses a side. volec "
        "completes the masked cloud with SymmCompletion (LSTNet predicts per-key-point "
        "symmetry transforms that map seen geometry into the missing region; SGFormer refines "
        "and upsamples the result, guided by the partial and the symmetric points), "
        "reimplemented in plain torch and trained on this machine's CPU on partial views of "
        "procedural foods that are not benchmark items. `make retrain` retrains; this "
        "notebook uses the checkpoint shipped with volec (`volec/completion/weights/`).\n\n"
        "Scores are Chamfer distances to the complete surface, in millimetres, on views the "
        "network never trained on: held-out shapes of the training families, and the 21 "
        "benchmark items (kinds it never saw). The mirror baseline adds the reflection of the "
        "partial cloud in its best mirror plane (nothing below the table)."
    ),
    parameters(
        "quick = False  # CI-sized run: a few test views\n"
        'shown = ["mango-2000", "carrot-2000", "apple", "banana"]\n'
        'shown_quick = ["egg-2000", "apple"]  # quick: egg, tomato, potato, apple, avocado'
    ),
    code(
        "import pandas as pd\n\n"
        "from volec.completion.complete import SHIPPED_CHECKPOINT\n"
        "from volec.completion.train import load_checkpoint\n"
        "from volec.experiments import completion_examples, completion_experiment, "
        "completion_table\n"
        "from volec.paths import data_dir, figures_dir\n"
        "from volec.tables import write_table\n"
        "from volec.viz import cloud_grid, loss_curves, save_figure"
    ),
    md("## Training\n\nThe shipped checkpoint's recipe, and its loss curves (from the log "
       "written next to it)."),
    code(
        "_, meta = load_checkpoint(SHIPPED_CHECKPOINT)\n"
        'print(meta["model_config"])\n'
        'print(meta["train_config"])\n'
        'print(meta["info"])\n'
        'log = pd.read_csv(SHIPPED_CHECKPOINT.with_suffix(".csv"))\n'
        'save_figure(loss_curves(log), figures_dir() / "completion_loss_curves.png")'
    ),
    md("## Chamfer distances\n\nMeans over the test views; `network` is the predicted points "
       "alone, `completed` the partial plus the predicted points (what the pipeline meshes)."),
    code(
        'raw = completion_experiment(SHIPPED_CHECKPOINT, data_dir() / "completion-eval", quick)\n'
        "table = completion_table(raw)\n"
        'write_table(table, figures_dir() / "completion_chamfer", float_digits=3)\n'
        'write_table(raw, figures_dir() / "completion_chamfer_views", float_digits=3)\n'
        "table.T"
    ),
    md("## Before and after (the paper's Fig. 1)\n\nSeen from below the table's level, "
       "where the phone never looked."),
    code(
        "names = shown_quick if quick else shown\n"
        "examples = completion_examples(SHIPPED_CHECKPOINT, names, quick)\n"
        "fig = cloud_grid(examples)\n"
        'save_figure(fig, figures_dir() / "completion_before_after.png")'
    ),
], "notebooks/04_completion_training.ipynb")

write([
    md(
        "# 05 · Meshing and volume: the whole pipeline on the benchmark\n\n"
        "Each item's capture goes through SfM, dense stereo and masking (reused from notebooks "
        "01-03 where they ran), then twice through meshing: once with the masked cloud as it "
        "is (the VolE-style baseline: the support plane, Poisson and the masks close the "
        "unseen underside) and once completed by the network. Meshing is screened Poisson, a "
        "ray-cast signed distance cut at the support plane (the plate top, found by RANSAC in "
        "the scene cloud) and intersected with the visual hull of the food masks, then marching "
        "cubes, so every mesh is watertight before its volume is taken.\n\n"
        "Each estimate is what `volec estimate` computes (the same core, "
        "`volec.estimate.estimate_from_stages`), with its trust flag and the reasons' codes; "
        "the ground truth is read only to score it. "
        "Results are cached per item (`work/volume_eval.json`), keyed by the config, the "
        "checkpoint and the code: a re-run only redoes what changed. Items not cached yet "
        "run two at a time (`workers`); the first full run of this notebook took 37 minutes "
        "on 2 cores."
    ),
    parameters(
        "quick = False  # CI-sized run: one item, a 20-frame capture\n"
        'shown_item = "apple"\n'
        'attribution_items = ["pear", "banana", "chocolate_croissant"]\n'
        "workers = 2  # captures processed at once (2 cores: measured 1.3x faster than one by one)"
    ),
    code(
        "from volec.experiments import (\n"
        "    attribution_experiment,\n"
        "    attribution_table,\n"
        "    qualitative_panels,\n"
        "    scenarios,\n"
        "    volume_experiment,\n"
        ")\n"
        "from volec.paths import experiment_dir, figures_dir\n"
        "from volec.synth import item_names, load_truth\n"
        "from volec.tables import write_table\n"
        "from volec.viz import panels_around, save_figure"
    ),
    code(
        'scenario = scenarios(quick)["quick" if quick else "full_orbit"]\n'
        'items = ["apple"] if quick else item_names()\n'
        "root = experiment_dir(quick)\n"
        "raw = volume_experiment(root, items, scenario, workers=workers)\n"
        'write_table(raw, figures_dir() / "volume_raw", float_digits=3)\n'
        'raw[["item", "gt_ml", "no_completion_ml", "completion_ml", "no_completion_chamfer_mm",\n'
        '     "completion_chamfer_mm", "completion_trusted", "completion_reasons"]]'
    ),
    md("## One item, stage by stage\n\nSeen from slightly below the plate's level: the "
       "completed cloud's grey points are the network's."),
    code(
        "item = items[0] if quick else shown_item\n"
        "panels = qualitative_panels(root, item, scenario)\n"
        'up = load_truth(root / f"{item}-{scenario.name}")["world_up"]\n'
        "fig = panels_around(panels, up, elevation_deg=-8.0)\n"
        'save_figure(fig, figures_dir() / "volume_stages.png")'
    ),
    md("## Where the surface offset comes from\n\nThe same items again, with each source "
       "of error taken away in turn: the exact camera poses instead of SfM's, then stereo at "
       "the full image resolution, then the renderer's exact depth maps instead of stereo "
       "(through the same fusion, masking, completion and meshing). Signed distances to the "
       "true surface in mm (+ outside); what remains with exact depth is the share of "
       "fusion, masking and meshing."),
    code(
        "chosen = items if quick else attribution_items\n"
        "attribution = attribution_table(attribution_experiment(root, chosen, scenario,\n"
        "                                                       workers=workers))\n"
        'write_table(attribution, figures_dir() / "surface_attribution", float_digits=3)\n'
        "attribution"
    ),
], "notebooks/05_meshing_volume.ipynb")

write([
    md(
        "# 06 · The paper's tables\n\n"
        "Table I (volumes and errors per item, without and with completion), Table III "
        "(paired t-tests), the runtime per stage and qualitative pictures (as the paper's "
        "Fig. 3), from the per-item results of notebooks 02 and 05 (cached, so this notebook only "
        "reads them). Every number here comes from that run."
    ),
    parameters(
        "quick = False  # CI-sized run: the one item of notebook 05's quick mode\n"
        'shown = ["apple", "banana", "chocolate_croissant", "capsicum"]\n'
        'offset_items = ["pear", "banana", "chocolate_croissant"]'
    ),
    code(
        "from volec.experiments import (\n"
        "    paired_tests,\n"
        "    qualitative_panels,\n"
        "    runtime_table,\n"
        "    scenarios,\n"
        "    segmentation_experiment,\n"
        "    signed_surfaces,\n"
        "    surface_offset_table,\n"
        "    volume_experiment,\n"
        "    volume_table,\n"
        ")\n"
        "from volec.paths import experiment_dir, figures_dir\n"
        "from volec.synth import item_names, load_truth\n"
        "from volec.tables import write_table\n"
        "from volec.viz import panels_around, save_figure, signed_distance_figure\n\n"
        'scenario = scenarios(quick)["quick" if quick else "full_orbit"]\n'
        'items = ["apple"] if quick else item_names()\n'
        "root = experiment_dir(quick)\n"
        "raw = volume_experiment(root, items, scenario, progress=False)"
    ),
    md("## Table I: volume per item\n\nAPE: absolute percentage error; accuracy = 100 - APE. "
       "With exact masks, without and with completion; then the default (with completion) "
       "with volec's automatic masks and with noisy masks (notebook 02). The last row is the "
       "mean (MAPE)."),
    code(
        "masks = segmentation_experiment(root, items, scenario, progress=False)\n"
        "table1 = volume_table(raw, masks)\n"
        'write_table(table1, figures_dir() / "table1_volume", float_digits=2)\n'
        "table1"
    ),
    md("## Table III: does completion help?\n\nPaired t-tests over the items, without against "
       "with completion (a positive mean difference: completion lowers it)."),
    code(
        "table3 = paired_tests(raw)\n"
        'write_table(table3, figures_dir() / "table3_ttests", float_digits=4)\n'
        "table3"
    ),
    md("## Where the surface lies\n\nSigned distances to the true surface, in mm (+ outside, "
       "- inside): median, 10th and 90th percentile of the masked cloud's points and of the "
       "final mesh (area-uniform samples), and the volume the mesh's offset implies (mean "
       "signed distance times area, in percent of the true volume) beside the volume error; "
       "then how far the poses misplaced the mesh and its signed distances once rigidly "
       "aligned to the truth (the shape's own offset; the misplacement moves the whole mesh "
       "and does not change its volume). A systematic offset of a fraction of a millimetre is "
       "a few percent of volume. The figure shows the aligned meshes."),
    code(
        "offsets = surface_offset_table(raw)\n"
        'write_table(offsets, figures_dir() / "surface_offset", float_digits=3)\n'
        "offsets"
    ),
    code(
        "shown_offsets = items if quick else offset_items\n"
        "surfaces = signed_surfaces(root, shown_offsets, scenario)\n"
        'up = load_truth(root / f"{shown_offsets[0]}-{scenario.name}")["world_up"]\n'
        "fig = signed_distance_figure(surfaces, up)\n"
        'save_figure(fig, figures_dir() / "surface_signed_distance.png")'
    ),
    md("## Runtime per stage\n\nWall time in seconds per 100-frame capture on this machine "
       "(SfM and dense as measured when they ran). Items that ran two at a time (column "
       "`workers` of `volume_raw`) shared the 2 cores, so these times are longer than those "
       "of a capture processed alone, which `benchmarks/bench_estimate.py` measures."),
    code(
        "runtime = runtime_table(raw)\n"
        'write_table(runtime, figures_dir() / "runtime_stages", float_digits=1)\n'
        "runtime"
    ),
    md("## Qualitative results (Fig. 3)\n\nMasked cloud, completed cloud, mesh and the true "
       "surface, seen from slightly below the plate's level."),
    code(
        "for item in (items if quick else shown):\n"
        "    panels = qualitative_panels(root, item, scenario)\n"
        '    up = load_truth(root / f"{item}-{scenario.name}")["world_up"]\n'
        "    fig = panels_around(panels, up, elevation_deg=-8.0)\n"
        '    save_figure(fig, figures_dir() / f"qualitative_{item}.png")'
    ),
], "notebooks/06_tables.ipynb")
