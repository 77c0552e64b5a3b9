"""A ROS 2 user's client of the agent, run as a script of its own: plain rclpy and the generated
``objsearch_msgs`` only, no objsearch module (checked at the end), as ``ros2 action send_goal``
and ``ros2 service call`` would meet the agent.

    python ros_user.py find DOMAIN TARGET,TARGET,...   # one goal per target, then one cancelled
    python ros_user.py where DOMAIN TARGET COUNT       # COUNT Where calls

Prints one JSON document on stdout with what it got.
"""

from __future__ import annotations

import json
import os
import sys
import threading
import time
from typing import Any

import rclpy
from objsearch_msgs.action import FindObject
from objsearch_msgs.srv import Where
from rclpy.action import ActionClient
from rclpy.executors import MultiThreadedExecutor

WAIT_S = 120.0
STATUS_SUCCEEDED, STATUS_CANCELED = 4, 5


def wait(future: Any, what: str, timeout_s: float = WAIT_S) -> Any:
    deadline = time.monotonic() + timeout_s
    while not future.done():
        if time.monotonic() > deadline:
            raise SystemExit(f"ros_user: no {what} within {timeout_s} s")
        time.sleep(0.01)
    return future.result()


def find(node: Any, targets: list[str]) -> dict[str, Any]:
    client = ActionClient(node, FindObject, "/objsearch/find_object")
    if not client.wait_for_server(timeout_sec=WAIT_S):
        raise SystemExit("ros_user: no FindObject server")
    goals = []
    for target in targets:
        feedback: list[Any] = []
        handle = wait(
            client.send_goal_async(
                FindObject.Goal(target=target), feedback_callback=feedback.append
            ),
            "goal answer",
        )
        if not handle.accepted:
            goals.append({"target": target, "accepted": False})
            continue
        got = wait(handle.get_result_async(), "result")
        r = got.result
        goals.append(
            {
                "target": target,
                "accepted": True,
                "status": got.status,
                "found": r.found,
                "task_id": r.task_id,
                "place": r.place,
                "room": r.room,
                "position": [r.pose.pose.position.x, r.pose.pose.position.y],
                "path_length": r.path_length,
                "error": r.error,
                "feedback": len(feedback),
                "feedback_rooms": sorted({f.feedback.room for f in feedback}),
                "feedback_belief": max((len(f.feedback.belief) for f in feedback), default=0),
            }
        )
    # One more, cancelled once its search is under way (its first feedback).
    started = threading.Event()
    heard: list[Any] = []

    def on_feedback(msg: Any) -> None:
        heard.append(msg)
        started.set()

    handle = wait(
        client.send_goal_async(FindObject.Goal(target=targets[0]), feedback_callback=on_feedback),
        "goal answer",
    )
    cancel: dict[str, Any] = {"accepted": bool(handle.accepted)}
    if handle.accepted:
        if not started.wait(WAIT_S):
            raise SystemExit("ros_user: no feedback of the goal to cancel")
        answer = wait(handle.cancel_goal_async(), "cancel answer")
        got = wait(handle.get_result_async(), "result of the cancelled goal")
        cancel.update(
            return_code=answer.return_code,
            status=got.status,
            error=got.result.error,
            task_id=got.result.task_id,
            found=got.result.found,
            feedback=len(heard),
        )
    return {"goals": goals, "cancelled": cancel}


def where(node: Any, target: str, count: int) -> dict[str, Any]:
    client = node.create_client(Where, "/objsearch/where_object")
    if not client.wait_for_service(timeout_sec=WAIT_S):
        raise SystemExit("ros_user: no Where service")
    answers = []
    for _ in range(count):
        r = wait(client.call_async(Where.Request(target=target)), "Where answer")
        answers.append(
            {
                "ok": r.ok,
                "target": r.target,
                "places": [(p.static_id, p.probability) for p in r.places],
                "rooms": [(p.room, p.probability) for p in r.rooms],
                "seen": r.last_seen.seen,
                "age_s": r.last_seen.age_s,
                "json": bool(r.answer_json),
            }
        )
    unknown = wait(client.call_async(Where.Request(target="Unicorn")), "Where answer")
    return {"answers": answers, "unknown": {"ok": unknown.ok, "error": unknown.error}}


def main() -> None:
    mode, domain = sys.argv[1], int(sys.argv[2])
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    rclpy.init(domain_id=domain)
    node = rclpy.create_node(f"ros_user_{os.getpid()}")
    executor = MultiThreadedExecutor(num_threads=4)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        if mode == "find":
            out = find(node, sys.argv[3].split(","))
        else:
            out = where(node, sys.argv[3], int(sys.argv[4]))
    finally:
        # Shut the context first (it wakes the executor's wait), then wait for the spin thread:
        # on a loaded machine a 5 s executor shutdown left it running, and a C++ thread alive at
        # interpreter exit aborts the process ("terminate called without an active exception").
        rclpy.try_shutdown()
        executor.shutdown(timeout_sec=60.0)
        spinner.join(timeout=60.0)
        node.destroy_node()
    out["objsearch_modules"] = sorted(
        n for n in sys.modules if n == "objsearch" or n.startswith("objsearch.")
    )
    print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
    # The answer is printed and every node destroyed; skip the interpreter's teardown, where
    # rclpy's C++ objects may still abort the process, which would fail a client that did its work.
    os._exit(0)
