"""A ROS 2 detector node as a robot's owner runs one, as a script of its own: plain rclpy and
``vision_msgs`` only, no objsearch module (checked at the end). It publishes
``vision_msgs/Detection3DArray`` on its output topic, each array made here from one it reads (a
detector that refines another's detections; here the stand-in robot's camera gives the input).

    python ros_detector.py DOMAIN IN_TOPIC OUT_TOPIC MATCH_S   # until its stdin closes

It prints ``ready`` once its output has a subscriber (the agent's) and its input a publisher
(the stand-in robot's), both matched, or at MATCH_S seconds a line saying which is missing; then,
at the end, one JSON document: the arrays and detections it published.

Why it waits: the stand-in robot sends each camera view once (a camera would send the next
frame), and a reliable, volatile writer delivers nothing written before it matched a reader, so
an array relayed before the agent's subscription matched this node's publisher was lost for
good, and the agent waited in vain for the view of its first container opening (issue 45). The
input is read transient-local (the test's robot offers its arrays so) because only the reader's
side of that match can be seen from here: an array the robot sent before its writer matched
this reader still comes.
"""

from __future__ import annotations

import json
import os
import sys
import threading
import time
from typing import Any

import rclpy
from rclpy.executors import MultiThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from vision_msgs.msg import Detection3D, Detection3DArray

#: The input's QoS: reliable, transient-local, the last 10 (robot.toml's ``[qos] detections``
#: of the test's robot offers the same).
LATCHED = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)


def main() -> None:
    domain, source, target = int(sys.argv[1]), sys.argv[2], sys.argv[3]
    match_s = float(sys.argv[4])
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    rclpy.init(domain_id=domain)
    node = rclpy.create_node(f"ros_detector_{os.getpid()}")
    publisher = node.create_publisher(Detection3DArray, target, 10)
    counts = {"arrays": 0, "detections": 0}

    def on_array(msg: Any) -> None:
        out = Detection3DArray(header=msg.header)
        for d in msg.detections:
            out.detections.append(
                Detection3D(header=d.header, results=list(d.results), bbox=d.bbox, id=d.id)
            )
        publisher.publish(out)
        counts["arrays"] += 1
        counts["detections"] += len(out.detections)

    subscription = node.create_subscription(Detection3DArray, source, on_array, LATCHED)
    executor = MultiThreadedExecutor(num_threads=2)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    deadline = time.monotonic() + match_s
    while not (publisher.get_subscription_count() and subscription.get_publisher_count()):
        if time.monotonic() > deadline:
            print(
                f"not matched after {match_s:g} s: {publisher.get_subscription_count()} "
                f"subscriber(s) of {target}, {subscription.get_publisher_count()} "
                f"publisher(s) of {source}",
                flush=True,
            )
            break
        time.sleep(0.01)
    else:
        print("ready", flush=True)
    try:
        sys.stdin.read()  # until the test closes it
    finally:
        rclpy.try_shutdown()
        executor.shutdown(timeout_sec=60.0)
        spinner.join(timeout=60.0)
        node.destroy_node()
    out: dict[str, Any] = dict(counts)
    out["objsearch_modules"] = sorted(
        n for n in sys.modules if n == "objsearch" or n.startswith("objsearch.")
    )
    print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
    os._exit(0)  # as ros_user.py: no interpreter teardown under rclpy's C++ objects
