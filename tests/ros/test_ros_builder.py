"""The shared message builders: the runtime's and the recorder's messages are the same bytes, and
the on-robot path loads no simulator or pipeline code."""

from __future__ import annotations

import subprocess
import sys
import textwrap

from objsearch.agent.geometry import Pose
from objsearch.agent.world import Detection
from objsearch.pipeline.bags.record import box_camera
from objsearch.ros.builder import DEFAULT_BOX_CAMERA, MessageBuilder
from objsearch.ros.topics import TopicMap
from objsearch.ros.types import Distro, typestore
from objsearch.runtime import messages as m
from objsearch.sim.perception import Camera


def test_default_box_camera_is_the_simulators() -> None:
    assert box_camera(Camera()) == DEFAULT_BOX_CAMERA


def test_runtime_detections_are_the_recorders_bytes() -> None:
    pose = Pose(1.0, 2.0, 0.5)
    dets = [Detection("Cup", "Cup|1", 900.0, (2.5, 2.5, 0.9))]
    recorded = MessageBuilder(Distro.ROS2, TopicMap(), box_camera(Camera())).detections(
        7, pose, dets
    )
    store = typestore(Distro.ROS2)
    assert m.encode(m.detections(7, pose, dets), m.DETECTIONS) == bytes(
        store.serialize_cdr(recorded, m.DETECTIONS)
    )
    (back,) = m.detections_of(
        m.decode(m.encode(m.detections(7, pose, dets), m.DETECTIONS), m.DETECTIONS)
    )
    assert back.object_class == "Cup" and back.instance_id == "Cup|1"
    assert abs(back.mask_area - 900.0) < 1e-6


def test_the_robot_path_loads_no_simulator_or_pipeline() -> None:
    """What ``objsearch agent run`` loads on a robot: the node, its world, the live view, and
    building an event and a detection message."""
    code = textwrap.dedent(
        """
        import sys
        from objsearch.agent.geometry import Pose
        from objsearch.agent.world import Detection
        import objsearch.runtime.agent_node, objsearch.runtime.rosworld
        import objsearch.runtime.liveview, objsearch.runtime.livesinks, objsearch.runtime.config
        from objsearch.runtime import messages as m
        m.encode(m.detections(1, Pose(0, 0, 0), [Detection("Cup", "Cup|1", 4.0, (1, 0, 1))]), m.DETECTIONS)
        loaded = sorted(n for n in sys.modules if n.startswith(("objsearch.sim", "objsearch.pipeline")))
        print(",".join(loaded))
        """
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""
