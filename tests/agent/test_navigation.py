"""The one path-walking loop: metres, rooms, stopping and the final turn."""

from __future__ import annotations

from collections.abc import Sequence

import pytest

from objsearch.agent.geometry import Pose
from objsearch.agent.navigation import walk_path
from objsearch.agent.session import load_context
from objsearch.agent.world import Detection


class _Recorder:
    """A step that moves nothing: it records each call and shows one detection per viewpoint."""

    def __init__(self) -> None:
        self.calls: list[tuple[Pose, float, bool]] = []

    def __call__(self, pose: Pose, metres: float, *, view: bool) -> Sequence[Detection]:
        self.calls.append((pose, metres, view))
        n = len(self.calls)
        return (Detection("Apple", f"apple-{n}", 100.0, (pose.x, pose.y, 1.0)),) if view else ()


def test_walks_every_viewpoint_and_counts_only_driven_metres() -> None:
    ctx = load_context("paper")
    start = ctx.home.start("kitchen-1")
    goal = ctx.navmap.doors["bathroom"]
    step = _Recorder()
    nav = walk_path(ctx.navmap, start, goal, step, final_yaw=1.0)
    assert nav.path == tuple(ctx.navmap.path(start.point, goal))
    assert nav.rooms == ("kitchen", "bathroom")
    assert nav.metres == pytest.approx(
        ctx.navmap.distance(start.point, ctx.navmap.doors["kitchen"])
    )
    assert sum(m for _, m, _ in step.calls) == pytest.approx(nav.metres)
    assert not any(view for _, _, view in step.calls)  # nobody listens: no views asked for
    assert step.calls[-1] == (Pose(goal.x, goal.y, 1.0), 0.0, False)  # the final turn
    assert nav.end == Pose(goal.x, goal.y, 1.0) and not nav.interrupted


def test_stops_where_the_handler_says_and_skips_the_final_turn() -> None:
    ctx = load_context("paper")
    start = ctx.home.start("kitchen-1")
    goal = ctx.navmap.doors["bathroom"]
    step = _Recorder()
    heard: list[str] = []

    def on_detection(det: Detection, pose: Pose) -> bool:
        heard.append(det.instance_id)
        return len(heard) == 2

    nav = walk_path(ctx.navmap, start, goal, step, on_detection=on_detection, final_yaw=1.0)
    assert nav.interrupted
    assert heard == ["apple-1", "apple-2"]
    assert len(nav.path) == 3 and len(step.calls) == 2
    assert all(view for _, _, view in step.calls)
    assert nav.end == step.calls[-1][0]
