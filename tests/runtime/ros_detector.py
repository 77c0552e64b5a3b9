"""A ROS 2 detector node as a robot's owner runs one, as a script of its own: plain rclpy and
``vision_msgs`` only, no objsearch module (checked at the end). It publishes
``vision_msgs/Detection3DArray`` on its output topic, each array made here from one it reads (a
detector that refines another's detections; here the stand-in robot's camera gives the input).

    python ros_detector.py DOMAIN IN_TOPIC OUT_TOPIC   # until its stdin closes

Prints one JSON document on stdout: the arrays and detections it published.
"""

from __future__ import annotations

import json
import os
import sys
import threading
from typing import Any

import rclpy
from rclpy.executors import MultiThreadedExecutor
from vision_msgs.msg import Detection3D, Detection3DArray


def main() -> None:
    domain, source, target = int(sys.argv[1]), sys.argv[2], sys.argv[3]
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

    node.create_subscription(Detection3DArray, source, on_array, 10)
    executor = MultiThreadedExecutor(num_threads=2)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
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
