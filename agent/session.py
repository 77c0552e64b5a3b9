"""An agent bound to its event log: the on-robot process's state is whatever the log folds to."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

from objsearch.agent.categories import Vocabulary, read_json
from objsearch.agent.home import Home, load_home
from objsearch.agent.navmap import NavigationMap
from objsearch.agent.planner import StopPlanner
from objsearch.agent.policy import Projection, Recorder, SearchAgent, SearchConfig, SearchResult
from objsearch.agent.relations import RelationModel
from objsearch.agent.scene_graph import SceneGraphProjection, UpdateMode, seed_relations
from objsearch.agent.semmap import SemanticMap
from objsearch.agent.world import World
from objsearch.events import EventLog, read_log
from objsearch.paths import data_dir

PRIOR_FILE = "priors/visual_genome.json"


@dataclass(frozen=True)
class HomeContext:
    """What the agent knows of a home before any search: maps and the vocabulary."""

    home: Home
    vocabulary: Vocabulary
    navmap: NavigationMap
    semmap: SemanticMap


@cache
def load_context(home_name: str) -> HomeContext:
    home = load_home(home_name)
    navmap = NavigationMap.from_home(home)
    return HomeContext(home, Vocabulary.load(), navmap, SemanticMap.from_home(home, navmap))


def prior_values(vocabulary: Vocabulary) -> tuple[str, list[dict[str, Any]]]:
    path = data_dir() / PRIOR_FILE
    prior = read_json(path, "the Visual Genome prior")
    relations = seed_relations(prior, vocabulary)
    values = [
        {"dynamic": d, "static": s, "rel": round(v, 12)} for (d, s), v in sorted(relations.items())
    ]
    return str(prior.get("source", PRIOR_FILE)), values


class Session:
    """Opens (or continues) a log, folds it into the scene graph and runs searches on top of it."""

    def __init__(
        self,
        ctx: HomeContext,
        log_dir: Path,
        config: SearchConfig,
        update_mode: UpdateMode,
        *,
        stream: str = "robot",
        params: dict[str, Any] | None = None,
        wall_clock: Callable[[], int] | None = None,
        observers: Sequence[Projection] = (),
        graph: RelationModel | None = None,
        planner: StopPlanner | None = None,
    ) -> None:
        """``observers`` see every event right after it is appended (e.g. the on-robot agent
        publishes each one on its events topic). ``graph`` is the relation model to fold the log
        into (default: the paper's Eq. 4) and ``planner`` the stop planner (default: the paper's
        for ``config.method``)."""
        self.ctx = ctx
        # First: the writer's lock guards the fold too. A fixed wall clock gives byte-identical
        # logs (golden logs); by default recorded_at_ns is the real time of each append.
        self.log = (
            EventLog.open(log_dir, stream)
            if wall_clock is None
            else EventLog.open(log_dir, stream, wall_clock=wall_clock)
        )
        self.graph: RelationModel = graph if graph is not None else SceneGraphProjection()
        #: The log's clock so far; a continued log must not run backwards.
        self.resume_time_ns = 0
        seeded = False
        for event in read_log(log_dir):
            self.graph.apply(event)
            self.resume_time_ns = event.time_ns
            seeded = seeded or event.type == "scene_graph_seeded"
        # Everything that can fail on bad data is read before the first append: a run that
        # cannot start leaves the log as it was.
        prior = None if seeded else prior_values(ctx.vocabulary)
        self.recorder = Recorder(self.log, [self.graph, *observers])
        self.recorder.record(
            "run_started",
            {
                "home": ctx.home.name,
                "home_digest": ctx.home.digest,
                "method": config.method.value,
                "alpha": config.alpha,
                "update_mode": update_mode.value,
                "seed": config.seed,
                "params": {"support_radius": config.support_radius, **(params or {})},
            },
            time_ns=self.resume_time_ns,
        )
        if prior is not None:
            source, values = prior
            self.recorder.record(
                "scene_graph_seeded",
                {"source": source, "values": values},
                time_ns=self.resume_time_ns,
            )
        self.agent = SearchAgent(
            ctx.navmap, ctx.semmap, ctx.vocabulary, self.graph, self.recorder, config, planner
        )

    def search(
        self, world: World, target: str, start: str, *, scene: int | None = None
    ) -> SearchResult:
        """One task; its events become durable together when it ends (one fsync per task)."""
        with self.log.batch():
            return self.agent.search(world, target, start, scene=scene)

    def close(self) -> None:
        self.log.close()


@contextlib.contextmanager
def open_session(
    home_name: str,
    log_dir: Path,
    config: SearchConfig,
    update_mode: UpdateMode,
    **kwargs: Any,
) -> Iterator[Session]:
    session = Session(load_context(home_name), log_dir, config, update_mode, **kwargs)
    try:
        yield session
    finally:
        session.close()
