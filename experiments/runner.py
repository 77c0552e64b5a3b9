"""Run searches for experiments: one job = one strategy, update mode and seed on one home and one
placement source, searched on one event log; jobs run in parallel processes."""

from __future__ import annotations

import json
import multiprocessing
import sys
import tempfile
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

from tqdm import tqdm

from objsearch.agent.catalogue import STORE
from objsearch.agent.geometry import Point
from objsearch.agent.scene_graph import UpdateMode
from objsearch.agent.session import load_context
from objsearch.agent.strategies import BELIEF, COVER_SUFFIX, RunSpec
from objsearch.events.log_read import read_log
from objsearch.experiments.calibration import Forecast, forecasts
from objsearch.experiments.decompose import Excess, decompose
from objsearch.experiments.failure_log import failure_causes
from objsearch.sim.longterm import TARGET_ORDER, Trial, run_schedule, scenes_of
from objsearch.sim.seeable import seeable_scenes
from objsearch.sim.world import DEFAULT_CAMERA

TARGETS = TARGET_ORDER


@dataclass(frozen=True)
class Job:
    """``placements``: ``table1`` (the paper's Table I scene), ``table2`` (its Table II schedule),
    ``stats-<seed>`` (a schedule drawn from AI2-THOR placement statistics with that seed) or
    ``rearr-<seed>`` (one taken from real AI2-THOR rearrangement episodes, ``sim/schedule_names.py``)."""

    experiment: str
    home: str
    placements: str
    strategy: str
    update_mode: str
    seed: int = 0
    targets: tuple[str, ...] = TARGETS
    scenes: tuple[int, ...] | None = None
    log_dir: str | None = None
    keep_routes: bool = False
    prior: str = "vg-cooccurrence"
    #: Search each target from this many seeded start points per scene (None: from every start).
    starts_per_search: int | None = None
    camera: str = DEFAULT_CAMERA
    #: The simulated detector's parameters as JSON (``params.perception``); None: perfect.
    perception: str | None = None
    #: The simulated localisation's parameters as JSON (``params.localisation``); None: perfect.
    localisation: str | None = None
    #: From this scene on the robot runs in a new map (``params.new_map_day``); None: never.
    new_map_day: int | None = None
    #: The new map's frame: the old one's (``same``) or moved (``params.new_map_frame``).
    new_map_frame: str = "same"
    #: The data folder the home and everything the run reads come from (None:
    #: ``datapaths.data_dir()``): ``bench table1``'s own build, handed to its workers.
    data: Path | None = None


@dataclass(frozen=True)
class Row:
    experiment: str
    home: str
    placements: str
    strategy: str
    update_mode: str
    seed: int
    scene: int
    target: str
    start: str
    success: bool
    path_length: float
    oracle_length: float
    task_id: str
    route: tuple[tuple[float, float], ...] = field(default=(), compare=False)
    #: The paper's path length: metres to the detection (the whole path if never found);
    #: ``path_length`` adds the approach to the target's viewpoint.
    path_to_discovery: float | None = None
    #: Where the excess over the oracle went (experiments/decompose.py); None for a failed search.
    wrong_rooms_m: float | None = None
    start_room_m: float | None = None
    right_room_m: float | None = None
    approach_m: float | None = None
    #: The belief's forecast at the start of the search (experiments/calibration.py, whatever the
    #: run's strategy); None for a search that did not find its target.
    belief_top_p: float | None = None
    belief_top_hit: bool | None = None
    belief_p_found: float | None = None
    belief_brier: float | None = None
    #: The agent said found, on a modelled detector's false positive or confusion (then
    #: ``success`` is False).
    false_found: bool = False
    #: The probabilities the forecast gave every other place, space-separated (CSV holds no
    #: lists): with ``belief_p_found``, every (search, place) prediction (calibration.place_pairs).
    belief_others: str | None = None
    #: Why a failed search failed, from its log (experiments/failure_log.py); None otherwise.
    failure: str | None = None

    def record(self) -> dict[str, object]:
        d = asdict(self)
        d.pop("route")
        return d


def run_job(job: Job) -> list[Row]:
    """Every target from every start in every scene, in that order, on one log."""
    ctx = load_context(job.home, job.data)
    spec = RunSpec.of(
        job.home,
        ctx.home.digest,
        job.strategy,
        seed=job.seed,
        update_mode=UpdateMode(job.update_mode),
        schedule=job.placements,
        prior=job.prior,
        params={
            "camera": job.camera,
            **({"perception": json.loads(job.perception)} if job.perception else {}),
            **({"localisation": json.loads(job.localisation)} if job.localisation else {}),
            **({"new_map_day": job.new_map_day} if job.new_map_day is not None else {}),
            **({"new_map_frame": job.new_map_frame} if job.new_map_frame != "same" else {}),
        },
    )
    scenes = scenes_of(job.home, job.placements, upto=_last_scene(job), data=job.data)
    with tempfile.TemporaryDirectory(prefix="objsearch-bench-") as tmp:
        trials = run_schedule(
            Path(job.log_dir) if job.log_dir else Path(tmp),
            spec,
            targets=job.targets,
            scenes=job.scenes,
            starts_per_search=job.starts_per_search,
            placements=scenes,
            skip_absent_targets=True,
            keep_routes=job.keep_routes,
            data=job.data,
        )
        log = Path(job.log_dir) if job.log_dir else Path(tmp)
        parts = decompose(read_log(log, store=STORE), ctx.navmap)
        # The run's own belief when it has one that knows the hour, else the time-blind one.
        timed = spec.relations.model in ("routine-belief", "routine-pooled")
        forecast = forecasts(
            read_log(log, store=STORE), spec.relations if timed else BELIEF, ctx.data
        )
        failed = [t.task_id for t in trials if not t.success]
        causes = failure_causes(read_log(log, store=STORE), scenes, failed) if failed else {}
    return [
        _row(job, t, parts.get(t.task_id), forecast.get(t.task_id), causes.get(t.task_id))
        for t in trials
    ]


def _row(
    job: Job,
    t: Trial,
    excess: Excess | None,
    forecast: Forecast | None = None,
    failure: str | None = None,
) -> Row:
    return Row(
        job.experiment,
        job.home,
        job.placements,
        job.strategy,
        job.update_mode,
        job.seed,
        t.scene,
        t.target,
        t.start,
        t.success,
        round(t.path_length, 4),
        round(t.oracle_length, 4),
        t.task_id,
        tuple((p.x, p.y) for p in t.route),
        path_to_discovery=None if t.path_to_discovery is None else round(t.path_to_discovery, 4),
        wrong_rooms_m=None if excess is None else round(excess.wrong_rooms, 4),
        start_room_m=None if excess is None else round(excess.start_room, 4),
        right_room_m=None if excess is None else round(excess.right_room(t.oracle_length), 4),
        approach_m=None if excess is None else round(excess.approach, 4),
        belief_top_p=None if forecast is None else round(forecast.top_p, 6),
        belief_top_hit=None if forecast is None else forecast.top_hit,
        belief_p_found=None if forecast is None else round(forecast.p_found, 6),
        belief_brier=None if forecast is None else round(forecast.brier, 6),
        false_found=t.false_found,
        belief_others=None if forecast is None else " ".join(f"{p:.4g}" for p in forecast.others),
        failure=failure,
    )


def _last_scene(job: Job) -> int | None:
    return max(job.scenes) if job.scenes else None


def _count(job: Job) -> int:
    ctx = load_context(job.home, job.data)
    upto = _last_scene(job)
    scenes, _ = seeable_scenes(
        ctx.home, scenes_of(job.home, job.placements, upto=upto, data=job.data), job.data
    )
    wanted = [s for s in job.scenes or sorted(scenes) if s in scenes]  # run_job names the others
    starts = len(ctx.home.starts)
    if job.starts_per_search:
        starts = min(starts, job.starts_per_search)
    return sum(
        starts * sum(1 for t in job.targets if t in {p.cls for p in scenes[s].values()})
        for s in wanted
    )


def unseeable(jobs: Sequence[Job]) -> list[dict[str, object]]:
    """The placements of the jobs' scenes no viewpoint can see, once per (home, placement
    source): ``run_schedule`` leaves them out of their scenes, and the bench reports them."""
    out: list[dict[str, object]] = []
    runs = {(j.home, j.placements, j.scenes, j.data) for j in jobs}
    for home, source, wanted, data in sorted(runs, key=str):
        ctx = load_context(home, data)
        upto = max(wanted) if wanted else None
        _, dropped = seeable_scenes(ctx.home, scenes_of(home, source, upto=upto, data=data), data)
        out += [
            {"placements": source, **asdict(u)}
            for u in dropped
            if wanted is None or u.scene in wanted
        ]
    return out


def run_jobs(
    jobs: Sequence[Job],
    *,
    workers: int = 1,
    progress: bool = True,
    label: str = "searches",
) -> list[Row]:
    """Run jobs (in ``workers`` processes); rows come back in job order whatever finishes first.
    ``progress``: a bar on a terminal; where stderr is none (a pipe, a log) a line at each tenth
    of the searches, ``bench homes: 330 of 3300 searches (41 s)``, so an hour's run is not silent
    there (DEVELOPERS.md, "Progress")."""
    total = sum(_count(j) for j in jobs)
    done: dict[int, list[Row]] = {}
    lines = _PipeLines(label, total) if progress and not sys.stderr.isatty() else None
    # disable=None: drawn on a terminal only, never into a pipe or log (DEVELOPERS.md).
    off = None if progress else True
    with tqdm(total=total, disable=off, file=sys.stderr, unit="search", desc=label) as bar:
        if workers <= 1 or len(jobs) <= 1:
            for i, job in enumerate(jobs):
                done[i] = run_job(job)
                bar.update(len(done[i]))
                if lines:
                    lines.add(len(done[i]))
        else:
            ctx = multiprocessing.get_context("fork" if sys.platform == "linux" else "spawn")
            with ctx.Pool(min(workers, len(jobs))) as pool:
                # Longest jobs first so the last one to finish is short.
                order = sorted(range(len(jobs)), key=lambda i: -_count(jobs[i]))
                for i, rows in pool.imap_unordered(_run_indexed, [(i, jobs[i]) for i in order]):
                    done[i] = rows
                    bar.update(len(rows))
                    if lines:
                        lines.add(len(rows))
    return [row for i in range(len(jobs)) for row in done[i]]


class _PipeLines:
    """A line on stderr each time the searches done pass another tenth of ``total``."""

    STEPS = 10

    def __init__(self, label: str, total: int) -> None:
        self.label, self.total, self.done, self.step = label, total, 0, 0
        self.started = time.monotonic()

    def add(self, searches: int) -> None:
        self.done += searches
        step = self.done * self.STEPS // max(self.total, 1)
        if step > self.step:
            self.step = step
            elapsed = time.monotonic() - self.started
            print(
                f"{self.label}: {self.done} of {self.total} searches ({elapsed:.0f} s)",
                file=sys.stderr,
                flush=True,
            )


def _run_indexed(item: tuple[int, Job]) -> tuple[int, list[Row]]:
    return item[0], run_job(item[1])


def to_frame(rows: Iterable[Row]) -> object:
    """The rows as a polars DataFrame (typed as object to keep polars out of the signatures)."""
    import polars as pl

    return pl.DataFrame([r.record() for r in rows], infer_schema_length=None)


def write_rows(rows: Sequence[Row], out: Path, stem: str) -> tuple[Path, Path]:
    """Parquet and CSV of the rows (same content)."""
    import polars as pl

    # Every row read for the schema: a column empty in the first rows (``failure``: most searches
    # succeed) would otherwise be typed null and refuse its first value.
    frame = pl.DataFrame([r.record() for r in rows], infer_schema_length=None)
    parquet, csv = out / f"{stem}.parquet", out / f"{stem}.csv"
    frame.write_parquet(parquet)
    frame.write_csv(csv)
    return parquet, csv


def read_rows(parquet: Path) -> list[Row]:
    """The rows :func:`write_rows` wrote (without routes, which it does not write)."""
    import polars as pl

    return [Row(**rec) for rec in pl.read_parquet(parquet).to_dicts()]


def inspection_suffix(strategy: str) -> str:
    """:data:`COVER_SUFFIX` for a strategy named ``NAME+cover``, else ``""``."""
    return COVER_SUFFIX if strategy.endswith(COVER_SUFFIX) else ""


def read_output(folder: Path) -> list[Row]:
    """The searches of one ``bench homes`` output folder, each under its strategy's full name: a
    cover run's is ``NAME+cover``, so every report pairs it with the same strategy's run without
    it instead of mixing the two. Outputs written before the rows carried the suffix said
    ``--inspection cover`` in their summary.json only; their rows get it here."""
    summary_path = folder / "summary.json"
    summary = json.loads(summary_path.read_text(encoding="utf-8")) if summary_path.is_file() else {}
    rows = read_rows(folder / str(summary.get("files", {}).get("parquet", "homes_trials.parquet")))
    if summary.get("inspection") == "cover":
        return [
            r if inspection_suffix(r.strategy) else replace(r, strategy=r.strategy + COVER_SUFFIX)
            for r in rows
        ]
    return rows


def command_line(words: str, options: Mapping[str, object]) -> str:
    """``words`` and its options as typed (``--name value``; lists comma-joined; None and
    False left out, True as a bare flag): what a summary records so a figure can be rerun."""
    parts = [words]
    for name, value in options.items():
        if value is None or value is False:
            continue
        flag = "--" + name.replace("_", "-")
        if value is True:
            parts.append(flag)
        elif isinstance(value, list | tuple):
            parts.append(f"{flag} {','.join(str(v) for v in value)}")
        else:
            parts.append(f"{flag} {value}")
    return " ".join(parts)


def route_points(rows: Sequence[Row]) -> Mapping[str, list[Point]]:
    return {r.task_id: [Point(x, y) for x, y in r.route] for r in rows if r.route}
