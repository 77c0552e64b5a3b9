"""``objsearch map``: show the ground-truth semantic map, or build one from simulated RGB-D."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

from objsearch import cli_types as t

if TYPE_CHECKING:
    from collections.abc import Mapping

    from objsearch.agent.mapping import BuiltMap
    from objsearch.agent.session import HomeContext
    from objsearch.pipeline.bags.rgbd import ViewReport
    from objsearch.sim.placements import Placement


def register(sub: Any) -> None:
    smap = sub.add_parser("map", help="the semantic map: show the ground-truth one, or build one")
    msub = smap.add_subparsers(dest="map_command", required=True, metavar="SUBCOMMAND")

    show = msub.add_parser(
        "show", help="print the ground-truth semantic map and its agreement with ALFRED"
    )
    show.add_argument("--home", default="paper", type=t.text, help="home in data/homes (paper)")
    t.format_option(show, "print JSON")
    show.set_defaults(func=cmd_map_show)

    build = msub.add_parser(
        "build",
        help="build the semantic map from rendered RGB-D views (§4.3) and score it",
        description="Survey every room (views every 45° at sampling points on its boundary), "
        "detect static objects, fuse the masked depth into voxels, project top-down, split into "
        "instances, then compare with the ground truth and with the searches it leads to.",
    )
    build.add_argument(
        "--home",
        default="paper",
        type=t.text,
        help="home in data/homes (paper); with --bag it gives the navigation map and the truth",
    )
    build.add_argument(
        "--bag",
        type=t.existing_path,
        help="build from a bag's depth, instance images + detections, camera info and TF "
        "(objsearch record --mapping-sweep; ROS 1, ROS 2 sqlite3 or MCAP) instead of rendering",
    )
    build.add_argument(
        "--topics", type=t.existing_file, help="topic map override for --bag (.toml or .json)"
    )
    build.add_argument(
        "--out", type=t.file_path, help="write the map here (objsearch.semmap/1 JSON)"
    )
    build.add_argument(
        "--points-per-room",
        type=t.int_range(1, 32),
        default=4,
        help="sampling points per room, 1-32: 1 is the paper's single median point (4; the "
        "bag's views with --bag)",
    )
    build.add_argument(
        "--voxel",
        type=t.float_range(0.01, 0.5),
        default=0.05,
        help="voxel size, 0.01-0.5 m (0.05)",
    )
    build.add_argument(
        "--model",
        type=t.existing_file,
        help="detector model: a torch.export .pt2 or TorchScript file (forward(image) -> masks, labels, scores); "
        "default: the simulator's ground-truth masks",
    )
    build.add_argument(
        "--class-names",
        type=t.name_list,
        **t.LIST,
        help="comma-separated class names of the model's labels (default: its class_names)",
    )
    build.add_argument(
        "--no-search", action="store_true", help="skip the search-cost comparison (64 × 2 searches)"
    )
    build.add_argument(
        "--threads",
        type=t.int_range(1, t.MAX_WORKERS),
        default=1,
        help=f"torch CPU threads, 1-{t.MAX_WORKERS} (1: on a shared 2-core CPU one thread fused 6× faster than two; "
        "benchmarks/mapping.py)",
    )
    t.format_option(build, "print the report as JSON")
    t.progress_option(build)
    build.set_defaults(func=cmd_map_build)


def cmd_map_show(args: argparse.Namespace) -> int:
    from objsearch.agent.semmap import compare_with_alfred
    from objsearch.agent.session import load_context

    ctx = load_context(args.home)
    agreement = compare_with_alfred(ctx.home, ctx.semmap)
    if args.format == "json":
        rows = [
            {
                "id": s.id,
                "class": s.cls,
                "room": s.room,
                "loc": [round(s.loc.x, 3), round(s.loc.y, 3)],
                "viewpoint": [s.viewpoint.x, s.viewpoint.y],
                "view_yaw": round(s.view_yaw, 4),
                "container": s.container,
            }
            for s in ctx.semmap.statics
        ]
        print(json.dumps({"statics": rows, "alfred_agreement": agreement.summary()}, indent=2))
        return 0
    _print_statics(ctx.semmap)
    print("agreement with ALFRED interaction poses:", json.dumps(agreement.summary()))
    return 0


def _print_statics(semmap: Any) -> None:
    print(f"{'static object':58} {'loc_s':>15} {'N_s':>15} {'θ_s°':>6}")
    for s in semmap.statics:
        print(
            f"{s.id:58} ({s.loc.x:5.2f},{s.loc.y:5.2f}) ({s.viewpoint.x:5.2f},{s.viewpoint.y:5.2f})"
            f" {math.degrees(s.view_yaw):6.0f}" + ("  container" if s.container else "")
        )


def cmd_map_build(args: argparse.Namespace) -> int:
    from objsearch.agent.extras import require_torch
    from objsearch.agent.session import load_context
    from objsearch.cli import _fail

    if args.bag and args.model:
        return _fail("--model does not apply to --bag: the bag's recorded instance masks are used")
    if args.topics and not args.bag:
        return _fail("--topics applies to --bag only")
    # The home before torch and the mapping modules (seconds of imports): a name that is not a
    # home is refused at once.
    ctx = load_context(args.home)
    # torch is an optional extra (agent/extras.py): without it, an error naming it, not a traceback.
    require_torch("objsearch map build")

    import time

    import torch

    from objsearch.agent.categories import Category
    from objsearch.agent.detect import Detector, GroundTruthDetector, TorchDetector
    from objsearch.agent.mapping import (
        MappingConfig,
        SemanticMapBuilder,
        default_device,
        detected,
        survey_poses,
    )
    from objsearch.sim.mapeval import compare
    from objsearch.sim.placements import base_placements, table1_removals
    from objsearch.sim.render import SimulatedCamera, SurveyFrames

    torch.set_num_threads(args.threads)
    classes = ctx.vocabulary.names(Category.STATIC)
    detector: Detector
    if args.model:
        detector = TorchDetector(args.model, ctx.vocabulary, class_names=args.class_names)
    else:
        detector = GroundTruthDetector(frozenset(classes))
    config = MappingConfig(voxel=args.voxel, points_per_room=args.points_per_room)
    poses = survey_poses(ctx.navmap, [r.name for r in ctx.home.rooms], config.points_per_room)
    # The survey maps the static objects; the home's movable objects stay where the data has them.
    placements = base_placements(ctx.home, table1_removals(ctx.home))
    device = default_device()
    bag_report = None
    t0 = time.perf_counter()
    if args.bag:
        from objsearch.pipeline.bags.rgbd import build_map_from_bag
        from objsearch.ros.topics import TopicMap

        topic_map = TopicMap.load(Path(args.topics)) if args.topics else TopicMap()
        built, bag_report = build_map_from_bag(
            Path(args.bag), ctx.navmap, classes, config, topic_map=topic_map, device=device
        )
    else:
        builder = SemanticMapBuilder(ctx.navmap, classes, config, device=device)
        camera = SimulatedCamera(ctx.home, placements)
        frames = SurveyFrames(camera, poses).frames()
        on = not args.no_progress
        builder.fuse(detected(t.progress(frames, "survey", " frames", enabled=on), detector))
        built = builder.build()
    seconds = time.perf_counter() - t0
    accuracy = compare(ctx.semmap, built.semmap)
    report: dict[str, Any] = {
        "home": ctx.home.name,
        "source": args.bag or "simulator",
        "frames": built.frames,
        "points_fused": built.points,
        "seconds": round(seconds, 2),
        "device": str(device),
        "detector": "the bag's instance masks"
        if args.bag
        else (args.model or "ground-truth masks"),
        "config": {
            "voxel_m": config.voxel,
            "points_per_room": None if args.bag else config.points_per_room,
        },
        "accuracy": accuracy.summary(),
    }
    if bag_report is not None:
        report["bag"] = _bag_summary(bag_report)
    if not args.no_search:
        report["search_cost"] = _search_cost(args, ctx, built, placements)
    if args.out:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_name(out.name + ".tmp")
        tmp.write_text(json.dumps(built.semmap.to_json(), indent=2, sort_keys=True) + "\n")
        tmp.replace(out)
        report["out"] = str(out)
    if args.format == "json":
        print(json.dumps(report, indent=2))
        return 0
    _print_map_report(args, report, built, bag_report, seconds, device)
    return 0


def _search_cost(
    args: argparse.Namespace,
    ctx: HomeContext,
    built: BuiltMap,
    placements: Mapping[str, Placement],
) -> dict[str, Any]:
    """Every target from every start searched with the true map and with the built one."""
    from objsearch.sim.longterm import TARGET_ORDER
    from objsearch.sim.mapeval import cost_summary, search_cost

    total = len(TARGET_ORDER) * len(ctx.home.starts)
    with t.progress_bar("search cost", " pairs", total=total, enabled=not args.no_progress) as bar:
        pairs = search_cost(
            ctx, built.semmap, placements, TARGET_ORDER, on_pair=lambda _: bar.update()
        )
    return cost_summary(pairs)


def _bag_summary(bag_report: ViewReport) -> dict[str, Any]:
    """What ``map build --bag`` read from the bag, for its report."""
    return {
        "format": bag_report.format,
        "reader": bag_report.reader,
        "views": bag_report.views,
        "skipped": bag_report.skipped,
        "rejected": bag_report.rejected,
        "losses": [str(loss) for loss in bag_report.losses],
        "notes": list(bag_report.notes),
    }


def _print_map_report(
    args: argparse.Namespace,
    report: dict[str, Any],
    built: BuiltMap,
    bag_report: ViewReport | None,
    seconds: float,
    device: Any,
) -> None:
    """``map build``'s text report."""
    if bag_report is not None:
        print(bag_report.render())
    _print_statics(built.semmap)
    print(
        f"{built.frames} frames, {built.points} points fused in {seconds:.1f} s on "
        f"{device} ({report['detector']})"
    )
    acc = report["accuracy"]
    print(
        f"vs ground truth: {acc['found']}/{acc['true_instances']} found, {acc['missed']} missed, "
        f"{acc['spurious']} spurious, {acc['merged']} built instances merge several; "
        f"loc_s error median {acc['median_error_m']} m, max {acc['max_error_m']} m; "
        f"N_s unchanged for {acc['same_viewpoint']:.0%} of found"
    )
    if acc["missed_ids"]:
        print("  missed: " + ", ".join(acc["missed_ids"]))
    if acc["spurious_ids"]:
        print("  spurious: " + ", ".join(acc["spurious_ids"]))
    if "search_cost" in report:
        c = report["search_cost"]
        print(
            f"searches ({c['searches']}, Table I placements, no updates): success "
            f"{c['success_truth']} with the true map, {c['success_built']} with the built one; "
            f"mean path {c['mean_path_truth_m']} m vs {c['mean_path_built_m']} m "
            f"(ratio {c['path_ratio_built_over_truth']}; {c['longer']} longer, "
            f"{c['shorter']} shorter)"
        )
    if args.out:
        print(f"wrote {args.out}")
