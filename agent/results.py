"""What a search returns (:class:`SearchResult`) and a sighting of its target (:class:`Found`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from objsearch.agent.geometry import Point, Pose, Vec3


@dataclass
class SearchResult:
    task_id: str
    target: str
    start: str
    success: bool
    path_length: float
    #: Metres from the start to the detection (the paper's path length); None if not found.
    path_to_discovery: float | None = None
    route: list[Point] = field(default_factory=list)
    found_instance: str | None = None
    plans: list[tuple[str, tuple[str, ...]]] = field(default_factory=list)


@dataclass
class Found:
    """A sighting of the target: the detection, and where the robot stood and how far it had
    driven when it was made (the paper's path to discovery)."""

    instance_id: str
    position: Vec3
    pose: Pose
    path_length: float
    score: float = 1.0
    mask_area: float = 0.0
    sure: bool = True
    #: The container the robot had opened when it saw it (a confirming look opens it again).
    container: str | None = None
