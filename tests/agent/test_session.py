"""End to end: the agent searching the simulated paper home and writing its log."""

from __future__ import annotations

import itertools
from pathlib import Path

import msgspec
import pytest

from objsearch.agent.catalogue import STORE
from objsearch.agent.categories import Vocabulary
from objsearch.agent.errors import ObjsearchError
from objsearch.agent.home import load_home
from objsearch.agent.navmap import NavigationMap
from objsearch.agent.policy import Method
from objsearch.agent.scene_graph import SceneGraphProjection, UpdateMode
from objsearch.agent.semmap import SemanticMap
from objsearch.agent.session import HomeContext, Session, load_context
from objsearch.agent.strategies import RunSpec
from objsearch.events import Event, fold, read_log
from objsearch.replay.asof import scene_graph_at
from objsearch.sim.longterm import TARGET_ORDER, run_schedule
from objsearch.sim.placements import base_placements, table1_removals
from objsearch.sim.world import SimClock, SimWorld

HOME = "paper"


def _search(log: Path, target: str, start: str, method: Method = Method.WPL) -> tuple[float, float]:
    ctx = load_context(HOME)
    placements = base_placements(ctx.home, table1_removals(ctx.home))
    session = Session.start(ctx, log, RunSpec.for_home(ctx.home, method.value))
    try:
        world = SimWorld(
            ctx.home,
            ctx.navmap,
            placements,
            ctx.home.start(start),
            clock=SimClock(session.resume_time_ns),
        )
        oracle = world.oracle_length(
            target, min_mask_px=ctx.vocabulary.classes[target].min_mask_area_px
        )
        result = session.search(world, target, start)
    finally:
        session.close()
    assert result.success, f"{target} from {start} not found"
    return result.path_length, oracle


def test_search_finds_the_apple_and_logs_every_step_in_order(tmp_path: Path) -> None:
    length, oracle = _search(tmp_path, "Apple", "kitchen-1")
    assert length > 0
    assert length >= oracle - 1e-9

    events = list(read_log(tmp_path, store=STORE))
    assert [e.seq for e in events] == list(range(1, len(events) + 1))
    assert all(a.time_ns <= b.time_ns for a, b in itertools.pairwise(events))
    kinds = [e.type for e in events]
    assert kinds[:3] == ["run_started", "scene_graph_seeded", "task_started"]
    assert kinds[-2:] == ["target_found", "task_ended"]
    assert kinds.index("plan_computed") < kinds.index("target_found")
    # The paper's metric: the mileage when the target was detected, before the approach.
    detected = next(e for e in events if e.type == "target_detected")
    assert kinds.index("target_detected") < kinds.index("target_found")
    moved_before = sum(
        e.payload["metres"] for e in events if e.type == "moved" and e.seq < detected.seq
    )
    assert detected.payload["path_length"] == pytest.approx(moved_before, abs=1e-3)
    assert detected.payload["path_length"] <= length + 1e-9
    ended = events[-1].payload
    assert ended["success"] is True
    assert ended["path_length"] == pytest.approx(length, abs=1e-4)
    moved = sum(e.payload["metres"] for e in events if e.type == "moved")
    assert moved == pytest.approx(length, abs=1e-3)
    assert {e.task_id for e in events[2:]} == {"task-00001"}


@pytest.mark.parametrize("method", list(Method))
def test_every_target_is_found_from_every_start(tmp_path: Path, method: Method) -> None:
    ctx = load_context(HOME)
    placements = base_placements(ctx.home, table1_removals(ctx.home))
    spec = RunSpec.for_home(ctx.home, method.value, update_mode=UpdateMode.NONE)
    session = Session.start(ctx, tmp_path, spec)
    clock = SimClock(session.resume_time_ns)
    try:
        for start, pose in ctx.home.starts.items():
            for target in TARGET_ORDER:
                world = SimWorld(ctx.home, ctx.navmap, placements, pose, clock=clock)
                oracle = world.oracle_length(
                    target, min_mask_px=ctx.vocabulary.classes[target].min_mask_area_px
                )
                result = session.search(world, target, start)
                assert result.success, f"{method.value}: {target} from {start} not found"
                assert result.path_length >= oracle - 1e-9
    finally:
        session.close()


def _schedule(log: Path, mode: UpdateMode, scenes: tuple[int, ...] = (1, 2)) -> None:
    spec = RunSpec.for_home(load_context(HOME).home, "wpl", update_mode=mode, schedule="table2")
    run_schedule(log, spec, scenes=list(scenes), targets=("Apple", "Cup", "Laptop"))


@pytest.fixture(scope="module")
def schedule_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    log = tmp_path_factory.mktemp("schedule")
    _schedule(log, UpdateMode.ALL)
    return log


def test_rebuilding_from_scratch_equals_the_live_fold(schedule_log: Path) -> None:
    ctx = load_context(HOME)
    rebuilt = fold(read_log(schedule_log, store=STORE), SceneGraphProjection())
    # A session continuing the log folds it on open; its live graph then advances event by event.
    session = Session.start(ctx, schedule_log, RunSpec.for_home(ctx.home, "wpl"))
    graph = session.graph
    assert isinstance(graph, SceneGraphProjection)
    try:
        assert graph.relations == rebuilt.relations
        world = SimWorld(
            ctx.home,
            ctx.navmap,
            base_placements(ctx.home),
            ctx.home.start("bedroom-1"),
            clock=SimClock(session.resume_time_ns),
        )
        session.search(world, "Pillow", "bedroom-1")
        live = dict(graph.relations)
    finally:
        session.close()
    assert live != rebuilt.relations  # the extra task changed something
    assert fold(read_log(schedule_log, store=STORE), SceneGraphProjection()).relations == live


def test_graph_at_seq_is_the_fold_up_to_that_event(schedule_log: Path) -> None:
    events = list(read_log(schedule_log, store=STORE))
    seeded = next(e for e in events if e.type == "scene_graph_seeded")
    first_end = next(e for e in events if e.type == "task_ended")
    before = scene_graph_at(schedule_log, first_end.seq - 1)
    after = scene_graph_at(schedule_log, first_end.seq)
    assert isinstance(before, SceneGraphProjection) and isinstance(after, SceneGraphProjection)
    prior = {(v["dynamic"], v["static"]): v["rel"] for v in seeded.payload["values"]}
    assert before.relations == prior
    assert after.relations != prior
    assert after.tasks_folded == 1
    target = events[first_end.seq - 1].payload["target"]
    changed = {d for pair, v in after.relations.items() if v != prior[pair] for d in [pair[0]]}
    assert target in changed


def test_update_modes_change_only_what_they_promise(tmp_path: Path) -> None:
    graphs: dict[UpdateMode, SceneGraphProjection] = {}
    for mode in UpdateMode:
        _schedule(tmp_path / mode.value, mode, scenes=(1,))
        graph = scene_graph_at(tmp_path / mode.value)
        assert isinstance(graph, SceneGraphProjection)
        graphs[mode] = graph
    seeded = next(
        e for e in read_log(tmp_path / "none", store=STORE) if e.type == "scene_graph_seeded"
    )
    prior = {(v["dynamic"], v["static"]): v["rel"] for v in seeded.payload["values"]}
    assert graphs[UpdateMode.NONE].relations == prior
    changed_targets = {
        d for (d, s), v in graphs[UpdateMode.TARGETS].relations.items() if v != prior[d, s]
    }
    assert changed_targets <= {"Apple", "Cup", "Laptop"}
    assert changed_targets
    changed_all = {d for (d, s), v in graphs[UpdateMode.ALL].relations.items() if v != prior[d, s]}
    assert changed_all >= changed_targets


def _without_wall_clock(events: list[Event]) -> list[Event]:
    return [msgspec.structs.replace(e, recorded_at_ns=0) for e in events]


def test_same_inputs_give_the_same_log(tmp_path: Path) -> None:
    for name in ("a", "b"):
        _schedule(tmp_path / name, UpdateMode.ALL, scenes=(3,))
    a, b = (list(read_log(tmp_path / name, store=STORE)) for name in ("a", "b"))
    assert a and _without_wall_clock(a) == _without_wall_clock(b)


def test_sdp_room_order_depends_on_the_seed_only(tmp_path: Path) -> None:
    def rooms(seed: int, name: str) -> list[tuple[str, ...]]:
        spec = RunSpec.for_home(
            load_context(HOME).home,
            "sdp",
            seed=seed,
            update_mode=UpdateMode.NONE,
            schedule="table2",
        )
        run_schedule(
            tmp_path / name,
            spec,
            scenes=[1],
            targets=("Vase",),
        )
        return [
            tuple(e.payload["room_order"])
            for e in read_log(tmp_path / name, store=STORE)
            if e.type == "plan_computed"
        ]

    assert rooms(1, "a") == rooms(1, "b")
    assert rooms(1, "a") != rooms(2, "c")


def test_a_continued_log_keeps_its_sequence_and_clock(tmp_path: Path) -> None:
    _search(tmp_path, "Apple", "kitchen-1")
    n = len(list(read_log(tmp_path, store=STORE)))
    _search(tmp_path, "Cup", "living-1")
    events = list(read_log(tmp_path, store=STORE))
    assert [e.seq for e in events] == list(range(1, len(events) + 1))
    assert events[n].type == "run_started"
    assert all(a.time_ns <= b.time_ns for a, b in itertools.pairwise(events))
    # The prior is seeded once per log, not once per run.
    assert sum(e.type == "scene_graph_seeded" for e in events) == 1
    assert events[-1].task_id == "task-00002"


def test_a_named_prior_is_recorded_in_the_seed_and_changes_the_values(tmp_path: Path) -> None:
    ctx = load_context(HOME)
    seeded = {}
    for prior in ("vg-cooccurrence", "vg-hoz-masked"):
        spec = RunSpec.for_home(ctx.home, "wpl", prior=prior)
        session = Session.start(ctx, tmp_path / prior, spec)
        session.close()
        (seed,) = [
            e for e in read_log(tmp_path / prior, store=STORE) if e.type == "scene_graph_seeded"
        ]
        seeded[prior] = seed.payload
    assert seeded["vg-hoz-masked"]["source"].startswith("vg-hoz-masked: ")
    assert not seeded["vg-cooccurrence"]["source"].startswith("vg-")
    rel = {
        p: {(v["dynamic"], v["static"]): v["rel"] for v in doc["values"]}
        for p, doc in seeded.items()
    }
    # HOZ links no AI2-THOR type of Apple with a Bathtub: the masked reading says 0.
    assert rel["vg-cooccurrence"][("Apple", "Bathtub")] > 0
    assert rel["vg-hoz-masked"][("Apple", "Bathtub")] == 0
    # A class HOZ does not know (Sofa) keeps its co-occurrence.
    assert rel["vg-hoz-masked"][("Apple", "Sofa")] == rel["vg-cooccurrence"][("Apple", "Sofa")]


@pytest.mark.parametrize(
    ("first", "then"), [("vg-hoz-masked", "vg-cooccurrence"), ("vg-cooccurrence", "vg-single-name")]
)
def test_a_log_continued_with_another_prior_is_refused(
    tmp_path: Path, first: str, then: str
) -> None:
    ctx = load_context(HOME)
    Session.start(ctx, tmp_path, RunSpec.for_home(ctx.home, "wpl", prior=first)).close()
    before = (tmp_path / "events.log").read_bytes()
    with pytest.raises(ObjsearchError, match=f"seeded with the {first} prior.*{then} prior"):
        Session.start(ctx, tmp_path, RunSpec.for_home(ctx.home, "wpl", prior=then))
    assert (tmp_path / "events.log").read_bytes() == before
    # The same prior continues the log (and is not seeded again).
    Session.start(ctx, tmp_path, RunSpec.for_home(ctx.home, "wpl", prior=first)).close()
    assert sum(e.type == "scene_graph_seeded" for e in read_log(tmp_path, store=STORE)) == 1


def test_a_run_builds_its_stops_distances_before_the_first_search(tmp_path: Path) -> None:
    """The shortest paths from every stop of the home are built when a run starts (so once per
    run, and again in a new map), not in a search's first decision: that decision builds one
    tree, from where the robot stands (issue 45: a robot asked to find something waited for
    the whole table before it moved)."""
    home = load_home(HOME)
    navmap = NavigationMap.from_home(home)  # its own: no other test's trees in it
    ctx = HomeContext(home, Vocabulary.load(), navmap, SemanticMap.from_home(home, navmap))
    spec = RunSpec.for_home(home, "global-belief+cover")
    session = Session.start(ctx, tmp_path, spec)
    try:
        viewpoints = {s.viewpoint for s in ctx.semmap.statics}
        assert set(navmap._trees) == viewpoints
        agent = session.agent
        here = next(p.point for p in home.starts.values() if p.point not in viewpoints)
        plan = agent.plan_global(here, {r: agent.stops(r, "Apple") for r in agent.rooms})
        assert plan is not None
        assert set(navmap._trees) == viewpoints | {here}
        table = agent.stop_table
        session.start_run(spec, new_map=True)
        assert session.agent.stop_table is not table
        assert session.agent.stop_table.matrix.tolist() == table.matrix.tolist()
    finally:
        session.close()
