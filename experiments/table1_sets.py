"""``objsearch bench table1``: the paper's Table I over a seeded sample of iTHOR FloorPlan sets
(one kitchen, living room, bedroom and bathroom) that satisfy the paper's removal rule; the
protocol is in docs/results-table1.md.

Eligibility is decided for every set at once: the removal rule acts room by room, so each of the
100 rooms is built once and a set's count of each target is the sum of its rooms' counts. Every
sampled set is then built as a whole home (into ``OUT/data``, never the committed ``data/``) and
checked again by the build's own rule (``pipeline/scenario.py``).
"""

from __future__ import annotations

import itertools
import json
import math
import random
import statistics
import sys
import time
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from objsearch.agent.errors import ObjsearchError
from objsearch.agent.session import DEFAULT_PRIOR, clear_contexts
from objsearch.experiments.paper import PAPER_TABLE1, discovery, table1_job
from objsearch.experiments.runner import TARGETS, Job, Row, run_jobs, unseeable, write_rows
from objsearch.pipeline.build import PAPER_HOME, build_data
from objsearch.pipeline.findings import EMPTY_ROOMS, LOST_GRID_POINTS
from objsearch.pipeline.home import build_home
from objsearch.pipeline.more_homes import TYPE_BASES
from objsearch.pipeline.rooms import ConvertedRoom
from objsearch.pipeline.scenario import TABLE1_KEEP_ONE, TABLE1_REMOVE_ALL
from objsearch.pipeline.vocabulary import SEMI_DYNAMIC_NAMES
from objsearch.sim.world import DEFAULT_CAMERA

#: FloorPlans per room type in the stored source data (1-25, 201-225, 301-325, 401-425).
SCENES_PER_TYPE = 25
DEFAULT_SEED = 1
#: Strategy → seeds; SDP picks rooms at random, the others are deterministic.
STRATEGY_SEEDS: tuple[tuple[str, tuple[int, ...]], ...] = (
    ("sdp", (0, 1)),
    ("rvp", (0,)),
    ("wpl", (0,)),
)
STRATEGIES = tuple(name for name, _ in STRATEGY_SEEDS)
#: The paper's ordering of Table I's averages: WPL ≤ RVP < SDP.
PAPER_ORDER = "wpl<=rvp<sdp"
OUTPUTS = (
    "table1_sets.csv",
    "table1_trials.csv",
    "table1_trials.parquet",
    "summary.json",
    "summary.md",
    "data",
)

FloorPlanSet = tuple[str, str, str, str]


@dataclass(frozen=True)
class Eligibility:
    candidates: int
    fail_rule: int
    #: Satisfy the rule, but a room's walking graph is in pieces (its searches cannot run).
    split_room: int
    eligible: tuple[FloorPlanSet, ...]  # sorted by FloorPlan numbers
    split_rooms: tuple[str, ...]


def set_name(scenes: Sequence[str]) -> str:
    """``fp2-201-303-401`` for FloorPlan2, 201, 303, 401."""
    return "fp" + "-".join(s.removeprefix("FloorPlan") for s in scenes)


def room_target_counts(room: ConvertedRoom) -> tuple[int, ...]:
    """How many instances of each target the room keeps after the paper's removals."""
    removed = {cls for name, cls in TABLE1_REMOVE_ALL if name == room.name}
    keep_one = {cls for name, cls in TABLE1_KEEP_ONE if name == room.name}
    have = Counter(o.cls for o in room.objects)
    return tuple(
        0 if c in removed else min(have[c], 1) if c in keep_one else have[c]
        for c in SEMI_DYNAMIC_NAMES
    )


def eligibility(source: Path, progress: Callable[[str], None] | None = None) -> Eligibility:
    """Every set of the stored FloorPlans, sorted into: fails the removal rule, satisfies it but
    has a room in pieces, eligible."""
    counts = np.zeros((4, SCENES_PER_TYPE, len(SEMI_DYNAMIC_NAMES)), dtype=np.int64)
    whole = np.zeros((4, SCENES_PER_TYPE), dtype=bool)
    scenes = [[f"FloorPlan{b + k}" for k in range(1, SCENES_PER_TYPE + 1)] for b in TYPE_BASES]
    split: list[str] = []
    for k in range(SCENES_PER_TYPE):
        # The k-th scene of each type as one home: each room is built exactly once.
        home = build_home(source, f"rooms-{k + 1}", [scenes[t][k] for t in range(4)], progress)
        for t, room in enumerate(home.rooms):
            counts[t, k] = room_target_counts(room)
            whole[t, k] = room.walkable_components == 1
            if not whole[t, k]:
                split.append(room.source_scene)
    n = SCENES_PER_TYPE
    total = (
        counts[0][:, None, None, None]
        + counts[1][None, :, None, None]
        + counts[2][None, None, :, None]
        + counts[3][None, None, None, :]
    )
    rule = (total == 1).all(axis=-1)
    connected = (
        whole[0][:, None, None, None]
        & whole[1][None, :, None, None]
        & whole[2][None, None, :, None]
        & whole[3][None, None, None, :]
    )
    ok = rule & connected
    eligible = tuple(
        (scenes[0][int(k)], scenes[1][int(li)], scenes[2][int(b)], scenes[3][int(w)])
        for k, li, b, w in np.argwhere(ok)
    )
    return Eligibility(
        candidates=n**4,
        fail_rule=int((~rule).sum()),
        split_room=int((rule & ~connected).sum()),
        eligible=eligible,  # argwhere walks indices in order: sorted
        split_rooms=tuple(sorted(split, key=lambda s: int(s.removeprefix("FloorPlan")))),
    )


def sample_order(eligible: Sequence[FloorPlanSet], seed: int) -> list[FloorPlanSet]:
    """The eligible sets shuffled by the seed; a sample of N is the first N (nested in N)."""
    order = sorted(eligible, key=lambda s: tuple(int(x.removeprefix("FloorPlan")) for x in s))
    random.Random(seed).shuffle(order)
    return order


def table1_jobs(
    homes: Sequence[str],
    targets: Sequence[str] = TARGETS,
    prior: str = DEFAULT_PRIOR,
    camera: str = DEFAULT_CAMERA,
    data: Path | None = None,
) -> list[Job]:
    """Every strategy and seed of Table I on each home of the data folder ``data`` (None:
    ``datapaths.data_dir()``): the folder goes with each job to the process that runs it."""
    return [
        table1_job(home, name, seed, targets, prior, camera, data)
        for home in homes
        for name, seeds in STRATEGY_SEEDS
        for seed in seeds
    ]


def per_set(rows: Sequence[Row], home: str) -> dict[str, float]:
    """Per strategy the mean path to discovery (over seeds and searches) and success rate."""
    out: dict[str, float] = {}
    for name in STRATEGIES:
        mine = [r for r in rows if r.home == home and r.strategy == name]
        out[name] = statistics.fmean(discovery(r) for r in mine)
        out[f"{name}_success"] = statistics.fmean(r.success for r in mine)
    return out


def ordering(means: dict[str, float]) -> str:
    """``wpl<rvp<sdp`` style, ``=`` for exact ties."""
    names = sorted(STRATEGIES, key=lambda n: (means[n], STRATEGIES.index(n)))
    text = names[0]
    for a, b in itertools.pairwise(names):
        text += ("=" if means[a] == means[b] else "<") + b
    return text


def paper_order_holds(means: dict[str, float]) -> bool:
    return means["wpl"] <= means["rvp"] < means["sdp"]


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    if n == 0:
        return (math.nan, math.nan)
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return (max(0.0, centre - half), min(1.0, centre + half))


def percentile_of(values: Sequence[float], v: float) -> float:
    """Share of ``values`` ≤ ``v``, in %."""
    return 100.0 * sum(x <= v for x in values) / len(values)


def distribution(values: Sequence[float]) -> dict[str, float]:
    q = np.percentile(np.asarray(values, dtype=float), [5, 25, 50, 75, 95])
    return {
        "mean": statistics.fmean(values),
        "p5": float(q[0]),
        "p25": float(q[1]),
        "median": float(q[2]),
        "p75": float(q[3]),
        "p95": float(q[4]),
        "min": min(values),
        "max": max(values),
    }


def summarise_sets(
    sets: Sequence[dict[str, Any]], paper_set: dict[str, Any] | None
) -> dict[str, Any]:
    n = len(sets)
    dist = {name: distribution([s[name] for s in sets]) for name in STRATEGIES}
    orders = Counter(s["ordering"] for s in sets)
    k = sum(s["paper_order"] for s in sets)
    placed: dict[str, Any] = {
        "paper_figures": {
            name: {
                "value": PAPER_TABLE1[name]["avg"],
                "percentile": percentile_of([s[name] for s in sets], PAPER_TABLE1[name]["avg"]),  # type: ignore[arg-type]
            }
            for name in STRATEGIES
        }
    }
    if paper_set is not None:
        placed["paper_set"] = {
            name: {
                "value": paper_set[name],
                "percentile": percentile_of([s[name] for s in sets], paper_set[name]),
            }
            for name in STRATEGIES
        }
        placed["paper_set"]["ordering"] = paper_set["ordering"]
    return {
        "sets": n,
        "distribution": dist,
        "orderings": dict(orders.most_common()),
        "paper_order": {"count": k, "share": k / n if n else math.nan, "wilson95": wilson(k, n)},
        "pairwise": {
            "wpl<sdp": sum(s["wpl"] < s["sdp"] for s in sets),
            "rvp<sdp": sum(s["rvp"] < s["sdp"] for s in sets),
            "wpl<=rvp": sum(s["wpl"] <= s["rvp"] for s in sets),
        },
        "placed": placed,
    }


def render(summary: dict[str, Any]) -> str:
    s = summary["summary"]
    e = summary["eligibility"]
    n = s["sets"]
    lines = [
        f"Table I over {n} FloorPlan sets (seed {summary['seed']}; {e['eligible']} of "
        f"{e['candidates']} sets eligible: {e['fail_rule']} fail the removal rule, "
        f"{e['split_room']} more have a room in pieces). Path length to discovery (m), per set "
        "the mean over 8 targets × 8 starts (SDP: seeds 0-1); prior "
        f"{summary['prior']}; targets {', '.join(summary['targets'])}.",
        "",
        "| strategy | median | IQR (25–75 %) | 5–95 % | mean | paper (percentile) | "
        "our paper set (percentile) |",
        "|---|---|---|---|---|---|---|",
    ]
    paper_set = s["placed"].get("paper_set")
    for name in STRATEGIES:
        d = s["distribution"][name]
        pf = s["placed"]["paper_figures"][name]
        ours = (
            f"{paper_set[name]['value']:.2f} ({paper_set[name]['percentile']:.0f} %)"
            if paper_set
            else "–"
        )
        lines.append(
            f"| {name.upper()} | {d['median']:.2f} | {d['p25']:.2f}–{d['p75']:.2f} | "
            f"{d['p5']:.2f}–{d['p95']:.2f} | {d['mean']:.2f} | {pf['value']:.2f} "
            f"({pf['percentile']:.0f} %) | {ours} |"
        )
    po = s["paper_order"]
    lo, hi = po["wilson95"]
    lines += [
        "",
        f"The paper's ordering WPL ≤ RVP < SDP: {po['count']} of {n} sets "
        f"({100 * po['share']:.0f} %, 95 % CI {100 * lo:.0f}–{100 * hi:.0f} %)"
        + (f"; our paper set: {paper_set['ordering']}." if paper_set else "."),
        "",
        "| ordering of the per-set means | sets | share |",
        "|---|---|---|",
    ]
    for order, count in s["orderings"].items():
        lines.append(f"| {order} | {count} | {100 * count / n:.0f} % |")
    pw = s["pairwise"]
    lines += [
        "",
        f"Pairwise: WPL < SDP in {pw['wpl<sdp']} of {n}, RVP < SDP in {pw['rvp<sdp']}, "
        f"WPL ≤ RVP in {pw['wpl<=rvp']}.",
        "",
        f"Command: `{summary['command']}` ({summary['searches']} searches; eligibility "
        f"{summary['eligibility_s']} s, build "
        f"{summary['build_s']} s, searches {summary['search_s']} s, "
        f"{summary['per_set_s']} s per set with {summary['workers']} worker(s)).",
    ]
    return "\n".join(lines)


def _set_records(
    homes: Mapping[str, FloorPlanSet],
    rows: Sequence[Row],
    sample: Sequence[FloorPlanSet],
    paper_name: str,
) -> list[dict[str, Any]]:
    """One record per home of the run (a FloorPlan set): its scenes, whether it was sampled or
    is the paper's set, its per-strategy means and their ordering (``table1_sets.csv``)."""
    records = []
    for name, scenes in homes.items():
        means = per_set(rows, name)
        records.append(
            {
                "home": name,
                "kitchen": scenes[0],
                "living": scenes[1],
                "bedroom": scenes[2],
                "bathroom": scenes[3],
                "sampled": name in {set_name(s) for s in sample},
                "paper_set": name == paper_name,
                **{k: round(v, 4) for k, v in means.items()},
                "ordering": ordering(means),
                "paper_order": paper_order_holds(means),
            }
        )
    return records


def _command(
    out: Path,
    source: Path,
    sets: int,
    seed: int,
    workers: int,
    targets: Sequence[str],
    prior: str,
    camera: str,
) -> str:
    """The ``bench table1`` command that reproduces a run (options at their default left out)."""
    command = (
        f"objsearch bench table1 --sets {sets} --seed {seed} --source {source} --out {out} "
        f"--workers {workers}"
    )
    if tuple(targets) != TARGETS:
        command += f" --targets {','.join(targets)}"
    if prior != DEFAULT_PRIOR:
        command += f" --prior {prior}"
    if camera != DEFAULT_CAMERA:
        command += f" --camera {camera}"
    return command


def run_table1_sets(
    out: Path,
    *,
    source: Path,
    sets: int,
    seed: int = DEFAULT_SEED,
    workers: int = 1,
    targets: Sequence[str] = TARGETS,
    with_paper_set: bool = True,
    progress: bool = True,
    prior: str = DEFAULT_PRIOR,
    camera: str = DEFAULT_CAMERA,
) -> dict[str, Any]:
    def say(msg: str) -> None:
        if progress:  # a stage line, on stderr: stdout holds the tables
            print(msg, file=sys.stderr, flush=True)

    out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    elig = eligibility(source)
    elig_s = time.perf_counter() - started
    started = time.perf_counter()
    if sets > len(elig.eligible):
        raise ObjsearchError(f"--sets {sets}: only {len(elig.eligible)} eligible FloorPlan sets")
    sample = sample_order(elig.eligible, seed)[:sets]
    homes = {set_name(s): s for s in sample}
    paper_name = set_name(PAPER_HOME)
    if with_paper_set:
        homes.setdefault(paper_name, PAPER_HOME)
    say(f"{len(elig.eligible)} eligible sets; building {len(homes)} homes")
    data = out / "data"
    # The sample is every set the removal rule admits (sets with a room in pieces are not
    # eligible); a room that lost grid points stays in it, recorded in the data's PROVENANCE.md.
    build_data(source, data, homes=homes, accept=[LOST_GRID_POINTS, EMPTY_ROOMS])
    missing = [h for h in homes if not (data / "scenarios" / f"table1-{h}.json").is_file()]
    if missing:  # the per-room rule and the build's rule disagree: a bug, not a skip
        raise ObjsearchError(f"the build derived no Table I scenario for {', '.join(missing)}")
    build_s = time.perf_counter() - started
    started = time.perf_counter()
    # The searches read the build in ``data``, handed down with each job (never set as
    # $OBJSEARCH_DATA); home contexts made before are forgotten, before and after, as the build
    # may have written other homes under the same names into the same folder.
    jobs = table1_jobs(list(homes), targets, prior, camera, data)
    clear_contexts()
    try:
        rows = run_jobs(jobs, workers=workers, progress=progress, label="bench table1")
        left_out = unseeable(jobs)
    finally:
        clear_contexts()
    search_s = time.perf_counter() - started
    write_rows(rows, out, "table1_trials")
    records = _set_records(homes, rows, sample, paper_name)
    import polars as pl

    pl.DataFrame(records).write_csv(out / "table1_sets.csv")
    sampled = [r for r in records if r["sampled"]]
    paper_rec = next((r for r in records if r["paper_set"]), None)
    summary: dict[str, Any] = {
        "command": _command(out, source, sets, seed, workers, targets, prior, camera),
        "seed": seed,
        "sets": sets,
        "workers": workers,
        "prior": prior,
        "targets": list(targets),
        "strategy_seeds": {name: list(s) for name, s in STRATEGY_SEEDS},
        "eligibility": {
            "candidates": elig.candidates,
            "fail_rule": elig.fail_rule,
            "split_room": elig.split_room,
            "eligible": len(elig.eligible),
            "split_rooms": list(elig.split_rooms),
        },
        "sample": [set_name(s) for s in sample],
        "searches": len(rows),
        "camera": camera,
        "unseeable": left_out,
        "eligibility_s": round(elig_s, 1),
        "build_s": round(build_s, 1),
        "search_s": round(search_s, 1),
        "per_set_s": round((build_s + search_s) / len(homes), 2),
        "summary": summarise_sets(sampled, paper_rec),
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    (out / "summary.md").write_text(render(summary) + "\n", encoding="utf-8")
    return summary


__all__ = ["run_table1_sets"]
