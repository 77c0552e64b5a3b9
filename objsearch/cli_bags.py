"""``objsearch record`` and ``objsearch ingest``: simulated runs to ROS bags, bags to the lake."""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path
from typing import Any

from objsearch import cli_types as t

#: Odometry rates a robot publishes at; faster ones only multiply the bag's size (1 kHz for the
#: hour of a full schedule is millions of messages held in memory before they are written).
ODOM_HZ = t.float_range(0.0, 200.0, lo_open=True)
#: Views per room of a mapping sweep (each view is ~2.8 MB; objsearch map build uses 4).
POINTS_PER_ROOM = t.int_range(1, 32)


#: ``record --bag-format`` (pipeline/bags/formats.py's BagFormat values).
BAG_FORMATS = ("ros1", "ros2-sqlite3", "ros2-mcap")


class _FormatOrBagFormat(argparse.Action):
    """``record --format``: the output format (text or json); a bag format there is the
    deprecated spelling of ``--bag-format``."""

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: object,
        option_string: str | None = None,
    ) -> None:
        if values in BAG_FORMATS:
            print(
                f"objsearch: note: {option_string} {values} is deprecated; use --bag-format "
                f"{values} (--format is the output format, text or json)",
                file=sys.stderr,
            )
            namespace.bag_format = values
        else:
            namespace.format = values


def _topic_map(args: argparse.Namespace) -> Any:
    from objsearch.ros.topics import TopicMap

    return TopicMap.load(Path(args.topics)) if args.topics else TopicMap()


def _recording_json(rec: Any, size: int, *, compress: bool, **extra: Any) -> str:
    return json.dumps(
        {
            "path": str(rec.path),
            "format": rec.format.value,
            "bytes": size,
            "compressed": rec.format.value == "ros2-mcap" and compress,
            "searches": rec.tasks,
            "events": rec.events,
            "start_ns": rec.start_ns,
            "end_ns": rec.end_ns,
            "messages": dict(sorted(rec.messages.items())),
            **extra,
        },
        indent=2,
    )


def _megabytes(n: int) -> str:
    return f"{n / 1e6:,.0f} MB" if n >= 100e6 else f"{n / 1e6:.1f} MB"


class _RecordProgress:
    """``record``'s progress on stderr: one bar for the searches, one for the messages."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self.bar: Any = None
        self.stage = ""

    def __call__(self, stage: str, done: int, total: int) -> None:
        if not self.enabled:
            return
        from tqdm import tqdm

        if stage != self.stage:
            self.close()
            self.stage = stage
            unit = "search" if stage == "searches" else "msg"
            self.bar = tqdm(  # disable=None: on a terminal only, never into a pipe or log
                total=total, desc=stage, unit=unit, file=sys.stderr, disable=None
            )
        self.bar.update(done - self.bar.n)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


def cmd_record(args: argparse.Namespace) -> int:
    from objsearch.pipeline.bags.formats import BagFormat, storage_files
    from objsearch.pipeline.bags.record import (
        expected_bytes,
        planned_searches,
        record,
        record_mapping_sweep,
    )

    fmt = BagFormat.parse(args.bag_format)
    compress = not args.no_compress
    if args.mapping_sweep:
        searches = [f"--{n}" for n in ("scenes", "targets", "starts", "log") if getattr(args, n)]
        if searches:
            print(
                f"objsearch: error: {', '.join(searches)} belong to searches, not --mapping-sweep",
                file=sys.stderr,
            )
            return 2
        rec = record_mapping_sweep(
            Path(args.out),
            fmt,
            home=args.home,
            rooms=args.rooms,
            points_per_room=4 if args.points_per_room is None else args.points_per_room,
            topic_map=_topic_map(args),
            odom_hz=args.odom_hz,
            compress=compress,
        )
        size = sum(f.stat().st_size for f in storage_files(rec.path))
        if args.format == "json":
            print(_recording_json(rec, size, compress=compress, mapping_sweep=True))
            return 0
        print(f"wrote {rec.path} ({rec.format.value}): mapping sweep, {size / 1e6:.1f} MB")
        _print_counts(rec.messages)
        return 0
    if args.rooms or args.points_per_room is not None:
        print(
            "objsearch: error: --rooms and --points-per-room need --mapping-sweep", file=sys.stderr
        )
        return 2
    n_searches = planned_searches(
        args.home, scenes=args.scenes, targets=args.targets, starts=args.starts
    )
    expected = expected_bytes(fmt, n_searches, compress=compress)
    print(
        f"objsearch record: {n_searches} searches into {args.out} ({fmt.value}"
        + (", zstd" if compress and fmt is BagFormat.ROS2_MCAP else "")
        + ")"
        + (f", about {_megabytes(expected)}" if expected is not None else ""),
        file=sys.stderr,
        flush=True,
    )
    progress = _RecordProgress(not args.no_progress)
    try:
        rec = record(
            Path(args.out),
            fmt,
            home=args.home,
            scenes=args.scenes,
            targets=args.targets,
            starts=args.starts,
            log_dir=Path(args.log) if args.log else None,
            topic_map=_topic_map(args),
            odom_hz=args.odom_hz,
            seed=args.seed,
            compress=compress,
            progress=progress,
            camera=args.camera,
        )
    finally:
        progress.close()
    size = sum(f.stat().st_size for f in storage_files(rec.path))
    if args.format == "json":
        print(_recording_json(rec, size, compress=compress, log=args.log))
        return 0
    print(
        f"wrote {rec.path} ({rec.format.value}): {rec.tasks} searches, {rec.events} agent "
        f"events, {size / 1e6:.1f} MB"
    )
    _print_counts(rec.messages)
    if args.log:
        print(f"  the agent's own log: {args.log}")
    return 0


def _print_counts(messages: dict[str, int]) -> None:
    for topic, n in sorted(messages.items()):
        print(f"  {topic:32} {n:8} messages")


def cmd_ingest(args: argparse.Namespace) -> int:
    from objsearch.pipeline.bags.engines import make_engine
    from objsearch.pipeline.bags.ingest import IngestResult, ingest

    # More workers than bags would only start idle processes.
    workers = min(args.workers, len(args.bags))
    engine = make_engine(args.engine, workers=workers, address=args.address)
    topic_map = _topic_map(args)
    failed = 0

    def show(result: IngestResult) -> None:
        nonlocal failed
        if args.format == "json":
            failed += result.error is not None
            print(json.dumps(_ingest_json(result, args.lake), default=str), flush=True)
            return
        if result.error is not None:
            failed += 1
            print(f"objsearch: error: {result.path}: {result.error}", file=sys.stderr)
        elif result.already:
            why = f" ({result.note})" if result.note else ""
            print(f"{result.path}: already in the lake; nothing to do{why}")
        else:
            assert result.report is not None
            print(result.report.render())
            if result.note:
                print(f"  {result.note}")
            if result.committed or not result.note:
                print(f"  committed {result.committed} events to {args.lake}")
        sys.stdout.flush()

    ingest(
        [Path(b) for b in args.bags],
        str(args.lake),  # a folder or a fleet lake's URI (s3://…)
        topic_map=topic_map,
        robot=args.robot,
        engine=engine,
        progress=not args.no_progress,
        reingest=args.reingest,
        on_result=show,
    )
    return 2 if failed else 0


def _ingest_json(result: Any, lake: str) -> dict[str, Any]:
    """One bag's outcome, a line of ``ingest --format json`` (JSON Lines: one per bag, as they end)."""
    import dataclasses

    report: Any = result.report
    return {
        "path": result.path,
        "lake": lake,
        "ok": result.error is None,
        "error": result.error,
        "already": result.already,
        "committed": result.committed,
        "note": result.note,
        "report": None if report is None else dataclasses.asdict(report),
    }


def _add_rec(sub: Any) -> None:
    rec = sub.add_parser(
        "record", help="run searches in the simulator and write them as a robot's ROS bag"
    )
    rec.add_argument(
        "--out",
        required=True,
        type=t.new_path,
        help="bag to write: NAME.bag (ros1) or a directory (ros2); never overwritten",
    )
    rec.add_argument(
        "--bag-format",
        type=t.text,
        choices=BAG_FORMATS,
        help="ros1, ros2-sqlite3 or ros2-mcap (required)",
        metavar="FORMAT",
    )
    rec.add_argument("--home", default="paper", type=t.text, help="home in data/homes (paper)")
    rec.add_argument(
        "--scenes",
        type=t.SCENES,
        **t.OLD_SPACED_LIST,
        help="comma-separated scenes of the schedule (all)",
    )
    rec.add_argument(
        "--targets",
        type=t.name_list,
        **t.OLD_SPACED_LIST,
        help="comma-separated targets to search for (all)",
    )
    rec.add_argument(
        "--starts",
        type=t.name_list,
        **t.OLD_SPACED_LIST,
        help="comma-separated start points, e.g. kitchen-1,livingroom-1 (all)",
    )
    rec.add_argument("--log", type=t.dir_path, help="also keep the agent's own event log here")
    rec.add_argument("--topics", type=t.existing_file, help="topic map override (.toml or .json)")
    rec.add_argument(
        "--odom-hz", type=ODOM_HZ, default=10.0, help="odometry rate, above 0 and up to 200 (10)"
    )
    rec.add_argument("--seed", type=t.SEED, default=0, help="seed (0)")
    t.camera_option(rec)
    rec.add_argument(
        "--mapping-sweep",
        action="store_true",
        help="record the §4.3 mapping survey instead of searches: RGB (rgb8), depth (32FC1 m), "
        "instance masks (mono16 + the detections as label table), camera info and TF per view "
        "(large: ~2.8 MB a view; the paper home at 4 points per room is 128 views)",
    )
    rec.add_argument(
        "--no-compress",
        action="store_true",
        help="write MCAP chunks uncompressed (ros2-mcap; by default zstd, as ros2 bag record)",
    )
    t.progress_option(rec)
    rec.check(
        lambda a: (
            None if a.bag_format else "--bag-format is required (ros1, ros2-sqlite3 or ros2-mcap)"
        )
    )
    # --format named the bag format before --bag-format did: those values still work.
    t.format_option(
        rec, "print what was written as JSON", action=_FormatOrBagFormat, also=BAG_FORMATS
    )
    rec.add_argument(
        "--rooms",
        type=t.name_list,
        **t.OLD_SPACED_LIST,
        help="comma-separated rooms to sweep (all; with --mapping-sweep)",
    )
    rec.add_argument(
        "--points-per-room",
        type=POINTS_PER_ROOM,
        help="sampling points per room, 1-32 (4, as objsearch map build; with --mapping-sweep)",
    )
    rec.set_defaults(func=cmd_record)


def _add_ing(sub: Any) -> None:
    ing = sub.add_parser("ingest", help="read ROS bags (ROS 1, ROS 2 sqlite3, MCAP) into the lake")
    ing.add_argument(
        "bags",
        nargs="+",
        metavar="BAG",
        type=t.existing_path,
        help=".bag files or ROS 2 bag directories",
    )
    ing.add_argument(
        "--lake",
        default=os.environ.get("OBJSEARCH_LAKE", "out/lake"),
        type=t.dir_path,
        help="the event lake directory ($OBJSEARCH_LAKE or out/lake, as query and lake use)",
    )
    ing.add_argument(
        "--workers",
        type=t.int_range(1, t.MAX_WORKERS),
        default=1,
        help=f"bags ingested in parallel, 1-{t.MAX_WORKERS} and at most one per bag (1); with "
        "--engine ray and no --address, the CPUs of the local Ray instance",
    )
    ing.add_argument(
        "--engine",
        default="local",
        choices=["local", "ray"],
        help="local processes (default) or Ray tasks (needs objsearch[fleet])",
    )
    ing.add_argument(
        "--address",
        type=t.ray_address,
        help="Ray cluster address (e.g. ray://head:10001 or auto); --engine ray only",
    )
    ing.add_argument(
        "--robot", default="robot", type=t.text, help="robot name, the lake's first partition"
    )
    ing.add_argument("--topics", type=t.existing_file, help="topic map override (.toml or .json)")
    t.progress_option(ing)
    ing.add_argument(
        "--reingest",
        action="store_true",
        help="read bags the lake already holds again and replace their rows (a changed topic "
        "map or converter version does this by itself)",
    )
    t.format_option(
        ing, "print each bag's outcome and report as a line of JSON (JSON Lines), as it ends"
    )
    ing.set_defaults(func=cmd_ingest)


def register(sub: Any) -> None:
    _add_rec(sub)
    _add_ing(sub)
