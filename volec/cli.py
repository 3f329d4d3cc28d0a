"""The ``volec`` command line (also ``python -m volec``).

In: command-line arguments. Out: files in the output folder the user names, a short report on
stdout, progress on stderr, and exit status 0 on success, 2 on a usage or input error.
Each subcommand is a thin wrapper over a library function.
"""

from __future__ import annotations

import argparse
import errno
import logging
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from volec import __version__
from volec.errors import VolecError

log = logging.getLogger("volec")


def _cmd_synth(args: argparse.Namespace) -> int:
    from volec.synth import ITEMS, PRESETS, write_benchmark, write_synthetic_capture

    if args.list:
        print(f"{'item':<22} {'volume_ml':>9}  label")
        for name, spec in ITEMS.items():
            print(f"{name:<22} {spec.volume_ml:>9.1f}  {spec.label}")
        return 0
    if not args.item:
        raise VolecError("name an item (see `volec synth --list`) or 'all', and --out DIR")
    if args.out is None:
        raise VolecError("--out DIR is required: the folder to write the capture to")
    if args.item != "all" and args.item not in ITEMS:
        raise VolecError(f"unknown item '{args.item}'; `volec synth --list` shows the 21 items")
    cfg = PRESETS[args.preset]
    changes: dict[str, object] = {"seed": args.seed, "workers": args.workers}
    if args.frames is not None:
        changes["n_frames"] = args.frames
    if args.arc is not None:
        changes["arc_deg"] = args.arc
    if args.drift_mm is not None:
        changes["drift_m"] = args.drift_mm / 1000.0
    if args.no_masks:
        changes["masks_in_capture"] = False
    if args.mask_noise:
        changes["mask_noise"] = True
    if args.setup:
        changes["setup"] = args.setup
    if args.motion_blur is not None:
        changes["motion_blur_share"] = args.motion_blur
    cfg = cfg.with_(**changes)
    start = time.perf_counter()
    if args.item == "all":
        outs = write_benchmark(Path(args.out), cfg=cfg, overwrite=args.overwrite)
        print(f"wrote {len(outs)} captures under {args.out} in {time.perf_counter() - start:.1f} s")
    else:
        out = write_synthetic_capture(args.item, Path(args.out), cfg, overwrite=args.overwrite)
        n = cfg.trajectory.n_frames
        took = time.perf_counter() - start
        print(f"wrote {out}/capture ({n} frames) and {out}/ground_truth in {took:.1f} s")
    return 0


def _open_capture(args: argparse.Namespace):  # -> (Capture, ScaleCheck)
    """The capture named on the command line, in metres (``--scale``,
    ``--scale-from-distance``), and why it is taken as metric."""
    from volec.capture import read_capture
    from volec.scale import require_metric, scale_from_distance, with_scale

    capture = read_capture(Path(args.capture), on_missing="skip" if args.skip_missing else "error")
    user_scale = args.scale is not None or args.scale_from_distance is not None
    if args.scale is not None and args.scale_from_distance is not None:
        raise VolecError("give either --scale or --scale-from-distance, not both")
    if args.scale is not None:
        capture = with_scale(capture, args.scale)
    elif args.scale_from_distance is not None:
        a, b, metres = args.scale_from_distance
        try:
            distance_m = float(metres)
        except ValueError:
            raise VolecError(f"--scale-from-distance: '{metres}' is not a distance in metres"
                             ) from None
        capture = with_scale(capture, scale_from_distance(capture, a, b, distance_m))
    return capture, require_metric(capture, user_scale=user_scale)


def _cmd_sfm(args: argparse.Namespace) -> int:
    from volec.io import folder_lock
    from volec.pipeline import check_output_folder, run_sfm_stage
    from volec.sfm import PRESETS

    work = Path(args.out)
    capture, _ = _open_capture(args)
    check_output_folder(capture, work)
    with folder_lock(work):
        result, computed = run_sfm_stage(capture, work, PRESETS[args.preset], args.overwrite)
    if not computed:
        print(f"{work}/sfm is already finished (pass --overwrite to redo it)")
    s = result.summary
    print(
        f"registered {s['registered']}/{s['frames']} frames, {s['points']} points, "
        f"reprojection {s['reprojection_error_px']:.2f} px, scale {result.scale:.5f} m/unit "
        f"({s['scale_method']}; the two estimates differ by {s['scale_short_vs_all_pct']:+.2f} %), "
        f"camera-centre residual to AR {s['residual_median_m'] * 1000:.1f} mm median"
    )
    print(f"COLMAP model: {work}/sfm/model; summary: {work}/sfm/summary.json")
    return 0


def _cmd_dense(args: argparse.Namespace) -> int:
    from volec.dense import PRESETS as DENSE_PRESETS
    from volec.io import folder_lock
    from volec.masking import PRESETS as MASK_PRESETS
    from volec.pipeline import check_output_folder, masks_source, run_stages
    from volec.sfm import PRESETS as SFM_PRESETS

    work = Path(args.out)
    capture, _ = _open_capture(args)
    check_output_folder(capture, work)
    masks_source(capture, args.masks)  # given masks that are missing: refused before any work
    with folder_lock(work):
        stages = run_stages(capture, work, SFM_PRESETS[args.sfm_preset], DENSE_PRESETS[args.preset],
                            MASK_PRESETS[args.mask_preset], overwrite=args.overwrite,
                            progress=not args.quiet, masks=args.masks)
    sfm, dense, masked = stages.sfm, stages.dense, stages.masked
    d, m = dense.summary, masked.report
    print(f"SfM: {sfm.summary['registered']}/{sfm.summary['frames']} frames registered")
    print(f"dense: {d['depth_maps']} depth maps, {d['points']} points -> {work}/scene.ply")
    print(f"masking: kept {m['kept']} of {m['input_points']} points "
          f"({m['removed_outside_mask']} outside a food mask, {m['removed_too_few_views']} "
          f"seen by too few views) -> {work}/food_masked.ply")
    for name, why in m.get("unusable_masks", {}).items():
        print(f"warning: the mask of {name} was left out: {why}")
    return 0


def _cmd_complete(args: argparse.Namespace) -> int:
    from volec.completion.complete import SHIPPED_CHECKPOINT, CompletionConfig, complete_cloud
    from volec.completion.preprocess import frame_needs_up
    from volec.completion.train import load_checkpoint
    from volec.errors import OutputExistsError
    from volec.meshing import with_normals
    from volec.pointcloud import read_ply, write_ply

    source, out = Path(args.partial), Path(args.out)
    if out.resolve() == source.resolve():
        raise OutputExistsError("--out is the input file; volec never writes over its input")
    if out.exists() and not args.overwrite:
        raise OutputExistsError(f"{out} exists; pass --overwrite to replace it")
    partial = read_ply(source)
    checkpoint = Path(args.checkpoint) if args.checkpoint else SHIPPED_CHECKPOINT
    try:
        model, meta = load_checkpoint(checkpoint)
    except FileNotFoundError as e:
        raise VolecError(str(e)) from e
    up = None if args.up is None else np.asarray(args.up, float)
    if up is None and frame_needs_up(model.cfg.input_frame):
        raise VolecError(f"{checkpoint.name} frames its input upright: pass --up X Y Z, the "
                         "table's normal in the cloud's frame (volec estimate writes it as "
                         "support_plane.normal in result.json)")
    result = complete_cloud(partial, model, CompletionConfig(merge_partial=not args.network_only),
                            up)
    # the predicted points' normals are unknown (NaN) until estimated here
    write_ply(with_normals(result.cloud) if result.cloud.normals is not None else result.cloud,
              out)
    s = result.summary
    print(f"completed {s['partial_points']} partial points with {s['predicted_kept']} predicted "
          f"ones in {s['seconds']:.2f} s -> {out} ({s['points']} points)")
    return 0


def _cmd_segment(args: argparse.Namespace) -> int:
    from volec.io import folder_lock
    from volec.pipeline import check_output_folder, run_segment_stage, run_sfm_stage

    work = Path(args.out)
    capture, _ = _open_capture(args)
    check_output_folder(capture, work)
    with folder_lock(work):
        sfm, redone = run_sfm_stage(capture, work, overwrite=args.overwrite)
        masks, computed = run_segment_stage(capture, sfm, work, overwrite=args.overwrite or redone,
                                            progress=not args.quiet)
    if not computed:
        print(f"{work}/segment.json is already finished (pass --overwrite to redo it)")
    print(f"{len(masks)} food masks -> {work}/masks/ (median confidence "
          f"{np.median(masks.confidence):.3f}); record: {work}/segment.json")
    for name, why in masks.failed.items():
        print(f"warning: {name}: {why}")
    return 0


EXIT_UNTRUSTED = 3
"""``volec estimate --strict``: the estimate was made but is not trusted."""


def _cmd_estimate(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from volec.estimate import PRESETS, run_estimate
    from volec.masking import PRESETS as MASK_PRESETS

    capture, scale = _open_capture(args)
    cfg = replace(PRESETS[args.preset], use_completion=not args.no_completion,
                  completion_method=args.completion, checkpoint=args.checkpoint or "")
    if args.mask_preset is not None:
        cfg = replace(cfg, masking=MASK_PRESETS[args.mask_preset])
    cfg = replace(cfg, masks=args.masks,
                  keyframes=replace(cfg.keyframes, max_frames=args.max_frames))
    result = run_estimate(capture, Path(args.out), cfg, overwrite=args.overwrite,
                          progress=not args.quiet, scale=scale)
    trust = "trusted" if result["trusted"] else "NOT TRUSTED"
    print(f"volume: {result['volume_ml']:.1f} mL "
          f"({'with' if result['completion_used'] else 'without'} completion; {trust})")
    low_ml, high_ml = result["volume_interval_ml"]
    if high_ml is not None:
        print(f"between {low_ml:.1f} and {high_ml:.1f} mL with what no camera saw and the "
              "metric scale's uncertainty (volume_interval_ml)")
    for reason in result["reasons"]:
        print(f"not trusted ({reason['code']}): {reason['message']}")
    for warning in result["warnings"][len(result["reasons"]):]:
        print(f"warning: {warning}")
    print(f"result: {Path(args.out) / 'result.json'}; mesh: {Path(args.out) / 'mesh.ply'}, "
          f"mesh.glb; report: {Path(args.out) / 'report.html'} (and report.md)")
    return EXIT_UNTRUSTED if args.strict and not result["trusted"] else 0


def _cmd_batch(args: argparse.Namespace) -> int:
    from volec.batch import INDEX, TABLE, BatchConfig, run_batch

    cfg = BatchConfig(preset=args.preset, masks=args.masks, use_completion=not args.no_completion,
                      max_frames=args.max_frames,
                      workers=args.workers, threads_per_worker=args.threads_per_worker,
                      scheduler=args.scheduler or "")
    table = run_batch(Path(args.captures), Path(args.out), cfg, progress=not args.quiet)
    done = table[table["status"] == "done"]
    print(f"{len(done)} of {len(table)} captures estimated ({int(done['trusted'].sum())} "
          f"trusted); table: {Path(args.out) / TABLE}; page: {Path(args.out) / INDEX}")
    for _, row in table[table["status"] != "done"].iterrows():
        print(f"failed: {row['capture']}: {row['error']}")
    return 0 if len(done) == len(table) else EXIT_UNTRUSTED


def _add_max_frames_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--max-frames", type=_positive_int, default=100, metavar="N",
                        help="reconstruct at most N keyframes, evenly spread (blurred frames "
                        "and near-duplicates are always dropped; default 100)")


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a whole number") from None
    if value < 3:
        raise argparse.ArgumentTypeError(f"need at least 3 frames, not {value}")
    return value


def _add_masks_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--masks", default="default", choices=["default", "given", "auto"],
                        help="the capture's food masks (given), automatic ones (auto), or the "
                        "capture's when every frame has one and automatic otherwise (default)")


def _add_capture_options(parser: argparse.ArgumentParser) -> None:
    """The options of every command that reads a capture."""
    parser.add_argument("--skip-missing", action="store_true",
                        help="skip frames whose image file is missing (default: fail)")
    parser.add_argument("--scale", type=float, metavar="METRES_PER_UNIT",
                        help="the capture's poses are not in metres: multiply their positions "
                        "by this (e.g. 0.01 for centimetres)")
    parser.add_argument("--scale-from-distance", nargs=3, metavar=("FRAME_A", "FRAME_B", "METRES"),
                        help="the capture's poses are not in metres: scale them so that the "
                        "cameras of these two frames are METRES apart")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``volec`` command."""
    parser = argparse.ArgumentParser(
        prog="volec", description="Food volume in millilitres from a phone capture."
    )
    parser.add_argument("--version", action="version", version=f"volec {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    synth = sub.add_parser(
        "synth",
        help="write a synthetic FoodKit capture with exact ground truth",
        description="Render a synthetic phone capture of a benchmark food item: "
        "OUT/capture (images, masks, transforms.json with drifting AR poses) and "
        "OUT/ground_truth (mesh, exact poses, masks, truth.json).",
    )
    synth.add_argument("item", nargs="?", help="item name, or 'all' for the 21-item benchmark")
    synth.add_argument("--list", action="store_true", help="list the items and their volumes")
    synth.add_argument("--out", type=Path, help="output folder (for 'all': one folder per item)")
    synth.add_argument("--preset", default="default",
                       choices=["default", "sharp", "half_orbit", "drift_1cm", "quick", "video"],
                       help="default: a phone's look; sharp: the first benchmark's look "
                       "(one ray per pixel, hard shadows, no blur); video: 1000 frames, a "
                       "quarter smeared by hand motion")
    synth.add_argument("--frames", type=int, help="number of frames (default 100)")
    synth.add_argument("--arc", type=float, help="orbit arc in degrees (default 360)")
    synth.add_argument("--drift-mm", type=float, help="largest AR position drift, mm (default 5)")
    synth.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    synth.add_argument("--workers", type=int, default=2, help="render processes (default 2)")
    synth.add_argument("--no-masks", action="store_true",
                       help="leave food masks out of the capture (ground truth keeps them)")
    synth.add_argument("--mask-noise", action="store_true",
                       help="give the capture masks as a real segmenter would (boundaries off, "
                       "shadow leaks, missed chunks, false blobs, two empty); ground truth "
                       "keeps the exact ones")
    synth.add_argument("--motion-blur", type=float, nargs="?", const=0.25, metavar="SHARE",
                       help="smear this share of the frames by hand motion, as in a phone video "
                       "(default when given: 0.25)")
    synth.add_argument("--setup", help="plain (default), hard (each item a hard setup for "
                       "segmentation) or one of: white_on_white, plate_like_food, "
                       "across_the_rim, strong_shadows, cup_beside, fork_beside, dim, bright")
    synth.add_argument("--overwrite", action="store_true",
                       help="replace an existing output folder")
    synth.set_defaults(func=_cmd_synth)

    sfm = sub.add_parser(
        "sfm",
        help="refine the AR poses with structure from motion (metric, in the capture's frame)",
        description="Run pycolmap SfM on a capture and align it to its AR poses. Writes "
        "WORKDIR/sfm (COLMAP model, sparse cloud, summary.json); the capture is only read.",
    )
    sfm.add_argument("capture", help="capture folder (transforms.json, or a COLMAP project)")
    sfm.add_argument("--out", required=True, type=Path, help="work folder")
    sfm.add_argument("--preset", default="default",
                     choices=["default", "exhaustive", "colmap_sift"])
    _add_capture_options(sfm)
    sfm.add_argument("--overwrite", action="store_true", help="redo a finished SfM stage")
    sfm.set_defaults(func=_cmd_sfm)

    dense = sub.add_parser(
        "dense",
        help="dense scene cloud and masked food cloud (runs or reuses SfM first)",
        description="Run SfM (reusing a finished one in WORKDIR), plane-sweep stereo on the "
        "CPU (or a GPU when present) and food-mask filtering. Writes WORKDIR/scene.ply and "
        "WORKDIR/food_masked.ply (metres, the capture's world frame) with dense.json and "
        "masking.json; the capture is only read.",
    )
    dense.add_argument("capture", help="capture folder (transforms.json, masks optional)")
    dense.add_argument("--out", required=True, type=Path, help="work folder")
    dense.add_argument("--preset", default="default",
                       choices=["default", "thorough", "fast", "full_image"],
                       help="dense stereo preset (thorough: 64 planes and 4 sources, the "
                       "default before 2026-12-05, 1.45 times the time)")
    dense.add_argument("--mask-preset", default="default", choices=["default", "tolerant"],
                       help="masking preset (tolerant: 90%% of views, masks grown 3 px)")
    _add_masks_option(dense)
    dense.add_argument("--sfm-preset", default="default",
                       choices=["default", "exhaustive", "colmap_sift"])
    _add_capture_options(dense)
    dense.add_argument("--overwrite", action="store_true",
                       help="redo every stage, replacing earlier results in WORKDIR")
    dense.add_argument("--quiet", action="store_true", help="no progress bars")
    dense.set_defaults(func=_cmd_dense)

    seg = sub.add_parser(
        "segment",
        help="automatic food masks for every frame (runs or reuses SfM first)",
        description="Find the food without any learned model: the support plane and the item "
        "standing on it from the SfM points, colour graph cuts seeded from them on a few "
        "views, their visual hull, and every frame's silhouette refined at its border. "
        "Writes WORKDIR/masks/*.png and WORKDIR/segment.json; the capture is only read.",
    )
    seg.add_argument("capture", help="capture folder (transforms.json, or a COLMAP project)")
    seg.add_argument("--out", required=True, type=Path, help="work folder")
    seg.add_argument("--overwrite", action="store_true", help="redo a finished SfM stage")
    seg.add_argument("--quiet", action="store_true", help="no progress bars")
    _add_capture_options(seg)
    seg.set_defaults(func=_cmd_segment)

    batch = sub.add_parser(
        "batch",
        help="volec estimate over every capture in a folder, on Dask, with one table",
        description="Run `volec estimate` on every capture (subfolder) of CAPTURES on a local "
        "Dask cluster (one capture per worker, threads limited per worker) or an existing one "
        "(--scheduler). Writes OUT/CAPTURE/ (each capture's result folder), OUT/batch.csv "
        "(capture, volume, trusted, reasons, warnings, seconds, error) and OUT/index.html (the "
        "table, sortable, linking each capture's report). A capture that fails is "
        "recorded and the others go on; a re-run skips the finished ones. Exits with 3 when a "
        "capture failed.",
    )
    batch.add_argument("captures", help="folder of captures")
    batch.add_argument("--out", required=True, type=Path, help="output folder")
    batch.add_argument("--preset", default="default",
                       choices=["default", "fast", "tolerant_masks"])
    _add_masks_option(batch)
    _add_max_frames_option(batch)
    batch.add_argument("--no-completion", action="store_true")
    batch.add_argument("--workers", type=int, default=0,
                       help="local worker processes (default: half the cores)")
    batch.add_argument("--threads-per-worker", type=int, default=0,
                       help="threads each worker may use (default: the cores shared out)")
    batch.add_argument("--scheduler", help="address of an existing Dask scheduler")
    batch.add_argument("--quiet", action="store_true", help="no progress bar")
    batch.set_defaults(func=_cmd_batch)

    complete = sub.add_parser(
        "complete",
        help="complete a metric partial cloud of one food item with the trained network",
        description="Normalize the partial cloud, predict the missing part with the shipped "
        "SymmCompletion checkpoint, map it back into the input's frame and remove outliers. "
        "Writes a PLY with the partial's points plus the predicted ones (magenta).",
    )
    complete.add_argument("partial", help="partial cloud (PLY; metres, any frame)")
    complete.add_argument("--out", required=True, type=Path, help="completed cloud (PLY)")
    complete.add_argument("--checkpoint", help="a checkpoint other than the shipped one")
    complete.add_argument("--network-only", action="store_true",
                          help="write only the predicted points, not the partial's")
    complete.add_argument("--up", nargs=3, type=float, metavar=("X", "Y", "Z"),
                          help="the support plane's normal in the cloud's frame (needed by a "
                          "checkpoint trained upright)")
    complete.add_argument("--overwrite", action="store_true", help="replace --out if it exists")
    complete.set_defaults(func=_cmd_complete)

    estimate = sub.add_parser(
        "estimate",
        help="the whole pipeline: volume in mL, a closed mesh and a report from a capture",
        description="SfM, dense stereo, masking, completion, meshing and volume. OUTDIR is "
        "also the work folder: a re-run reuses the finished stages. Writes OUTDIR/result.json "
        "(volume_ml, warnings, stage times), mesh.ply, mesh.glb, the clouds of each stage, "
        "report.html (open it in a browser, offline) and report.md; the capture is only read.",
    )
    estimate.add_argument("capture", help="capture folder (transforms.json, masks optional)")
    estimate.add_argument("--out", required=True, type=Path, help="output folder")
    estimate.add_argument("--no-completion", action="store_true",
                          help="mesh the masked cloud as it is (the VolE-style baseline)")
    estimate.add_argument("--completion", default="auto",
                          choices=["network", "mirror", "rotation", "auto"],
                          help="what completes the masked cloud: (auto, the default) its "
                          "half-turn about its best vertical axis where the food is symmetric "
                          "under it, then the shipped network; the network alone; its "
                          "reflection in its best mirror plane; or the half-turn alone")
    estimate.add_argument("--preset", default="default",
                          choices=["default", "fast", "tolerant_masks"],
                          help="fast: coarser dense stereo and meshing; tolerant_masks: for "
                          "imperfect masks")
    estimate.add_argument("--checkpoint", help="a completion checkpoint other than the shipped one")
    estimate.add_argument("--mask-preset", choices=["default", "tolerant"],
                          help="masking preset (tolerant: for imperfect masks, 90%% of views, "
                          "masks grown 3 px)")
    _add_masks_option(estimate)
    _add_max_frames_option(estimate)
    estimate.add_argument("--strict", action="store_true",
                          help=f"exit with status {EXIT_UNTRUSTED} when the estimate is not "
                          "trusted (result.json says why)")
    _add_capture_options(estimate)
    estimate.add_argument("--overwrite", action="store_true",
                          help="redo every stage, replacing an earlier result in OUTDIR")
    estimate.add_argument("--quiet", action="store_true", help="no progress display")
    estimate.set_defaults(func=_cmd_estimate)
    return parser


#: errno values that mean the user's disk or permissions, not a bug in volec.
_USER_OS_ERRORS = {errno.ENOSPC, errno.EDQUOT, errno.EACCES, errno.EPERM, errno.EROFS}


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``volec`` command; returns the process exit status: 0 done, 2 an error the user
    can act on (one line on stderr), 3 an untrusted estimate with ``--strict``, 1 a bug in volec
    (with its traceback)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(levelname)s %(name)s: %(message)s",
    )
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args))
    except VolecError as e:
        print(f"volec: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:
        if e.errno not in _USER_OS_ERRORS:
            raise
        where = e.filename or "a file"
        print(f"volec: error: cannot write or read {where}: {e.strerror}", file=sys.stderr)
        return 2
