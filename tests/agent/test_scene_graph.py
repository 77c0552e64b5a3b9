"""Eq. 2 seeding and the Eq. 4 fold."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import pytest

from objsearch.agent.catalogue import Detected, PlanarPose, Support, TaskEnded, TaskStarted, encode
from objsearch.agent.categories import Vocabulary
from objsearch.agent.scene_graph import (
    SceneGraphProjection,
    UpdateMode,
    apply_eq4,
    experience_to_fold,
    seed_relations,
)
from objsearch.agent.strategies import RunSpec

VOCAB = Vocabulary.from_dict(
    {
        "static": {"Sink": {}, "Table": {}, "Fridge": {}},
        "semi_dynamic": {"Apple": {"aliases": ["apple"]}, "Cup": {}},
    }
)


@dataclass(frozen=True)
class Ev:
    seq: int
    type: str
    payload: dict[str, Any] = field(default_factory=dict)
    task_id: str | None = None


def test_eq2_is_pair_count_over_image_count() -> None:
    prior = {
        "image_counts": {"Apple": 824, "Cup": 0},
        "pair_counts": {"Apple": {"Sink": 20, "Table": 15}},
    }
    rel = seed_relations(prior, VOCAB)
    assert rel[("Apple", "Sink")] == pytest.approx(20 / 824)
    assert rel[("Apple", "Table")] == pytest.approx(15 / 824)
    assert rel[("Apple", "Fridge")] == 0.0
    assert rel[("Cup", "Sink")] == 0.0  # never seen in the corpus: no relation, no division by 0


def test_eq2_clips_alias_overcount_to_one() -> None:
    prior = {"image_counts": {"Apple": 10}, "pair_counts": {"Apple": {"Sink": 14}}}
    assert seed_relations(prior, VOCAB)[("Apple", "Sink")] == 1.0


def test_eq4_three_cases() -> None:
    rel = {("Apple", "Sink"): 0.2, ("Apple", "Table"): 0.6, ("Cup", "Sink"): 0.4}
    out = apply_eq4(rel, {"Apple": {"Sink"}})
    assert out[("Apple", "Sink")] == pytest.approx(0.2 / 2 + 0.5)  # seen at N_s
    assert out[("Apple", "Table")] == pytest.approx(0.3)  # seen, not at N_s
    assert out[("Cup", "Sink")] == 0.4  # not seen


def seeded_events(mode: str) -> list[Ev]:
    values = [
        {"dynamic": "Apple", "static": "Sink", "rel": 0.2},
        {"dynamic": "Apple", "static": "Table", "rel": 0.6},
        {"dynamic": "Cup", "static": "Sink", "rel": 0.4},
        {"dynamic": "Cup", "static": "Table", "rel": 0.1},
    ]
    return [
        Ev(
            1,
            "run_started",
            RunSpec.of("paper", "x", "wpl", update_mode=UpdateMode(mode)).payload(),
        ),
        Ev(2, "scene_graph_seeded", {"source": "test", "values": values}),
    ]


def detection(seq: int, cls: str, static: str | None, *, accepted: bool = True) -> Ev:
    return Ev(
        seq,
        "detection",
        encode(
            Detected(
                object_class=cls,
                instance_id=f"{cls}|1",
                mask_area=900.0,
                position=(0.0, 0.0, 0.0),
                accepted=accepted,
                score=1.0,
                classes=(),
                support=None
                if static is None
                else Support(static_id=f"{static}|1", static_class=static, at=True),
            )
        ),
    )


def started(seq: int) -> Ev:
    pose = PlanarPose(x=0.0, y=0.0, yaw=0.0)
    return Ev(
        seq,
        "task_started",
        encode(TaskStarted(target="Apple", start="k", pose=pose, scene=None, clock=None)),
    )


def ended(seq: int) -> Ev:
    return Ev(seq, "task_ended", encode(TaskEnded(target="Apple", success=True, path_length=0.0)))


def task(seq: int) -> list[Ev]:
    # Looking for an apple: sees a cup at the table, then the apple at the sink.
    return [
        started(seq),
        detection(seq + 1, "Cup", "Table"),
        detection(seq + 2, "Apple", None, accepted=False),  # below threshold: not seen
        detection(seq + 3, "Apple", "Sink"),
        ended(seq + 4),
    ]


@pytest.mark.parametrize(
    ("mode", "expected"),
    [
        ("none", {("Apple", "Sink"): 0.2, ("Apple", "Table"): 0.6, ("Cup", "Table"): 0.1}),
        ("targets", {("Apple", "Sink"): 0.6, ("Apple", "Table"): 0.3, ("Cup", "Table"): 0.1}),
        ("all", {("Apple", "Sink"): 0.6, ("Apple", "Table"): 0.3, ("Cup", "Table"): 0.55}),
    ],
)
def test_update_modes(mode: str, expected: dict[tuple[str, str], float]) -> None:
    graph = SceneGraphProjection()
    for ev in [*seeded_events(mode), *task(3)]:
        graph.apply(ev)
    for pair, value in expected.items():
        assert graph.relations[pair] == pytest.approx(value)
    assert graph.tasks_folded == 1
    assert graph.last_seq == 7


def test_repeated_updates_follow_closed_form() -> None:
    graph = SceneGraphProjection()
    for ev in seeded_events("targets"):
        graph.apply(ev)
    seq = 3
    for _ in range(4):
        for ev in task(seq):
            graph.apply(ev)
        seq += 5
    # r_k = r_0 / 2^k + Σ_{j=1..k} 1/2^(k-j+1)  with every b_j = 1
    assert graph.relations[("Apple", "Sink")] == pytest.approx(0.2 / 16 + (1 - 1 / 16))
    assert graph.relations[("Apple", "Table")] == pytest.approx(0.6 / 16)


def test_failed_search_with_nothing_seen_changes_nothing() -> None:
    graph = SceneGraphProjection()
    for ev in seeded_events("all"):
        graph.apply(ev)
    before = dict(graph.relations)
    graph.apply(started(3))
    graph.apply(ended(4))
    assert graph.relations == before


def test_the_update_mode_chooses_which_experience_is_folded() -> None:
    seen = {"Apple": {"Fridge"}, "Cup": {"Sink"}, "Ghost": {"Table"}}
    known = {"Apple", "Cup"}
    assert experience_to_fold(UpdateMode.ALL, "Apple", seen, known) == {
        "Apple": {"Fridge"},
        "Cup": {"Sink"},
    }
    assert experience_to_fold(UpdateMode.TARGETS, "Apple", seen, known) == {"Apple": {"Fridge"}}
    assert experience_to_fold(UpdateMode.TARGETS, "Bowl", seen, known) == {}
    assert experience_to_fold(UpdateMode.TARGETS, None, seen, known) == {}
    assert experience_to_fold(UpdateMode.NONE, "Apple", seen, known) == {}
