"""``objsearch bench dhs`` and ``bench stot``: our belief inside external benchmarks, each run
from the user's checkout of the public code at a pinned commit (docs/results-dhs.md,
docs/results-stot.md)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from objsearch import cli_types as t


def cmd_bench_dhs(args: argparse.Namespace) -> int:
    from objsearch.agent.errors import ObjsearchError
    from objsearch.experiments.dhs import (
        EXPERIMENTS,
        OURS,
        SGM_AGENTS,
        THEIR_AGENTS,
        render,
        run_dhs,
        verify_source,
    )

    seeds = list(range(args.seeds))
    experiments = args.experiments or list(EXPERIMENTS)
    agents = args.agents or [*THEIR_AGENTS, OURS]
    if any(a in SGM_AGENTS for a in agents):
        from objsearch.experiments.dhs_sgm import check_weights, sgm_overrides

        for a in agents:
            if a in SGM_AGENTS:
                sgm_overrides(a, args.sgm_outputs)
        check_weights(Path(args.sgm_outputs), experiments, agents)
    elif args.sgm_outputs is not None:
        raise ObjsearchError(
            f"--sgm-outputs is for its learned agents ({', '.join(SGM_AGENTS)}), none of which "
            "--agents names"
        )
    source = verify_source(args.source)

    def progress(run: Any) -> None:
        if not args.no_progress:  # on stderr with --format json, so stdout stays JSON
            print(
                f"  {run.line()}",
                file=sys.stderr if args.format == "json" else sys.stdout,
                flush=True,
            )

    summary = run_dhs(
        source,
        experiments=experiments,
        agents=agents,
        seeds=seeds,
        steps=args.steps,
        eps_per_scene=args.eps_per_scene,
        workers=t.workers(args),
        progress=progress,
        sgm_outputs=Path(args.sgm_outputs) if args.sgm_outputs else None,
    )
    if args.format == "json":
        print(json.dumps(summary, indent=2))
    else:
        print(render(summary))
        print(f"\n{summary['elapsed_s']} s")
    return 0


def cmd_bench_stot(args: argparse.Namespace) -> int:
    from objsearch.experiments.stot import (
        METHODS,
        format_text,
        run_household,
        summary,
        verify_source,
    )

    households = sorted(set(args.households or [3, 4]))
    checkout = verify_source(args.source, args.dataset, households)
    out = sys.stderr if args.format == "json" else sys.stdout

    def log(line: str) -> None:
        if not args.no_progress:  # on stderr with --format json, so stdout stays JSON
            print(f"  {line}", file=out, flush=True)

    results = []
    for h in households:
        results.extend(
            run_household(
                checkout,
                args.dataset,
                h,
                args.methods or list(METHODS),
                max_test_days=args.days,
                log=log,
            )
        )
    s = summary(results, checkout.missing)
    if args.format == "json":
        print(json.dumps(s, indent=2))
    else:
        print(format_text(s))
    return 0


def _dhs_options(p: argparse.ArgumentParser) -> None:
    from objsearch.experiments.dhs import (
        ALL_THEIR_AGENTS,
        BOUND,
        BOUND_AGENTS,
        EXPERIMENTS,
        OURS,
        RUNNABLE_EXPERIMENTS,
        SGM_AGENTS,
    )

    p.add_argument(
        "--experiments",
        type=t.subset_of(RUNNABLE_EXPERIMENTS),
        **t.LIST,
        help="comma-separated experiment configs of the simulator whose scenes to run "
        f"(default: {','.join(EXPERIMENTS)})",
    )
    p.add_argument(
        "--agents",
        type=t.subset_of((*ALL_THEIR_AGENTS, *SGM_AGENTS, OURS, *BOUND_AGENTS)),
        **t.LIST,
        help=f"comma-separated agents: its {', '.join(ALL_THEIR_AGENTS)}, its learned "
        f"{', '.join(SGM_AGENTS)} (a model trained here: --sgm-outputs), ours, {OURS}, and "
        f"{BOUND}, a reference that knows its generative model, or it without one piece of "
        f"that ({', '.join(BOUND_AGENTS[1:])}) (default: all but oracle_upper_bound, the "
        "learned ones and the bounds)",
    )


def _stot_options(p: argparse.ArgumentParser) -> None:
    from objsearch.experiments.stot import DATASETS, METHODS

    p.add_argument(
        "--dataset",
        type=t.text,
        choices=DATASETS,
        default="householdsDifferent",
        help="its folder of processed HOMER households (householdsDifferent)",
    )
    p.add_argument(
        "--methods",
        type=t.subset_of(METHODS),
        **t.LIST,
        help=f"comma-separated methods: ours and its baselines (default: {','.join(METHODS)})",
    )


def add_dhs(bsub: Any) -> None:
    dhs = bsub.add_parser(
        "dhs",
        help="our belief inside the Dynamic House Simulator's find-object task, beside its agents "
        "(docs/results-dhs.md)",
        description="Runs the find-object task of the Dynamic House Simulator (Kurenkov et al., "
        "ICML 2023; a checkout of andreykurenkov/modeling_env_dynamics at the pinned commit, "
        "checked file by file) with its non-learned agents and our belief, each (agent, seed) in "
        "a fresh process, and prints its metrics: attempts to find (not found within 10 counts "
        "11), share found, travel cost; then ours minus each of its agents seed by seed, with a "
        "95 % t interval.",
    )
    dhs.add_argument(
        "--source",
        type=t.existing_dir,
        help="the simulator's checkout (default: $OBJSEARCH_DHS_SOURCE)",
    )
    dhs.defer(_dhs_options)
    dhs.add_argument(
        "--sgm-outputs",
        type=t.existing_dir,
        help="for its learned agents (--agents sgm_gcn, …): the folder their weights were "
        "trained into, E/models/<model>.pt for each experiment E (`python -m "
        "objsearch.experiments.dhs_sgm train --workdir W`: W/outputs)",
    )
    dhs.add_argument(
        "--seeds",
        type=t.int_range(1, 1000),
        default=1,
        help="seeds 0..N-1 of random.seed before each agent's run, N 1-1000 (1: its published "
        "seed 0)",
    )
    dhs.add_argument(
        "--steps",
        type=t.int_range(1, 1_000_000),
        help="queries per agent and seed, 1-1000000 (default: its find_object task's 11000)",
    )
    dhs.add_argument(
        "--eps-per-scene",
        type=t.int_range(1, 1_000_000),
        help="queries per sampled scene, 1-1000000 (default: its task's 110)",
    )
    dhs.add_argument(
        "--workers",
        type=t.int_range(0, t.MAX_WORKERS),
        default=0,
        help=f"processes, at most {t.MAX_WORKERS} (0, the default: min(2, cores))",
    )
    t.format_option(dhs, "print the summary as JSON")
    dhs.add_argument("--no-progress", action="store_true", help="no line per finished run")
    dhs.set_defaults(func=cmd_bench_dhs)


def add_stot(bsub: Any) -> None:
    stot = bsub.add_parser(
        "stot",
        help="our belief at SpatioTemporalObjectTracking's object-movement prediction on HOMER "
        "households, beside its baselines (docs/results-stot.md)",
        description="Runs the evaluation of SpatioTemporalObjectTracking (Patel & Chernova, CoRL "
        "2022; a checkout of Maithili/SpatioTemporalObjectTracking at the pinned commit, checked "
        "file by file) on its processed HOMER households with its baselines and our belief, and "
        "prints its counts as shares of the moved objects (correct, wrong, missed), false "
        "positives, precision and F1 at the next step and within its 12-step lookahead; then "
        "ours minus each baseline, paired over test days, with a 95 % bootstrap interval.",
    )
    stot.add_argument(
        "--source",
        type=t.existing_dir,
        help="its checkout (default: $OBJSEARCH_STOT_SOURCE)",
    )
    stot.defer(_stot_options)
    stot.add_argument(
        "--households",
        type=t.int_list(0, 4),
        **t.LIST,
        help="comma-separated households 0-4 (default: 3,4)",
    )
    stot.add_argument(
        "--days",
        type=t.int_range(1, 1000),
        help="at most N test days per household, 1-1000 (default: all in the checkout)",
    )
    t.format_option(stot, "print the summary as JSON")
    stot.add_argument("--no-progress", action="store_true", help="no line per finished method")
    stot.set_defaults(func=cmd_bench_stot)
