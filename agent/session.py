"""An agent bound to its event log: the on-robot process's state is whatever the log folds to."""

from __future__ import annotations

import contextlib
import json
import logging
import time
import uuid
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any, Unpack

import msgspec

from objsearch.agent.catalogue import STORE, SceneGraphSeeded, SeedValue, TaskAborted
from objsearch.agent.categories import Vocabulary, read_json
from objsearch.agent.datapaths import data_dir, data_key
from objsearch.agent.errors import ObjsearchError
from objsearch.agent.home import Home, load_home
from objsearch.agent.map_frames import InFrame, Registration, ReportsStatics, register
from objsearch.agent.maps import DEFAULT_MAP, next_map
from objsearch.agent.navmap import NavigationMap
from objsearch.agent.policy import SearchAgent, SearchOptions
from objsearch.agent.recorder import Recorder
from objsearch.agent.relations import RelationModel
from objsearch.agent.results import SearchResult
from objsearch.agent.scene_graph import seed_relations
from objsearch.agent.semmap import SemanticMap
from objsearch.agent.state import AgentState
from objsearch.agent.strategies import AGENT_MODELS, RelationModels, RunSpec
from objsearch.agent.world import World
from objsearch.events import CorruptLogError, EventLog
from objsearch.events.hub import Member, ProjectionHub, restore_hub
from objsearch.events.projection import EventObserver
from objsearch.events.snapshot import save_snapshot

_log = logging.getLogger(__name__)

PRIOR_FILE = "priors/visual_genome.json"
#: The readings of Eq. 2 ``objsearch data build`` writes (pipeline/vg_prior.py; docs/paper-readings.md).
PRIOR_FILES = {
    "vg-cooccurrence": PRIOR_FILE,
    "vg-single-name": "priors/vg_single_name.json",
    "vg-hoz-masked": "priors/vg_hoz_masked.json",
}
DEFAULT_PRIOR = "vg-cooccurrence"
# uuid5(NAMESPACE_URL, "urn:objsearch:runs"); fixed forever, like the event id namespace.
RUN_ID_NAMESPACE = uuid.uuid5(uuid.NAMESPACE_URL, "urn:objsearch:runs")
#: The agent's own state in a session's projection hub.
AGENT = "agent"


@dataclass(frozen=True)
class HomeContext:
    """What the agent knows of a home before any search: maps and the vocabulary."""

    home: Home
    vocabulary: Vocabulary
    navmap: NavigationMap
    semmap: SemanticMap
    #: The data folder the home and vocabulary were read from (:func:`load_context`: resolved),
    #: where a run on this home reads the rest of what it needs (the prior, the belief's home,
    #: the class sizes); None: ``datapaths.data_dir()``.
    data: Path | None = None


def load_context(home_name: str, data: Path | None = None) -> HomeContext:
    """Home ``home_name`` of the data folder ``data`` (None: ``datapaths.data_dir()``), its maps
    and the folder's vocabulary; made once per (resolved folder, home) in a process."""
    return _context(home_name, data_key(data))


def clear_contexts() -> None:
    """Forget every home context made (a benchmark's cold start: no path of an earlier run)."""
    _context.cache_clear()


@cache
def _context(home_name: str, folder: Path) -> HomeContext:
    home = load_home(home_name, folder)
    navmap = NavigationMap.from_home(home)
    vocabulary = Vocabulary.load(data=folder)
    return HomeContext(home, vocabulary, navmap, SemanticMap.from_home(home, navmap), folder)


def prior_file(name: str) -> str:
    try:
        return PRIOR_FILES[name]
    except KeyError:
        raise ObjsearchError(
            f"unknown prior {name!r}; choose from {', '.join(PRIOR_FILES)}"
        ) from None


def prior_values(
    vocabulary: Vocabulary, name: str = DEFAULT_PRIOR, data: Path | None = None
) -> SceneGraphSeeded:
    """The ``scene_graph_seeded`` record of a named prior, read from the data folder ``data``
    (None: ``datapaths.data_dir()``). Its source names the reading of Eq. 2
    (``vg-hoz-masked: vg/VSGM/…``), except for the default, which keeps the source string older
    logs carry; the values are in the log, so nothing re-reads the file."""
    rel_path = prior_file(name)
    prior = read_json(data_dir(data) / rel_path, f"the {name} prior")
    relations = seed_relations(prior, vocabulary)
    values = tuple(
        SeedValue(dynamic=d, static=s, rel=round(v, 12)) for (d, s), v in sorted(relations.items())
    )
    source = str(prior.get("source", rel_path))
    return SceneGraphSeeded(
        source=source if name == DEFAULT_PRIOR else f"{name}: {source}", values=values
    )


def prior_of_source(source: str) -> str:
    """The name of the prior a ``scene_graph_seeded`` source was written by (:func:`prior_values`:
    every prior but the default prefixes its name)."""
    for name in PRIOR_FILES:
        if name != DEFAULT_PRIOR and source.startswith(f"{name}: "):
            return name
    return DEFAULT_PRIOR


def derived_run_id(stream: str, spec: RunSpec, inputs: Mapping[str, Any] | None = None) -> str:
    """A run id that is a function of everything that decides the run's facts: the stream, the
    spec (its seed included) and ``inputs`` — what it is asked to do (the searches: targets,
    starts, scenes). A seeded simulation writes the same log every time; two runs asked for
    different things never share ids."""
    doc: dict[str, Any] = {"stream": stream, **spec.payload()}
    if inputs:
        doc["inputs"] = dict(inputs)
    if spec.prior != DEFAULT_PRIOR:  # the default leaves the ids of existing logs as they were
        doc["prior"] = spec.prior
    text = json.dumps(doc, sort_keys=True, separators=(",", ":"))
    return str(uuid.uuid5(RUN_ID_NAMESPACE, text))


class Session:
    """An agent bound to its log: opened (restored from the log, once), then runs started on it.

    :meth:`open` locks the log, restores its projection hub — the :class:`AgentState` and any
    other projection of the process (the ``where`` memory), from one snapshot when one is given
    and trusted, else by one fold of the log — and closes a task a crash left open with a
    ``task_aborted`` event. :meth:`start_run` records ``run_started`` (and the prior, the first
    time) and builds the agent from the spec; :meth:`start` does both.
    """

    def __init__(
        self,
        ctx: HomeContext,
        log: EventLog,
        hub: ProjectionHub,
        observers: Sequence[EventObserver],
        snapshot_dir: Path | None,
    ) -> None:
        # Private: use open() or start().
        self.ctx = ctx
        self.log = log
        self.hub = hub
        state = hub[AGENT]
        assert isinstance(state, AgentState)
        self.state = state
        self.snapshot_dir = snapshot_dir
        self.recorder = Recorder(log, [hub, *observers], time_floor_ns=log.last_time_ns)
        self._agent: SearchAgent | None = None
        #: Each map registered to the working frame this session (agent/map_frames.py).
        self.registrations: dict[str, Registration] = {}

    @classmethod
    def open(
        cls,
        ctx: HomeContext,
        log_dir: Path,
        *,
        stream: str = "robot",
        run_id: str | None = None,
        wall_clock: Callable[[], int] | None = None,
        observers: Sequence[EventObserver] = (),
        projections: Sequence[Member[Any]] = (),
        views: Callable[[AgentState], Sequence[EventObserver]] | None = None,
        snapshot_dir: Path | None = None,
        models: RelationModels = AGENT_MODELS,
    ) -> Session:
        """Open (or create) the log at ``log_dir`` and restore what the agent knew.

        ``run_id`` names a log this call creates (see :func:`derived_run_id`); a fixed
        ``wall_clock`` gives byte-identical logs (golden logs). ``projections``: more projections
        of the log the process keeps, restored and fed with the agent's state (the hub's
        ``agent``) from the same snapshot and the same read. ``views``: observers that read the
        restored state instead of folding the log themselves (the live view), told of each
        event after the hub's projections; ``observers`` are told of each appended event after
        those. With ``snapshot_dir``, the hub is restored from its snapshot there (if trusted)
        plus the events after it, and a new snapshot is written when the session closes.
        """
        log = EventLog.open(
            log_dir,
            stream,
            run_id=run_id,
            wall_clock=wall_clock if wall_clock is not None else time.time_ns,
            # With a snapshot, a restart checks the prefix by its seals (CRC of whole ranges) and
            # parses only what came after the last clean close; nothing acknowledged goes
            # unchecked before the first append.
            verify="all" if snapshot_dir is None else "sealed",
            store=STORE,
        )
        try:
            agent: Member[AgentState] = Member(
                AGENT,
                lambda: AgentState(models=models, data=ctx.data),
                lambda doc, seq: AgentState.from_snapshot(doc, seq, models, ctx.data),
            )
            hub, _ = restore_hub(
                log_dir, [agent, *projections], snapshot_dir=snapshot_dir, store=STORE
            )
            session = cls(ctx, log, hub, observers, snapshot_dir)
            for view in views(session.state) if views is not None else ():
                hub.follow(view)
            session._close_open_task()
        except BaseException:
            log.close()
            raise
        return session

    @classmethod
    def start(
        cls,
        ctx: HomeContext,
        log_dir: Path,
        spec: RunSpec,
        *,
        stream: str = "robot",
        run_id: str | None = None,
        inputs: Mapping[str, Any] | None = None,
        new_map: bool = False,
        **kwargs: Any,
    ) -> Session:
        """:meth:`open` then :meth:`start_run` (in a new map with ``new_map``); a new log's run id
        is derived from ``spec`` and ``inputs`` (what the run will be asked to do) unless
        ``run_id`` is given."""
        chosen = run_id if run_id is not None else derived_run_id(stream, spec, inputs)
        session = cls.open(ctx, log_dir, stream=stream, run_id=chosen, **kwargs)
        try:
            session.start_run(spec, new_map=new_map)
        except BaseException:
            session.close()
            raise
        return session

    @property
    def resume_time_ns(self) -> int:
        """The log's clock so far: a continued log must not run backwards."""
        return self.log.last_time_ns

    @property
    def graph(self) -> RelationModel:
        return self.state.graph()

    @property
    def agent(self) -> SearchAgent:
        if self._agent is None:
            raise ObjsearchError("no run started in this session: call start_run(spec) first")
        return self._agent

    def start_run(self, spec: RunSpec, *, new_map: bool = False) -> None:
        """Record ``run_started`` (and, the first time, the Visual Genome prior) and build the
        agent from ``spec``. A log's relation model is fixed by its first run.

        The run is in the map ``spec`` names (``params.map``); naming none, in the map of the
        log's latest run; with ``new_map``, in the map after it (agent/maps.py)."""
        current = self.state.maps.current
        if new_map:
            spec = spec.with_changes(
                params={**spec.params, "map": next_map(current or DEFAULT_MAP)}
            )
        elif "map" not in spec.params and current not in (None, DEFAULT_MAP):
            spec = spec.with_changes(params={**spec.params, "map": current})
        first = self.state.first_run
        if first is not None and first.relations != spec.relations:
            raise ObjsearchError(
                f"this log's memory is folded by {first.relations.model} "
                f"({first.strategy}); a {spec.strategy} run ({spec.relations.model}) needs a new log"
            )
        seeded = self.state.seeded_source
        if seeded is not None and prior_of_source(seeded) != spec.prior:
            # The seed is recorded once, by the first run; a later run with another prior would
            # silently plan with the first one's values.
            raise ObjsearchError(
                f"this log's scene graph was seeded with the {prior_of_source(seeded)} prior "
                f"({seeded}); a run with the {spec.prior} prior needs a new log"
            )
        # Everything that can fail on bad data is read before the first append: a run that
        # cannot start leaves the log as it was.
        prior = (
            None
            if self.state.seeded
            else prior_values(self.ctx.vocabulary, spec.prior, self.ctx.data)
        )
        at = self.resume_time_ns
        started = spec.record()
        if self.log.run_id is not None:
            # The log's run id, so a reader holding only some events (a split bag's piece) can
            # prove which run they belong to: event ids are uuid5(run id, seq).
            started = msgspec.structs.replace(
                started, params={**started.params, "run_id": self.log.run_id}
            )
        self.recorder.emit(started, time_ns=at)
        if prior is not None:
            self.recorder.emit(prior, time_ns=at)
        ctx = self.ctx
        self._agent = SearchAgent(
            ctx.navmap,
            ctx.semmap,
            ctx.vocabulary,
            self.state.graph(),
            self.recorder,
            spec.config(),
            spec.stop_planner(),
            next_task_id=self.state.tasks.next_task_id,
            data=ctx.data,
        )
        # The distances between the home's stops, built here, once per run (a new map id is a
        # new run), so that no search's first decision waits for them.
        _ = self._agent.stop_table

    def _close_open_task(self) -> None:
        open_task = self.state.tasks.open
        if open_task is None:
            return
        self.recorder.emit(
            TaskAborted(
                target=open_task.target, reason="restart", path_length=round(open_task.metres, 4)
            ),
            time_ns=self.resume_time_ns,
            task_id=open_task.task_id,
        )

    def search(
        self, world: World, target: str, start: str, **options: Unpack[SearchOptions]
    ) -> SearchResult:
        """One task; its events become durable together when it ends (one fsync per task).
        ``options``: what its ``task_started`` records (:class:`SearchOptions`).

        A world that says where its map puts the statics (a new map with a frame of its own,
        :class:`~objsearch.agent.map_frames.ReportsStatics`) is registered to the working frame
        once per map and read through that registration: its coordinates are re-anchored to the
        frame of the agent's maps and memory before the agent sees them."""
        if isinstance(world, ReportsStatics):
            world = self._registered(world)
        with self.log.batch():
            return self.agent.search(world, target, start, **options)

    def _registered(self, world: ReportsStatics) -> World:
        current = self.state.maps.current or DEFAULT_MAP
        registration = self.registrations.get(current)
        if registration is None:
            registration = register(self.ctx.semmap, world.mapped_statics())
            self.registrations[current] = registration
            _log.info("%s registered to the working frame: %s", current, registration.params())
        return InFrame(world, registration.to_working, outer=self.ctx.navmap)

    def close(self) -> None:
        try:
            if self.snapshot_dir is not None and not self.log.closed and self.hub.last_seq:
                try:
                    save_snapshot(self.snapshot_dir, self.hub, log=self.log, store=self.log.store)
                except CorruptLogError:
                    raise  # the log itself is damaged: that is the error, not a missing snapshot
                except (ObjsearchError, OSError, ValueError) as exc:
                    # The log is the record; a missing snapshot only makes the next start fold it.
                    _log.warning("snapshot not written (%s); the next start folds the log", exc)
        finally:
            self.log.close()


@contextlib.contextmanager
def open_session(home_name: str, log_dir: Path, spec: RunSpec, **kwargs: Any) -> Iterator[Session]:
    session = Session.start(load_context(home_name), log_dir, spec, **kwargs)
    try:
        yield session
    finally:
        session.close()
