"""The Beta relation model: negative evidence and decay, checked against hand computations."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import pytest

from objsearch.agent.catalogue import (
    Candidate,
    Detected,
    PlanarPose,
    PlanComputed,
    Support,
    TaskEnded,
    TaskStarted,
    ViewTaken,
    encode,
)
from objsearch.agent.relations import BetaRelations
from objsearch.agent.scene_graph import SceneGraphProjection, UpdateMode
from objsearch.agent.strategies import RunSpec


@dataclass(frozen=True)
class Ev:
    seq: int
    type: str
    payload: dict[str, Any] = field(default_factory=dict)


PRIOR = [
    {"dynamic": "Apple", "static": "Sink", "rel": 0.2},
    {"dynamic": "Apple", "static": "Table", "rel": 0.6},
    {"dynamic": "Apple", "static": "Fridge", "rel": 0.1},
    {"dynamic": "Cup", "static": "Sink", "rel": 0.4},
    {"dynamic": "Cup", "static": "Table", "rel": 0.1},
]


POSE = PlanarPose(x=0.0, y=0.0, yaw=0.0)


def det(cls: str, static: str | None) -> dict[str, Any]:
    return encode(
        Detected(
            object_class=cls,
            instance_id=f"{cls}|1",
            mask_area=900.0,
            position=(0.0, 0.0, 0.0),
            accepted=True,
            score=1.0,
            classes=(),
            support=None
            if static is None
            else Support(static_id=f"{static}|1", static_class=static, at=True),
        )
    )


def task(
    seq: int, target: str, viewed: list[tuple[str, str]], seen: list[tuple[str, str | None]]
) -> list[Ev]:
    """One task: a plan naming the viewed statics, a view of each, then the detections."""
    plan = PlanComputed(
        room="kitchen-1",
        room_order=("kitchen-1",),
        objective="wpl",
        alpha=10.0,
        candidates=tuple(
            Candidate(static_id=sid, static_class=c, viewpoint=(0.0, 0.0), rel=0.5)
            for sid, c in viewed
        ),
        order=tuple(sid for sid, _ in viewed),
        terms=(),
        value=0.0,
    )
    started = TaskStarted(target=target, start="kitchen-1", pose=POSE, scene=None, clock=None)
    evs = [Ev(seq, "task_started", encode(started)), Ev(seq + 1, "plan_computed", encode(plan))]
    n = seq + 2
    for sid, _ in viewed:
        evs.append(
            Ev(
                n,
                "view_taken",
                encode(ViewTaken(pose=POSE, pitch=0.0, static_id=sid, reason="look")),
            )
        )
        n += 1
    for cls, static in seen:
        evs.append(Ev(n, "detection", det(cls, static)))
        n += 1
    ended = TaskEnded(target=target, success=True, path_length=0.0)
    evs.append(Ev(n, "task_ended", encode(ended)))
    return evs


def fold(model: Any, events: list[Ev]) -> Any:
    for e in events:
        model.apply(e)
    return model


def start(mode: str = "all") -> list[Ev]:
    return [
        Ev(
            1,
            "run_started",
            RunSpec.of("paper", "x", "wpl", update_mode=UpdateMode(mode)).payload(),
        ),
        Ev(2, "scene_graph_seeded", {"source": "test", "values": PRIOR}),
    ]


def test_prior_is_the_posterior_mean_before_any_evidence() -> None:
    m = fold(BetaRelations(prior_strength=2.0), start())
    assert m.rel("Apple", "Sink") == pytest.approx(0.2)
    assert m.rel("Apple", "Bed") == 0.0  # unknown pair


def test_positive_and_negative_evidence_by_hand() -> None:
    # Looked at the sink (s1) and fridge (f1) without an apple, found it on the table (t1).
    events = start() + task(
        10, "Apple", [("s1", "Sink"), ("f1", "Fridge"), ("t1", "Table")], [("Apple", "Table")]
    )
    m = fold(BetaRelations(prior_strength=2.0), events)
    # a = k·Rel0 (+1 if seen there), b = k·(1 − Rel0) (+1 if looked at and not seen there)
    assert m.rel("Apple", "Table") == pytest.approx((1.2 + 1) / (1.2 + 1 + 0.8))
    assert m.rel("Apple", "Sink") == pytest.approx(0.4 / (0.4 + 1.6 + 1))
    assert m.rel("Apple", "Fridge") == pytest.approx(0.2 / (0.2 + 1.8 + 1))
    assert m.rel("Cup", "Sink") == pytest.approx(0.4)  # other classes untouched
    # Eq. 4 halves pairs it has no evidence against, but never lowers a looked-at static more.
    eq4 = fold(SceneGraphProjection(), events)
    assert eq4.rel("Apple", "Sink") == pytest.approx(0.1)
    assert eq4.rel("Apple", "Fridge") == pytest.approx(0.05)


def test_negative_evidence_needs_an_update_mode_and_a_view() -> None:
    events = start("none") + task(10, "Apple", [("s1", "Sink")], [])
    assert fold(BetaRelations(), events).rel("Apple", "Sink") == pytest.approx(0.2)
    # A candidate that was planned but never looked at teaches nothing.
    planned = task(10, "Apple", [("s1", "Sink")], [])
    events = [*start(), *(e for e in planned if e.type != "view_taken")]
    assert fold(BetaRelations(), events).rel("Apple", "Sink") == pytest.approx(0.2)


def test_all_mode_counts_other_classes_seen_targets_mode_does_not() -> None:
    events_all = start("all") + task(
        10, "Apple", [("t1", "Table")], [("Apple", "Table"), ("Cup", "Table")]
    )
    events_tgt = start("targets") + task(
        10, "Apple", [("t1", "Table")], [("Apple", "Table"), ("Cup", "Table")]
    )
    assert fold(BetaRelations(), events_all).rel("Cup", "Table") == pytest.approx(1.2 / 3.0)
    assert fold(BetaRelations(), events_tgt).rel("Cup", "Table") == pytest.approx(0.1)


def test_decay_halves_evidence_after_half_life_tasks() -> None:
    # One sighting at the sink, then two empty tasks of another target: with a half-life of
    # 2 tasks the evidence has faded to 1/2 when the third task starts (two task starts later).
    events = start() + task(10, "Apple", [("s1", "Sink")], [("Apple", "Sink")])
    events += task(30, "Cup", [], []) + task(40, "Cup", [], [])
    m = fold(BetaRelations(prior_strength=2.0, half_life_tasks=2.0), events)
    assert m.rel("Apple", "Sink") == pytest.approx((0.4 + 0.5) / (2.0 + 0.5))
    no_decay = fold(BetaRelations(prior_strength=2.0), events)
    assert no_decay.rel("Apple", "Sink") == pytest.approx(1.4 / 3.0)


def test_bad_parameters_are_refused() -> None:
    with pytest.raises(ValueError, match="prior strength"):
        BetaRelations(prior_strength=0)
    with pytest.raises(ValueError, match="half-life"):
        BetaRelations(half_life_tasks=-1)
