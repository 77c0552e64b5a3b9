"""A recorded robot answers each command with the pose and view the live agent would have taken
(pipeline/bags/views.py, the rule of ros/detections.py view_not_before), and says where a replay
leaves the recording."""

from __future__ import annotations

import pytest

from objsearch.agent.geometry import Pose
from objsearch.agent.session import load_context
from objsearch.agent.world import Detection
from objsearch.pipeline.bags.views import RecordedRobot, Recording, ReplayDiverged

S = 10**9


def seen(cls: str) -> tuple[Detection, ...]:
    return (Detection(cls, f"{cls}|1", 900.0, (1.0, 2.0, 0.5), 0.9),)


def test_a_look_after_a_turn_gets_its_own_view_and_a_teleport_its_next_frame() -> None:
    ctx = load_context("paper")
    start = ctx.home.start("kitchen-1")
    turned = Pose(start.x, start.y, start.yaw + 1.0)
    frame = S // 30
    recording = Recording(
        agent=(),
        poses=(
            (S, start),
            (2 * S, turned),
            (3 * S, turned),
            (3 * S + frame, turned),
            (4 * S, turned),
        ),
        # The turn's view (nobody waits for it), the look's, then a view one frame later.
        views=((2 * S, seen("Apple")), (3 * S, seen("Cup")), (3 * S + frame, seen("Bowl"))),
        rejected={},
    )
    robot = RecordedRobot(ctx.navmap, recording, S)
    assert robot._step(turned, 0.0, view=False) == ()
    assert robot.now_ns() == 2 * S
    # At the goal already: arrival is the turn's pose; the view is the first after the clock.
    assert [d.object_class for d in robot.look(turned.yaw)] == ["Cup"]
    # A command that took no robot time but a camera frame (a teleport) gets that frame.
    assert [d.object_class for d in robot.look(turned.yaw)] == ["Bowl"]
    with pytest.raises(ReplayDiverged, match="command 4 \\(view\\): no recorded view stamped"):
        robot.look(turned.yaw)
    with pytest.raises(ReplayDiverged, match="never reached"):
        robot.look(turned.yaw + 1.0)


def test_looks_after_a_turn_already_within_tolerance_each_get_the_robots_answer_to_them() -> None:
    """Issue 45: a turn so small that the robot is within tolerance of it already arrives on the
    robot's answer to it (the pose stamped after the clock), not on the pose before it; so the
    confirming looks that follow from the same pose get one frame each, in order, as live."""
    ctx = load_context("paper")
    start = ctx.home.start("kitchen-1")
    nudged = Pose(start.x, start.y, start.yaw + 0.015)  # within TOLERANCE_RAD of start
    recording = Recording(
        agent=(),
        poses=tuple((k * S, start if k == 1 else nudged) for k in range(1, 6)),
        # The start's view, the turn's (nobody waits for it), then one per look.
        views=(
            (S, seen("Start")),
            (2 * S, ()),
            (3 * S, seen("Cup")),
            (4 * S, ()),
            (5 * S, seen("Bowl")),
        ),
        rejected={},
    )
    robot = RecordedRobot(ctx.navmap, recording, S)
    assert robot._step(nudged, 0.0, view=False) == ()
    assert robot.now_ns() == 2 * S
    looks = [[d.object_class for d in robot.look(nudged.yaw)] for _ in range(3)]
    assert looks == [["Cup"], [], ["Bowl"]]
    assert robot.now_ns() == 5 * S
