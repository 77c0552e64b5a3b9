"""Why a search failed, read from its run's log while ``bench homes`` still has it (issue 45:
"every failure named with its cause"). Under a modelled detector a failure is a false "found"
(a false positive or a confusion confirmed) or a search that gave up: the log says which, with
the stopping rule's reason and what the detector reported of the true target on the way
(docs/perception.md). :func:`report_homes.failure_cause` adds what the camera could show."""

from __future__ import annotations

from collections.abc import Iterable, Mapping

from objsearch.agent.catalogue import (
    Detected,
    SearchFailed,
    SightingRejected,
    TargetFound,
    TaskStarted,
    decode,
)
from objsearch.events.projection import EventView
from objsearch.sim.placements import Placements

#: The id prefix of a modelled detector's false positive (sim/detector_model.py FALSE_PREFIX;
#: repeated here so reading a log imports no simulator).
FALSE_PREFIX = "false:"


class _Task:
    def __init__(self, target: str, classes: Mapping[str, str]) -> None:
        self.target = target
        self.classes = classes  # instance id → class, of the task's scene
        self.true_ids = frozenset(i for i, c in classes.items() if c == target)
        self.reports = 0  # detections of a true instance under its own class
        self.best_score = 0.0
        self.best_mask = 0.0  # px: a report under its class's mask threshold is no sighting
        self.rejected_true: list[float] = []  # posteriors of rejected sightings of a true instance
        self.rejected_other = 0
        self.scores: dict[str, float] = {}  # last accepted score per instance reported as target
        self.found: str | None = None
        self.reason: str | None = None

    def cause(self) -> str:
        if self.found is not None and self.found not in self.true_ids:
            score = self.scores.get(self.found)
            at = "" if score is None else f" at score {score:.3f}"
            if self.found.startswith(FALSE_PREFIX):
                return f"false found: a false positive {self.target}{at} confirmed"
            was = self.classes.get(self.found)
            who = f"a {was}" if was else f"instance {self.found}"
            return f"false found: {who} reported as {self.target}{at} (a confusion) confirmed"
        seen = (
            "the true target was never reported"
            if self.reports == 0
            else f"the true target was reported {self.reports}× (best score {self.best_score:.3f}, "
            f"largest mask {self.best_mask:.0f} px)"
        )
        if self.rejected_true:
            seen += (
                f", {len(self.rejected_true)} sighting(s) of it rejected (posterior at most "
                f"{max(self.rejected_true):.3f})"
            )
        if self.rejected_other:
            seen += f"; {self.rejected_other} false sighting(s) rejected"
        return f"not found ({self.reason or 'no reason logged'}): {seen}"


def failure_causes(
    events: Iterable[EventView], scenes: Mapping[int, Placements], failed: Iterable[str]
) -> dict[str, str]:
    """Per task id of ``failed``: its cause, from the run's events and its scenes' placements
    (which instances were the target)."""
    wanted = set(failed)
    tasks: dict[str, _Task] = {}
    current: _Task | None = None
    for event in events:
        task_id = getattr(event, "task_id", None)
        kind = event.type
        if kind == "task_started":
            current = None
            if task_id in wanted:
                started = decode(event, TaskStarted)
                placed = scenes.get(started.scene, {}) if started.scene is not None else {}
                classes = {i: p.cls for i, p in placed.items()}
                current = tasks[str(task_id)] = _Task(started.target, classes)
            continue
        if current is None:
            continue
        if kind == "detection":
            d = decode(event, Detected)
            if d.object_class != current.target:
                continue
            if d.instance_id in current.true_ids:
                current.reports += 1
                current.best_score = max(current.best_score, d.score)
                current.best_mask = max(current.best_mask, d.mask_area)
            if d.accepted:
                current.scores[d.instance_id] = d.score
        elif kind == "sighting_rejected":
            r = decode(event, SightingRejected)
            if r.instance_id in current.true_ids:
                current.rejected_true.append(r.posterior)
            else:
                current.rejected_other += 1
        elif kind == "target_found":
            current.found = decode(event, TargetFound).instance_id
        elif kind == "search_failed":
            current.reason = decode(event, SearchFailed).reason
        elif kind == "task_ended":
            current = None
    return {task_id: task.cause() for task_id, task in tasks.items()}
