"""The belief and the scene graph as typed messages and as markers RViz draws (issue 44): the
live view of a real log published by the agent's node (``--live-topics``) over ``--transport
ros2``, read by a plain rclpy subscriber with the standard and the generated types."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable
from contextlib import suppress
from pathlib import Path
from typing import Any

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.agent.session import load_context
from objsearch.agent.where import where
from objsearch.events import read_log
from objsearch.runtime import liveview as lv
from objsearch.runtime.backends import open_transport
from objsearch.runtime.livesinks import TopicSink
from objsearch.runtime.transport import Backend, TransportConfig

from .runtime_fixtures import STARTUP_S, next_domain
from .searches import TRIALS, in_process

rclpy = pytest.importorskip("rclpy")


def until(condition: Callable[[], bool], what: str) -> None:
    deadline = time.monotonic() + STARTUP_S
    while not condition():
        assert time.monotonic() < deadline, f"not within {STARTUP_S} s: {what}"
        time.sleep(0.02)


def test_a_subscriber_receives_the_belief_markers_and_the_typed_graph(tmp_path: Path) -> None:
    from objsearch_msgs.msg import Belief, SceneGraph
    from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
    from visualization_msgs.msg import MarkerArray

    in_process(tmp_path / "log", TRIALS[:2])
    events = list(read_log(tmp_path / "log", store=STORE))
    ctx = load_context("paper")
    domain = next_domain()
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    transport = open_transport(TransportConfig(backend=Backend.ROS2, domain_id=domain))
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node("rviz_like", context=context)
    executor = MultiThreadedExecutor(num_threads=2, context=context)
    executor.add_node(node)

    def spin() -> None:
        with suppress(ExternalShutdownException):
            executor.spin()

    spinner = threading.Thread(target=spin, daemon=True)
    spinner.start()
    got: dict[str, list[Any]] = {lv.BELIEF_MARKERS: [], lv.BELIEF: [], lv.GRAPH: []}
    for topic, cls in (
        (lv.BELIEF_MARKERS, MarkerArray),
        (lv.BELIEF, Belief),
        (lv.GRAPH, SceneGraph),
    ):
        node.create_subscription(cls, topic, got[topic].append, 1000)
    try:
        view = lv.LiveView(ctx, [TopicSink(transport)])
        first_plan = next(i for i, e in enumerate(events) if e.type == "plan_computed")
        for event in events[: first_plan + 1]:  # the channels' publishers are made on first use
            view.apply(event)
        until(
            lambda: all(node.count_publishers(t) == 1 for t in got),
            "the belief channels matched",
        )
        for event in events[first_plan + 1 :]:
            view.apply(event)
        last = events[-1]
        assert last.type == "task_ended"
        until(lambda: any(g.seq == last.seq for g in got[lv.GRAPH]), "the last scene graph")
        # Those sent before the match (task start, first plan) are volatile and lost.
        until(lambda: len(got[lv.BELIEF]) >= view.written[lv.BELIEF] - 2, "every later belief")
    finally:
        executor.shutdown(timeout_sec=5.0)
        node.destroy_node()
        context.try_shutdown()
        spinner.join(5.0)
        transport.close()
    # Markers RViz draws: a box per static instance coloured by the target's probability, and
    # its label.
    markers = got[lv.BELIEF_MARKERS][-1].markers
    boxes = [mk for mk in markers if mk.type == lv.CUBE and mk.action == lv.ADD]
    labels = [mk.text for mk in markers if mk.type == lv.TEXT]
    assert len(boxes) == len(labels) == len(ctx.home.statics)
    assert all(mk.header.frame_id == "map" for mk in markers)
    assert len({(round(b.color.r, 3), round(b.color.g, 3)) for b in boxes}) > 2
    # The typed belief is the where answer over the same events (the last search's target).
    target = got[lv.BELIEF][-1].target
    answer = where(events, target, top=len(ctx.home.statics))
    places = [(p.static_id, round(p.probability, 4)) for p in got[lv.BELIEF][-1].places]
    assert places == [(p["static_id"], p["probability"]) for p in answer["most_likely_now"]]
    best = answer["most_likely_now"][0]
    label = f"{ctx.home.statics[best['static_id']].cls} {100 * best['probability']:.1f} %"
    assert label in labels
    # The typed scene graph: every Rel > 0, the task's plan.
    graph = next(g for g in got[lv.GRAPH] if g.event == "plan_computed")
    assert graph.relations and all(0 < r.rel <= 1 for r in graph.relations)
    assert graph.target and graph.room and list(graph.order)
