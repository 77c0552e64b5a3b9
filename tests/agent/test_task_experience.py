"""The task bookkeeping the relation models share: what counts as seen, at what, and when a
task's pool starts and ends."""

from __future__ import annotations

from objsearch.agent.catalogue import Detected, Support
from objsearch.agent.task_experience import SeenBy, TaskExperience


def _detected(cls: str, *, accepted: bool = True, at: bool | None = True) -> Detected:
    support = None if at is None else Support(static_id=f"{cls}-s", static_class="Table", at=at)
    return Detected(
        object_class=cls,
        instance_id=f"{cls}|1",
        mask_area=900.0,
        position=(1.0, 0.5, 2.0),
        accepted=accepted,
        score=1.0,
        classes=(),
        support=support,
    )


def _pool(seen_by: SeenBy) -> TaskExperience:
    task = TaskExperience(seen_by)
    task.start("Apple")
    for detection in (
        _detected("Apple"),
        _detected("Cup", at=False),
        _detected("Bowl", at=None),
        _detected("Vase", accepted=False),
    ):
        task.detected(detection)
    task.viewed |= {"Table", "Sink"} if seen_by is SeenBy.CLASS else {"Apple-s", "sink-1"}
    return task


def test_by_class_every_accepted_sighting_enters_its_class() -> None:
    """Eq. 4 halves the Rel of a class seen away from every static, so it must be in the pool."""
    task = _pool(SeenBy.CLASS)
    assert task.seen_at == {"Apple": {"Table"}, "Cup": set(), "Bowl": set()}
    assert task.missed() == {"Sink"}


def test_by_instance_only_sightings_at_a_static_count() -> None:
    task = _pool(SeenBy.INSTANCE)
    assert task.seen_at == {"Apple": {"Apple-s"}}
    assert task.missed() == {"sink-1"}


def test_a_new_task_or_an_abort_empties_the_pool() -> None:
    task = _pool(SeenBy.CLASS)
    task.start("Cup")
    assert (task.target, task.seen_at, task.viewed) == ("Cup", {}, set())
    task.detected(_detected("Cup"))
    task.clear()
    assert (task.target, task.seen_at, task.viewed, task.missed()) == (None, {}, set(), set())
