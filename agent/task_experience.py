"""The task in progress as a relation model folds it: its target, where each class was seen, and
which statics the robot looked at — kept once, the same way, for every model that learns from a
task's end (Eq. 4's :class:`~objsearch.agent.scene_graph.SceneGraphProjection`, the Beta
posterior, the instance memory).

A task starts at ``task_started`` and is over at ``task_ended`` (the model folds it, then
:meth:`TaskExperience.clear`) or ``task_aborted`` (a search a crash cut short: Eq. 4 applies
"after each search", so nothing of it is folded — :meth:`TaskExperience.clear` alone).
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from objsearch.agent.catalogue import Detected


class SeenBy(enum.Enum):
    """What a model counts a sighting at: a static *class* (Eq. 4, the Beta posterior: every
    accepted detection enters its class, at a static or not, so Eq. 4 halves the Rel of a class
    seen elsewhere), or a static *instance* (the memory: only sightings at a static count)."""

    CLASS = "class"
    INSTANCE = "instance"


@dataclass
class TaskExperience:
    """The experience pool of the task in progress."""

    seen_by: SeenBy = SeenBy.CLASS
    target: str | None = None
    #: object class → the statics (classes or instances, :attr:`seen_by`) it was seen at
    seen_at: dict[str, set[str]] = field(default_factory=dict)
    #: the statics the robot looked at, as the model names them (it fills this on view_taken)
    viewed: set[str] = field(default_factory=set)

    def start(self, target: str) -> None:
        """A task for ``target`` began: nothing seen or viewed yet."""
        self.target = target
        self.seen_at = {}
        self.viewed = set()

    def clear(self) -> None:
        """The task is over (folded, or aborted): no task in progress."""
        self.target = None
        self.seen_at = {}
        self.viewed = set()

    def detected(self, detection: Detected) -> None:
        """Fold one ``detection`` (only accepted ones count)."""
        if not detection.accepted:
            return
        support = detection.support
        at = support is not None and support.at
        if self.seen_by is SeenBy.CLASS:
            statics = self.seen_at.setdefault(detection.object_class, set())
            if at and support is not None:
                statics.add(support.static_class)
        elif at and support is not None:
            self.seen_at.setdefault(detection.object_class, set()).add(support.static_id)

    def record_handler(self) -> Callable[[Any], None]:
        """:meth:`detected` of a record's envelope (``events.fold_read``: its ``payload`` the
        detection), in one call: a fold reads every detection of a log."""
        if self.seen_by is not SeenBy.CLASS:
            return lambda r: self.detected(r.payload)

        def detected(r: Any) -> None:
            detection = r.payload
            if not detection.accepted:
                return
            support = detection.support
            statics = self.seen_at.setdefault(detection.object_class, set())
            if support is not None and support.at:
                statics.add(support.static_class)

        return detected

    def missed(self) -> set[str]:
        """The statics looked at in this task where the target was not seen."""
        if self.target is None:
            return set()
        return self.viewed - self.seen_at.get(self.target, set())

    # -- snapshots: each model keeps its own keys, so its snapshot format does not change ------

    def seen_at_rows(self) -> dict[str, list[str]]:
        return {d: sorted(s) for d, s in sorted(self.seen_at.items())}

    @staticmethod
    def seen_at_from(rows: Mapping[str, Any]) -> dict[str, set[str]]:
        return {d: set(s) for d, s in rows.items()}
