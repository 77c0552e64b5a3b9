"""Walking a viewpoint path: the one loop behind every :class:`~objsearch.agent.world.World`'s
``navigate`` (the simulator's and the ROS robot's), so metres, rooms, stops and the final turn are
counted the same way whoever moves the robot."""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Protocol

from objsearch.agent.geometry import Point, Pose, heading
from objsearch.agent.navmap import NavigationMap
from objsearch.agent.world import Detection, DetectionHandler, Navigation


class Step(Protocol):
    """Moves the robot to ``pose``, the next viewpoint of the path (or, at the end, the same place
    turned to the final yaw); ``metres`` is what that move drives (0 for a teleport between room
    entries and for the final turn). With ``view`` it returns what the camera sees there; without,
    nobody reads the view and the world may skip it."""

    def __call__(self, pose: Pose, metres: float, *, view: bool) -> Sequence[Detection]: ...


def walk_path(
    navmap: NavigationMap,
    start: Pose,
    goal: Point,
    step: Step,
    *,
    on_detection: DetectionHandler | None = None,
    final_yaw: float | None = None,
) -> Navigation:
    """Walk the navigation map's shortest path from ``start`` to ``goal`` one viewpoint at a time.

    After each step every detection of the view goes to ``on_detection``; if any call returns True
    the walk stops there (interrupted) and the final turn is skipped.
    """
    path = navmap.path(start.point, goal)
    walked: list[Point] = [path[0]]
    rooms = [navmap.room_of[path[0]]]
    metres = 0.0
    yaw = start.yaw
    interrupted = False
    for a, b in itertools.pairwise(path):
        driven = 0.0
        if navmap.is_teleport(a, b):
            rooms.append(navmap.room_of[b])
        else:
            yaw = heading(a, b)
            driven = navmap.edge_weight(a, b)
            metres += driven
        pose = Pose(b.x, b.y, yaw)
        detections = step(pose, driven, view=on_detection is not None)
        walked.append(b)
        if on_detection is not None:
            # Every detection of the view reaches the agent, even after one asked to stop.
            stops = [on_detection(det, pose) for det in detections]
            if any(stops):
                interrupted = True
                break
    end = Pose(walked[-1].x, walked[-1].y, yaw)
    if final_yaw is not None and not interrupted:
        end = Pose(end.x, end.y, final_yaw)
        step(end, 0.0, view=False)
    return Navigation(tuple(walked), metres, end, tuple(rooms), interrupted)
