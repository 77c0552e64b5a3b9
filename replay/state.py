"""Projections replay needs besides the scene graph: the run's settings, the task, the robot's pose.

Each is a fold of the same log the agent wrote, so a replay sees exactly what the robot knew at any
event: the scene graph (``agent.scene_graph``), the run's method and α, the task in progress with its
start room, and the robot's last known pose.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from objsearch.agent.catalogue import (
    ContainerOpened,
    Moved,
    PlanarPose,
    TargetFound,
    TaskStarted,
    ViewTaken,
    decode,
)
from objsearch.agent.geometry import Pose
from objsearch.agent.relations import RelationModel
from objsearch.agent.state import AgentState
from objsearch.agent.strategies import RunSpec
from objsearch.events.projection import EventView


@dataclass(frozen=True, slots=True)
class TaskState:
    task_id: str
    target: str
    start: str
    start_pose: Pose
    scene: int | None
    plans_so_far: int = 0
    #: Static ids looked at or opened so far in the task: the stops the whole-home planner
    #: (method ``global``) no longer plans over.
    searched: frozenset[str] = frozenset()


def _pose(pose: PlanarPose) -> Pose:
    return Pose(pose.x, pose.y, pose.yaw)


@dataclass
class ReplayState:
    """What the agent knew (its :class:`AgentState`: run spec, relation model, tasks) plus the
    task in progress and the robot's pose, advanced together one event at a time."""

    agent: AgentState = field(default_factory=AgentState)
    task: TaskState | None = None
    pose: Pose | None = None
    last_seq: int = 0
    last_time_ns: int = 0

    @property
    def state(self) -> ReplayState:
        return self

    @property
    def run(self) -> RunSpec | None:
        return self.agent.run

    @property
    def graph(self) -> RelationModel:
        return self.agent.graph()

    def apply(self, event: EventView) -> None:
        """Fold one event; the scene graph last, so a plan sees the graph as it was before it."""
        kind = event.type
        if kind == "task_started":
            started = decode(event, TaskStarted)
            self.pose = _pose(started.pose)
            self.task = TaskState(
                task_id=str(getattr(event, "task_id", None) or ""),
                target=started.target,
                start=started.start,
                start_pose=self.pose,
                scene=started.scene,
            )
        elif kind == "moved":
            self.pose = _pose(decode(event, Moved).end)
        elif kind == "view_taken":
            view = decode(event, ViewTaken)
            self.pose = _pose(view.pose)
            if self.task is not None and view.static_id is not None:
                self.task = replace(self.task, searched=self.task.searched | {view.static_id})
        elif kind == "container_opened":
            opened = decode(event, ContainerOpened)
            self.pose = _pose(opened.pose)
            if self.task is not None:
                self.task = replace(self.task, searched=self.task.searched | {opened.static_id})
        elif kind == "target_found":
            self.pose = _pose(decode(event, TargetFound).approach)
        elif kind == "plan_computed" and self.task is not None:
            self.task = replace(self.task, plans_so_far=self.task.plans_so_far + 1)
        elif kind in ("task_ended", "task_aborted"):
            self.task = None
        self.agent.apply(event)
        self.last_seq = event.seq
        self.last_time_ns = int(getattr(event, "time_ns", self.last_time_ns))
