"""The seam between the agent and a robot: what the agent may ask of the world it searches.

The simulator (``objsearch.sim``) implements it from home data; a ROS adapter implements it on a
real robot. The agent never reads the world's ground truth, only what these calls return.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from objsearch.agent.geometry import Point, Pose, Vec3


@dataclass(frozen=True, slots=True)
class Detection:
    """One object in one camera view, as a detector and a depth camera report it."""

    object_class: str
    instance_id: str
    mask_area: float  # pixels
    position: Vec3  # object position reconstructed from depth, map frame
    #: The detector's confidence (1: a perfect detector) and its class distribution: (class,
    #: probability) pairs, the reported class first; empty when it gave only ``object_class``.
    score: float = 1.0
    class_scores: tuple[tuple[str, float], ...] = ()


@dataclass(frozen=True, slots=True)
class Navigation:
    """The outcome of one navigation goal."""

    path: tuple[Point, ...]  # viewpoints passed, first = where the robot started
    metres: float  # walked (teleports between room entries cost nothing)
    end: Pose
    rooms: tuple[str, ...]  # rooms passed through, in order
    interrupted: bool  # stopped early because the agent asked to


#: Called for each detection while the robot drives; returning True stops the robot there.
DetectionHandler = Callable[[Detection, Pose], bool]


class World(Protocol):
    def pose(self) -> Pose: ...

    def now_ns(self) -> int:
        """The robot clock (simulated time in the simulator), nanoseconds."""
        ...

    def navigate(
        self,
        goal: Point,
        *,
        on_detection: DetectionHandler | None = None,
        final_yaw: float | None = None,
    ) -> Navigation: ...

    def look(self, yaw: float, pitch: float = 0.0) -> tuple[Detection, ...]:
        """Turn in place to ``yaw``, tilt the camera ``pitch`` radians down and take one view."""
        ...

    def open(self, static_id: str, pitch: float = 0.0) -> tuple[Detection, ...]:
        """Open a container the robot stands at and look inside, the camera ``pitch`` radians
        down. While the robot drives the camera is level (pitch 0)."""
        ...
