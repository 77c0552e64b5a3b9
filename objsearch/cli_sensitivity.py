"""``objsearch bench sensitivity``: the detector grid of issue 45 (experiments/sensitivity.py)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from objsearch import cli_types as t
from objsearch.agent.outdir import claim


def cmd_bench_sensitivity(args: argparse.Namespace) -> int:
    from objsearch.experiments.homes import heldout_homes
    from objsearch.experiments.sensitivity import OUTPUTS, STRATEGIES, render, run_sensitivity

    out = Path(args.out)
    quiet = args.no_progress

    def line(text: str) -> None:
        # A line per grid cell, in a pipe too (a cell is a whole bench homes run).
        if not quiet:
            print(text, file=sys.stderr, flush=True)

    with claim(out, command="bench sensitivity", owns=OUTPUTS, replace_needs_force=False):
        summary = run_sensitivity(
            out,
            homes=args.homes or list(heldout_homes()),
            seeds=args.seeds,
            scenes=args.scenes_per_schedule,
            schedules=args.schedules,
            starts_per_search=args.starts_per_scene,
            strategies=args.strategies or list(STRATEGIES),
            recall_scales=args.recall_scales,
            fp_per_image=args.fp_rates,
            base=args.perception,
            relook=args.relook,
            inspection=args.inspection,
            camera=args.camera,
            workers=t.workers(args),
            bar=not quiet and sys.stderr.isatty(),  # in a pipe its cell lines are enough
            progress=line,
        )
    if args.format == "json":
        print(json.dumps(summary, indent=2))
    else:
        print(render(summary))
        print(
            f"\n{summary['searches']} searches in {summary['elapsed_s']} s; results in {args.out} "
            f"(sensitivity.txt, .json, .md, .png)"
        )
    return 0


def _sensitivity_options(p: argparse.ArgumentParser) -> None:
    from objsearch.agent.detector_model import OVERRIDES, PRESETS, RELOOKS
    from objsearch.experiments.sensitivity import FP_PER_IMAGE, RECALL_SCALES, STRATEGIES

    def numbers(values: tuple[float, ...]) -> str:
        return ",".join(f"{v:g}" for v in values)

    (r_lo, r_hi), (f_lo, f_hi) = OVERRIDES["recall_scale"], OVERRIDES["fp_per_image"]
    p.add_argument(
        "--recall-scales",
        type=t.float_list(r_lo, r_hi),
        default=list(RECALL_SCALES),
        **t.LIST,
        help=f"comma-separated factors of the detector's recall, each {r_lo:g}-{r_hi:g} "
        f"({numbers(RECALL_SCALES)})",
    )
    p.add_argument(
        "--fp-rates",
        type=t.float_list(f_lo, f_hi),
        default=list(FP_PER_IMAGE),
        **t.LIST,
        help=f"comma-separated false positives per image (Poisson mean per view), each "
        f"{f_lo:g}-{f_hi:g} ({numbers(FP_PER_IMAGE)})",
    )
    p.add_argument(
        "--perception",
        type=t.text,
        choices=PRESETS,
        default=PRESETS[0],
        help="the detector the grid scales: its recall times each --recall-scales value, each "
        "--fp-rates value replacing its false positives (perfect: recall 1 times the scale)",
    )
    p.add_argument(
        "--relook",
        type=t.text,
        choices=RELOOKS,
        default=None,
        help="after an inspection that missed the target: off or likeliest (look again from "
        "where the robot stands while that stop is likelier than every stop left in the pass) "
        "(the preset's: likeliest for realistic and harsh, off for perfect, whatever its recall "
        "scale)",
    )
    p.add_argument(
        "--strategies",
        type=t.name_list,
        **t.LIST,
        help="comma-separated strategies, each run beside dist-oracle-global with the same "
        f"inspection and detector ({','.join(STRATEGIES)})",
    )


def register(bsub: Any) -> None:
    """``bench sensitivity`` under ``bsub`` (``objsearch bench``'s subcommands)."""
    sens = bsub.add_parser(
        "sensitivity",
        help="success, path ÷ reference and where's calibration as the detector's recall falls "
        "and its false positives rise (docs/perception.md, Sensitivity)",
        description="A grid of detectors (recall × each scale, each rate of false positives per "
        "image); each cell is a bench homes run of the strategies beside the distribution oracle "
        "seeing with the same detector. Writes sensitivity.txt, .json, .md (a block for the "
        "docs), a plot with a panel per measure (.png, .svg, .pdf) and each cell's searches.",
    )
    sens.add_argument(
        "--out",
        default="out/bench-sensitivity",
        type=t.dir_path,
        help="output folder (out/bench-sensitivity)",
    )
    sens.add_argument(
        "--homes",
        type=t.name_list,
        **t.LIST,
        help="comma-separated home names (default: all but 'paper')",
    )
    sens.add_argument(
        "--seeds",
        type=t.int_range(1, 1000),
        default=1,
        help="schedules per home, seeds 0..N-1, N 1-1000 (1)",
    )
    sens.add_argument(
        "--scenes-per-schedule",
        type=t.int_range(1, t.MAX_SEEDED_SCENES),
        help=f"scenes per schedule, 1-{t.MAX_SEEDED_SCENES} (each kind's own: habit 30)",
    )
    sens.add_argument(
        "--schedules",
        default="habit",
        type=t.name_list,
        **t.LIST,
        help="comma-separated schedule kinds, as bench homes (habit)",
    )
    sens.add_argument(
        "--starts-per-scene",
        type=t.int_range(1, 100),
        help="search each target from this many start points per scene, 1-100 (default: from "
        "every start point)",
    )
    sens.add_argument(
        "--inspection",
        type=t.text,
        choices=("single", "cover"),
        default="single",
        help="cover: every strategy as NAME+cover (single: as each strategy's name says)",
    )
    sens.defer(_sensitivity_options)
    sens.add_argument(
        "--workers",
        type=t.int_range(0, t.MAX_WORKERS),
        default=0,
        help=f"processes, at most {t.MAX_WORKERS} and one per job (0, the default: min(2, cores))",
    )
    t.format_option(sens, "print the whole summary as JSON")
    t.progress_option(sens)
    t.camera_option(sens)
    sens.set_defaults(func=cmd_bench_sensitivity)
